"""Mitsuba's XML scene format, parsed into a tree of plugins (Plugin) with typed parameters.

What this module promises: the file and every file it includes are read with a hardened XML
parser (defusedxml: no entity declarations, no DTDs, no external references); `$name` in an
attribute is replaced by its value from `-D name=value` (the `defines`) or the file's own
`<default name=.. value=..>`; `<include>` and `<path>` read only inside the scene's folder;
`<ref>` finds an `id` anywhere in the scene; every value element (`<float>`, `<integer>`,
`<boolean>`, `<string>`, `<rgb>`, `<spectrum>` (a constant, wavelength:value pairs, or a file of
them),
`<point>`, `<vector>`, `<transform>`) becomes a checked Python value. Files of version 0.4 to
0.6 are upgraded as Mitsuba 3 upgrades them: camelCase parameter names become snake_case,
`<lookAt>` becomes `<lookat>`, `<srgb>` an RGB colour decoded from sRGB. Every problem is one
SceneError naming the file and the element.
"""
import os
import re
import stat

import defusedxml
import defusedxml.ElementTree as safe_xml
import numpy as np

from ..errors import SceneError
from .files import require_regular_file
from .limits import is_float, problem
from .mitsuba_spectra import blackbody_rgb, spectrum_to_rgb
from .mitsuba_transforms import (
    ElementError,
    Transform,
    at,
    describe,
    element_error,
    parse_transform,
)

OBJECT_TAGS = ("scene", "shape", "bsdf", "emitter", "sensor", "film", "sampler", "integrator",
               "texture", "medium", "phase", "rfilter", "volume")
VALUE_TAGS = ("float", "integer", "boolean", "string", "rgb", "spectrum", "point", "vector",
              "transform", "srgb")
MAX_INCLUDE_DEPTH = 32
MAX_NESTING = 64
MAX_SPECTRUM_FILE = 1 << 20     # bytes of a <spectrum filename=..> file
NAME = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


class Colour(tuple):
    """An RGB triple (linear) from <rgb>, <spectrum> or <srgb>."""


class Plugin:
    """One object of the scene: <shape type="obj" id=...>, its parameters by name (values, or
    Plugins for named nested objects and references), its unnamed nested Plugins in file order
    (children), the file it was read from, and how to name it in a message (where). A builder
    takes each parameter it reads with the typed getters; unread() lists those it never took."""

    def __init__(self, tag, kind, ident, path, where, line=None):
        self.tag, self.type, self.id, self.path, self.where = tag, kind, ident, path, where
        self.line = line        # of its element in its file, where the parser gave one
        self.params, self.children, self._read = {}, [], set()

    def fail(self, message):
        raise ElementError(self.path, f"{self.where}: {message}", self.line)

    def has(self, name):
        return name in self.params

    def get(self, name, default=None):
        self._read.add(name)
        return self.params.get(name, default)

    def _typed(self, name, default, types, what):
        value = self.get(name, None)
        if value is None:
            return default
        if not isinstance(value, types) or isinstance(value, bool) and bool not in types:
            self.fail(f"parameter {name!r} must be {what}, not {_kind_of(value)}")
        return value

    def float(self, name, default=None):
        value = self._typed(name, default, (float, int), "a number (<float>)")
        return None if value is None else float(value)

    def integer(self, name, default=None):
        return self._typed(name, default, (int,), "a whole number (<integer>)")

    def boolean(self, name, default=False):
        return self._typed(name, default, (bool,), "<boolean>")

    def string(self, name, default=None):
        return self._typed(name, default, (str,), "<string>")

    def transform(self, name="to_world"):
        value = self._typed(name, None, (Transform,), "a <transform>")
        return Transform(np.eye(4)) if value is None else value

    def point(self, name, default=None):
        value = self._typed(name, default, (np.ndarray,), "a <point> or <vector>")
        return None if value is None else np.asarray(value, dtype=np.float64)

    def colour(self, name, default=None):
        """An RGB colour (a <rgb>, constant <spectrum> or <float>), or a texture Plugin."""
        value = self._typed(name, default, (Colour, float, int, Plugin),
                            "a colour (<rgb>, <spectrum>, <float>) or a <texture>")
        if isinstance(value, (float, int)):
            return Colour((float(value),) * 3)
        if isinstance(value, Plugin) and value.tag != "texture":
            self.fail(f"parameter {name!r} is a <{value.tag}>, not a colour or a <texture>")
        return value

    def unread(self):
        return sorted(set(self.params) - self._read)


def _kind_of(value):
    for types, what in ((bool, "a <boolean>"), (int, "an <integer>"), (float, "a <float>"),
                        (str, "a <string>"), (Colour, "a colour"), (Transform, "a <transform>"),
                        (np.ndarray, "a <point>")):
        if isinstance(value, types):
            return what
    return f"a <{value.tag}>" if isinstance(value, Plugin) else type(value).__name__


class LineParser(safe_xml.DefusedXMLParser):
    """defusedxml's parser (no entity declarations, no external references), each element
    given the line it starts on as its sourceline."""

    def _start(self, tag, attr_list):
        element = super()._start(tag, attr_list)
        element.sourceline = self.parser.CurrentLineNumber
        return element


def camel_to_snake(name):
    """Mitsuba 3's rule: '_' before an upper-case letter that follows a lower-case one, then
    lower case (intIOR -> int_ior, toWorld -> to_world)."""
    return re.sub(r"(?<=[a-z])(?=[A-Z])", "_", name).lower()


class Reader:
    """Reads a scene file and its includes into a Plugin tree: read()."""

    def __init__(self, path, defines=None):
        self.path = str(path)
        self.folder = os.path.dirname(os.path.realpath(self.path))
        self.search = [self.folder]
        self.roots = [self.folder]     # the folders files may be read from (_inside)
        self.params = {str(k): str(v) for k, v in (defines or {}).items()}
        self.ids, self.refs, self.including = {}, [], []
        self.upgrade = False
        self.version = None
        self.notes = []     # what the parse converted, for the loader's notes

    # --- files ----------------------------------------------------------------------------

    def read(self):
        """The <scene> Plugin of the file, its references resolved."""
        root = self._parse_file(self.path)
        self.version = self._version(root)
        scene = Plugin("scene", "scene", None, self.path, "<scene>")
        self._children(root, scene, self.path, 0)
        for holder, name, element, ident, path in self.refs:
            if ident not in self.ids:
                raise at(path, element, f": no object has id {ident!r}")
            if name is None:
                holder.children.append(self.ids[ident])
            else:
                holder.params[name] = self.ids[ident]
        return scene

    def _parse_file(self, path):
        require_regular_file(path)
        try:
            with open(path, "rb") as stream:
                data = stream.read()
        except OSError as error:
            raise SceneError(path, f"cannot read the file: {error.strerror or error}") from None
        try:
            parser = LineParser()
            parser.feed(data)
            root = parser.close()
        except defusedxml.DefusedXmlException as error:
            raise SceneError(path, f"refused unsafe XML ({type(error).__name__}: entity "
                                   f"declarations, DTDs and external references are not "
                                   f"allowed)") from None
        except safe_xml.ParseError as error:
            line = getattr(error, "position", (None,))[0]
            raise ElementError(path, f"not well-formed XML: {error}", line) from None
        except (LookupError, ValueError, UnicodeError) as error:
            raise SceneError(path, f"not readable as XML: {error}") from None
        if root.tag != "scene":
            raise element_error(path, root, f"not a Mitsuba scene: the root element is "
                                            f"<{root.tag}>, "
                                            f"not <scene>")
        return root

    def _version(self, root):
        text = root.get("version")
        if text is None:
            raise element_error(self.path, root, "<scene> has no version attribute (Mitsuba "
                                                 "requires one, e.g. version=\"3.0.0\")")
        numbers = re.fullmatch(r"\s*(\d+)\.(\d+)(?:\.(\d+))?\s*", text)
        major, minor = (int(numbers[1]), int(numbers[2])) if numbers else (None, None)
        if major in (2, 3):
            return text
        if major == 0 and 4 <= minor <= 6:
            self.upgrade = True
            return text
        raise element_error(self.path, root, f'<scene version="{text[:20]}">: ptrace reads '
                                             f"Mitsuba scenes of versions 0.4 to 0.6 (upgraded) "
                                             f"and 2.x to 3.x")

    def resolve(self, plugin, name):
        """The real path of the file `name` that a Plugin names, inside the scene's folder and
        a regular file (a FIFO or device is never opened: it could block or stream forever)."""
        path = self._resolve(plugin.where, plugin.path, name, plugin.line)
        if not stat.S_ISREG(os.stat(path).st_mode):
            plugin.fail(f"{name!r} is not a regular file")
        return path

    def _inside(self, candidate):
        return any(os.path.commonpath([root, candidate]) == root for root in self.roots)

    def _resolve(self, where, path, name, line=None):
        """The real path of a file named in `path` at `where`, inside the scene's folder or a
        folder its <path> elements name (as named, from the naming file's folder or a <path>
        folder)."""
        if not name or "\x00" in name:
            raise ElementError(path, f"{where}: an empty or invalid file name", line)
        name = name.replace("\\", "/")
        for folder in ([os.path.dirname(os.path.realpath(path))] + self.search):
            candidate = os.path.realpath(os.path.join(folder, name))
            if not self._inside(candidate):
                continue
            if os.path.exists(candidate):
                return candidate
        candidate = os.path.realpath(os.path.join(self.folder, name))
        if not self._inside(candidate):
            raise ElementError(path, f"{where}: {name!r} is outside the scene's folder; ptrace "
                                     f"reads only files inside it and the folders its <path> "
                                     f"elements name", line)
        raise ElementError(path, f"{where}: file {name!r} not found", line)

    def _search_folder(self, element, path):
        """A <path value=..> folder (from the naming file's folder): searched for the files
        the scene names, and read from even outside the scene's folder (as Mitsuba's scenes
        share a `common` folder beside theirs), since the file itself names it (noted)."""
        name = self.required(element, "value", path).replace("\\", "/")
        if not name or "\x00" in name:
            raise at(path, element, ": an empty or invalid folder name")
        # from the naming file's folder, else the scene's (an included file's <path> is
        # Mitsuba's relative to the scene's folder)
        found = [f for f in (os.path.realpath(os.path.join(base, name)) for base in
                             (os.path.dirname(os.path.realpath(path)), self.folder))
                 if os.path.isdir(f)]
        if not found:
            raise at(path, element, f": folder {name!r} not found")
        folder = found[0]
        if not self._inside(folder):
            self.roots.append(folder)
            self.notes.append(f"<path value=\"{name}\">: a folder outside the scene's folder, "
                              f"read from as the file names it")
        self.search.append(folder)

    # --- elements -------------------------------------------------------------------------

    def attribute(self, element, key, path, default=None):
        """An attribute with every $name replaced; an unknown name is an error."""
        text = element.get(key)
        if text is None:
            return default

        def value(match):
            name = match.group(1)
            if name not in self.params:
                raise at(path, element, f": ${name} has no value (no "
                                        f'<default name="{name}"> before it and no -D '
                                        f"{name}=...)")
            return self.params[name]
        return NAME.sub(value, text)

    def required(self, element, key, path):
        value = self.attribute(element, key, path)
        if value is None:
            raise at(path, element, f" has no {key} attribute")
        return value

    def _children(self, element, holder, path, depth):
        if depth > MAX_NESTING:
            raise at(path, element, f": nested more than {MAX_NESTING} deep")
        for child in element:
            if not isinstance(child.tag, str):      # comments, processing instructions
                continue
            tag = child.tag
            if self.upgrade and tag == "lookAt":
                tag = child.tag = "lookat"
            if tag == "default":
                name = self.required(child, "name", path)
                self.params.setdefault(name, self.required(child, "value", path))
            elif tag == "include":
                self._include(child, holder, path, depth)
            elif tag == "path":
                self._search_folder(child, path)
            elif tag == "alias":
                ident = self.required(child, "id", path)
                if ident not in self.ids:
                    raise at(path, child, f": no object has id {ident!r}")
                self.ids[self.required(child, "as", path)] = self.ids[ident]
            elif tag == "ref":
                ident = self.required(child, "id", path)
                self.refs.append((holder, self._name(child, path), child, ident, path))
            elif tag in VALUE_TAGS:
                name = self._name(child, path)
                if name is None:
                    raise at(path, child, " has no name attribute")
                holder.params[name] = self._value(child, tag, path, holder.tag == "emitter")
            elif tag in OBJECT_TAGS and tag != "scene":
                self._object(child, holder, path, depth)
            else:
                hint = (" (Mitsuba 0.6's blackbody element, which Mitsuba 3 does not read "
                        "either: write <spectrum name=\"radiance\" type=\"blackbody\"> with its "
                        "temperature)") if tag == "blackbody" else ""
                raise at(path, child, f": unknown element <{tag}> in "
                                      f"{holder.where}{hint}")

    def _name(self, element, path):
        name = self.attribute(element, "name", path)
        return camel_to_snake(name) if (self.upgrade and name is not None) else name

    def _include(self, element, holder, path, depth):
        """The children of the included file's <scene>, read into holder. An include of a
        file that is including it (itself, however indirectly) is refused in the file that
        closes the cycle."""
        target = self._resolve(describe(element), path,
                               self.required(element, "filename", path),
                               getattr(element, "sourceline", None))
        chain = self.including + [os.path.realpath(path)]
        if target in chain:
            names = " -> ".join(os.path.basename(p) for p in chain + [target])
            raise at(path, element, f": includes itself ({names})")
        if len(chain) > MAX_INCLUDE_DEPTH:
            raise at(path, element, ": includes nested more than "
                                    f"{MAX_INCLUDE_DEPTH} deep")
        self.including.append(os.path.realpath(path))
        try:
            self._children(self._parse_file(target), holder, target, depth + 1)
        finally:
            self.including.pop()

    def _object(self, element, holder, path, depth):
        kind = self.required(element, "type", path)
        ident = self.attribute(element, "id", path)
        plugin = Plugin(element.tag, kind, ident, path, describe(element),
                        getattr(element, "sourceline", None))
        self._children(element, plugin, path, depth + 1)
        if ident is not None:
            if ident in self.ids:
                raise at(path, element, f": the id {ident!r} is given twice")
            self.ids[ident] = plugin
        name = self._name(element, path)
        if name is None:
            holder.children.append(plugin)
        else:
            holder.params[name] = plugin

    # --- values ---------------------------------------------------------------------------

    def number(self, element, path, text, what):
        """The one number of an attribute's text (what names the attribute)."""
        values = self.numbers(element, path, text, what)
        if values.size != 1:
            raise at(path, element, f": {what} needs one number, has "
                                    f"{values.size}")
        return float(values[0])

    def numbers(self, element, path, text, what="value"):
        """The numbers of an attribute's text, separated by commas or spaces, each finite."""
        words = [w for w in re.split(r"[,\s]+", text.strip()) if w]
        try:
            values = np.array([float(w) for w in words], dtype=np.float64)
        except ValueError:
            bad = next(w for w in words if not is_float(w))
            raise at(path, element, f": {bad[:40]!r} in its {what} is not a "
                                    f"number") from None
        wrong = problem(values)
        if wrong is not None:
            raise at(path, element, f": in its {what}, {wrong}")
        return values

    def _value(self, element, tag, path, emitter=False):
        attr = lambda key, default=None: self.attribute(element, key, path, default)
        if tag == "transform":
            return parse_transform(self, element, path)
        if tag == "string":
            return self.required(element, "value", path)
        if tag == "spectrum" and element.get("filename") is not None:
            return self._spectrum_file(element, path, emitter)
        if tag == "spectrum" and element.get("type") is not None:
            return self._spectrum_plugin(element, path, emitter)
        text = self.required(element, "value", path) if tag not in ("point", "vector") \
            else attr("value")
        if tag == "boolean":
            word = text.strip().lower()
            if word not in ("true", "false"):
                raise at(path, element, f": {text[:40]!r} is neither true "
                                        f"nor false")
            return word == "true"
        if tag == "integer":
            try:
                return int(text.strip())
            except ValueError:
                raise at(path, element, f": {text[:40]!r} is not a whole "
                                        f"number") from None
        if tag in ("point", "vector"):
            if text is not None:
                values = self.numbers(element, path, text)
            else:
                values = np.array([self.number(element, path, attr(k, "0"), k)
                                   for k in "xyz"])
            if values.size != 3:
                raise at(path, element, ": needs 3 numbers, has "
                                        f"{values.size}")
            return values
        if tag == "spectrum" and ":" in text:
            return self._spectrum(element, path, text, emitter)
        if tag == "rgb" and text.strip().startswith("#"):
            raise at(path, element, ": hexadecimal colours are not "
                                    "supported (give three numbers)")
        values = self.numbers(element, path, text)
        if tag == "float":
            if values.size != 1:
                raise at(path, element, ": needs one number, has "
                                        f"{values.size}")
            return float(values[0])
        if tag == "spectrum" and values.size != 1:     # as Mitsuba 3 refuses it
            raise at(path, element, f": needs one number or wavelength:value pairs, has "
                                    f"{values.size} numbers (for a colour, give <rgb>)")
        if values.size not in (1, 3):
            raise at(path, element, ": needs one number or three, has "
                                    f"{values.size}")
        values = np.resize(values, 3)
        if tag == "srgb":   # 0.x files: an sRGB-encoded colour
            values = np.where(values <= 0.04045, values / 12.92,
                              ((values + 0.055) / 1.055) ** 2.4)
        return Colour(float(v) for v in values)

    def _spectrum(self, element, path, text, emitter):
        """The RGB colour of a spectrum of wavelength:value pairs (ptrace.io.mitsuba_spectra)."""
        pairs = []
        for item in re.split(r"[,\s]+", text.strip()):
            if item:
                wavelength, _, value = item.partition(":")
                pair = self.numbers(element, path, f"{wavelength} {value}", "spectrum")
                if pair.size != 2:
                    raise at(path, element, f": {item[:40]!r} is not a "
                                            f"wavelength:value pair")
                pairs.append(pair)
        return self._spectrum_rgb(element, path, pairs, emitter)

    def _spectrum_file(self, element, path, emitter):
        """The RGB colour of <spectrum filename=..>: a text file of one wavelength and one
        value a line (lines starting with # are comments), read as Mitsuba reads it."""
        name = self.attribute(element, "filename", path)
        target = self._resolve(describe(element), path, name,
                               getattr(element, "sourceline", None))
        require_regular_file(target)
        if os.path.getsize(target) > MAX_SPECTRUM_FILE:
            raise at(path, element, f": {name!r} is larger than a spectrum's "
                                    f"{MAX_SPECTRUM_FILE:,} bytes")
        try:
            with open(target, encoding="utf-8", errors="replace") as stream:
                lines = stream.read().splitlines()
        except OSError as error:
            raise at(path, element, f": cannot read {name!r}: "
                                    f"{error.strerror or error}") from None
        pairs = []
        for number, line in enumerate(lines, 1):
            if line.strip() and not line.lstrip().startswith("#"):
                pair = self.numbers(element, path, line, f"line {number} of {name!r}")
                if pair.size != 2:
                    raise at(path, element, f": line {number} of {name!r} is not a "
                                            f"wavelength and a value")
                pairs.append(pair)
        return self._spectrum_rgb(element, path, pairs, emitter)

    def _spectrum_plugin(self, element, path, emitter):
        """The RGB colour of <spectrum type="blackbody"> (its temperature in kelvin) on an
        emitter, as Mitsuba's spectral variants render it (its RGB variants cannot)."""
        kind = self.attribute(element, "type", path)
        if kind != "blackbody":
            raise at(path, element, f": spectrum type {kind[:40]!r} is not supported (ptrace "
                                    f"reads blackbody, values and files)")
        if not emitter:
            raise at(path, element, ": a blackbody spectrum outside an emitter")
        temperature = None
        for child in element:
            if child.tag == "float" and self.attribute(child, "name", path) == "temperature":
                temperature = self.number(child, path, self.required(child, "value", path),
                                          "value")
        if temperature is None or not temperature > 0:
            raise at(path, element, ": a blackbody needs a temperature above 0 kelvin")
        self.notes.append(f"{describe(element)}: converted to RGB as Mitsuba's spectral "
                          f"variants see it (its RGB variants cannot render a blackbody)")
        return Colour(blackbody_rgb(temperature))

    def _spectrum_rgb(self, element, path, pairs, emitter):
        pairs = np.array(pairs).reshape(-1, 2)
        if len(pairs) < 2 or np.any(np.diff(pairs[:, 0]) <= 0):
            raise at(path, element, ": a spectrum needs two or more "
                                    "wavelength:value pairs, wavelengths increasing")
        return Colour(spectrum_to_rgb(pairs[:, 0], pairs[:, 1], emitter))
