"""The header every benchmark report starts with (machine, date, versions, exact command),
where reports go (RESULTS: `destination`, `write`) and the defaults --quick picks
(`quick_defaults`)."""
import datetime
import os
import platform
import shlex
import sys
from importlib import metadata
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
PACKAGES = ("numpy", "numba", "llvmlite", "embreex", "trimesh", "ptrace")


def cpu_model():
    """The CPU's model name, with its family and model numbers where the name has no number
    of its own (a virtual machine's "AMD EPYC" is a Zen 1 or a Zen 3, whose speeds differ)."""
    fields = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            fields.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    name = fields.get("model name") or platform.processor() or "unknown"
    if not any(c.isdigit() for c in name) and "cpu family" in fields and "model" in fields:
        name += f" family {fields['cpu family']} model {fields['model']}"
    return name


def vector_extensions():
    """The widest x86 vector extension the CPU reports (AVX-512 changes what SIMD code gains
    over AVX2), or '' where /proc/cpuinfo has no flags."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                flags = set(line.split(":", 1)[1].split())
                for name, flag in (("AVX-512", "avx512f"), ("AVX2", "avx2"), ("AVX", "avx"),
                                   ("SSE4.2", "sse4_2")):
                    if flag in flags:
                        return name
    except OSError:
        pass
    return ""


def header(title):
    versions = []
    for name in PACKAGES:
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            pass
    vectors = vector_extensions() or "vector extensions unknown"
    command = "python -m " + " ".join(
        [__import__("__main__").__spec__.name if getattr(__import__("__main__"), "__spec__", None)
         else sys.argv[0]] + [shlex.quote(a) for a in sys.argv[1:]])
    return "\n".join([
        f"# {title}", "",
        f"- machine: {os.cpu_count()} cores, {cpu_model()} ({vectors}), {platform.system()} "
        f"{platform.machine()}",
        f"- date: {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}",
        f"- python {platform.python_version()}; " + ", ".join(versions),
        f"- command: `{command}`", "", ""])


def destination(name):
    """RESULTS / name (an absolute name stays as it is), its folder made: where a report that
    saves files beside it goes."""
    path = RESULTS / name
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def quick_defaults(args, **defaults):
    """Fill in the arguments of args left None: defaults[name] is (its value with --quick,
    its value without), chosen by args.quick. Returns args."""
    for name, (quick, full) in defaults.items():
        if getattr(args, name) is None:
            setattr(args, name, quick if args.quick else full)
    return args


def write(name, text):
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / name
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path
