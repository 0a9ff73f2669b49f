"""Each observation kind owns its data: outside its own files, the registry,
the schemas and the docs, no code names a kind (issue 29, item 1).

Generic code asks the registry (C++ ``KindOf`` / ``FindKind`` /
``ObservationKinds``; Python ``_core.observation_kinds()``) what a kind is
and what it shows, so a new kind needs no edit outside its own files
(docs/adding_an_observation_kind.md; tests/cpp/kind_plugin/stylus3d.cc is such a
kind). The scan looks for a registered kind's name *used as a kind*, not for
the word: "point" is also a facet's and an axis's file key, "distance" a word
of messages. A use as a kind is

* Python (``ast``, string literals; docstrings are docs): a comparison with
  something named type/kind (``o["type"] == "facet"``, ``kind in
  ("point", "pose")``), the value of a ``"type"`` key (``{"type": "dbb"}``), a
  keyword or default of a parameter named type/kind (``kind="ball3d"``), an
  assignment to a name that says type/kind, or a literal tuple, list, set or
  dict of two kind names or more (a per-kind table);
* C++ (tokens, comments and strings of comments stripped): the kind's type
  constant (``ObservationType::kFacet``), its registry accessor
  (``FacetKind()``), a comparison with its name (``== "dbb"``) and a JSON
  ``{"type", "dbb"}`` pair.

Files that still name kinds are listed in ``PENDING`` with what they name: the
list may only shrink (a file that no longer names a kind must leave it, a
file not in it may name none), so the debt is visible and cannot grow.
``BY_DESIGN`` lists the procedures that are about one kind's data (a circular
test is ball-bar samples) and the importers of one instrument's files.
"""
from __future__ import annotations

import ast
import functools
import pathlib
import re

import pytest

from fivecal import _core
from fivecal.io import tables

ROOT = pathlib.Path(__file__).resolve().parents[2]
KINDS = [k["name"] for k in _core.observation_kinds()]


def _camel(name: str) -> str:
    return name[:1].upper() + name[1:]


# ---- what may name a kind --------------------------------------------------------------------------

#: The registry, and the header that holds the type codes' enum.
REGISTRY = {"cpp/src/observations/registry.cc", "cpp/include/fivecal/observations/registry.h",
            "cpp/include/fivecal/observations/dataset.h"}

#: A kind's own files: its file pair, and the family base it derives from
#: (probe touches, ball mountings, the fixed-frame instruments of point.h).
FAMILY = {"facet": "probe_touch", "sphere": "probe_touch", "cylinder": "probe_touch",
          "dbb": "ball_mount", "ball3d": "ball_mount", "pose": "point", "distance": "point"}


def own_files(kind: str) -> set:
    out = set()
    for stem in {kind, FAMILY.get(kind, kind)}:
        out |= {f"cpp/src/observations/{stem}.cc", f"cpp/include/fivecal/observations/{stem}.h"}
    return out


#: Code about one kind's data by design: a procedure is a test with one
#: instrument, an importer reads one instrument's files, the design plans
#: probe touches (DESIGN.md: "the procedures work on the kinds their test
#: uses; they are not generic by design").
BY_DESIGN = {
    "cpp/src/procedures/dbb_four_step.cc", "cpp/src/procedures/sphere_test.cc", "cpp/src/design/design.cc",
    "cpp/src/procedures/sphere_check.cc", "cpp/src/procedures/rtest.cc",
    "python/fivecal/procedures/dbb.py", "python/fivecal/procedures/rtest.py", "python/fivecal/procedures/tango.py",
    "python/fivecal/procedures/machining.py", "python/fivecal/procedures/classify.py",
    "python/fivecal/io/dbb_program.py", "python/fivecal/report/polar.py",
}

#: Files that still name kinds (file -> the kinds it names). Only shrinks:
#: empty since the registry exports each kind's instrument table (KindTable,
#: observations/kind.h), which fivecal.io.tables reads.
PENDING: dict = {}


# ---- the scan --------------------------------------------------------------------------------------

_TYPEISH = re.compile(r"(^|_)(type|types|typ|kind|kinds)($|_)", re.I)


def _typeish(node) -> bool:
    """Whether an expression names a type or kind: ``kind``, ``o["type"]``,
    ``o.get("type")``, ``self.kind``."""
    if isinstance(node, ast.Name):
        return bool(_TYPEISH.search(node.id))
    if isinstance(node, ast.Attribute):
        return bool(_TYPEISH.search(node.attr))
    if isinstance(node, ast.Subscript):
        s = node.slice
        return isinstance(s, ast.Constant) and s.value == "type"
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get":
        return bool(node.args) and isinstance(node.args[0], ast.Constant) and node.args[0].value == "type"
    return False


def _names_in(node, kinds) -> list:
    """Kind names among the string constants of ``node`` (itself or the
    elements of a literal tuple, list or set)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value] if node.value in kinds else []
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [e.value for e in node.elts if isinstance(e, ast.Constant) and e.value in kinds]
    return []


def python_uses(text: str, kinds) -> list:
    """(line, kind) of every use of a kind name as a kind in Python source."""
    tree = ast.parse(text)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            sides = [node.left] + list(node.comparators)
            if any(_typeish(s) for s in sides):
                for s in sides:
                    out += [(node.lineno, k) for k in _names_in(s, kinds)]
        elif isinstance(node, ast.Dict):
            keys = [k.value for k in node.keys if isinstance(k, ast.Constant) and k.value in kinds]
            if len(keys) >= 2:
                out += [(node.lineno, k) for k in keys]
            for k, v in zip(node.keys, node.values):
                if isinstance(k, ast.Constant) and k.value == "type":
                    out += [(node.lineno, n) for n in _names_in(v, kinds)]
        elif isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            names = _names_in(node, kinds)
            if len(names) >= 2:
                out += [(node.lineno, k) for k in names]
        elif isinstance(node, ast.keyword) and node.arg and _TYPEISH.search(node.arg):
            out += [(node.value.lineno, k) for k in _names_in(node.value, kinds)]
        elif isinstance(node, ast.arguments):
            args = node.posonlyargs + node.args
            for a, d in zip(args[len(args) - len(node.defaults):], node.defaults):
                if _TYPEISH.search(a.arg):
                    out += [(d.lineno, k) for k in _names_in(d, kinds)]
            for a, d in zip(node.kwonlyargs, node.kw_defaults):
                if d is not None and _TYPEISH.search(a.arg):
                    out += [(d.lineno, k) for k in _names_in(d, kinds)]
        elif isinstance(node, ast.Assign):
            if any(isinstance(t, ast.Name) and _TYPEISH.search(t.id) for t in node.targets):
                out += [(node.lineno, k) for k in _names_in(node.value, kinds)]
    return sorted(set(out))


def _strip_cpp_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S)
    return re.sub(r"//[^\n]*", "", text)


def cpp_uses(text: str, kinds) -> list:
    """(line, kind) of every use of a kind as a kind in C++ source."""
    text = _strip_cpp_comments(text)
    out = []
    for k in kinds:
        c = _camel(k)
        pats = [rf"ObservationType::k{c}\b", rf"\b{c}Kind\s*\(", rf"[=!]=\s*\"{k}\"", rf"\"{k}\"\s*[=!]=",
                rf"\{{\s*\"type\"\s*,\s*\"{k}\"\s*\}}"]
        for p in pats:
            for m in re.finditer(p, text):
                out.append((text.count("\n", 0, m.start()) + 1, k))
    return sorted(set(out))


def scan(root: pathlib.Path = ROOT, kinds=KINDS) -> dict:
    """file (relative to root) -> {kind: [lines]} of every use outside the
    kind's own files and the registry."""
    found: dict = {}
    files = [p for d in ("cpp", "python/fivecal") for p in (root / d).rglob("*") if p.suffix in (".cc", ".h", ".py")]
    for p in files:
        rel = p.relative_to(root).as_posix()
        if rel in REGISTRY:
            continue
        text = p.read_text(encoding="utf-8")
        uses = python_uses(text, kinds) if p.suffix == ".py" else cpp_uses(text, kinds)
        for line, k in uses:
            if rel in own_files(k):
                continue
            found.setdefault(rel, {}).setdefault(k, []).append(line)
    return found


@functools.lru_cache(maxsize=None)
def tree_uses() -> dict:
    """scan() of the source tree, once per session."""
    return scan()


# ---- the tests -------------------------------------------------------------------------------------

def test_no_kind_is_named_outside_its_files():
    found = tree_uses()
    new = {f: {k: v for k, v in ks.items() if k not in PENDING.get(f, set())}
           for f, ks in found.items() if f not in BY_DESIGN}
    new = {f: ks for f, ks in new.items() if ks}
    assert not new, ("kind names outside their kinds' files (ask the registry instead: "
                     "docs/adding_an_observation_kind.md):\n"
                     + "\n".join(f"  {f}: " + ", ".join(f"{k} (lines {v})" for k, v in ks.items())
                                 for f, ks in sorted(new.items())))


def test_the_pending_list_only_shrinks():
    """A file rid of its kind names leaves PENDING, so it cannot take them back."""
    found = tree_uses()
    stale = {f: sorted(ks - set(found.get(f, {}))) for f, ks in PENDING.items()}
    stale = {f: ks for f, ks in stale.items() if ks}
    assert not stale, f"no longer named there (remove from PENDING): {stale}"
    assert not BY_DESIGN - set(found), f"names no kind any more (remove from BY_DESIGN): {BY_DESIGN - set(found)}"


@pytest.mark.parametrize("module", [
    "python/fivecal/plausibility.py", "python/fivecal/design.py", "python/fivecal/report/document.py",
    "python/fivecal/report/plots.py", "python/fivecal/dataset.py", "cpp/bindings/identification.cc",
    "cpp/src/observations/simulate.cc", "cpp/src/observations/dataset.cc", "python/fivecal/io/tables.py"])
def test_the_generic_layers_name_no_kind(module):
    """The modules issue 29 found naming kinds now ask the registry."""
    assert module not in PENDING and module not in BY_DESIGN
    assert module not in tree_uses(), tree_uses()[module]


# The scan can fail: each rule finds a use planted in a copy of the tree's layout.
PLANTED_PY = '''
def f(o, kind="ball3d"):
    """A docstring may say facet."""
    if o["type"] == "facet":
        pass
    if kind in ("point", "pose"):
        pass
    PROBING = ("facet", "sphere", "cylinder")
    caption = {"ball3d": 1, "point": 2}
    e = {"type": "dbb", "point": [0, 0, 0]}
    x = o.get("point")           # a file key, not a kind
    for key in ("point", "normal"):  # file keys
        pass
    return f(o, kind="distance")
'''

PLANTED_CC = '''
// ObservationType::kFacet in a comment is docs
if (o.type == ObservationType::kSphere) {}
const ObservationKind& k = DbbKind();
if (*type == "ball3d") {}
json e = {{"type", "cylinder"}, {"point", p}};
'''


def test_the_scan_finds_planted_uses():
    lines = python_uses(PLANTED_PY, KINDS)
    assert {k for _, k in lines} == {"ball3d", "facet", "point", "pose", "sphere", "cylinder", "dbb", "distance"}
    assert not any(line in (11, 12) for line, _ in lines)  # file keys are not kinds
    assert not any(line == 3 for line, _ in lines)  # the docstring
    assert {k for _, k in cpp_uses(PLANTED_CC, KINDS)} == {"sphere", "dbb", "ball3d", "cylinder"}


def test_the_scan_fails_on_a_kind_named_in_generic_code(tmp_path):
    (tmp_path / "python/fivecal/report").mkdir(parents=True)
    (tmp_path / "cpp/src/observations").mkdir(parents=True)
    (tmp_path / "python/fivecal/report/new.py").write_text('def g(o):\n    return o["type"] == "dbb"\n')
    (tmp_path / "cpp/src/observations/dbb.cc").write_text('bool F() { return DbbKind().rows() == 1; }\n')
    found = scan(tmp_path)
    assert found == {"python/fivecal/report/new.py": {"dbb": [2]}}


# ---- the data Python reads instead of naming kinds -------------------------------------------------

#: a joint layout's columns: they give the axes, not a file key
_JOINT_COLUMNS = {"joint", "position", "home", "joint_type"}


@pytest.mark.parametrize("kind", _core.observation_kinds(), ids=lambda k: k["name"])
def test_each_kind_exports_a_table_of_its_own_keys(kind):
    """The registry's instrument table of a kind (what fivecal.io.tables reads)
    fills the kind's own file keys only, in its layout's terms."""
    t = kind["table"]
    assert t["layout"] in ("touch", "mount", "instrument", "station", "generic")
    keys = set(kind["json_keys"]) | {"approach"}
    for c in t["columns"]:
        assert c["field"] in keys | _JOINT_COLUMNS, (kind["name"], c)
        assert c["quantity"] in ("length", "rotation", "number", "text", "joint"), c
        assert (c["range"] > 0) == bool(c["range_message"]), c
        if c["range_message"]:
            # the message formats with what the importer hands it
            assert c["range_message"].format(value=1.5, limit=2.0, limit_m=0.002, column=c["name"])
    # a vector's entries are 0, 1, 2 ... in order (a pose's sigma: one per residual row, six)
    for field in {c["field"] for c in t["columns"] if c["index"] is not None}:
        got = [c["index"] for c in t["columns"] if c["field"] == field and c["index"] is not None]
        assert got == list(range(max(3, len(got)))), (kind["name"], field)
    if t["layout"] == "generic":
        assert set(t["header_aliases"].values()) <= keys | {k + "_" for k in keys} | {"reference_"}
    else:
        # another header name of one of its columns ("tx" -> "measured_x")
        assert set(t["header_aliases"].values()) <= {c["name"] for c in t["columns"]}, kind["name"]
    assert set(t["directions"]) <= keys


def test_kinds_sharing_an_import_share_its_table():
    """One probing log for every probe touch: the kinds of one import name
    agree on its layout and columns, so a row's target alone says its kind."""
    by_name: dict = {}
    for k in _core.observation_kinds():
        by_name.setdefault(k["table"]["name"], []).append(k)
    for name, ks in by_name.items():
        assert len({repr((k["table"]["layout"], k["table"]["columns"])) for k in ks}) == 1, name
        if len(ks) > 1:
            assert all(k["probe_touch"] and k["report"]["target_list"] for k in ks), name


@pytest.mark.parametrize("kind,option,owners", [
    ("probing", {"length": 100.0}, "a dbb import, not probing"),
    ("machined", {"tool_ball": [0, 0, 1]}, "a dbb or ball3d import, not machined"),
    ("distance", {"instrument_origin": [0, 0, 0]}, "a point or pose import, not distance"),
    ("point", {"target_rotation": [0, 0, 0]}, "a pose import, not point"),
])
def test_an_option_of_another_import_is_refused_naming_the_imports_that_take_it(kind, option, owners):
    """Which import takes which option is each kind's table's (its options),
    so the refusal names the imports the registry says take it."""
    key = next(iter(option))
    with pytest.raises(ValueError, match=rf"^--{key.replace('_', '-')}: {key} belongs to {owners}$"):
        tables.read_table(ROOT / "examples/import/probing.csv", kind, ROOT / "examples/machines/c600u.json",
                          **option)


# ---- a kind's file keys ----------------------------------------------------------------------------

#: Keys of every observation (the common header, read and written by the
#: generic code), and keys of the artefact that some kinds also have (a
#: scale bar's length, a facet's point and normal).
HEADER_KEYS = {"type", "axes", "direction", "sigma", "id", "setup", "target"}
ARTEFACT_KEYS = {"length", "point", "normal"}

#: The loaders and writers: they know a kind's own keys from its flat form
#: (ObservationKind::flat_keys) and its Read and Write, never by name.
KEY_BLIND = ["cpp/src/observations/dataset.cc", "cpp/src/observations/writer.cc",
             "cpp/include/fivecal/observations/kind.h", "cpp/include/fivecal/observations/writer.h"]


def kind_keys() -> set:
    keys = set()
    for k in _core.observation_kinds():
        keys |= set(k["json_keys"])
    return keys - HEADER_KEYS - ARTEFACT_KEYS


def cpp_key_literals(text: str, keys) -> list:
    """(line, key) of every string literal of C++ source that is one of ``keys``."""
    text = _strip_cpp_comments(text)
    return [(text.count("\n", 0, m.start()) + 1, m.group(1))
            for m in re.finditer(r'"([A-Za-z_]+)"', text) if m.group(1) in keys]


@pytest.mark.parametrize("path", KEY_BLIND)
def test_the_loaders_and_writers_name_no_kinds_own_key(path):
    found = cpp_key_literals((ROOT / path).read_text(), kind_keys())
    assert not found, f"{path} names a kind's file keys {found}: let the kind declare them (flat_keys)"


def test_the_key_scan_finds_a_planted_key():
    assert {"tool_ball", "reading"} <= kind_keys()
    planted = 'const char* k = "tool_ball";  // "reading" in a comment is docs\nf.set("setup");'
    assert cpp_key_literals(planted, kind_keys()) == [(1, "tool_ball")]


#: words a kind's rules use that the importer also uses as words of its own:
#: "point" is the value of --decimal (a decimal point)
_IMPORTER_WORDS = {"point"}


def _code_strings(path: pathlib.Path) -> list:
    """(line, text) of the string literals of a module, docstrings left out."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and n.body
            and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    return [(n.lineno, n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]


def test_the_importer_names_no_key_or_value_of_a_kinds_rules():
    """A kind's table checks are its table's rules in the registry
    (KindTable::rules); the importer applies them and names none of the keys
    or values they are about (the machined kind's part, feature, face, step,
    reference cut and normals used to be a branch of tables.py)."""
    words = set()
    for k in _core.observation_kinds():
        for r in k["table"]["rules"]:
            words |= set(r["keys"]) | set(r["values"]) | {r["if_key"], r["value"], r["then"], r["option"]}
    words -= {"", "setup", "id", "type", "sigma"} | _IMPORTER_WORDS  # the common header's keys
    assert words, "no kind declares table rules: the test would check nothing"
    found = sorted((line, w) for line, text in _code_strings(ROOT / "python/fivecal/io/tables.py")
                   for w in words if re.search(rf"(?<![A-Za-z_]){re.escape(w)}(?![A-Za-z])", text))
    assert not found, f"python/fivecal/io/tables.py names what a kind's table rules are about: {found}"
