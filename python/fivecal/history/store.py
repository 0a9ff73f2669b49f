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
"""
from __future__ import annotations

import datetime
import hashlib
import json
import math
import os
import sqlite3
from dataclasses import dataclass, field
from typing import Iterable, List, Mapping, Optional, Sequence

import numpy as np

from .._version import __version__

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

#: (version, SQL) in order; the store's ``schema_version`` table holds the last applied
MIGRATIONS = [(1, _V1), (2, _V2), (3, _V3)]
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
    from ..dataset import Dataset, load_dataset

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
        from ..files import read_json

        source = source or os.fspath(result)
        result = read_json(os.fspath(result), "result")
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
                       covariance=cov, procedure=procedure, digest=digest,
                       fixed={n: float(p["value"]) for n, p in params.items() if p.get("fixed")},
                       prior_std=np.array([_f(p) for p in prior]) if any(p is not None for p in prior) else None,
                       rms=_f(d.get("residual_rms")), chi2=_f(chi2.get("value")), dof=chi2.get("dof"),
                       chi2_p=_f(chi2.get("p")), verdict=str(d.get("verdict", "ok")),
                       converged=bool(d.get("converged", True)), undetermined=list(d.get("undetermined") or []),
                       fivecal_version=_version(), source=source)


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
            self._db = sqlite3.connect(self.path, timeout=timeout, isolation_level=None, check_same_thread=False)
            self._db.execute(f"PRAGMA busy_timeout = {int(timeout * 1000)}")
            self._db.execute("PRAGMA journal_mode = WAL")
            self._migrate()
        except sqlite3.DatabaseError as e:
            raise ValueError(f"{self.path}: not a calibration store ({e})") from None

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
            digest: Optional[str] = None, source: str = "") -> int:
        """Record an identification: a :class:`fivecal.Result`, a result dict
        or the path of a result.json. ``machine``: the machine definition
        (Machine, dict or path; a Result brings its own) kept for the
        volumetric comparisons. Returns the new row id."""
        cal = result if isinstance(result, Calibration) else calibration_from_result(
            result, machine_id, time, procedure, digest, source)
        if machine is None and hasattr(result, "dataset"):
            machine = result.dataset.machine
        return self.add_many([cal], machine=machine)[0]

    def add_many(self, calibrations: Iterable[Calibration], machine=None,
                 machines: Optional[Mapping[str, object]] = None) -> List[int]:
        """Record several calibrations in one transaction (all or none)."""
        cals = list(calibrations)
        defs = {}
        if machine is not None:
            for c in cals:
                defs[c.machine_id] = _machine_json(machine)
        for k, m in (machines or {}).items():
            defs[k] = _machine_json(m)
        ids = []
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            for k, text in defs.items():
                db.execute("INSERT INTO machines VALUES (?, ?) ON CONFLICT(machine_id) DO UPDATE SET "
                           "definition = excluded.definition", (k, text))
            for c in cals:
                n = len(c.names)
                v = np.asarray(c.values, float).reshape(n)
                C = np.asarray(c.covariance, float).reshape(n, n)
                cur = db.execute(
                    "INSERT INTO calibrations (machine_id, time, procedure, digest, names, \"values\", covariance, "
                    "fixed, rms, chi2, verdict, converged, undetermined, fivecal_version, prior_std, dof, chi2_p, "
                    "source, uncertainty) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (_machine_id(c.machine_id), utc_time(c.time), c.procedure, c.digest, json.dumps(list(c.names)),
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
        return ids

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
        from ..machine import Machine

        return Machine.from_dict(json.loads(r[0]))

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
        from ..files import read_json

        machine = read_json(os.fspath(machine), "machine")
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


def write_parquet(calibrations: Sequence[Calibration], path) -> None:
    require_pyarrow()
    import pyarrow.parquet as pq

    pq.write_table(arrow_table(calibrations), os.fspath(path))


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
