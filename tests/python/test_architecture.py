"""The Python layers are imported one way only (DESIGN.md "Python layers";
README "Where the code is"): the core API and its helpers, then io/,
procedures/ and history/, then report/, then cli/. Every import of every
module of python/fivecal is read from its source (those inside functions
too, where a cycle would otherwise hide), so this holds without importing
anything."""
import ast
import os

import pytest

ROOT = os.path.join(os.path.dirname(__file__), "..", "..", "python", "fivecal")

#: layer of each module (the longest matching prefix wins). A module imports
#: only from its own layer or lower ones. The package ``fivecal`` itself (its
#: __init__ re-exports the API) is no layer: nothing inside imports from it.
LAYERS = {
    # 0: the core API and the helpers it stands on
    "fivecal._core": 0, "fivecal._json": 0, "fivecal._version": 0, "fivecal.compensation": 0, "fivecal.dataset": 0,
    "fivecal.design": 0, "fivecal.figures": 0, "fivecal.files": 0, "fivecal.gcode": 0, "fivecal.guards": 0, "fivecal.manual": 0,
    "fivecal.identification": 0, "fivecal.machine": 0, "fivecal.plausibility": 0, "fivecal.progress": 0,
    "fivecal.schema": 0, "fivecal.simulation": 0, "fivecal.tolerances": 0, "fivecal.uncertainty": 0,
    "fivecal.units": 0, "fivecal.views": 0,
    # 1: files of the world outside, the named procedures, the calibration history
    "fivecal.io": 1, "fivecal.procedures": 1, "fivecal.history": 1,
    # 2: what a user reads (and the demo, which writes a report)
    "fivecal.report": 2, "fivecal.demo": 2,
    # 3: the command line, one module per command
    "fivecal.cli": 3, "fivecal.__main__": 3,
}
#: same-layer packages that must not import each other in a circle either
SIBLINGS = ("fivecal.io", "fivecal.procedures", "fivecal.history")


def _modules() -> dict:
    """module name -> source path, for every .py of the package."""
    out = {}
    for folder, _, names in os.walk(ROOT):
        for n in names:
            if not n.endswith(".py"):
                continue
            rel = os.path.relpath(os.path.join(folder, n), ROOT)[:-3].split(os.sep)
            if rel[-1] == "__init__":
                rel = rel[:-1]
            out[".".join(["fivecal"] + rel)] = os.path.join(folder, n)
    return out


MODULES = _modules()


def _imports(name: str, path: str):
    """(line, target module) of every fivecal import of a module: relative
    ones resolved; ``from P import x`` names module P.x when that is a
    module, else P; ``_core`` is the compiled extension module."""
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read(), path)
    package = name if path.endswith("__init__.py") else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "fivecal" or a.name.startswith("fivecal."):
                    yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod != "fivecal" and not mod.startswith("fivecal."):
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                yield node.lineno, sub if sub in MODULES or sub == "fivecal._core" else mod


def _layer(module: str):
    best = None
    for prefix, layer in LAYERS.items():
        if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > len(best[0])):
            best = (prefix, layer)
    return None if best is None else best[1]


def _graph(packages: bool = False) -> dict:
    """module -> sorted (target, line) of the imports of :func:`_imports`;
    with ``packages`` also the packages a target sits in (importing
    ``fivecal.io.columnar`` runs ``fivecal/io/__init__.py`` first) unless
    the importer is inside them."""
    out = {}
    for name, path in MODULES.items():
        edges = set()
        for line, t in _imports(name, path):
            edges.add((t, line))
            parts = t.split(".")
            for i in range(2, len(parts) if packages else 0):
                p = ".".join(parts[:i])
                if p in MODULES and not (name == p or name.startswith(p + ".")):
                    edges.add((p, line))
        out[name] = sorted(edges)
    return out


def _cycles(edges: dict) -> list:
    """The strongly connected components with more than one node (or a self
    loop) of a graph node -> set of nodes (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in edges.get(v, ()):
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_every_module_has_a_layer():
    assert not [m for m in MODULES if m != "fivecal" and _layer(m) is None], \
        "place the new module in LAYERS (and in README 'Where the code is')"


def test_no_module_imports_the_package_init():
    bad = [f"{m}:{line}" for m, targets in _graph().items() if m != "fivecal"
           for t, line in targets if t == "fivecal"]
    assert not bad, f"import from the defining module, not from fivecal itself: {bad}"


def test_no_import_from_a_higher_layer():
    bad = []
    for m, targets in _graph().items():
        if m == "fivecal":
            continue
        for t, line in targets:
            lt = _layer(t)
            if lt is not None and lt > _layer(m):
                bad.append(f"{m}:{line} -> {t} (layer {_layer(m)} -> {lt})")
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def test_no_import_cycle_between_modules():
    edges = {m: {t for t, _ in targets if t in MODULES and t != "fivecal"} for m, targets in _graph(True).items()
             if m != "fivecal"}
    cycles = _cycles(edges)
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_import_cycle_between_sibling_packages():
    def package(m):
        return next((p for p in SIBLINGS if m == p or m.startswith(p + ".")), None)

    edges = {}
    for m, targets in _graph().items():
        for t, _ in targets:
            a, b = package(m), package(t)
            if a and b and a != b:
                edges.setdefault(a, set()).add(b)
    cycles = _cycles(edges)
    assert not cycles, f"io / procedures / history import each other in a circle: {cycles}"


#: modules still allowed a function-local fivecal import (path relative to
#: python/fivecal): none.
LOCAL_IMPORT_ALLOWED: set = set()


def _local_imports(name: str, path: str):
    """(line, statement) of every fivecal import (relative, or of
    ``fivecal``) made inside a function or lambda of a module."""
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read(), path)
    out = []

    def fivecal_import(node) -> bool:
        if isinstance(node, ast.ImportFrom):
            return bool(node.level) or (node.module or "").split(".")[0] == "fivecal"
        return isinstance(node, ast.Import) and any(a.name.split(".")[0] == "fivecal" for a in node.names)

    def visit(node, in_function: bool):
        for child in ast.iter_child_nodes(node):
            if in_function and fivecal_import(child):
                out.append((child.lineno, ast.unparse(child)))
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(tree, False)
    return out


def test_no_function_local_fivecal_import():
    """An import inside a function hides a dependency from the reader and,
    when it was put there to dodge a cycle, the cycle from the tests above:
    every fivecal import sits at the top of its module."""
    bad = []
    for name, path in MODULES.items():
        rel = os.path.relpath(path, ROOT).replace(os.sep, "/")
        if rel in LOCAL_IMPORT_ALLOWED:
            continue
        bad += [f"{rel}:{line}: {text}" for line, text in _local_imports(name, path)]
    assert not bad, ("fivecal imports inside functions (move them to the top of the module; if that makes a "
                     "cycle or an upward import, move the function or the shared helper to the right layer):\n"
                     + "\n".join(bad))


def test_local_import_allowlist_names_existing_modules():
    missing = [p for p in LOCAL_IMPORT_ALLOWED if not os.path.isfile(os.path.join(ROOT, p))]
    assert not missing, f"allowlisted modules that do not exist: {missing}"


@pytest.mark.parametrize("text, found", [
    ("from . import files", []), ("def f():\n    from . import files", [2]),
    ("def f():\n    import fivecal.machine", [2]), ("def f():\n    from fivecal import _core", [2]),
    ("def f():\n    import json\n    from numpy import array", []),
    ("class C:\n    def m(self):\n        def g():\n            from ..x import y", [4]),
    ("f = lambda: __import__('json')", []), ("class C:\n    from . import files", [])])
def test_local_import_finder(tmp_path, text, found):
    """The finder the check above rests on: it must see imports in nested
    functions and methods, and only fivecal ones."""
    p = tmp_path / "m.py"
    p.write_text(text + "\n")
    assert [line for line, _ in _local_imports("fivecal.m", str(p))] == found


@pytest.mark.parametrize("module, text, expected", [
    ("fivecal.m", "from . import _core", "fivecal._core"), ("fivecal.io.m", "from .. import files", "fivecal.files"),
    ("fivecal.io.m", "from ..report.plots import x", "fivecal.report.plots"),
    ("fivecal.io.m", "from . import tables", "fivecal.io.tables"),
    ("fivecal.io.m", "from .tables import KINDS", "fivecal.io.tables"),
    ("fivecal.io.m", "import fivecal.machine", "fivecal.machine"),
    ("fivecal.io.m", "def f():\n    from .. import __version__", "fivecal")])
def test_resolution(tmp_path, module, text, expected):
    """The resolver the checks above rest on."""
    p = tmp_path / "m.py"
    p.write_text(text + "\n")
    assert [t for _, t in _imports(module, str(p))] == [expected]
