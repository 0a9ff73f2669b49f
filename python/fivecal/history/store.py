"""The calibration store: one SQLite file, one row per identification.

Nothing to install or start: the standard library's ``sqlite3``. Values,
standard uncertainties and covariance are stored as little-endian float64
blobs, so what is read back is bit for bit what was written. The schema and
its versions are described in docs/history.md; every change of schema is a
numbered migration in :data:`MIGRATIONS`, applied in order when an older
store is opened, so a store written by one fivecal version opens in the next.

Several processes may write to one store at once: the file is in WAL mode,
each write is one ``BEGIN IMMEDIATE`` transaction and a writer that finds the
file locked waits (``timeout`` seconds) instead of failing.

What goes in is checked: a calibration whose values or uncertainties are not
finite is refused, a result of another machine than the one the store holds
for that machine id is refused unless the machine was rebuilt (which the
store records, and trends start again there), and recording the same
dataset of a machine again changes nothing unless asked to replace it.
"""
from __future__ import annotations

import datetime
import hashlib
import json
import math
import os
import sqlite3
import warnings
from dataclasses import dataclass, field
from typing import Iterable, List, Mapping, Optional, Sequence

import numpy as np

from .. import files
from ..schema import validate as validate_document
from .._version import __version__
from ..dataset import Dataset, load_dataset
from ..machine import Machine
from ..units import _BACKLASH, _LOCATION, _MOTION

# ---------------------------------------------------------------------------
# schema: migrations in order, never edited once released (a store written
# with version n is brought to the current one by running n+1 .. latest)
# ---------------------------------------------------------------------------

_V1 = """
CREATE TABLE machines (
    machine_id TEXT PRIMARY KEY,
    definition TEXT NOT NULL
);
CREATE TABLE calibrations (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    machine_id TEXT NOT NULL,
    time TEXT NOT NULL,
    procedure TEXT NOT NULL DEFAULT '',
    digest TEXT NOT NULL,
    names TEXT NOT NULL,
    "values" BLOB NOT NULL,
    covariance BLOB NOT NULL,
    fixed TEXT NOT NULL DEFAULT '{}',
    rms REAL,
    chi2 REAL,
    verdict TEXT NOT NULL,
    converged INTEGER NOT NULL,
    undetermined TEXT NOT NULL DEFAULT '[]',
    fivecal_version TEXT NOT NULL
);
CREATE INDEX calibrations_machine_time ON calibrations (machine_id, time);
"""

# v2: prior sigmas and the chi-square's degrees of freedom and p value (the
# fit-quality verdict needs them to be re-judged), a label for the source
# file, and the failures of fleet runs (recorded so a run never dies on one
# bad dataset, and so one can see what failed).
_V2 = """
ALTER TABLE calibrations ADD COLUMN prior_std BLOB;
ALTER TABLE calibrations ADD COLUMN dof INTEGER;
ALTER TABLE calibrations ADD COLUMN chi2_p REAL;
ALTER TABLE calibrations ADD COLUMN source TEXT NOT NULL DEFAULT '';
CREATE INDEX calibrations_digest ON calibrations (digest);
CREATE TABLE failures (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    digest TEXT NOT NULL,
    source TEXT NOT NULL DEFAULT '',
    machine_id TEXT NOT NULL DEFAULT '',
    time TEXT NOT NULL,
    error TEXT NOT NULL,
    fivecal_version TEXT NOT NULL
);
CREATE INDEX failures_digest ON failures (digest);
"""

# v3: how the covariance was obtained: "gum" (the fit's linearised covariance)
# or "monte_carlo:N" (JCGM 101 with N trials, fleet runs with trials)
_V3 = """
ALTER TABLE calibrations ADD COLUMN uncertainty TEXT NOT NULL DEFAULT 'gum';
"""

# v4: machines rebuilt (the user said so when a result of another machine
# definition was recorded under an existing machine id): the trend of a
# machine starts again at the latest rebuild, never pooling across it
_V4 = """
CREATE TABLE rebuilds (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    machine_id TEXT NOT NULL,
    time TEXT NOT NULL,
    previous TEXT,
    definition TEXT,
    recorded TEXT NOT NULL,
    fivecal_version TEXT NOT NULL
);
CREATE INDEX rebuilds_machine_time ON rebuilds (machine_id, time);
"""

#: (version, SQL) in order; the store's ``schema_version`` table holds the last applied
MIGRATIONS = [(1, _V1), (2, _V2), (3, _V3), (4, _V4)]
SCHEMA_VERSION = MIGRATIONS[-1][0]


def _version() -> str:
    return __version__


def _blob(a) -> bytes:
    return np.ascontiguousarray(np.asarray(a, dtype="<f8")).tobytes()


def _array(b, shape=None) -> Optional[np.ndarray]:
    if b is None:
        return None
    a = np.frombuffer(b, dtype="<f8").astype(np.float64)
    return a.reshape(shape) if shape is not None else a


def utc_time(t=None) -> str:
    """``t`` (None = now, a datetime, or ISO text) as UTC ISO 8601 text
    ``YYYY-MM-DDTHH:MM:SS[.ffffff]Z`` (a naive time is taken as UTC). Order
    stored times with :func:`time_key` (or SQLite's ``julianday``), not as
    text: ``...:00.5Z`` sorts before ``...:00Z`` as text."""
    if t is None:
        t = datetime.datetime.now(datetime.timezone.utc)
    elif isinstance(t, str):
        s = t.strip()
        try:
            t = datetime.datetime.fromisoformat(s[:-1] + "+00:00" if s.endswith("Z") else s)
        except ValueError:
            raise ValueError(f"time: '{t}' is not an ISO 8601 date or time (e.g. 2026-11-24T03:00:00Z)") from None
    elif isinstance(t, datetime.date) and not isinstance(t, datetime.datetime):
        t = datetime.datetime(t.year, t.month, t.day)
    if not isinstance(t, datetime.datetime):
        raise ValueError(f"time: expected ISO text or a datetime, got {type(t).__name__}")
    if t.tzinfo is None:
        t = t.replace(tzinfo=datetime.timezone.utc)
    t = t.astimezone(datetime.timezone.utc)
    return t.strftime("%Y-%m-%dT%H:%M:%S") + (f".{t.microsecond:06d}" if t.microsecond else "") + "Z"


def time_key(text: str) -> datetime.datetime:
    """The instant a stored time (:func:`utc_time`) stands for, to order by."""
    return datetime.datetime.fromisoformat(text[:-1] + "+00:00" if text.endswith("Z") else text)


def dataset_digest(dataset) -> str:
    """sha256 (hex) of a dataset's canonical JSON (a :class:`fivecal.Dataset`,
    its dict, or a path): the JSON the core writes for the loaded dataset,
    keys sorted and no spaces, so the same data give the same digest whatever
    the file's layout, key order or number formatting."""
    if isinstance(dataset, (str, os.PathLike)):
        dataset = load_dataset(os.fspath(dataset))
    elif not isinstance(dataset, Dataset):
        dataset = Dataset.from_dict(dataset)
    return hashlib.sha256(dataset._core.to_json().encode("utf-8")).hexdigest()


@dataclass
class Calibration:
    """One stored identification. ``names`` are the estimated parameters in
    the order of ``values`` and ``covariance`` (mm, rad); ``fixed`` the
    parameters held at a non-zero value; ``prior_std`` the prior one-sigma
    of each estimated parameter (None when the fit had none)."""
    machine_id: str
    time: str
    names: List[str]
    values: np.ndarray
    covariance: np.ndarray
    procedure: str = ""
    digest: str = ""
    fixed: dict = field(default_factory=dict)
    prior_std: Optional[np.ndarray] = None
    rms: float = math.nan
    chi2: float = math.nan
    dof: Optional[int] = None
    chi2_p: float = math.nan
    verdict: str = "ok"
    converged: bool = True
    undetermined: List[str] = field(default_factory=list)
    fivecal_version: str = ""
    source: str = ""
    #: how ``covariance`` was obtained: "gum" (the fit's) or "monte_carlo:N"
    uncertainty: str = "gum"
    id: Optional[int] = None

    @property
    def std(self) -> np.ndarray:
        """One-sigma standard uncertainties in ``names`` order (sqrt of the covariance diagonal)."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def value(self, name: str) -> float:
        if name in self.fixed:
            return float(self.fixed[name])
        return float(self.values[self.names.index(name)])

    def as_dict(self) -> dict:
        """Name -> value of every estimated and fixed parameter."""
        d = dict(self.fixed)
        d.update({n: float(v) for n, v in zip(self.names, self.values)})
        return d

    def to_dict(self) -> dict:
        """Plain JSON-able form (``fivecal history show --json``)."""
        std = self.std
        return {"id": self.id, "machine_id": self.machine_id, "time": self.time, "procedure": self.procedure,
                "digest": self.digest, "source": self.source,
                "parameters": {n: {"value": _num(v), "std": _num(s),
                                   **({"prior_std": _num(self.prior_std[i])} if self.prior_std is not None else {})}
                               for i, (n, v, s) in enumerate(zip(self.names, self.values, std))},
                "fixed": self.fixed, "covariance": [[_num(x) for x in row] for row in self.covariance],
                "rms": _num(self.rms), "chi2": {"value": _num(self.chi2), "dof": self.dof, "p": _num(self.chi2_p)},
                "verdict": self.verdict, "converged": self.converged, "undetermined": self.undetermined,
                "uncertainty": self.uncertainty, "fivecal_version": self.fivecal_version}

    @property
    def usable(self) -> bool:
        return self.verdict == "ok" and self.converged

    def check(self) -> "Calibration":
        """ValueError naming the parameter when a value, a fixed value or an
        uncertainty is not finite (or a variance negative), or the sizes do
        not agree: such a result is not a measurement and is never recorded."""
        n = len(self.names)
        v = np.asarray(self.values, float).reshape(-1)
        C = np.asarray(self.covariance, float)
        who = f"calibration of {self.machine_id}"
        if v.size != n or C.size != n * n:
            raise ValueError(f"{who}: {n} names but {v.size} values and a covariance of {C.size} entries")
        C = C.reshape(n, n)
        for i, name in enumerate(self.names):
            if not math.isfinite(v[i]):
                raise ValueError(f"{who}: {name} = {v[i]} is not a finite value; a fit with non-finite values "
                                 "is not recorded")
        # a parameter's own variance first: a NaN std spreads into every covariance of its column
        bad = [i for i in range(n) if not (math.isfinite(C[i, i]) and C[i, i] >= 0)] or \
              [i for i in range(n) if not np.all(np.isfinite(C[i]))]
        if bad:
            raise ValueError(f"{who}: the uncertainty of {self.names[bad[0]]} is not finite (variance "
                             f"{C[bad[0], bad[0]]}); a fit with non-finite uncertainties is not recorded")
        for name, x in self.fixed.items():
            if not (isinstance(x, (int, float)) and math.isfinite(x)):
                raise ValueError(f"{who}: fixed {name} = {x} is not a finite value")
        return self


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _f(x) -> float:
    return math.nan if x is None else float(x)


def calibration_from_result(result, machine_id: str, time=None, procedure: str = "", digest: Optional[str] = None,
                            source: str = "") -> Calibration:
    """A :class:`Calibration` from a :class:`fivecal.Result`, or from the
    result format of docs/formats.md (a dict, or the path of a result.json;
    its covariance is rebuilt from ``correlation`` and ``std``)."""
    if isinstance(result, (str, os.PathLike)):
        source = source or os.fspath(result)
        # any procedure's result document, checked as export and compensate check it
        result = validate_document(files.read_json(os.fspath(result), "result"), "result", os.fspath(result))
    if isinstance(result, Mapping):
        return _from_result_dict(result, machine_id, time, procedure, digest or "", source)
    names = list(result.estimated)
    values = np.array([result.values.get(n, 0.0) for n in names], dtype=float)
    cov = np.array(result.covariance, dtype=float).reshape(len(names), len(names))
    prior = getattr(result, "prior_std", None) or {}
    fixed = {n: float(v) for n, v in result.values.items() if n not in set(names)}
    if digest is None:
        digest = dataset_digest(result.dataset)
    return Calibration(machine_id=_machine_id(machine_id), time=utc_time(time), names=names, values=values,
                       covariance=cov, procedure=procedure, digest=digest, fixed=fixed,
                       prior_std=np.array([prior.get(n, math.nan) for n in names]) if prior else None,
                       rms=float(result.rms), chi2=float(result.chi2), dof=int(result.dof),
                       chi2_p=float(result.chi2_p), verdict=str(result.verdict), converged=bool(result.converged),
                       undetermined=list(result.undetermined), fivecal_version=_version(), source=source)


def _procedure_name(d: Mapping) -> str:
    # the label a result document brings (its procedure section) when the
    # caller gives none: a sphere check is recorded as one without --procedure
    p = d.get("procedure")
    return str(p.get("name", "")) if isinstance(p, Mapping) else ""


def _from_result_dict(d: Mapping, machine_id, time, procedure, digest, source) -> Calibration:
    params = d.get("parameters")
    if not isinstance(params, Mapping):
        raise ValueError("result: no 'parameters' object (expected the result format of fivecal identify --out)")
    names = list(d.get("estimated") or [n for n, p in params.items() if not p.get("fixed")])
    missing = [n for n in names if n not in params]
    if missing:
        raise ValueError(f"result: estimated parameter {missing[0]} has no entry in 'parameters'")
    values = np.array([_f(params[n].get("value")) for n in names])
    std = np.array([_f(params[n].get("std")) for n in names])
    corr = d.get("correlation")
    if corr is not None and len(corr) == len(names):
        R = np.array([[_f(x) for x in row] for row in corr], dtype=float)
    else:
        R = np.eye(len(names))
    cov = R * np.outer(std, std)
    chi2 = d.get("chi2") or {}
    if not isinstance(chi2, Mapping):
        chi2 = {"value": chi2}
    prior = [params[n].get("prior_std") for n in names]
    return Calibration(machine_id=_machine_id(machine_id), time=utc_time(time), names=names, values=values,
                       covariance=cov, procedure=procedure or _procedure_name(d), digest=digest,
                       fixed={n: float(p["value"]) for n, p in params.items() if p.get("fixed")},
                       prior_std=np.array([_f(p) for p in prior]) if any(p is not None for p in prior) else None,
                       rms=_f(d.get("residual_rms")), chi2=_f(chi2.get("value")), dof=chi2.get("dof"),
                       chi2_p=_f(chi2.get("p")), verdict=str(d.get("verdict", "ok")),
                       converged=bool(d.get("converged", True)), undetermined=list(d.get("undetermined") or []),
                       fivecal_version=_version(), source=source)


class AlreadyRecorded(UserWarning):
    """The dataset was already recorded for this machine: nothing changed."""

    def __init__(self, machine_id: str, id: int, time: str):
        self.machine_id, self.id, self.time = machine_id, id, time
        super().__init__(f"{machine_id}: this dataset is already recorded (calibration #{id} at {time}); "
                         "nothing changed (replace it with --replace / replace=True)")


def _is_machine_error(name: str) -> bool:
    return bool(_LOCATION.match(name) or _MOTION.match(name) or _BACKLASH.match(name))


def _kinematics(definition: Mapping) -> tuple:
    """What makes two machine definitions the same machine: the topology and
    each axis's type, direction and point (not its name, tool, limits or priors)."""
    def vec(x, default):
        return tuple(round(float(c), 9) + 0.0 for c in (x if x is not None else default))

    axes = definition.get("axes") or {}
    if isinstance(axes, Mapping):
        axes = [dict(a, name=k) for k, a in axes.items()]
    return (str(definition.get("topology", "")),
            tuple(sorted((str(a.get("name")), str(a.get("type")), vec(a.get("direction"), (0, 0, 0)),
                          vec(a.get("point"), (0, 0, 0))) for a in axes)))


def describe_machine(definition: Mapping) -> str:
    """``'HU40T-like (wCBXfZYSt)'``: a machine definition named in a message."""
    name = definition.get("name") or "a machine"
    return f"{name} ({definition.get('topology', '?')})"


def _machine_id(m) -> str:
    if not isinstance(m, str) or not m.strip():
        raise ValueError("machine_id: a non-empty text naming the machine is required")
    return m.strip()


_COLUMNS = ("id, machine_id, time, procedure, digest, names, \"values\", covariance, fixed, rms, chi2, verdict, "
            "converged, undetermined, fivecal_version, prior_std, dof, chi2_p, source, uncertainty")


class Store:
    """A calibration store (a SQLite file, created when missing; older
    schemas are migrated on open). Use as a context manager or call
    :meth:`close`.

    ``timeout``: seconds a writer waits for another one to finish."""

    def __init__(self, path, timeout: float = 60.0, create: bool = True):
        self.path = os.fspath(path)
        if not create and not os.path.exists(self.path):
            raise ValueError(f"{self.path}: no such calibration store")
        d = os.path.dirname(os.path.abspath(self.path))
        if not os.path.isdir(d):
            raise ValueError(f"{self.path}: folder {d} does not exist")
        try:
            # check_same_thread off: a fleet run writes from its collector thread (one user at a time)
            # through files: while open, the store is an input no output may overwrite
            self._db = files.open_sqlite(self.path, timeout=timeout, isolation_level=None, check_same_thread=False)
        except sqlite3.DatabaseError as e:
            raise ValueError(f"{self.path}: not a calibration store ({e})") from None
        try:
            self._db.execute(f"PRAGMA busy_timeout = {int(timeout * 1000)}")
            self._db.execute("PRAGMA journal_mode = WAL")
            self._migrate()
        except BaseException as e:
            self._db.close()        # a file refused is not held as an open store
            if isinstance(e, sqlite3.DatabaseError):
                raise ValueError(f"{self.path}: not a calibration store ({e})") from None
            raise

    # -- schema ------------------------------------------------------------
    def _migrate(self) -> None:
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            db.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL, applied TEXT NOT NULL, "
                       "fivecal_version TEXT NOT NULL)")
            row = db.execute("SELECT MAX(version) FROM schema_version").fetchone()
            have = row[0] or 0
            if have > SCHEMA_VERSION:
                raise ValueError(f"{self.path}: written by a newer fivecal (store schema {have}, this fivecal "
                                 f"reads up to {SCHEMA_VERSION}); upgrade fivecal")
            for version, sql in MIGRATIONS:
                if version > have:
                    for stmt in [s.strip() for s in sql.split(";") if s.strip()]:
                        db.execute(stmt)
                    db.execute("INSERT INTO schema_version VALUES (?, ?, ?)", (version, utc_time(), _version()))
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise

    @property
    def schema_version(self) -> int:
        return int(self._db.execute("SELECT MAX(version) FROM schema_version").fetchone()[0])

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- writing -----------------------------------------------------------
    def add(self, result, machine_id: str, procedure: str = "", time=None, machine=None,
            digest: Optional[str] = None, source: str = "", replace: bool = False, rebuilt: bool = False) -> int:
        """Record an identification: a :class:`fivecal.Result`, a result dict
        or the path of a result.json. ``machine``: the machine definition
        (Machine, dict or path; a Result brings its own) kept for the
        volumetric comparisons. Returns the row id.

        A result of another machine than the one recorded for ``machine_id``
        is refused (ValueError) unless ``rebuilt`` (the machine was rebuilt:
        recorded, and trends start again from this calibration). The same
        dataset (digest) of the same machine id recorded again changes
        nothing (an :class:`AlreadyRecorded` warning, the stored id
        returned) unless ``replace``."""
        cal = result if isinstance(result, Calibration) else calibration_from_result(
            result, machine_id, time, procedure, digest, source)
        if machine is None and hasattr(result, "dataset"):
            machine = result.dataset.machine
        return self.add_many([cal], machine=machine, replace=replace, rebuilt=rebuilt)[0]

    def add_many(self, calibrations: Iterable[Calibration], machine=None,
                 machines: Optional[Mapping[str, object]] = None, replace: bool = False,
                 rebuilt: bool = False) -> List[int]:
        """Record several calibrations in one transaction (all or none), with
        the checks of :meth:`add`. Returns the row ids (a repeat: the stored one)."""
        cals = list(calibrations)
        for c in cals:
            c.machine_id = _machine_id(c.machine_id)
            c.check()
        defs = {}
        if machine is not None:
            for c in cals:
                defs[c.machine_id] = _machine_json(machine)
        for k, m in (machines or {}).items():
            defs[_machine_id(k)] = _machine_json(m)
        ids, repeats = [], []
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            for k in dict.fromkeys([c.machine_id for c in cals] + list(defs)):
                names = [n for c in cals if c.machine_id == k for n in c.names + list(c.fixed)]
                if not rebuilt:
                    self._refuse_other_machine(k, defs.get(k), names)
                if rebuilt and self._has_calibrations(k):
                    first = min((c for c in cals if c.machine_id == k), key=lambda c: time_key(utc_time(c.time)),
                                default=None)
                    prev = db.execute("SELECT definition FROM machines WHERE machine_id = ?", (k,)).fetchone()
                    db.execute("INSERT INTO rebuilds (machine_id, time, previous, definition, recorded, "
                               "fivecal_version) VALUES (?, ?, ?, ?, ?, ?)",
                               (k, utc_time(first.time if first is not None else None), prev and prev[0],
                                defs.get(k), utc_time(), _version()))
            for k, text in defs.items():
                db.execute("INSERT INTO machines VALUES (?, ?) ON CONFLICT(machine_id) DO UPDATE SET "
                           "definition = excluded.definition", (k, text))
            for c in cals:
                n = len(c.names)
                v = np.asarray(c.values, float).reshape(n)
                C = np.asarray(c.covariance, float).reshape(n, n)
                same = self._same_record(c.machine_id, c.digest, c.names, v)
                if same and not replace:
                    ids.append(same[0])
                    repeats.append((c, same[0]))
                    continue
                for i in same:
                    db.execute("DELETE FROM calibrations WHERE id = ?", (i,))
                cur = db.execute(
                    "INSERT INTO calibrations (machine_id, time, procedure, digest, names, \"values\", covariance, "
                    "fixed, rms, chi2, verdict, converged, undetermined, fivecal_version, prior_std, dof, chi2_p, "
                    "source, uncertainty) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (c.machine_id, utc_time(c.time), c.procedure, c.digest, json.dumps(list(c.names)),
                     _blob(v), _blob(C), json.dumps(c.fixed), _nullable(c.rms), _nullable(c.chi2), c.verdict,
                     int(bool(c.converged)), json.dumps(list(c.undetermined)), c.fivecal_version or _version(),
                     None if c.prior_std is None else _blob(np.asarray(c.prior_std, float).reshape(n)),
                     None if c.dof is None else int(c.dof), _nullable(c.chi2_p), c.source, c.uncertainty))
                ids.append(cur.lastrowid)
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise
        for c, i in zip(cals, ids):
            c.id = i
        for c, i in repeats:
            warnings.warn(AlreadyRecorded(c.machine_id, i, self.get(i).time), stacklevel=3)
        return ids

    def _has_calibrations(self, machine_id: str) -> bool:
        return self._db.execute("SELECT 1 FROM calibrations WHERE machine_id = ? LIMIT 1",
                                (machine_id,)).fetchone() is not None

    def _same_record(self, machine_id: str, digest: str, names, v: np.ndarray) -> List[int]:
        """Ids of the stored calibrations this one repeats: the same machine
        id and dataset digest, or, where one of the two has no digest (a
        result.json added alone), the same estimates bit for bit (no two
        measurements give that; the covariance is not compared: a result
        file keeps it as correlation and std, which rebuild it to rounding)."""
        rows = self._db.execute(
            "SELECT id FROM calibrations WHERE machine_id = ? AND ((? != '' AND digest = ?) OR "
            "((digest = '' OR ? = '') AND names = ? AND \"values\" = ?)) ORDER BY id",
            (machine_id, digest or "", digest or "", digest or "", json.dumps(list(names)), _blob(v)))
        return [r[0] for r in rows]

    def check_machine(self, machine_id: str, machine=None, names: Sequence[str] = ()) -> None:
        """ValueError naming the machine id and both machines when a result
        of ``machine`` (Machine, dict, path or None) with parameters ``names``
        is not of the machine the store holds for ``machine_id``."""
        self._refuse_other_machine(_machine_id(machine_id), None if machine is None else _machine_json(machine),
                                   list(names))

    def _refuse_other_machine(self, machine_id: str, definition: Optional[str], names: Sequence[str]) -> None:
        why = self._machine_conflict(machine_id, definition, names)
        if why is not None:
            raise ValueError(f"{why}; if machine {machine_id} was rebuilt, say so (--rebuilt, rebuilt=True) and "
                             "its trend starts again here, else give this result its own machine id")

    def _machine_conflict(self, machine_id: str, definition: Optional[str], names: Sequence[str]) -> Optional[str]:
        """Why a result (its machine's ``definition`` JSON, or None when not
        known, and its parameter ``names``) is not of the machine the store
        holds for ``machine_id``; None when nothing says so."""
        row = self._db.execute("SELECT definition FROM machines WHERE machine_id = ?", (machine_id,)).fetchone()
        stored = json.loads(row[0]) if row else None
        new = json.loads(definition) if definition else None
        if stored is not None and new is not None:
            if _kinematics(stored) != _kinematics(new):
                return (f"machine {machine_id} is {describe_machine(stored)} in {self.path}; this result is of "
                        f"{describe_machine(new)}")
            return None
        ref = stored if stored is not None else new
        if ref is None:
            return None
        # one side's definition is unknown: its parameter names must be the other machine's
        if stored is None:
            names = [n for (ns,) in self._db.execute("SELECT names FROM calibrations WHERE machine_id = ?",
                                                     (machine_id,)) for n in json.loads(ns)]
        known = set(Machine.from_dict(ref).parameter_names())
        foreign = sorted({n for n in names if _is_machine_error(n) and n not in known})
        if not foreign:
            return None
        if stored is not None:
            return (f"machine {machine_id} is {describe_machine(stored)} in {self.path}, which has no "
                    f"{', '.join(foreign[:4])}: this result is of another machine")
        return (f"machine {machine_id} has calibrations in {self.path} with {', '.join(foreign[:4])}, which "
                f"{describe_machine(new)} (this result's machine) does not have")

    def add_failure(self, digest: str, error: str, source: str = "", machine_id: str = "", time=None) -> None:
        """Record that identifying a dataset failed (a fleet run goes on)."""
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            db.execute("DELETE FROM failures WHERE digest = ?", (digest,))
            db.execute("INSERT INTO failures (digest, source, machine_id, time, error, fivecal_version) "
                       "VALUES (?, ?, ?, ?, ?, ?)", (digest, source, machine_id, utc_time(time), error, _version()))
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise

    def set_machine(self, machine_id: str, machine) -> None:
        """Keep the machine definition of ``machine_id`` (for volumetric comparisons)."""
        self.add_many([], machines={_machine_id(machine_id): machine})

    # -- reading -----------------------------------------------------------
    def list(self, machine_id: Optional[str] = None, procedure: Optional[str] = None, since=None,
             until=None) -> List[Calibration]:
        """Calibrations in time order (then in order of recording), filtered."""
        where, args = [], []
        if machine_id is not None:
            where.append("machine_id = ?")
            args.append(machine_id)
        if procedure is not None:
            where.append("procedure = ?")
            args.append(procedure)
        if since is not None:
            where.append("julianday(time) >= julianday(?)")
            args.append(utc_time(since))
        if until is not None:
            where.append("julianday(time) <= julianday(?)")
            args.append(utc_time(until))
        sql = f"SELECT {_COLUMNS} FROM calibrations" + (" WHERE " + " AND ".join(where) if where else "") + \
              " ORDER BY julianday(time), id"
        return [_row(r) for r in self._db.execute(sql, args)]

    def get(self, id: int) -> Calibration:
        r = self._db.execute(f"SELECT {_COLUMNS} FROM calibrations WHERE id = ?", (int(id),)).fetchone()
        if r is None:
            raise ValueError(f"{self.path}: no calibration with id {id}")
        return _row(r)

    def machines(self) -> List[str]:
        return [r[0] for r in self._db.execute("SELECT DISTINCT machine_id FROM calibrations ORDER BY machine_id")]

    def machine(self, machine_id: str):
        """The :class:`fivecal.Machine` recorded for ``machine_id``, or None."""
        r = self._db.execute("SELECT definition FROM machines WHERE machine_id = ?", (machine_id,)).fetchone()
        if r is None:
            return None
        return Machine.from_dict(json.loads(r[0]))

    def rebuilds(self, machine_id: str) -> List[str]:
        """Times (UTC ISO) at which ``machine_id`` was recorded as rebuilt, in order."""
        return [r[0] for r in self._db.execute("SELECT time FROM rebuilds WHERE machine_id = ? ORDER BY "
                                               "julianday(time), id", (machine_id,))]

    def rebuilt_at(self, machine_id: str) -> Optional[str]:
        """The latest rebuild of ``machine_id`` (None: never): its trend starts there."""
        r = self.rebuilds(machine_id)
        return r[-1] if r else None

    def digests(self) -> set:
        """Digests of the datasets already identified (a fleet re-run skips them)."""
        return {r[0] for r in self._db.execute("SELECT DISTINCT digest FROM calibrations")}

    def failures(self) -> List[dict]:
        cols = ["digest", "source", "machine_id", "time", "error", "fivecal_version"]
        return [dict(zip(cols, r)) for r in self._db.execute(f"SELECT {', '.join(cols)} FROM failures ORDER BY id")]

    def __len__(self) -> int:
        return int(self._db.execute("SELECT COUNT(*) FROM calibrations").fetchone()[0])

    def export_parquet(self, path, machine_id: Optional[str] = None) -> str:
        """Write the calibrations to a Parquet file (needs pyarrow: ``pip install
        'fivecal[arrow]'``): one row per calibration, ``names``, ``values``,
        ``std`` and the row-major ``covariance`` as lists of float64."""
        write_parquet(self.list(machine_id), path)
        return os.fspath(path)


def _nullable(x):
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else float(x)


def _machine_json(machine) -> str:
    if isinstance(machine, (str, os.PathLike)):
        machine = files.read_json(os.fspath(machine), "machine")
        if "machine" in machine and "axes" not in machine:   # a dataset: its machine
            machine = machine["machine"]
    if hasattr(machine, "to_dict"):
        machine = machine.to_dict()
    return json.dumps(machine, sort_keys=True)


def _row(r) -> Calibration:
    (id_, machine_id, time, procedure, digest, names, values, cov, fixed, rms, chi2, verdict, converged,
     undetermined, version, prior, dof, chi2_p, source, unc) = r
    names = json.loads(names)
    n = len(names)
    return Calibration(machine_id=machine_id, time=time, names=names, values=_array(values),
                       covariance=_array(cov, (n, n)), procedure=procedure, digest=digest, fixed=json.loads(fixed),
                       prior_std=_array(prior), rms=_f(rms), chi2=_f(chi2), dof=dof, chi2_p=_f(chi2_p),
                       verdict=verdict, converged=bool(converged), undetermined=json.loads(undetermined),
                       fivecal_version=version, source=source or "", uncertainty=unc, id=id_)


# ---------------------------------------------------------------------------
# Parquet (optional pyarrow)
# ---------------------------------------------------------------------------

def require_pyarrow():
    try:
        import pyarrow
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        raise ValueError("Parquet needs pyarrow, which is not installed: pip install 'fivecal[arrow]'") from None
    return pyarrow


def arrow_table(calibrations: Sequence[Calibration]):
    pa = require_pyarrow()
    cols = {k: [] for k in ("id", "machine_id", "time", "procedure", "digest", "source", "names", "values", "std",
                            "covariance", "prior_std", "fixed", "rms", "chi2", "dof", "chi2_p", "verdict",
                            "converged", "undetermined", "uncertainty", "fivecal_version")}
    for c in calibrations:
        cols["id"].append(c.id)
        for k in ("machine_id", "time", "procedure", "digest", "source", "verdict", "uncertainty",
                  "fivecal_version"):
            cols[k].append(getattr(c, k))
        cols["names"].append(list(c.names))
        cols["values"].append(np.asarray(c.values, float))
        cols["std"].append(c.std)
        cols["covariance"].append(np.asarray(c.covariance, float).ravel())
        cols["prior_std"].append(None if c.prior_std is None else np.asarray(c.prior_std, float))
        cols["fixed"].append(json.dumps(c.fixed))
        cols["rms"].append(c.rms)
        cols["chi2"].append(c.chi2)
        cols["dof"].append(c.dof)
        cols["chi2_p"].append(c.chi2_p)
        cols["converged"].append(bool(c.converged))
        cols["undetermined"].append(list(c.undetermined))
    f64 = pa.list_(pa.float64())
    schema = pa.schema([("id", pa.int64()), ("machine_id", pa.string()), ("time", pa.string()),
                        ("procedure", pa.string()), ("digest", pa.string()), ("source", pa.string()),
                        ("names", pa.list_(pa.string())), ("values", f64), ("std", f64), ("covariance", f64),
                        ("prior_std", f64), ("fixed", pa.string()), ("rms", pa.float64()), ("chi2", pa.float64()),
                        ("dof", pa.int64()), ("chi2_p", pa.float64()), ("verdict", pa.string()),
                        ("converged", pa.bool_()), ("undetermined", pa.list_(pa.string())),
                        ("uncertainty", pa.string()), ("fivecal_version", pa.string())])
    return pa.table(cols, schema=schema)


def write_parquet(calibrations: Sequence[Calibration], path, label: str = "") -> None:
    """The calibrations as one Parquet file, written through :mod:`fivecal.files`
    (atomic; never over an input or an open store)."""
    require_pyarrow()
    files.guard_output(path, label)
    files.write_parquet_table(path, arrow_table(calibrations), label=label)


def read_parquet(path) -> List[Calibration]:
    """Calibrations back from :func:`write_parquet` / ``export`` (a file or a partitioned folder)."""
    require_pyarrow()
    import pyarrow.parquet as pq

    t = pq.read_table(os.fspath(path)).to_pylist()
    out = []
    for r in t:
        n = len(r["names"])
        out.append(Calibration(machine_id=str(r["machine_id"]), time=r["time"], names=list(r["names"]),
                               values=np.array(r["values"], float),
                               covariance=np.array(r["covariance"], float).reshape(n, n),
                               procedure=r["procedure"], digest=r["digest"], fixed=json.loads(r["fixed"]),
                               prior_std=None if r["prior_std"] is None else np.array(r["prior_std"], float),
                               rms=_f(r["rms"]), chi2=_f(r["chi2"]), dof=r["dof"], chi2_p=_f(r["chi2_p"]),
                               verdict=r["verdict"], converged=bool(r["converged"]),
                               undetermined=list(r["undetermined"]), fivecal_version=r["fivecal_version"],
                               source=r["source"], uncertainty=r.get("uncertainty") or "gum", id=r["id"]))
    return out
