"""JSON Schema checks of fivecal's files (machine, dataset, simulation spec,
design spec, result), run before the C++ loader.

The schemas (draft 2020-12) ship in ``fivecal/schemas/*.schema.json`` and are
the machine-readable half of the format reference ``docs/formats.md``. They
fix the structure: which keys exist (an unknown key is refused, with a
did-you-mean), their JSON types and the obvious signs. What a value means and
whether it fits the machine (an axis the machine lacks, a unit normal, an
unknown facet id) stays with the C++ loader, which names the field as well.

Every refusal is one ``ValueError`` line naming the JSON path, e.g.
``dataset.observations[3].dirction: unknown key; did you mean 'direction'?``.

Big documents (jsonschema needs about 1 ms per observation, and 10^6
observations are ~10^7 Python objects): a dataset *text* over
:data:`BIG_TEXT` bytes is checked without parsing its observations in Python
(every other member and the first :data:`BIG_TEXT_SAMPLE` observations go
through the schema; the C++ loader checks every observation, unknown keys
included, with the same path names). An in-memory document with more than
:data:`FULL_CHECK_LIMIT` observations or plan entries has each distinct
entry *shape* (its type and the keys of the entry, of its ``axes`` and of its
``direction``) checked once, at its first occurrence, so an unknown or
missing key is refused in every entry; the C++ loader checks the values.
docs/formats.md states the same rule for users.
"""
from __future__ import annotations

import difflib
import json
import math
import os
from functools import lru_cache
from typing import Any, Optional

from . import files
from . import _core
from ._json import plain

__all__ = ["KINDS", "FULL_CHECK_LIMIT", "BIG_TEXT", "BIG_TEXT_SAMPLE", "schema_path", "load_schema",
           "validate", "parse", "check_text", "check_file", "checked_dumps", "guess_kind", "read_checked"]

#: The file kinds with a schema (``fivecal/schemas/<kind>.schema.json``).
KINDS = ("machine", "dataset", "spec", "design", "result", "errors", "import")

#: Datasets with more observations are checked by shape (see the module docstring).
FULL_CHECK_LIMIT = 200

_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "schemas")
_BASE = "https://fivecal.invalid/schemas/"
# The name a path starts with in messages (the C++ loader's names).
_ROOT = {"machine": "machine", "dataset": "dataset", "spec": "spec", "design": "spec", "result": "result",
         "errors": "result", "import": "sidecar"}


def schema_path(kind: str) -> str:
    """Path of the installed schema file of ``kind`` (one of :data:`KINDS`)."""
    if kind not in KINDS:
        raise ValueError(f"unknown file kind '{kind}' (one of {', '.join(KINDS)})")
    return os.path.join(_DIR, f"{kind}.schema.json")


@lru_cache(maxsize=None)
def load_schema(kind: str) -> dict:
    """The schema of ``kind`` as a dict (dataset and spec: with every
    registered observation kind, see :func:`_with_registered_kinds`)."""
    if kind == "common":
        path = os.path.join(_DIR, "common.schema.json")
    else:
        path = schema_path(kind)
    with open(path, encoding="utf-8") as f:
        s = json.load(f)
    return _with_registered_kinds(kind, s) if kind in _KIND_ITEMS else s


# Where a file lists observation kinds: the $defs entry of one observation
# (plan entry) and the registry field with its keys.
_KIND_ITEMS = {"dataset": ("observation", "json_keys"), "spec": ("plan_item", "plan_keys")}
_KEY_SCHEMAS = {"axes": {"$ref": "common.schema.json#/$defs/axes"},
                "direction": {"$ref": "common.schema.json#/$defs/direction"},
                "id": {"type": "string"},
                "sigma": {"description": "mm (rad for rotation rows): one number or one per residual row",
                          "anyOf": [{"type": "number", "exclusiveMinimum": 0},
                                    {"type": "array", "minItems": 1,
                                     "items": {"type": "number", "exclusiveMinimum": 0}}]}}


def _with_registered_kinds(kind: str, s: dict) -> dict:
    """The observation kinds of a dataset or spec schema follow the C++
    registry (``_core.observation_kinds()``), so a new kind needs no schema
    edit: the type enum lists every registered kind, a kind the file does not
    describe gets a block made of its keys (an unknown key is refused here;
    the C++ loader checks the values, naming the field), and the spec's
    ``sigma`` object takes every noise class."""
    try:

        kinds, classes = _core.observation_kinds(), _core.noise_classes()
    except (ImportError, AttributeError):  # a module built before the registry said so
        return s
    item_def, keys_field = _KIND_ITEMS[kind]
    item = s["$defs"][item_def]
    enum = item["properties"]["type"]["enum"]
    for k in kinds:
        if k["name"] in enum:
            continue
        enum.append(k["name"])
        props = {key: dict(_KEY_SCHEMAS.get(key, {})) for key in k[keys_field]}
        props["type"] = {"const": k["name"]}
        item.setdefault("allOf", []).append(
            {"if": {"properties": {"type": {"const": k["name"]}}, "required": ["type"]},
             "then": {"type": "object", "additionalProperties": False, "required": ["type"], "properties": props}})
    if kind == "spec":
        levels = s["properties"]["sigma"]["then"]["properties"]
        for c in classes:
            levels.setdefault(c, {"type": "number", "minimum": 0})
    return s


def _finite_number(checker, instance) -> bool:
    # JSON has no NaN or infinity; Python's json module reads them anyway.
    return (isinstance(instance, (int, float)) and not isinstance(instance, bool)
            and math.isfinite(instance))


def _integer(checker, instance) -> bool:
    # Integral floats (1.0, as numpy writes them) are integers, as JSON Schema says.
    if isinstance(instance, bool):
        return False
    if isinstance(instance, int):
        return True
    return isinstance(instance, float) and math.isfinite(instance) and instance.is_integer()


@lru_cache(maxsize=None)
def _validator(kind: str):
    import jsonschema
    from referencing import Registry, Resource

    resources = []
    for name in ("common",) + KINDS:
        resources.append((_BASE + f"{name}.schema.json", Resource.from_contents(load_schema(name))))
    registry = Registry().with_resources(resources)
    base = jsonschema.Draft202012Validator
    checker = base.TYPE_CHECKER.redefine_many({"number": _finite_number, "integer": _integer})
    cls = jsonschema.validators.extend(base, type_checker=checker)
    return cls(load_schema(kind), registry=registry)


def _path(root: str, parts) -> str:
    out = root
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else f".{p}"
    return out


def _json_type(x: Any) -> str:
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, (int, float)):
        return "a number"
    if isinstance(x, str):
        return "a string"
    if isinstance(x, list):
        return "an array"
    if isinstance(x, dict):
        return "an object"
    return type(x).__name__


def _did_you_mean(word: str, choices) -> str:
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    if not close and isinstance(word, str):
        close = [c for c in choices if isinstance(c, str) and c.lower() == word.lower()][:1]
    return f"; did you mean '{close[0]}'?" if close else ""


_TYPE_WORDS = {"number": "a number", "integer": "an integer", "string": "a string", "array": "an array",
               "object": "an object", "boolean": "true or false", "null": "null"}


def _message(error, root: str) -> str:
    """One line for a jsonschema error: the JSON path first, then what is wrong."""
    where = _path(root, error.absolute_path)
    v, inst, sch = error.validator, error.instance, error.schema
    if (sch.get("type") == "integer" and sch.get("minimum") == -1 and sch.get("maximum") == 1
            and v in ("type", "minimum", "maximum") and isinstance(inst, (int, float))
            and not isinstance(inst, bool)):
        # a backlash direction: name the three values, as the C++ loader does
        # ("must be <= 1" would invite 0.5)
        shown = f"{inst:g}" if isinstance(inst, float) and math.isfinite(inst) else repr(inst)
        return f"{where}: must be -1, 0 or +1 (got {shown})"
    if v == "additionalProperties" and isinstance(inst, dict):
        allowed = list(sch.get("properties", {}))
        extra = [k for k in inst if k not in allowed]
        if extra:
            k = extra[0]
            hint = _did_you_mean(k, allowed)
            return (f"{_path(root, list(error.absolute_path) + [k])}: unknown key{hint}"
                    + (f" (allowed: {', '.join(allowed)})" if not hint and allowed else ""))
    if v == "required" and isinstance(inst, dict):
        missing = [k for k in error.validator_value if k not in inst]
        if missing:
            return f"{_path(root, list(error.absolute_path) + [missing[0]])}: missing"
    if v == "type":
        want = error.validator_value
        want = [want] if isinstance(want, str) else list(want)
        if isinstance(inst, float) and not math.isfinite(inst) and ("number" in want or "integer" in want):
            return f"{where}: value is not finite (NaN or inf)"
        if "integer" in want and isinstance(inst, float):
            return f"{where}: expected an integer, got {inst!r}"
        words = " or ".join(_TYPE_WORDS.get(w, w) for w in want)
        return f"{where}: expected {words}, got {_json_type(inst)}"
    if v in ("enum", "const"):
        options = error.validator_value if v == "enum" else [error.validator_value]
        return (f"{where}: {json.dumps(inst)} is not one of {', '.join(json.dumps(o) for o in options)}"
                + (_did_you_mean(inst, options) if isinstance(inst, str) else ""))
    if v in ("minItems", "maxItems") and isinstance(inst, list):
        n = sch.get("minItems")
        if n is not None and n == sch.get("maxItems"):
            return f"{where}: expected {n} values, got {len(inst)}"
        return f"{where}: {len(inst)} values; expected {'at least' if v == 'minItems' else 'at most'} " \
               f"{error.validator_value}"
    if v == "minimum":
        return f"{where}: must be >= {error.validator_value}, got {inst!r}"
    if v == "exclusiveMinimum":
        return f"{where}: must be > {error.validator_value}, got {inst!r}"
    if v == "maximum":
        return f"{where}: must be <= {error.validator_value}, got {inst!r}"
    if v == "pattern" and error.validator_value == "^[^.]+$":
        return f"{where}: {inst!r} must not contain '.'"
    if v == "not" and error.validator_value == {"required": ["S", "C1"]}:
        return f"{where}: duplicate axis 'S': both 'S' and its alias 'C1' are given; keep one"
    if v == "minLength":
        return f"{where}: empty string"
    if v == "anyOf" and isinstance(sch.get("anyOf"), list) and error.context:
        # the alternative that got furthest names the problem best
        best = max(error.context, key=lambda e: len(e.absolute_path))
        return _message(best, root)
    return f"{where}: {error.message}"


_RANK = {"additionalProperties": 0, "required": 1, "enum": 2, "const": 2, "type": 3}


def _order_key(error):
    # The first bad array item first (the first bad observation of a file);
    # at one place an unknown or missing key before a type or range complaint.
    path = tuple((0, p, "") if isinstance(p, int) else (1, 0, str(p)) for p in error.absolute_path)
    return path, _RANK.get(error.validator, 4)


def _first_error(validator, doc):
    errors = list(validator.iter_errors(doc))
    return min(errors, key=_order_key) if errors else None


def _raise(validator, doc, root: str, prefix: str, path_prefix=()):
    err = _first_error(validator, doc)
    if err is None:
        return
    err.path.extendleft(reversed(list(path_prefix)))  # where a sub-document sits in the file
    raise ValueError(prefix + _message(err, root))


# The arrays checked by shape when long: kind -> (key, schema of one item).
_BIG_ARRAYS = {"dataset": ("observations", "dataset.schema.json#/$defs/observation"),
               "spec": ("plan", "spec.schema.json#/$defs/plan_item"),
               "design": ("plan", "spec.schema.json#/$defs/plan_item")}


@lru_cache(maxsize=None)
def _item_validator(kind: str, item_def: str):
    return _validator(kind).evolve(schema={"$ref": _BASE + item_def})


def _shape(o):
    if type(o) is not dict:
        return None
    ax = o.get("axes")
    d = o.get("direction")
    return (o.get("type") if type(o.get("type")) is str else None, tuple(o),
            tuple(ax) if type(ax) is dict else type(ax).__name__,
            tuple(d) if type(d) is dict else (None if d is None else type(d).__name__))


def validate(doc: Any, kind: str, where: Optional[str] = None) -> Any:
    """Check ``doc`` (parsed JSON: dicts, lists, numbers, strings) against the
    schema of ``kind``; returns ``doc``. Raises ValueError naming the JSON path
    (prefixed with ``where:``, e.g. the file name, when given)."""
    prefix = f"{where}: " if where else ""
    root = _ROOT.get(kind, kind)
    if kind == "machine_or_dataset":  # `fivecal compensate` takes either
        kind = "dataset" if isinstance(doc, dict) and "observations" in doc else "machine"
        root = kind
    v = _validator(kind)
    key, item_def = _BIG_ARRAYS.get(kind, (None, None))
    items = doc.get(key) if key and isinstance(doc, dict) else None
    if isinstance(items, list) and len(items) > FULL_CHECK_LIMIT:
        _raise(v, dict(doc, **{key: []}), root, prefix)
        item = _item_validator(kind, item_def)
        seen = set()
        for i, o in enumerate(items):
            s = _shape(o)
            if s is None or s not in seen:
                _raise(item, o, root, prefix, (key, i))
                if s is not None:
                    seen.add(s)
        return doc
    _raise(v, doc, root, prefix)
    return doc


def parse(text: str, where: Optional[str] = None) -> Any:
    """JSON text -> Python objects; ValueError with the line and column of a syntax error."""
    prefix = f"{where}: " if where else ""
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{prefix}not valid JSON ({e.msg} at line {e.lineno}, column {e.colno})") from None
    except RecursionError:
        raise ValueError(f"{prefix}not a fivecal file (JSON nested too deeply)") from None


#: Dataset texts longer than this (bytes) are not parsed whole in Python.
BIG_TEXT = 8_000_000
#: How many observations of a big dataset text the schema checks (the first ones).
BIG_TEXT_SAMPLE = 1000

_WS = " \t\n\r"


def _members_after(text: str, i: int, dec: json.JSONDecoder):
    """The top-level members that follow the observations array, whose text
    starts at ``text[i]`` and runs to the end of the file, and the index of
    the array's closing bracket; None if no ``]`` leaves a valid member list
    behind it. Searching back from the end keeps to the small members that
    fivecal writes after the observations (``probe``), so the 10^6 items of
    the array are never looked at."""
    k = len(text)
    for _ in range(10000):
        k = text.rfind("]", i, k)
        if k < 0:
            return None
        tail = text[k + 1:].strip(_WS)
        if tail == "}":
            return {}, k
        if tail.startswith(","):
            try:
                members, end = dec.raw_decode("{" + tail[1:])
            except ValueError:
                continue
            if end == len(tail):
                return members, k
    return None


def _head_of_big_dataset(text: str):
    """The top-level members other than ``observations`` and the first
    :data:`BIG_TEXT_SAMPLE` observations of a dataset text, parsed without
    building the whole observations array (10^6 observations are ~10^7 Python
    objects: tens of seconds). None when the fast path does not apply."""
    dec = json.JSONDecoder()
    n = len(text)

    def ws(i):
        while i < n and text[i] in _WS:
            i += 1
        return i

    i = ws(0)
    if i >= n or text[i] != "{":
        return None
    head = {}
    i = ws(i + 1)
    while i < n and text[i] == '"':
        key, i = dec.raw_decode(text, i)
        i = ws(i)
        if i >= n or text[i] != ":":
            return None
        i = ws(i + 1)
        if key != "observations":
            head[key], i = dec.raw_decode(text, i)
            i = ws(i)
            if i < n and text[i] == ",":
                i = ws(i + 1)
            continue
        if i >= n or text[i] != "[":
            return None
        after = _members_after(text, i, dec)
        if after is None:
            return None
        members, last = after
        if "observations" in members or set(members) & set(head):
            return None  # a repeated key: the ordinary parse (and the C++ loader) decide
        head.update(members)
        sample, j = [], ws(i + 1)
        while j < last and text[j] == "{" and len(sample) < BIG_TEXT_SAMPLE:
            item, j = dec.raw_decode(text, j)
            sample.append(item)
            j = ws(j)
            if text[j] != ",":
                break
            j = ws(j + 1)
        return head, sample
    return None


def check_text(text: str, kind: str, where: Optional[str] = None) -> Any:
    """Parse JSON ``text`` and :func:`validate` it; returns the parsed document,
    or None for a big dataset text (over :data:`BIG_TEXT` bytes, observations
    and ASCII) of which only the members other than the observations and the
    first :data:`BIG_TEXT_SAMPLE` observations are parsed and checked: the C++
    loader checks every observation."""
    if kind == "dataset" and len(text) > BIG_TEXT:
        try:
            split = _head_of_big_dataset(text)
        except (ValueError, RecursionError, IndexError):
            split = None  # a syntax error: the ordinary parse names its line
        if split is not None:
            head, sample = split
            validate(dict(head, observations=[]), kind, where)
            validate({"machine": head.get("machine"), "observations": sample}, kind, where)
            return None
    return validate(parse(text, where), kind, where)


def check_file(path, kind: str) -> Any:
    """Read, parse and :func:`validate` a JSON file; messages start with the path."""
    path = os.fspath(path)
    return check_text(files.read_text(path, kind), kind, path)


def guess_kind(what: str) -> str:
    """The kind for a CLI description of a file (``"the simulation spec"`` -> spec)."""
    w = what.lower()
    for word, kind in (("design", "design"), ("spec", "spec"), ("result", "errors"),
                       ("dataset", "dataset"), ("machine", "machine_or_dataset")):
        if word in w:
            return kind
    raise ValueError(f"no schema for {what}")


def checked_dumps(obj: Any, kind: str) -> str:
    """JSON text of a user dict (numpy values allowed) after :func:`validate`."""

    root = _ROOT.get(kind, kind)
    doc = plain(obj, root)
    validate(doc, kind)
    return json.dumps(doc)


def read_checked(path: str, what: str):
    """A JSON file a command is given, read and :func:`validate`d against
    the schema :func:`guess_kind` finds for ``what`` ("the simulation
    spec" -> spec); messages name the file."""
    return validate(files.read_json(path, what), guess_kind(what), path)
