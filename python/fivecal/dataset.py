"""Dataset: a machine, its artefact and the recorded observations
(format: docs/formats.md, "Dataset"). Validated by the C++ core on load; errors
name the observation index and field."""
from __future__ import annotations

import json
import os
from typing import Iterable, Mapping, Union

import numpy as np

from . import _core, _json, files, plausibility, schema
from .machine import Machine
from .views import Viewable

#: Dataset file formats besides JSON, as (is_format(path), read(path),
#: name suffixes, write(ds, path)): io/columnar.py registers Parquet (the
#: package's __init__ imports it), since this module, below io/, imports none of it.
_FORMATS: list = []


def register_format(is_format, read, suffixes, write) -> None:
    """Let :func:`load_dataset` read a file ``is_format(path)`` recognises
    with ``read(path)``, and :func:`save_dataset` write a name ending in one
    of ``suffixes`` with ``write(ds, path)``."""
    _FORMATS.append((is_format, read, tuple(s.lower() for s in suffixes), write))


class _ReadOnly:
    """Refuses the mutating methods of a dict or list: the dataset's own view
    of its observations is shared by every caller, and the core (what the fit
    sees) would not follow an edit."""

    def _refuse(self, *args, **kwargs):
        raise TypeError("a Dataset's observations and artefact are read-only: edit a copy from "
                        "Dataset.to_dict() and build a new Dataset with Dataset.from_dict()")

    __setitem__ = __delitem__ = __iadd__ = __imul__ = __ior__ = _refuse
    append = extend = insert = pop = remove = clear = sort = reverse = _refuse
    update = setdefault = popitem = _refuse

    # A copy is the caller's: plain, editable.
    def __copy__(self):
        return _thawed(self, deep=False)

    def __deepcopy__(self, memo):
        return _thawed(self)

    def __reduce_ex__(self, protocol):
        return _thawed, (_thawed(self, deep=False),)


class _ReadOnlyDict(_ReadOnly, dict):
    __slots__ = ()


class _ReadOnlyList(_ReadOnly, list):
    __slots__ = ()


def _frozen_pairs(pairs):
    # json.loads hook, called innermost first: a dict's lists hold numbers or
    # dicts frozen already (a dataset has no list of lists).
    return _ReadOnlyDict((k, _ReadOnlyList(v) if type(v) is list else v) for k, v in pairs)


def _thawed(x, deep: bool = True):
    if isinstance(x, dict):
        return {k: _thawed(v) if deep else v for k, v in x.items()}
    if isinstance(x, list):
        return [_thawed(v) if deep else v for v in x]
    return x


def dumps(obj, path: str = "dataset") -> str:
    """JSON text of dicts that may hold numpy arrays or a Machine."""
    return _json.dumps(obj, path)


class Dataset(Viewable):
    """A validated dataset. Build with :func:`load_dataset`, :meth:`from_dict`
    or :func:`fivecal.simulate`."""

    def __init__(self, core: "_core.Dataset"):
        self._core = core
        self._dict = None

    @classmethod
    def from_dict(cls, d: Mapping) -> "Dataset":
        """Validate and build from a dict in the dataset format (docs/formats.md)
        (mm, degrees for rotary readings); a Dataset is returned as is.
        ValueError names the observation and field."""
        if isinstance(d, Dataset):
            return d
        ds = cls(_core.Dataset.from_json(schema.checked_dumps(d, "dataset")))
        plausibility.check_loaded(ds)
        return ds

    def to_dict(self) -> dict:
        """The dataset as a JSON-ready dict (docs/formats.md, mm / degrees): a
        new copy on every call, the caller's to edit (the dataset does not change)."""
        return _thawed(self._view())

    def _view(self) -> dict:
        # Built once, read-only: observations and artefact hand it out without copying.
        if self._dict is None:
            self._dict = json.loads(self._core.to_json(), object_pairs_hook=_frozen_pairs)
        return self._dict

    @property
    def machine(self) -> Machine:
        """The machine the observations were taken on."""
        return Machine(self._core.machine)

    @property
    def observations(self) -> list:
        """Observation dicts (type, target or setup, axes in mm / degrees, ...),
        read-only (edit a copy from :meth:`to_dict`)."""
        return self._view()["observations"]

    @property
    def artefact(self) -> dict:
        """Facets, spheres and scale bars (mm, workpiece frame), read-only."""
        return self._view()["artefact"]

    @property
    def observation_types(self) -> list:
        """The type of each observation (``facet``, ``sphere``, ``dbb``, ``ball3d``, ...)."""
        return self._core.observation_types

    def __len__(self) -> int:
        return self._core.num_observations

    def subset(self, indices: Iterable[int]) -> "Dataset":
        """The same machine and artefact with only the given observations."""
        return Dataset(self._core.subset([int(i) for i in indices]))

    def axes(self) -> dict:
        """Axis readings of every observation: dict axis -> array (mm / degrees)."""
        m = self.machine
        return {a: np.array([o["axes"].get(a, 0.0) for o in self.observations]) for a in m.axis_names}

    def __repr__(self) -> str:
        types = {}
        for t in self.observation_types:
            types[t] = types.get(t, 0) + 1
        return f"Dataset({self.machine.name!r}, {types})"


def load_dataset(path: Union[str, os.PathLike]) -> Dataset:
    """Load a dataset file, JSON or Parquet (recognised by its first bytes;
    docs/formats.md); ValueError names the file, observation and field."""
    path = os.fspath(path)
    for is_format, read, _, _ in _FORMATS:
        if is_format(path):
            return read(path)
    text = files.read_text(path, "dataset")
    schema.check_text(text, "dataset", path)
    try:
        ds = Dataset(_core.Dataset.from_json(text))
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    plausibility.check_loaded(ds, where=path)
    return ds


def save_dataset(ds: Union[Dataset, Mapping], path: Union[str, os.PathLike]) -> None:
    """Write a dataset (validated first) in the dataset format (docs/formats.md):
    Parquet when the name ends in ``.parquet`` or ``.pq`` (needs pyarrow),
    otherwise JSON. Streamed (10^6 observations in seconds, without a copy
    of the dataset in memory) and atomic: a write that fails or is
    interrupted leaves ``path`` as it was."""
    ds = Dataset.from_dict(ds)
    for _, _, suffixes, write in _FORMATS:
        if os.fspath(path).lower().endswith(suffixes):
            write(ds, path)
            return
    write_json(ds, path)


def write_json(ds: Union[Dataset, Mapping], path: Union[str, os.PathLike]) -> None:
    """Write a dataset as a JSON file whatever the name says: the head
    indented, then one observation per line, written by the core piece by
    piece into a temporary file that replaces ``path`` at the end."""
    ds = Dataset.from_dict(ds)
    with files.atomic_output(path) as out:
        ds._core.write_json(out.write)


def ball_dataset(machine, type: str, axes: Mapping, tool_ball, table_ball, length: float = 0.0,
                 readings=None, measured=None, setup: str = "", directions=None, sigma=None) -> Dataset:
    """A dataset of ball-bar (``type="dbb"``, ``readings`` (N,) mm, bar ``length`` mm)
    or 3D ball (``type="ball3d"``, ``measured`` (N, 3) mm) samples of one mounting,
    built from arrays without JSON (fast for 10^5-10^6 samples). ``axes``: dict axis ->
    array (mm / degrees); ``tool_ball`` in F at the zero pose, ``table_ball`` in the
    workpiece frame. ``sigma``: the declared noise (one sigma, mm) that weights the
    samples in the fit, as ``"sigma"`` in a dataset file: one number for every
    sample, (N,) one per sample, or for ball3d (N, 3) one per component; None =
    the instrument's default."""
    m = Machine.from_dict(machine)
    q = m.axes_matrix(axes)
    d = m.directions_matrix(directions, q.shape[0])
    kinds = {k["name"]: k for k in _core.observation_kinds() if k["ball_mount"]}
    if type not in kinds:
        raise ValueError(f"ball_dataset: type {type!r}: expected one of {', '.join(map(repr, kinds))}")
    # the kind's own value: readings (one row) or measured displacements (three)
    rows, arg = kinds[type]["rows"], ("readings", "measured")[kinds[type]["rows"] > 1]
    given = readings if rows == 1 else measured
    if given is None:
        raise ValueError(f"ball_dataset: {arg!r} missing for type {type}")
    values = np.asarray(given, dtype=float).reshape(-1, rows)
    plausibility.check_balls(m, type, q, values, "ball_dataset")
    sig = None
    if sigma is not None:
        try:
            sig = np.asarray(sigma, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("ball_dataset: sigma: expected a number or an array of numbers (mm)") from None
        if sig.ndim == 0:
            sig = np.full((q.shape[0], 1), float(sig))
        elif sig.ndim == 1:
            if sig.shape[0] != q.shape[0]:
                raise ValueError(f"ball_dataset: sigma: {sig.shape[0]} values for {q.shape[0]} samples")
            sig = sig.reshape(-1, 1)
    return Dataset(_core.Dataset.balls(m._core, type, setup, q, d, np.asarray(tool_ball, float),
                                       np.asarray(table_ball, float), float(length), values, sig))
