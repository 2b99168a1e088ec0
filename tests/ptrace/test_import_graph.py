"""The import graph of ptrace/ and accel/ has no cycle, and accel never imports ptrace.

The graph is read from the source (ast), not by importing: every `import a.b` and
`from .x import y` anywhere in a module (at module level or inside a function, where a lazy
import hides a cycle from Python but not from a reader) is an edge from that module to the
module it names; `from . import x` names the submodule x when there is one, else the package.
A package's own __init__ is a node like any other; a submodule's implicit import of its parent
package is not an edge (every submodule would otherwise cycle with its package).

    python tests/ptrace/test_import_graph.py     # prints the cycles, if any
"""
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("ptrace", "accel")


def modules(root=ROOT, packages=PACKAGES):
    """{dotted name: path} of every .py file under the packages."""
    found = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _is_package(name, known):
    return any(other.startswith(name + ".") for other in known)


def _targets(node, module, known):
    """The known modules that one import statement in `module` names."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    else:
        if node.level:
            package = module if _is_package(module, known) else module.rpartition(".")[0]
            for _ in range(node.level - 1):
                package = package.rpartition(".")[0]
            base = ".".join(part for part in (package, node.module) if part)
        else:
            base = node.module
        names = []
        for alias in node.names:    # `from pkg import sub` imports the submodule pkg.sub
            sub = f"{base}.{alias.name}"
            names.append(sub if sub in known else base)
    out = set()
    for name in names:
        while name and name not in known:   # `import a.b.c` of a non-module: its nearest module
            name = name.rpartition(".")[0]
        if name:
            out.add(name)
    return out


def import_graph(root=ROOT, packages=PACKAGES):
    """{module: set of the modules it imports} among the packages' modules."""
    known = modules(root, packages)
    graph = {}
    for name, path in known.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        edges = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                edges |= _targets(node, name, known)
        edges.discard(name)
        graph[name] = edges
    return graph


def cycles(graph):
    """The strongly connected components of more than one module (Tarjan's algorithm), each
    sorted, the list sorted."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in sorted(graph.get(node, ())):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                other = stack.pop()
                on_stack.discard(other)
                component.append(other)
                if other == node:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for node in sorted(graph):
            if node not in index:
                visit(node)
    finally:
        sys.setrecursionlimit(limit)
    return sorted(out)


def describe(graph, component):
    """One cycle's edges, as 'a -> b' lines."""
    members = set(component)
    return [f"{a} -> {b}" for a in component for b in sorted(graph[a] & members)]


def test_the_graph_sees_module_and_function_level_imports(tmp_path):
    """The reader itself: a cycle made only by a lazy import inside a function is found, and
    `from . import x` of a submodule is an edge to it."""
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from .b import thing\n")
    (package / "b.py").write_text("def f():\n    from . import a\n    return a\nthing = 1\n")
    (package / "c.py").write_text("import pkg.a\n")
    graph = import_graph(tmp_path, ("pkg",))
    assert graph == {"pkg": set(), "pkg.a": {"pkg.b"}, "pkg.b": {"pkg.a"}, "pkg.c": {"pkg.a"}}
    assert cycles(graph) == [["pkg.a", "pkg.b"]]
    (package / "b.py").write_text("thing = 1\n")
    assert cycles(import_graph(tmp_path, ("pkg",))) == []


def test_no_import_cycle_in_ptrace_or_accel():
    graph = import_graph()
    assert {"ptrace.app.cli", "ptrace.app.view", "ptrace.rendering.settings",
            "accel.bvh"} <= set(graph)
    found = cycles(graph)
    assert found == [], "\n".join(line for component in found
                                  for line in describe(graph, component) + [""])


def test_accel_never_imports_ptrace():
    graph = import_graph()
    wrong = [f"{a} -> {b}" for a, edges in sorted(graph.items()) if a.startswith("accel")
             for b in sorted(edges) if b.split(".")[0] == "ptrace"]
    assert wrong == []


def test_the_settings_import_no_kernel_module():
    """ptrace.rendering.settings (pickled to every Dask worker, read by both commands) and the
    commands' options import no numba code at module level: what they load is what they need."""
    kernels = {"ptrace.integrator", "ptrace.lights", "ptrace.light_bvh", "ptrace.bsdf",
               "ptrace.sampling", "ptrace.textures", "ptrace.environment"}
    for name in ("ptrace.rendering.settings", "ptrace.codes", "ptrace.app.options"):
        path = modules()[name]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        top = set()
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                top |= _targets(node, name, modules())
                assert "numba" not in ast.unparse(node), (name, ast.unparse(node))
        assert not top & kernels, (name, sorted(top & kernels))


if __name__ == "__main__":
    graph = import_graph()
    found = cycles(graph)
    print(f"{len(graph)} modules, {sum(map(len, graph.values()))} edges, {len(found)} cycle(s)")
    for component in found:
        print(f"cycle of {len(component)}: " + ", ".join(component))
        for line in describe(graph, component):
            print(f"  {line}")
