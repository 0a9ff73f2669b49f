"""JSON encoding of user dicts that may hold numpy values; a non-finite
number is reported with the path of the field that holds it."""
from __future__ import annotations

import json
import math

import numpy as np

#: Deepest nesting accepted.  The formats nest a few levels; a document nested
#: thousands deep is a broken or hostile file, and the C++ parser would then
#: recurse as deep.
MAX_DEPTH = 256


def _leaf(obj, path: str):
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"{path}: value is not finite (NaN or inf)")
    return obj


def plain(obj, path: str):
    """A copy of ``obj`` with numpy arrays/scalars as Python lists/floats;
    raises ValueError naming ``path`` for NaN or inf, or for nesting deeper
    than :data:`MAX_DEPTH`.  Iterative, so deep input cannot exhaust
    Python's recursion limit."""
    def expand(o):
        if hasattr(o, "to_dict") and not isinstance(o, dict):
            o = o.to_dict()
        if isinstance(o, np.ndarray):
            o = o.tolist()
        return o

    root = [None]
    # (value, where to store its copy: container and key, path, depth)
    stack = [(obj, root, 0, path, 0)]
    while stack:
        o, parent, key, where, depth = stack.pop()
        o = expand(o)
        if isinstance(o, dict) or isinstance(o, (list, tuple)):
            if depth >= MAX_DEPTH:
                short = where if len(where) <= 80 else where[:80] + "..."
                raise ValueError(f"{short}: nested deeper than {MAX_DEPTH} levels")
            if isinstance(o, dict):
                out = {}
                parent[key] = out
                for k in o:
                    out[k] = None  # keeps the key order
                # reversed: children are visited in document order, so the
                # first bad value is the one reported
                stack.extend((v, out, k, f"{where}.{k}", depth + 1) for k, v in reversed(list(o.items())))
            else:
                out = [None] * len(o)
                parent[key] = out
                stack.extend((o[i], out, i, f"{where}[{i}]", depth + 1) for i in range(len(o) - 1, -1, -1))
        else:
            parent[key] = _leaf(o, where)
    return root[0]


def dumps(obj, path: str) -> str:
    """JSON text of :func:`plain` ``(obj, path)``."""
    return json.dumps(plain(obj, path))
