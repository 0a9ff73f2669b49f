"""JSON encoding of user dicts that may hold numpy values; a non-finite
number is reported with the path of the field that holds it."""
from __future__ import annotations

import json
import math

import numpy as np


def plain(obj, path: str):
    """A copy of ``obj`` with numpy arrays/scalars as Python lists/floats;
    raises ValueError naming ``path`` for NaN or inf."""
    if hasattr(obj, "to_dict") and not isinstance(obj, dict):
        obj = obj.to_dict()
    if isinstance(obj, dict):
        return {k: plain(v, f"{path}.{k}") for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    if isinstance(obj, (list, tuple)):
        return [plain(v, f"{path}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"{path}: value is not finite (NaN or inf)")
    return obj


def dumps(obj, path: str) -> str:
    """JSON text of :func:`plain` ``(obj, path)``."""
    return json.dumps(plain(obj, path))
