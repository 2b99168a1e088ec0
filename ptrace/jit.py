"""numba's on-disk cache: where it goes, what happens when it is broken, and whether it is cold.

Imported first by the ptrace package, before any kernel is decorated, so that:
- with no writable cache folder anywhere numba looks (NUMBA_CACHE_DIR, the __pycache__ beside
  ptrace's and accel's sources, the user's cache folder) ptrace still imports: the cache goes to
  a per-user folder under the temporary directory (owned by the user, mode 0700), else a fresh
  temporary folder (kept for this run only), else nowhere (every run compiles);
- a cache file that cannot be read back (garbage in an index or data file, a truncated pickle)
  counts as missing: the kernel is recompiled and the file rewritten, not an UnpicklingError;
  a cache file that cannot be saved (a full disk) leaves the compiled kernel in use.
Each of these says so in one note (cache_notes(); render() warns with them once).
"""
import hashlib
import json
import os
import re
import stat
import tempfile

# The wait the cold notice announces until this machine has measured its own (remember_compile):
# a small render's compile with an empty cache ("first"), and another backend's on the first
# one's cache ("backend"), on the 2-core development machine, rounded (the commit that last set
# them gives the command and the runs; re-measure them when the kernels change much).
COLD_COMPILE_SECONDS = {"first": 15, "backend": 5}
_MEASURED = "ptrace-compile-seconds.json"   # in the cache folder of the stage cold() reads

_NOTES = {}   # kind -> (its first note, the files it concerned), in the order they happened


def _note(text, kind=None, path=None):
    """Note `text`, once per kind (default: the text itself), counting the files it concerns."""
    _NOTES.setdefault(kind or text, (text, set()))[1].add(path)


def cache_notes(clear=False):
    """The notes about numba's cache so far (a fallback folder, corrupt files recompiled), one
    line per kind, each with how many more files it concerned; clear=True empties the list, so
    that each is told once."""
    notes = [text if len(paths) < 2 else f"{text} (and {len(paths) - 1} more files like it)"
             for text, paths in _NOTES.values()]
    if clear:
        _NOTES.clear()
    return notes


def _kernel_folders():
    """The folders whose sources hold cached kernels: ptrace's and accel's (found without
    importing accel, whose kernels would be decorated before the cache is set up)."""
    import importlib.util
    here = os.path.dirname(os.path.abspath(__file__))
    spec = importlib.util.find_spec("accel")
    folders = [here]
    if spec is not None and spec.origin:
        folders.append(os.path.dirname(os.path.abspath(spec.origin)))
    return folders


def _numba_finds_a_cache(folder):
    """Whether numba's own locators (in their order) find a writable cache folder for a
    kernel defined in `folder`: the same test numba makes when it decorates one."""
    from numba.core import caching
    implementation = getattr(caching, "CacheImpl", None) or caching._CacheImpl

    def probe():
        pass
    source = os.path.join(folder, "__init__.py")
    if not os.path.exists(source):
        source = os.path.abspath(__file__)
    for locator in implementation._locator_classes:
        try:
            if locator.from_function(probe, source) is not None:
                return True
        except Exception:   # noqa: BLE001 - a locator that fails finds nothing
            continue
    return False


def _writable(folder):
    try:
        os.makedirs(folder, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except OSError:
        return False


def _private_folder():
    """<tmp>/ptrace-numba-<uid>, made mode 0700 if missing, and used only if it is a real folder
    (not a link) owned by this user that no one else can write (another user's planted cache
    would be code run here); else None."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    folder = os.path.join(tempfile.gettempdir(), f"ptrace-numba-{uid}")
    try:
        os.mkdir(folder, 0o700)
    except FileExistsError:
        pass
    except OSError:
        return None
    try:
        info = os.lstat(folder)
    except OSError:
        return None
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != uid or info.st_mode & 0o077:
        return None
    return folder if _writable(folder) else None


def _use_folder(folder):
    import numba
    os.environ["NUMBA_CACHE_DIR"] = folder   # numba's compiler reloads its config from here
    numba.config.CACHE_DIR = folder


def _disable_caching():
    """Every kernel compiles in each process: cache=True is ignored."""
    from numba.core import dispatcher
    dispatcher.Dispatcher.enable_caching = lambda self: None


def configure_cache(folders=None):
    """Give numba a writable cache folder for kernels in `folders` (default ptrace's and
    accel's), or turn caching off, with a note saying which; nothing changes when numba finds
    one itself."""
    folders = _kernel_folders() if folders is None else folders
    try:
        if all(_numba_finds_a_cache(folder) for folder in folders):
            return None
    except Exception:   # noqa: BLE001 - numba's internals moved: leave numba to it
        return None
    folder = _private_folder()
    lasting = folder is not None
    if folder is None:
        try:
            folder = tempfile.mkdtemp(prefix="ptrace-numba-")
        except OSError:
            folder = None
    where = "beside ptrace's sources, in NUMBA_CACHE_DIR or in the user's cache folder"
    if folder is None:
        _disable_caching()
        _note(f"numba's cache: no writable folder {where} or in the temporary folder; the "
              f"kernels are compiled anew in every run")
        return None
    _use_folder(folder)
    _note(f"numba's cache: no writable folder {where}; compiled kernels are kept in {folder}"
          + ("" if lasting else " for this run only"))
    return folder


def _guard_cache_files():
    """A cache file numba cannot read back counts as missing (recompile and rewrite it), and
    one it cannot save leaves the compiled kernel in use; each says so in a note."""
    from numba.core import caching
    index_file, cache = caching.IndexDataCacheFile, caching.Cache
    if getattr(index_file, "_ptrace_guarded", False):
        return
    load_index, load_overload = index_file._load_index, cache.load_overload
    save_overload = cache.save_overload

    def guarded_load_index(self):
        try:
            return load_index(self)
        except Exception as error:   # noqa: BLE001 - garbage in the file: any unpickling error
            _note(f"numba's cache: {self._index_path} could not be read "
                  f"({type(error).__name__}); recompiling and rewriting it", "index",
                  self._index_path)
            return {}

    def guarded_load_overload(self, sig, target_context):
        try:
            return load_overload(self, sig, target_context)
        except Exception as error:   # noqa: BLE001 - as above, for a data file
            _note(f"numba's cache: a compiled kernel in {self._cache_path} could not be read "
                  f"({type(error).__name__}); recompiling it", "data",
                  (self._cache_path, self._name, repr(sig)))
            return None

    def guarded_save_overload(self, sig, data):
        try:
            return save_overload(self, sig, data)
        except Exception as error:   # noqa: BLE001 - a full or read-only cache folder
            _note(f"numba's cache: a compiled kernel could not be saved in {self._cache_path} "
                  f"({error}); it is compiled again next run", "save",
                  (self._cache_path, self._name, repr(sig)))

    index_file._load_index = guarded_load_index
    cache.load_overload = guarded_load_overload
    cache.save_overload = guarded_save_overload
    index_file.save = _locked(index_file.save, exclusive=True)
    index_file.load = _locked(index_file.load, exclusive=False)
    index_file._ptrace_guarded = True


def _locked(method, exclusive):
    """An IndexDataCacheFile method run holding a lock on its index (a .lock file beside it):
    numba saves an entry as two replaced files (the index, then the data file it names), so two
    processes compiling two kernels of one index at once (two closures of a stage, two
    backends' records) could leave an index naming the other's data, and a third process reading
    between the two writes could load one kernel for another's arguments. Saves are exclusive,
    loads shared. Where no lock can be had (no fcntl, a read-only folder) numba's own way
    stands."""
    def locked(self, *args):
        try:
            import fcntl
            handle = open(self._index_path + ".lock", "ab")
        except (ImportError, OSError):
            return method(self, *args)
        with handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
            except OSError:   # a filesystem without locks
                pass
            return method(self, *args)     # closing the file releases the lock
    locked.__wrapped__ = method
    return locked


def _one_compile_of_a_kernel_at_a_time():
    """Processes that lack the same kernel at the same time (the test suite's workers, two
    renders started together, a render and its compile-ahead workers sharing a callee) each
    compiled it. A process about to compile or load a kernel holds a lock named by the
    kernel's cache key (a file beside its index) until it has the kernel, so a second process
    waits for the first's save and loads it. The lock is taken inside numba's compiler lock
    (one thread of a process compiles at a time), so no two threads of a process wait on each
    other through it; a kernel's lock is held while its callees compile, and a callee never
    calls its caller, so no two processes wait on each other either. Where no lock can be had
    (no fcntl, a read-only folder), numba's own way stands."""
    from numba.core import dispatcher
    from numba.core.compiler_lock import global_compiler_lock
    compile_ = dispatcher.Dispatcher.compile
    if getattr(compile_, "_ptrace_locked", False):
        return

    def compile(self, sig):
        with global_compiler_lock:
            path = _compile_lock_path(self, sig)
            if path is None:
                return compile_(self, sig)
            try:
                import fcntl
                handle = open(path, "ab")
            except (ImportError, OSError):
                return compile_(self, sig)
            with handle:
                try:
                    fcntl.flock(handle, fcntl.LOCK_EX)
                except OSError:   # a filesystem without locks
                    pass
                return compile_(self, sig)    # closing the file releases the lock

    compile._ptrace_locked = True
    compile.__wrapped__ = compile_
    dispatcher.Dispatcher.compile = compile


def _compile_lock_path(kernel, sig):
    """The lock file of kernel's compile for sig, beside its cache index; None without an
    on-disk cache, or when the kernel is compiled in this process already."""
    try:
        if isinstance(sig, tuple) and sig in kernel.overloads:
            return None
        index_file = getattr(kernel._cache, "_cache_file", None)
        if index_file is None:    # caching off (numba's NullCache)
            return None
        key = kernel._cache._index_key(sig, kernel.targetctx.codegen())
        name = hashlib.sha256(repr(key).encode()).hexdigest()[:24]
        return f"{index_file._index_path}.{name}.compiling"
    except Exception:   # noqa: BLE001 - numba's internals moved: compile without the lock
        return None


_DEPENDENCY_FOLDERS = []
_BY_IMPORTS = []   # the folders of _DEPENDENCY_FOLDERS whose kernels depend on their imports


# ptrace's subpackages that hold no compiled code and that no kernel reads from (the loaders,
# the commands and viewer, the render job): an edit there recompiles nothing
# (tests/ptrace/test_layout.py checks both)
KERNEL_FREE = ("io", "app", "rendering")


def _folders_digest(folders):
    """sha256 over the contents of every .py file under the folders (by path relative to its
    folder) but those in its KERNEL_FREE subfolders, so that any edit to any of them changes
    it."""
    digest = hashlib.sha256()
    for folder in folders:
        for root, dirs, files in os.walk(folder):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__" and not (
                os.path.samefile(root, folder) and d in KERNEL_FREE))
            for name in sorted(files):
                if name.endswith(".py"):
                    path = os.path.join(root, name)
                    digest.update(os.path.relpath(path, folder).encode() + b"\0")
                    with open(path, "rb") as source:
                        digest.update(source.read())
    return digest.digest()


_NAMES = {}    # folders -> _module_names(folders)


def _module_names(folders):
    """{dotted module name: source path} of every .py file under the folders (each folder a
    package named as it is)."""
    if tuple(folders) in _NAMES:
        return _NAMES[tuple(folders)]
    names = _NAMES[tuple(folders)] = {}
    for folder in folders:
        package = os.path.basename(folder)
        for root, dirs, files in os.walk(folder):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            for name in sorted(files):
                if name.endswith(".py"):
                    path = os.path.join(root, name)
                    parts = [package] + os.path.relpath(path, folder)[:-3].split(os.sep)
                    if parts[-1] == "__init__":
                        parts.pop()
                    names[".".join(parts)] = path
    return names


_PARSED = {}   # source path -> (modules it imports within the by-imports folders, other folders)

# an import statement at a line's start (or after a `;`): `from BASE import NAMES` (NAMES in
# parentheses over several lines, or to the line's end) or `import MODULES`
_STATEMENT = re.compile(r"(?:^|;)[ \t]*(?:from[ \t]+(\.*[\w.]*)[ \t]+import[ \t]+"
                        r"(\([^)]*\)|[^\n;]*)|import[ \t]+([^\n;]*))", re.MULTILINE)


def _import_statements(text):
    """[(base, [names])] of a module's source: `from base import names` (base with its leading
    dots) and, with base None, `import names`; inside functions too. Read by a regular
    expression, not by parsing the module (ast.parse of a kernel's modules took about 0.4 s of
    every process that loads one): words that read as an import inside a string may add a
    name, which at most makes a kernel depend on one module more."""
    found = []
    for match in _STATEMENT.finditer(text.replace("\\\n", " ")):
        body = re.sub(r"#[^\n]*", "", match.group(3) if match.group(3) is not None
                      else match.group(2)).strip().strip("()")
        names = [re.split(r"\s+as\s+", part.strip())[0] for part in body.split(",")]
        found.append((match.group(1), [name for name in names if name]))
    return found


def _imports(path, module, names):
    """(the modules of `names` that the source at `path`, module `module`, imports anywhere in
    it, inside functions too; the other dependency folders whose packages it imports from), by
    its import statements: `from a import b` imports a.b if that is a module, else a."""
    if path in _PARSED:
        return _PARSED[path]
    with open(path, encoding="utf-8", errors="replace") as source:
        statements = _import_statements(source.read())
    package = module if path.endswith("__init__.py") else module.rpartition(".")[0]
    own = module.split(".")[0]
    packages = {os.path.basename(folder): folder for folder in _DEPENDENCY_FOLDERS}
    found, others = set(), set()
    for base, imported in statements:
        if base is None:
            found.update(imported)
            continue
        level = len(base) - len(base.lstrip("."))
        base = base[level:]
        if level:
            parts = package.split(".")
            parts = parts[:len(parts) - level + 1]
            base = ".".join(parts + ([base] if base else []))
        found.update(f"{base}.{name}" if f"{base}.{name}" in names else base
                     for name in imported)
    for name in found:
        head = name.split(".")[0]
        if head != own and head in packages:
            others.add(packages[head])
    _PARSED[path] = ({name for name in found if name in names}, others)
    return _PARSED[path]


def _imports_digest(path, folders, whole):
    """sha256 over the sources of the module at `path` and of every module it imports,
    directly or through others, within `folders`; another dependency folder imported from
    brings in its whole digest (`whole(folder)`)."""
    names = _module_names(folders)
    modules = {os.path.abspath(source): name for name, source in names.items()}
    start = modules.get(os.path.abspath(path))
    if start is None:    # (not a module of theirs: a file numba found another way)
        return b"".join(whole(folder) for folder in folders)
    seen, todo, others = {start}, [start], set()
    while todo:
        module = todo.pop()
        imported, folders_used = _imports(names[module], module, names)
        others |= folders_used
        for name in imported - seen:
            seen.add(name)
            todo.append(name)
    digest = hashlib.sha256()
    for name in sorted(seen):
        digest.update(name.encode() + b"\0")
        with open(names[name], "rb") as source:
            digest.update(source.read())
    for folder in sorted(others):
        digest.update(whole(folder))
    return digest.digest()


def depend_on_folders(folders, by_imports=()):
    """Make the cached kernels defined under `folders` depend on other source files, not only on
    the file that defines each: numba's cache checks a kernel's own file alone, so after an edit
    to a module it calls (and inlines), the old kernel would be loaded (an editable install
    updated with `git pull` would render with stale code). A kernel under a folder of
    `by_imports` depends on its module and every module that one imports, directly or through
    others, by their import statements (so an edit to the BSDFs recompiles what imports them,
    not the sampler or the solid-angle code); any other kernel, and any module importing from
    another of the folders, on every source file of that folder (accel's backends register
    themselves with accel.compiled, which imports none of them). Called for ptrace's (by
    imports) and accel's folders on import."""
    from numba.core import caching
    mixin = caching._SourceFileBackedLocatorMixin
    folders = [os.path.abspath(folder) for folder in folders]
    by_imports = [os.path.abspath(folder) for folder in by_imports]
    _DEPENDENCY_FOLDERS.extend(f for f in folders + by_imports if f not in _DEPENDENCY_FOLDERS)
    _BY_IMPORTS.extend(f for f in by_imports if f not in _BY_IMPORTS)
    if getattr(mixin, "_ptrace_stamp", None) is not None:
        return
    own_stamp = mixin.get_source_stamp
    digests = {}

    def whole(folder):
        if folder not in digests:
            digests[folder] = _folders_digest([folder])
        return digests[folder]

    def digest(path):
        for folder in _DEPENDENCY_FOLDERS:
            if path.startswith(folder + os.sep):
                if folder not in _BY_IMPORTS:
                    return whole(folder)
                if path not in digests:
                    digests[path] = _imports_digest(path, _BY_IMPORTS, whole)
                return digests[path]
        return None

    def stamp(self):
        base = own_stamp(self)
        path = os.path.abspath(self._py_file)
        if not any(path.startswith(folder + os.sep) for folder in _DEPENDENCY_FOLDERS):
            return base
        return _Later(lambda: (base, digest(path)))

    mixin.get_source_stamp = stamp
    mixin._ptrace_stamp = stamp
    _stamps_read_when_used()


class _Later:
    """A kernel's source stamp to be worked out when numba's cache first reads or writes its
    index (_stamps_read_when_used), not when the kernel is defined: the digests read and parse
    the sources, which took about 0.4 s of every process's start, --help and refused files
    included, though most processes load or compile only a few kernels, or none."""

    def __init__(self, work):
        self.work = work


def _stamps_read_when_used():
    """numba's index file keeps its kernel's source stamp as _source_stamp, set when the kernel
    is defined: make it an attribute that works out a _Later stamp on first use."""
    from numba.core import caching
    index_file = caching.IndexDataCacheFile
    if isinstance(getattr(index_file, "_source_stamp", None), property):
        return

    def get(self):
        # (an index made before ptrace.jit was imported holds its stamp as numba set it)
        value = self.__dict__.get("_ptrace_source_stamp", self.__dict__.get("_source_stamp"))
        if isinstance(value, _Later):
            value = self.__dict__["_ptrace_source_stamp"] = value.work()
        return value

    def set_(self, value):
        self.__dict__["_ptrace_source_stamp"] = value

    index_file._source_stamp = property(get, set_)


def _cell_key(value):
    """What a closure's cell holds, as its cached kernels' key sees it: a numba function by what
    it is (its module, name, bytecode, options and, for a closure, its own cells), anything else
    as it is."""
    from numba.core.dispatcher import Dispatcher
    if not isinstance(value, Dispatcher):
        return value
    function = value.py_func
    return ("numba function", function.__module__, function.__qualname__,
            function.__code__.co_code, sorted(value.targetoptions.items()),
            tuple(_cell_key(cell.cell_contents) for cell in function.__closure__ or ()))


def _key_closures_by_their_functions():
    """numba keys a cached closure by the pickled contents of its cells, and a numba function
    pickles with an id drawn afresh in each process (numba issue 6264): a kernel made by a
    factory that captures numba functions (ptrace's shading and hit stages capture their kind's
    BSDF functions and their light sampler's) was never found in the cache, and compiled again
    in every run. Such a closure's key hashes its cells by _cell_key instead (the sources those
    functions come from are in the key already: depend_on_folders). Closures of other values
    keep numba's own key."""
    from numba.core import caching, serialize
    from numba.core.dispatcher import Dispatcher
    cache = caching.Cache
    if getattr(cache, "_ptrace_keyed", False):
        return
    own_key = cache._index_key

    def index_key(self, sig, codegen):
        closure = self._py_func.__closure__
        if not closure or not any(isinstance(cell.cell_contents, Dispatcher)
                                  for cell in closure):
            return own_key(self, sig, codegen)
        cells = serialize.dumps(tuple(_cell_key(cell.cell_contents) for cell in closure))
        return (sig, codegen.magic_tuple(),
                (hashlib.sha256(self._py_func.__code__.co_code).hexdigest(),
                 hashlib.sha256(cells).hexdigest()))

    cache._index_key = index_key
    cache._ptrace_keyed = True


try:
    _guard_cache_files()
    depend_on_folders(_kernel_folders()[1:], by_imports=_kernel_folders()[:1])
    _key_closures_by_their_functions()
    _one_compile_of_a_kernel_at_a_time()
except (ImportError, AttributeError):   # numba's internals moved: its own behaviour stays
    pass
configure_cache()


def _closest_stage():
    """The stage compiled once per backend (and first): the one whose cache cold() reads."""
    from .kernel.trace import closest_stage
    return closest_stage


def cold(record_class, dispatcher=None):
    """What numba's cache lacks of this backend's render kernels: None (they are cached),
    "backend" (another backend's are: the stages that every backend shares come from the cache)
    or "first" (none are). Reads only the cache's index, of `dispatcher` (default the closest-hit
    stage, which dominates the backend's compile); any surprise in numba's internals counts as
    cached (no message rather than a wrong one)."""
    dispatcher = _closest_stage() if dispatcher is None else dispatcher
    try:
        index = dispatcher._cache._cache_file._load_index()
    except Exception:   # noqa: BLE001 - numba internals: never let a notice break a render
        return None
    classes = {getattr(t, "instance_class", None) for key in index for t in key[0]}
    if record_class in classes:
        return None
    return "backend" if classes - {None} else "first"


def _measured_path(dispatcher=None):
    dispatcher = _closest_stage() if dispatcher is None else dispatcher
    return os.path.join(dispatcher._cache._cache_path, _MEASURED)


def compile_estimate(kind, dispatcher=None):
    """The seconds a cold compile of `kind` (cold()'s "first" or "backend") takes here: the last
    one measured on this cache (remember_compile), else COLD_COMPILE_SECONDS'."""
    try:
        with open(_measured_path(dispatcher)) as file:
            seconds = float(json.load(file)[kind])
        if 0.0 < seconds < 1e5:
            return seconds
    except Exception:   # noqa: BLE001 - none measured, or a file not ours: the default
        pass
    return float(COLD_COMPILE_SECONDS[kind])


def remember_compile(kind, seconds, dispatcher=None):
    """Keep a cold compile's measured seconds beside numba's cache, for the next cold notice of
    the same kind (written whole or not at all; a read-only cache keeps nothing)."""
    try:
        path = _measured_path(dispatcher)
        try:
            with open(path) as file:
                measured = {k: v for k, v in json.load(file).items()
                            if k in COLD_COMPILE_SECONDS}
        except Exception:   # noqa: BLE001 - none yet, or unreadable: start again
            measured = {}
        measured[kind] = round(float(seconds), 1)
        temporary = f"{path}.{os.getpid()}.tmp"
        with open(temporary, "w") as file:
            json.dump(measured, file)
        os.replace(temporary, path)
    except Exception:   # noqa: BLE001 - a notice's estimate never breaks a render
        pass
