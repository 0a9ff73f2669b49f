"""Machine: the machine-tool model (topology, axes, tool) and its kinematics.

Units: linear commands and lengths in mm, rotary commands in degrees, angular
error parameters in rad. Points are returned in the workpiece frame, which
coincides with the machine frame F at the zero pose.
"""
from __future__ import annotations

import json
import os
import warnings
from typing import Mapping, Optional, Union

import numpy as np

from . import _core
from ._json import dumps

ArrayLike = Union[float, np.ndarray, list]


class RadiansWarning(UserWarning):
    """Rotary axis values look like radians where degrees are expected."""


def _looks_like_radians(v: np.ndarray) -> bool:
    a = np.abs(v[np.isfinite(v)])
    if a.size == 0 or a.max() == 0.0 or a.max() > 2 * np.pi + 1e-6:
        return False
    non_integer = a[np.abs(a - np.round(a)) > 1e-9]
    if non_integer.size == 0:
        return False
    # Typical radian indexations (multiples of pi/12) or a dense sweep within 2 pi.
    k = non_integer / (np.pi / 12)
    if np.any(np.abs(k - np.round(k)) < 1e-4):
        return True
    return np.unique(np.round(non_integer, 9)).size > 3 and a.max() > 1.0


class Machine:
    """A machine tool: topology, axes and tool, with forward and inverse kinematics.

    Build one with :meth:`load` (JSON file) or :meth:`from_dict`. The topology
    string is read from workpiece to tool (``wCBXfZYSt``); see DESIGN.md.
    """

    def __init__(self, core: "_core.Machine"):
        self._core = core

    # ---- construction -------------------------------------------------
    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "Machine":
        """Load a machine definition (JSON, or TOML with the same keys)."""
        path = os.fspath(path)
        if path.endswith(".toml"):
            import tomllib

            with open(path, "rb") as f:
                return cls.from_dict(tomllib.load(f))
        return cls(_core.Machine.load(path))

    @classmethod
    def from_dict(cls, d: Mapping) -> "Machine":
        """Build from a machine definition dict (DESIGN.md keys: name, topology,
        axes with direction and point in mm, tool.tip in mm); a Machine is
        returned as is."""
        if isinstance(d, Machine):
            return d
        if not isinstance(d, Mapping):
            raise ValueError("machine: expected a mapping with 'topology' and 'axes'")
        return cls(_core.Machine.from_json(dumps(d, "machine")))

    def to_dict(self) -> dict:
        """The machine definition as a JSON-ready dict (mm, unit directions)."""
        return json.loads(self._core.to_json())

    # ---- description --------------------------------------------------
    @property
    def name(self) -> str:
        """The machine's name from its definition."""
        return self._core.name

    @property
    def topology(self) -> str:
        """Topology string read from workpiece to tool, e.g. ``'wCBXfZYSt'``."""
        return self._core.topology

    @property
    def axis_names(self) -> str:
        """Axis letters in topology order (workpiece to tool), e.g. ``'CBXZYS'``."""
        return self._core.axis_names

    @property
    def axes(self) -> list:
        """Axis descriptions in topology order: dicts with name, type
        (``linear``/``rotary``), direction (unit vector in F at the zero pose)
        and point (mm)."""
        return self._core.axes

    @property
    def workpiece_chain(self) -> str:
        """Workpiece-side axes from the foundation outward."""
        return self._core.workpiece_chain

    @property
    def tool_chain(self) -> str:
        """Tool-side axes from the foundation outward."""
        return self._core.tool_chain

    @property
    def tip(self) -> np.ndarray:
        """Nominal tool tip (3,) in mm, in the machine frame F at the zero pose."""
        return np.asarray(self._core.tip)

    def is_rotary(self, axis: str) -> bool:
        """True for the rotary axis letters A, B, C and the spindle S (commands in degrees)."""
        return axis in "ABCS"

    def parameter_names(self) -> list:
        """All machine error parameter names (location, error motion, backlash, tip)."""
        return self._core.parameter_names()

    def parameter_kind(self, name: str) -> str:
        """'location', 'motion', 'backlash' or 'tip'."""
        return self._core.parameter_kind(name)

    def parameter_is_angular(self, name: str) -> bool:
        """True for parameters in rad (angular location errors, angular error
        motions and rotary-axis backlash)."""
        return self._core.parameter_is_angular(name)

    def __repr__(self) -> str:
        return f"Machine({self.name!r}, topology={self.topology!r})"

    # ---- conversions --------------------------------------------------
    def theta(self, errors: Optional[Mapping[str, float]] = None) -> np.ndarray:
        """The full machine parameter vector for a dict name -> value."""
        theta = np.zeros(self._core.num_parameters)
        if errors is None:
            return theta
        if hasattr(errors, "values") and not isinstance(errors, Mapping):
            errors = errors.values  # a Result
        for name, value in errors.items():
            if "." in name and not name.startswith("tip."):
                continue  # setup parameters of a result (facet.F3, sphere.S1.x, ...)
            theta[self._core.parameter_index(name)] = _finite_scalar(value, f"errors.{name}")
        return theta

    def axes_matrix(self, axes: Mapping[str, ArrayLike], name: str = "axes") -> np.ndarray:
        """(N, num_axes) matrix in machine axis order from a dict of arrays.

        Missing axes are an error except the spindle S (taken as 0)."""
        if not isinstance(axes, Mapping):
            raise ValueError(f"{name}: expected a dict axis letter -> array")
        if "S" in axes and "C1" in axes:
            raise ValueError(f"{name}: both 'S' and its alias 'C1' are given; keep one")
        cols = {}
        n = None
        for key, val in axes.items():
            letter = "S" if key == "C1" else key
            if letter not in self.axis_names:
                raise ValueError(
                    f"{name}: unknown axis '{key}' for machine {self.name!r} "
                    f"(axes {', '.join(self.axis_names)})")
            arr = np.asarray(val, dtype=float)
            if arr.ndim > 1:
                raise ValueError(f"{name}.{key}: expected a 1-D array, got shape {arr.shape}")
            if arr.ndim == 1:
                if n is not None and arr.size != n:
                    raise ValueError(
                        f"{name}: arrays of different lengths ({name}.{key} has {arr.size}, "
                        f"others {n})")
                n = arr.size
            bad = ~np.isfinite(np.atleast_1d(arr))
            if bad.any():
                raise ValueError(f"{name}.{key}[{int(np.argmax(bad))}]: value is not finite (NaN or inf)")
            if letter in "ABC" and _looks_like_radians(np.atleast_1d(arr)):
                warnings.warn(
                    f"{name}.{key}: rotary values look like radians (max {np.abs(arr).max():.4g}); "
                    "fivecal expects degrees", RadiansWarning, stacklevel=3)
            cols[letter] = arr
        missing = [a for a in self.axis_names if a not in cols and a != "S"]
        if missing:
            raise ValueError(f"{name}: missing axis {', '.join(missing)} (machine axes "
                             f"{', '.join(self.axis_names)})")
        n = 1 if n is None else n
        out = np.zeros((n, len(self.axis_names)))
        for i, a in enumerate(self.axis_names):
            if a in cols:
                out[:, i] = cols[a]
        return out

    def directions_matrix(self, directions: Optional[Mapping[str, ArrayLike]], n: int):
        """(n, num_axes) int32 matrix of last-move directions (-1, 0, +1) in
        machine axis order from a dict axis -> array, or None."""
        if directions is None:
            return None
        if not isinstance(directions, Mapping):
            raise ValueError("directions: expected a dict axis letter -> array of -1, 0 or +1, "
                             f"got {type(directions).__name__}")
        if "S" in directions and "C1" in directions:
            raise ValueError("directions: both 'S' and its alias 'C1' are given; keep one")
        out = np.zeros((n, len(self.axis_names)), dtype=np.int32)
        for key, val in directions.items():
            letter = "S" if key == "C1" else key
            if letter not in self.axis_names:
                raise ValueError(f"directions: unknown axis '{key}' (machine axes "
                                 f"{', '.join(self.axis_names)})")
            try:
                arr = np.asarray(val, dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"directions.{key}: expected numbers -1, 0 or +1") from None
            # A scalar applies to every pose, like a scalar axis value; any
            # other shape than one value per pose is refused, never broadcast.
            if arr.ndim > 1:
                raise ValueError(f"directions.{key}: expected a 1-D array of {n} values, "
                                 f"got shape {arr.shape}")
            if arr.ndim == 1 and arr.size != n:
                raise ValueError(f"directions.{key}: length {arr.size}, expected {n}")
            if not np.all(np.isin(arr, (-1.0, 0.0, 1.0))):
                raise ValueError(f"directions.{key}: values must be -1, 0 or +1")
            out[:, self.axis_names.index(letter)] = arr
        return out

    def axes_dict(self, matrix: np.ndarray) -> dict:
        """Dict axis letter -> (N,) array (mm / degrees) from an (N, num_axes) matrix."""
        return {a: np.ascontiguousarray(matrix[:, i]) for i, a in enumerate(self.axis_names)}

    # ---- kinematics ---------------------------------------------------
    def tool_pose(self, axes: Mapping[str, ArrayLike], errors=None, directions=None, tip=None):
        """Tool point (N, 3) mm and unit tool axis (N, 3), both in the workpiece frame.

        ``axes``: dict axis letter -> array (mm, rotary in degrees);
        ``errors``: dict parameter name -> value (mm, rad);
        ``directions``: dict axis letter -> array of -1/+1 (last move direction, for backlash);
        ``tip``: a tool point (mm, F at the zero pose) replacing the machine tip and its
        tip.x|y|z offsets, e.g. a ball-bar tool ball.
        """
        return self._poses(axes, errors, directions, tip, True)

    def tool_point(self, axes: Mapping[str, ArrayLike], errors=None, directions=None,
                   tip=None) -> np.ndarray:
        """Tool point (N, 3) mm in the workpiece frame for the given axis readings."""
        return self._poses(axes, errors, directions, tip, False)[0]

    def _poses(self, axes, errors, directions, tip, with_axes):
        q = self.axes_matrix(axes)
        d = self.directions_matrix(directions, q.shape[0])
        t = None if tip is None else np.asarray(tip, dtype=float).reshape(3)
        return _core.tool_poses(self._core, self.theta(errors), q, d, t, with_axes)

    def volumetric_error(self, axes: Mapping[str, ArrayLike], errors, directions=None) -> np.ndarray:
        """Tool-point error (N, 3) mm in the workpiece frame at the given poses:
        where the erroneous machine puts the tool minus where the nominal one
        would (a volumetric error map of identified errors)."""
        q = self.axes_matrix(axes)
        d = self.directions_matrix(directions, q.shape[0])
        real = _core.tool_poses(self._core, self.theta(errors), q, d, None, False)[0]
        ideal = _core.tool_poses(self._core, self.theta(None), q, None, None, False)[0]
        return real - ideal

    def inverse(self, points, tool_axes=None, start: Optional[Mapping[str, float]] = None,
                errors=None, directions=None) -> dict:
        """Axis commands (dict axis -> array, mm / degrees) that put the tool point at
        ``points`` (N, 3) and, if given, the tool axis along ``tool_axes`` (N, 3), both in
        the workpiece frame. Among several solutions the one with the smallest move from
        the previous pose (``start`` for the first) is chosen. With ``errors`` the
        erroneous model is inverted: the commands that compensate those errors."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        if pts.shape[1] != 3:
            raise ValueError(f"points: expected shape (N, 3), got {pts.shape}")
        ta = None
        if tool_axes is not None:
            ta = np.atleast_2d(np.asarray(tool_axes, dtype=float))
            if ta.shape == (1, 3) and pts.shape[0] > 1:
                ta = np.repeat(ta, pts.shape[0], axis=0)
            if ta.shape != pts.shape:
                raise ValueError(f"tool_axes: expected shape {pts.shape}, got {ta.shape}")
        s = np.zeros(len(self.axis_names))
        if start is not None:
            s = self.axes_matrix(start, "start")[0]
        d = self.directions_matrix(directions, pts.shape[0])
        return self.axes_dict(_core.inverse(self._core, self.theta(errors), pts, ta, s, d))


def _finite_scalar(value, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number, got {value!r}") from None
    if not np.isfinite(v):
        raise ValueError(f"{what}: value is not finite (NaN or inf)")
    return v
