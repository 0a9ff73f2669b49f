"""Machine: the machine-tool model (topology, axes, tool) and its kinematics.

Units: linear commands and lengths in mm, rotary commands in degrees, angular
error parameters in rad. Points are returned in the workpiece frame, which
coincides with the machine frame F at the zero pose.
"""
from __future__ import annotations

import json
import numbers
import os
import warnings
from typing import Mapping, Optional, Union

import numpy as np

from . import _core, schema
from .units import looks_like_radians, radians_message
from . import files
from .views import Viewable

ArrayLike = Union[float, np.ndarray, list]


class RadiansWarning(UserWarning):
    """Rotary axis values look like radians where degrees are expected."""


class Machine(Viewable):
    """A machine tool: topology, axes and tool, with forward and inverse kinematics.

    Build one with :meth:`load` (JSON file) or :meth:`from_dict`. The topology
    string is read from workpiece to tool (``wCBXfZYSt``); see docs/formats.md.
    """

    def __init__(self, core: "_core.Machine"):
        self._core = core

    # ---- construction -------------------------------------------------
    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "Machine":
        """Load a machine definition (JSON, or TOML with the same keys)."""

        path = os.fspath(path)
        text = files.read_text(path, "machine")
        if path.endswith(".toml"):
            try:
                import tomllib
            except ImportError:  # Python < 3.11: the same parser as the tomli package
                import tomli as tomllib
            try:
                return cls.from_dict(tomllib.loads(text))
            except tomllib.TOMLDecodeError as e:
                raise ValueError(f"{path}: not valid TOML ({e})") from None
        schema.check_text(text, "machine", path)
        try:
            return cls(_core.Machine.from_json(text))
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None

    @classmethod
    def from_dict(cls, d: Mapping) -> "Machine":
        """Build from a machine definition dict (docs/formats.md keys: name, topology,
        axes with direction and point in mm, tool.tip in mm); a Machine is
        returned as is."""
        if isinstance(d, Machine):
            return d
        if not isinstance(d, Mapping):
            raise ValueError("machine: expected a mapping with 'topology' and 'axes'")
        return cls(_core.Machine.from_json(schema.checked_dumps(d, "machine")))

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
            if not isinstance(name, str):
                raise ValueError(f"errors: parameter names are strings, got {name!r}")
            try:
                i = self._core.parameter_index(name)
            except ValueError as e:  # the message names the nearest parameter
                # A result also carries its set-up values (facet.F3, sphere.S1.x,
                # ...): only names of that shape are skipped; a typo such as
                # EX0C.x would otherwise vanish and leave the error at zero.
                if _core.is_setup_parameter_name(name):
                    continue
                raise ValueError(f"errors.{name}: {e}") from None
            theta[i] = _finite_scalar(value, f"errors.{name}")
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
            arr = float_array(val, f"{name}.{key}")
            if arr.ndim > 1:
                raise ValueError(f"{name}.{key}: expected a 1-D array, got shape {arr.shape}")
            if arr.ndim == 1:
                if n is not None and arr.size != n:
                    raise ValueError(
                        f"{name}: arrays of different lengths ({name}.{key} has {arr.size}, "
                        f"others {n})")
                n = arr.size
            if letter in "ABC" and looks_like_radians(arr):
                warnings.warn(radians_message(f"{name}.{key}", arr), RadiansWarning, stacklevel=3)
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
            arr = float_array(val, f"directions.{key}")
            # A scalar applies to every pose, like a scalar axis value; any
            # other shape than one value per pose is refused, never broadcast.
            if arr.ndim > 1:
                raise ValueError(f"directions.{key}: expected a 1-D array of {n} values, "
                                 f"got shape {arr.shape}")
            if arr.ndim == 1 and arr.size != n:
                raise ValueError(f"directions.{key}: length {arr.size}, expected {n}")
            bad = ~np.isin(np.atleast_1d(arr), (-1.0, 0.0, 1.0))
            if bad.any():
                i = int(np.argmax(bad))
                raise ValueError(f"directions.{key}{'' if arr.ndim == 0 else f'[{i}]'}: values must be -1, 0 "
                                 f"or +1, got {np.atleast_1d(arr)[i]:g}")
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
        t = None if tip is None else _vector3(tip, "tip")
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
        pts = np.atleast_2d(float_array(points, "points"))
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points: expected shape (N, 3), got {pts.shape}")
        ta = None
        if tool_axes is not None:
            ta = np.atleast_2d(float_array(tool_axes, "tool_axes"))
            if ta.shape == (1, 3) and pts.shape[0] > 1:
                ta = np.repeat(ta, pts.shape[0], axis=0)
            if ta.shape != pts.shape:
                raise ValueError(f"tool_axes: expected shape {pts.shape}, got {ta.shape}")
        s = np.zeros(len(self.axis_names))
        if start is not None:
            s = self.axes_matrix(start, "start")[0]
        d = self.directions_matrix(directions, pts.shape[0])
        return self.axes_dict(_core.inverse(self._core, self.theta(errors), pts, ta, s, d))


def _is_number(x) -> bool:
    # bool is an int to Python, and numpy turns "1.5" into 1.5: neither is a
    # number a user meant to give.
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def _where(what: str, index) -> str:
    return what + "".join(f"[{i}]" for i in index)


def float_array(value, what: str) -> np.ndarray:
    """``value`` (a number or nested lists / array of numbers) as a float
    array. Anything else is refused with a ValueError naming ``what`` and the
    index of the first bad element: ``axes.X[1]: expected a number, got 'a'``,
    ``points[2][0]: value is not finite (NaN or inf)``, or a ragged nesting."""
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{what}: expected a number or an array of numbers, got {value!r}")
    try:
        raw = np.asarray(value)
    except ValueError:  # numpy refuses nested lists of unequal lengths
        raise ValueError(f"{what}: rows of different lengths (ragged); expected a rectangular array of "
                         "numbers") from None
    if raw.dtype.kind in "iuf":
        arr = raw.astype(float, copy=False)
    else:  # strings, booleans, objects, complex: find the element to name
        # As objects, [1, "+"] keeps its 1 (numpy would make it the string "1").
        obj = raw if isinstance(value, np.ndarray) else np.asarray(value, dtype=object)
        arr = np.empty(obj.shape)
        for index in np.ndindex(obj.shape):
            x = obj[index]
            if isinstance(x, np.generic):
                x = x.item()  # np.str_('a') -> 'a', for the message
            if isinstance(x, (list, tuple, np.ndarray)):
                raise ValueError(f"{_where(what, index)}: rows of different lengths (ragged); expected a "
                                 "rectangular array of numbers")
            if not _is_number(x):
                raise ValueError(f"{_where(what, index)}: expected a number, got {x!r}")
            try:
                arr[index] = float(x)
            except OverflowError:
                raise ValueError(f"{_where(what, index)}: {x!r} is out of the range of a double") from None
    bad = ~np.isfinite(arr)
    if bad.any():
        index = np.unravel_index(int(np.argmax(bad)), arr.shape) if arr.ndim else ()
        raise ValueError(f"{_where(what, index)}: value is not finite (NaN or inf)")
    return arr


def _vector3(value, what: str) -> np.ndarray:
    v = float_array(value, what)
    if v.shape != (3,):
        raise ValueError(f"{what}: expected 3 numbers (x, y, z in mm), got shape {v.shape}")
    return v


def _finite_scalar(value, what: str) -> float:
    if not _is_number(value) and not (isinstance(value, np.ndarray) and value.shape == ()):
        raise ValueError(f"{what}: expected a number, got {value!r}")
    v = float(float_array(value, what))
    return v
