"""identify(): from recorded machine readings to the machine's errors, with
uncertainties and an identifiability report (C++ core, Ceres)."""
from __future__ import annotations

import functools
import json
import math
import warnings
from typing import Any, Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _core, files, guards, schema
from .dataset import Dataset
from .units import display_scale, format_value
from .views import Viewable


#: Result files list ``residual_ids`` for datasets of at most this many observations.
RESIDUAL_IDS_LIMIT = 20000

#: The procedures a result document may come from (the result schema's ``procedure.name``).
PROCEDURES = ("identify", "four-step", "wang", "circular", "jiang-cripps", "sphere-check", "sphere-test",
              "rtest", "machining", "tango")


_ROW_ARRAYS = ("residuals", "residual_ids", "correlation")


def _plain_values(obj: Any, where: str) -> Any:
    # Procedure values are numbers a person reads: numpy scalars and arrays
    # become JSON numbers and lists, and a value the procedure could not
    # determine (NaN, inf) is written as null rather than as invalid JSON.
    if isinstance(obj, Mapping):
        return {str(k): _plain_values(v, f"{where}.{k}") for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    if isinstance(obj, (list, tuple)):
        return [_plain_values(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    raise ValueError(f"{where}: {type(obj).__name__} is not a JSON value")


def result_document(result: Union["Result", Mapping], procedure: str = "identify",
                    values: Optional[Mapping] = None) -> dict:
    """The one result document every procedure writes (docs/formats.md, the
    result schema): the fit (a :class:`Result`, or a dict already in the
    result format: parameters with value and std under their ISO 230-1 names,
    verdict, chi2, ...) plus ``procedure``: ``{"name": procedure, "values":
    values}`` with the procedure's own values (dispersion, K-test ranges,
    ISO 230-4 values ...; NaN / inf written as null). The document is
    checked against the result schema, so a procedure cannot write one that
    ``export``, ``compensate`` or ``history`` would refuse."""
    if procedure not in PROCEDURES:
        raise ValueError(f"procedure: {procedure!r} is not one of {', '.join(PROCEDURES)}")
    if isinstance(result, Result):
        d = result.to_dict(procedure=None)
    elif isinstance(result, Mapping):
        d = json.loads(json.dumps(result))
    else:
        raise ValueError(f"result: expected a fivecal Result or a result dict, got {type(result).__name__}")
    d.pop("procedure", None)
    sec = {"name": procedure}
    if values:
        sec["values"] = _plain_values(dict(values), "procedure.values")
    d["procedure"] = sec
    # the per-row arrays (10^5 rows for a ball bar trace) are written by the
    # core in one shape: their head stands for them, the check stays fast
    schema.validate({k: (v[:100] if k in _ROW_ARRAYS and isinstance(v, list) else v) for k, v in d.items()},
                    "result", f"{procedure} result")
    return d


def result_json(result: Union["Result", Mapping], procedure: str = "identify",
                values: Optional[Mapping] = None) -> str:
    """JSON text of :func:`result_document`."""
    return json.dumps(result_document(result, procedure, values), indent=1, sort_keys=True, ensure_ascii=False)


def write_result(path, result: Union["Result", Mapping], procedure: str = "identify",
                 values: Optional[Mapping] = None) -> None:
    """Write :func:`result_document` to ``path``: the file ``export``,
    ``compensate``, ``history`` and the report read, whichever procedure
    wrote it."""
    files.write_text(path, result_json(result, procedure, values) + "\n")


class Result(Viewable):
    """Identified parameters (mm, rad), their one-sigma uncertainties,
    residuals and the identifiability diagnosis."""

    def __init__(self, core: "_core.Result", dataset: Dataset):
        self._core = core
        self.dataset = dataset
        self.estimated: list = list(core.estimated)
        # Python floats and a set: a table of hundreds of names is walked once per fit.
        estimated = set(self.estimated)
        #: estimated parameters and fixed non-zero ones, name -> value
        self.values: dict = {n: v for n, v in zip(core.names, np.asarray(core.values).tolist())
                             if v != 0.0 or n in estimated}
        self.std: dict = dict(zip(self.estimated, np.asarray(core.std).tolist()))
        self.covariance: np.ndarray = np.asarray(core.covariance)
        self.correlation: np.ndarray = np.asarray(core.correlation)
        self.residuals: np.ndarray = np.asarray(core.residuals)
        self.residual_source: np.ndarray = np.asarray(core.residual_source)
        self.residual_vectors: np.ndarray = np.asarray(core.residual_vectors)
        self.points: np.ndarray = np.asarray(core.points)
        #: rms, largest |residual| and a posteriori sigma of the mm rows (a pose's
        #: rotation rows are in :attr:`residual_units`)
        self.rms: float = core.rms
        self.max_abs: float = core.max_abs
        self.sigma: float = core.sigma
        #: per unit of the residual rows ("mm"; "rad": a pose's rotation rows) a dict with
        #: rows, rms, max_abs and sigma in that unit
        self.residual_units: dict = {u.unit: {"rows": u.rows, "rms": u.rms, "max_abs": u.max_abs,
                                              "sigma": u.sigma} for u in core.residual_units}
        self.condition_number: float = core.condition_number
        self.rank: int = core.rank
        self.unidentifiable: list = [list(g) for g in core.unidentifiable]
        self.converged: bool = core.converged
        self.iterations: int = core.iterations
        self.n_observations: int = core.n_observations
        self.n_parameters: int = core.n_parameters
        self.outliers: list = list(core.outliers)
        #: prior one-sigma scale of every estimated parameter (mm / rad ...)
        self.prior_std: dict = {n: float(s) for n, s in zip(self.estimated, core.prior_std)}
        #: posterior sigma / prior sigma: below ``INFORMED_THRESHOLD`` the data informed it
        self.informed: dict = {n: float(s) for n, s in zip(self.estimated, core.informed)}
        #: placement uncertainty of each estimated set-up quantity that has one
        #: (its prior row in the fit; docs/setup_uncertainty.md)
        self.placement_std: dict = {n: float(s) for n, s in zip(self.estimated, core.placement) if s > 0}
        #: estimated parameters this data did not determine (their values are the prior's, not measured)
        self.undetermined: list = list(core.undetermined)
        #: values beyond 5 prior sigmas (flagged; a determined machine error among them makes
        #: the fit not usable: :attr:`plausible`)
        self.implausible: list = list(core.implausible)
        #: True when the fit had prior rows (estimate "auto" or prior=True)
        self.map_fit: bool = core.map_fit
        #: "dense" or "normal_equations": how the fit ran (identify's fit_path)
        self.fit_path: str = core.fit_path
        #: estimate "auto": factor (0.001-1) the data put on each machine-error class's
        #: prior for the point estimate (small: the data show no sign of that class)
        self.class_scales: dict = dict(core.class_scales)
        #: variance_components=True: per instrument group ("probe", "dbb", "ball3d", "point", "pose",
        #: "pose_rad" (a pose's rotation rows, rad), "distance"; "point.T1", "point.T2" ... when a
        #: kind's observations come from several instruments) a dict with rows, redundancy,
        #: declared_sigma, factor, sigma (mm, or rad) and estimated
        self.variance_components: dict = {
            c.group: {"rows": c.rows, "redundancy": c.redundancy, "declared_sigma": c.declared,
                      "factor": c.factor, "sigma": c.sigma, "estimated": c.estimated}
            for c in core.variance_components}
        #: chi-square of the residuals against the declared noise, its degrees of freedom and p value
        self.chi2: float = core.chi2
        self.dof: int = core.dof
        self.chi2_p: float = core.chi2_p
        #: False when the residuals are too large for the declared noise; ``adequacy`` says why
        self.adequate: bool = core.adequate
        self.adequacy: str = core.adequacy
        #: every value and std finite
        self.finite: bool = core.finite
        #: False when the data put a machine error far beyond its plausible size (a 100 mm
        #: pivot): the machine file's nominal geometry is wrong; ``plausibility`` names the
        #: values and the likely cause (verdict "implausible")
        self.plausible: bool = core.plausible
        self.plausibility: str = core.plausibility
        #: machine errors the data identified: determined (not :attr:`held`) to a tenth of
        #: their prior sigma, or beyond 2 sigma of 0; a fit for machine errors with none is
        #: not usable (verdict "undetermined")
        self.identified_machine_errors: int = core.identified_machine_errors
        #: estimate "auto": parameters determined in a class the data show no sign of
        #: (:attr:`class_scales`): their values are held near 0, not measured
        self.held: list = list(core.held)
        #: estimate "location": the candidates its selection left out, as (name, why)
        #: pairs (too weakly seen against the prior, or confounded with those chosen)
        self.left_out: list = [(str(n), str(w)) for n, w in getattr(core, "left_out", [])]
        #: what each left-out candidate would do to the estimates were it not 0:
        #: name -> (its plausible size, {estimate: d(estimate)/d(candidate)}); a real
        #: value of it is carried into those estimates whatever their sigma says
        self.left_out_moves: dict = {str(n): (float(p), {str(e): float(a) for e, a in m.items()})
                                     for n, (p, m) in dict(getattr(core, "left_out_moves", {})).items()}
        #: what the data could not tell, one dict per family of parameters (location
        #: offsets, location angles, scale gains, error motions of one degree, backlash,
        #: set-up): family, machine, estimated, names and why (the measurement that would tell it)
        self.not_determined: list = list(core.not_determined)
        #: "ok", "not_converged", "implausible", "inadequate", "non_finite" or "undetermined"
        self.verdict: str = core.verdict

    def machine_errors(self, force: bool = False, include_undetermined: bool = False) -> dict:
        """The machine's errors (name -> mm / rad): no setup values (facet,
        sphere, dbb), no probe stylus offsets ``tip.*`` (they belong to the
        probe, not the machine) and, unless ``include_undetermined``, no
        parameter the data did not determine (its value is arbitrary).

        The plain dict this returns is what compensation is fed and carries no
        verdict, so the guard applies here: a result that is not
        :attr:`usable` raises :class:`fivecal.UnusableResultError` unless
        ``force``."""
        self.require_usable(force)
        names = set(self.dataset.machine.parameter_names())
        skip = set() if include_undetermined else set(self.assessment().undetermined)
        return {n: v for n, v in self.values.items()
                if n in names and not n.startswith("tip.") and n not in skip}

    # -- guards: may this result be used? ----------------------------------
    def assessment(self) -> "guards.Assessment":
        """Verdict, reason in plain words, undetermined and implausible names."""
        return guards.assess(self)

    @property
    def usable(self) -> bool:
        """True when the fit converged, is finite, agrees with the declared
        noise and determined what was asked: what every consumer requires."""
        return self.assessment().usable

    def require_usable(self, force: bool = False) -> None:
        """Raise :class:`fivecal.UnusableResultError` with the reason unless
        the result is :attr:`usable` or ``force`` is set."""
        guards.require_usable(self, force, "this identification result")

    def predict(self, dataset: Dataset) -> np.ndarray:
        """Residuals (mm) of another dataset's observations under these values:
        the prediction check on held-out indexations."""
        r, _ = _core.predict_residuals(dataset._core, self.values)
        return np.asarray(r)

    def residual_table(self, rows=None) -> list:
        """One dict per residual row (or per row of ``rows``, in that order):
        ``row``, ``observation`` (its index in
        the dataset, -1 for a scale bar), ``id`` (the observation's id, or
        ``scale_bar``), ``type``, ``target`` (facet / sphere id or setup),
        ``component`` (``x y z`` for ball3d and point rows, ``x y z rx ry rz``
        for pose rows, else empty) and ``residual`` (mm, rad for a pose's
        ``rx ry rz``, as :attr:`residuals`)."""
        src = np.asarray(self.residual_source, dtype=int)
        res = np.asarray(self.residuals)
        # rows of one observation are consecutive: j = position within its run
        start = np.r_[True, src[1:] != src[:-1]] if src.size else np.zeros(0, bool)
        first = np.maximum.accumulate(np.where(start, np.arange(src.size), 0)) if src.size else src
        run = np.diff(np.r_[np.flatnonzero(start), src.size])
        size = np.repeat(run, run)
        j = np.arange(src.size) - first
        obs = self.dataset.observations
        out = []
        for row in (range(src.size) if rows is None else (int(i) for i in rows)):
            k, n = int(src[row]), int(size[row])
            o = obs[k] if 0 <= k < len(obs) else {}
            out.append({"row": row, "observation": k,
                        "id": o.get("id", "") if k >= 0 else "scale_bar",
                        "type": o.get("type", "scale_bar"),
                        "target": o.get("target", o.get("setup", "")),
                        "component": ("xyz"[j[row]] if n == 3 and k >= 0 else
                                      ("x", "y", "z", "rx", "ry", "rz")[j[row]] if n == 6 and k >= 0 else ""),
                        "residual": float(res[row])})
        return out

    def row_units(self) -> np.ndarray:
        """The unit of every residual row ("mm"; "rad" for a pose's rotation
        rows), from the registered kinds' rows."""
        src = np.asarray(self.residual_source, dtype=int)
        out = np.full(src.size, "mm", dtype=object)
        kinds = {k["name"]: k["row_units"] for k in _core.observation_kinds()}
        other = {n for n, u in kinds.items() if set(u) != {"mm"}}
        types = self.dataset.observation_types
        if not src.size or not other.intersection(types):
            return out
        # rows of one observation are consecutive: k = position within its run
        start = np.r_[True, src[1:] != src[:-1]]
        first = np.maximum.accumulate(np.where(start, np.arange(src.size), 0))
        k = np.arange(src.size) - first
        mixed = np.array([t in other for t in types] + [False])  # [-1]: a scale bar row
        for i in np.flatnonzero(mixed[src]):
            out[i] = kinds[types[src[i]]][k[i]]
        return out

    def write_residuals(self, path) -> None:
        """:meth:`residual_table` as CSV (``residual_um`` in µm; µrad for the
        ``rx ry rz`` rows of a pose), observation ids kept."""
        import csv
        import io

        f = io.StringIO(newline="")
        w = csv.writer(f)
        w.writerow(["row", "observation", "id", "type", "target", "component", "residual_um"])
        for r in self.residual_table():
            # mm -> um; a rotation row's rad -> urad (same small-number scale).
            scale = 1e6 if r["component"] in ("rx", "ry", "rz") else 1e3
            w.writerow([r["row"], r["observation"], r["id"], r["type"], r["target"], r["component"],
                        f"{r['residual'] * scale:.4f}"])
        files.write_text(path, f.getvalue())

    def _with_ids(self) -> bool:
        # Reading the ids builds the dataset's Python dicts (seconds per 10^5
        # observations): beyond RESIDUAL_IDS_LIMIT the result file leaves them to
        # write_residuals, so saving a big ball bar fit stays fast.
        return len(self.dataset) <= RESIDUAL_IDS_LIMIT and any("id" in o for o in self.dataset.observations)

    def to_dict(self, procedure: Optional[str] = "identify", values: Optional[Mapping] = None) -> dict:
        """The result in the result format of docs/formats.md (values and std in mm / rad);
        ``residual_ids`` gives each residual row's observation id when the dataset has ids
        (and at most :data:`RESIDUAL_IDS_LIMIT` observations). ``procedure`` (one of
        :data:`PROCEDURES`) and its ``values`` make the ``procedure`` section
        (:func:`result_document`); ``procedure=None`` leaves it out."""
        d = json.loads(self._core.to_json())
        if self._with_ids():
            d["residual_ids"] = [r["id"] for r in self.residual_table()]
        return d if procedure is None else result_document(d, procedure, values)

    def to_json(self, procedure: Optional[str] = "identify", values: Optional[Mapping] = None) -> str:
        """JSON text of :meth:`to_dict`."""
        return json.dumps(self.to_dict(procedure, values), indent=1, sort_keys=True, ensure_ascii=False)

    def save(self, path, procedure: str = "identify", values: Optional[Mapping] = None) -> None:
        """Write the result document (:meth:`to_json`) to ``path``: the file
        ``export``, ``compensate``, ``history`` and the report read. Every
        procedure writes its result through here or :func:`write_result`."""
        write_result(path, self, procedure, values)

    def report(self) -> str:
        """A readable text report in µm, µrad and µm/m: the verdict first,
        then what was identified, what was informed only in part and what the
        data could not tell."""
        m = self.dataset.machine
        fd = guards.findings(self)
        a = fd.assessment
        lines = [f"fivecal identification: {m.name} ({m.topology})"]
        lines += ["  " + t for t in verdict_lines(self, fd)]
        lines += [f"  observations {self.n_observations}, parameters {self.n_parameters}, "
                  f"rank {self.rank}, condition number {self.condition_number:.4g}"]
        lines += ["  " + t for t in residual_lines(self)]
        lines += ["  " + t for t in noise_lines(self)]
        lines.append("")
        prior = getattr(self, "prior_std", None) or {}
        with_prior = bool(prior)
        negative = {x["name"] for x in m.axes if min(x["direction"]) < -0.5 and max(x["direction"]) < 0.5}
        machine_names = set(m.parameter_names())
        und, part, impl, held = set(fd.undetermined), set(fd.partly), set(fd.implausible), set(fd.held)
        # One row per parameter the data told something about; those it did not
        # (or held near 0) are summarised below (hundreds of rows would bury the rest).
        shown = [n for n in self.estimated if (n not in und and n not in held) or n in impl]
        if shown:
            lines.append(f"  {'parameter':<18}{'value':>14}{'std':>12}"
                         + (f"{'prior':>12}{'informed':>10}" if with_prior else "") + "  unit")
        else:
            lines.append("  no parameter was determined by this data: no values to show")
        for n in shown:
            f, unit = display_scale(n)
            notes = []
            if n in und:
                notes.append("NOT DETERMINED by this data")
            elif n in held:
                notes.append("held near 0: its class shows no sign in the data")
            elif n in part:
                notes.append("informed only in part")
            if n in impl:
                notes.append("IMPLAUSIBLE: far outside its plausible size")
            if n in machine_names and len(n) == 4 and n[1] == n[2] and n[3] == "1" and n[2] in negative:
                notes.append("axis points along a negative basis vector: positive shortens the travel")
            extra = ""
            if with_prior:
                ps, inf = prior.get(n), fd.informed.get(n)
                extra = (f"{ps * f:>12.3f}" if ps is not None else f"{'-':>12}") + \
                        (f"{inf:>10.2f}" if inf is not None else f"{'-':>10}")
            lines.append(f"  {n:<18}{self.values[n] * f:>14.3f}{self.std[n] * f:>12.3f}{extra}  {unit}"
                         + (f"  ({'; '.join(notes)})" if notes else ""))
        lines.append("")
        lines += ["  " + t for t in finding_lines(fd)]
        lines += ["  " + t for t in confounded_lines(self.unidentifiable)]
        if self.outliers:
            ids = self.residual_table()
            lines.append(f"  robust loss flagged {len(self.outliers)} outlier rows: "
                         + ", ".join(f"{i} ({ids[i]['id']})" if 0 <= i < len(ids) and ids[i]["id"] else str(i)
                                     for i in self.outliers[:20]))
        if not a.usable:
            lines.append("  Not usable: compensation, error tables and G-code refuse this result "
                         "(force=True / --force only to inspect it).")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"Result({self.n_parameters} parameters, rms {self.rms * 1e3:.3f} µm, "
                f"cond {self.condition_number:.3g})")


class IdentifyOptionsDefaults:
    selection_tolerance = 1e-2


#: posterior sigma / prior sigma below which a parameter counts as informed by the data
INFORMED_THRESHOLD: float = _core.informed_threshold()


def prior_classes() -> list:
    """The prior classes with their default one-sigma scales (dicts: name, sigma, unit, description)."""
    return [dict(c) for c in _core.prior_classes()]


def _names(x: Union[None, str, Iterable[str]]) -> list:
    if x is None:
        return []
    if isinstance(x, str):
        return [s for s in x.replace(",", " ").split() if s]
    return list(x)


def identify(dataset: Union[Dataset, Mapping], estimate: Union[str, Sequence[str]] = "auto",
             fix: Union[None, str, Sequence[str]] = None, robust: Optional[str] = None,
             initial: Optional[Mapping[str, float]] = None, robust_scale: float = 0.0,
             allow_unidentifiable: bool = False, default_setup: bool = True,
             max_iterations: int = 200, num_threads: int = 0,
             selection_tolerance: Optional[float] = None,
             priors: Optional[Mapping[str, float]] = None, prior: bool = False,
             variance_components: bool = False, fit_path: str = "auto",
             setup_priors: bool = True) -> Result:
    """Fit the machine errors to a dataset.

    ``estimate``: parameter names and/or presets (``S1``-``S4`` on ``wCBXfZYSt``,
    ``location``, ``auto``), as a list or a comma/space separated string. The
    default setup set (tip, touched facets, touched sphere centres, DBB lengths, ball3d
    nest positions) is
    added unless ``default_setup=False``. ``selection_tolerance``: for ``location``
    and ``auto``, the fraction of a candidate's (scaled) Jacobian column that must
    lie outside the span of the parameters already chosen. ``fix`` removes names. ``robust``:
    ``"huber"`` or ``"cauchy"`` to down-weight and flag outlier touches; ``robust_scale``
    (mm, default 3 robust sigmas of a plain fit) is where flagging starts; a pose's rotation
    rows are held to the same multiple of their declared noise as its position rows.
    ``estimate="auto"`` (the default) fits every candidate machine error under
    its prior (a MAP fit): :attr:`Result.informed` says how far the data narrowed
    each prior and :attr:`Result.undetermined` lists those the data did not
    determine (their values are the prior's, not measurements). Explicit lists
    and ``location`` are plain least squares (``prior=True`` adds the prior rows).
    ``priors``: prior sigma overrides, a parameter name or ``"class:<name>"`` ->
    sigma (see docs/identification.md for the classes and defaults).
    ``variance_components``: estimate the noise of each instrument group (probe
    touches, ball bar, ball3d, ...; one group per instrument id when a kind's
    observations come from several trackers or stations) from its residuals (Helmert / REML variance
    components) instead of trusting the declared sigmas; mixed data are then
    weighed by what they show, :attr:`Result.variance_components` reports each
    group's sigma, and the covariance uses them.
    ``fit_path``: ``"auto"`` (default), ``"dense"`` or ``"normal_equations"``.
    Long data (rows times estimated parameters above two million, or above
    one hundred thousand when every observation is an R-test or ball-bar
    sample, which the core then reads as column blocks: R-test and ball-bar
    traces, tracker streams) are fitted on normal equations
    accumulated from the data in chunks, in memory proportional to the
    parameters squared instead of to rows times parameters, and with
    ``num_threads`` threads (0, the default: every core); the result is the
    same as the dense fit's, whatever the thread count.
    ``estimate`` ``"auto"``/``"location"``, robust losses and
    ``variance_components`` always take the dense path; ``"normal_equations"``
    forces the accumulated path (ValueError where it cannot run), ``"dense"``
    the dense one. :attr:`Result.fit_path` says which ran.
    ``setup_priors``: every estimated set-up quantity a person places (ball bar
    and R-test nests, bar lengths, a calibrated sphere's radius, a tracker's pose, a
    test part's datum) carries its placement uncertainty as a prior row, in
    least squares too (docs/setup_uncertainty.md; the dataset's
    ``setup_uncertainty`` overrides the defaults); ``False`` drops those rows,
    as for a set-up measured beforehand or an analysis of the path alone.
    Raises ValueError when the data cannot determine an explicitly requested
    set, naming the groups and the likely cause.
    """
    ds = Dataset.from_dict(dataset)
    core = _core.identify(ds._core, _names(estimate), _names(fix), dict(initial or {}),
                          robust or "", float(robust_scale), int(max_iterations),
                          bool(allow_unidentifiable), bool(default_setup), int(num_threads),
                          IdentifyOptionsDefaults.selection_tolerance if selection_tolerance is None
                          else float(selection_tolerance),
                          {str(k): float(v) for k, v in (priors or {}).items()}, bool(prior),
                          bool(variance_components), str(fit_path), bool(setup_priors))
    return Result(core, ds)


def verdict_lines(result, fd: "guards.Findings") -> list:
    """The verdict of a fit in plain words, for the text and HTML reports."""
    a = fd.assessment
    it = getattr(result, "iterations", 0)
    chi2, dof, p = getattr(result, "chi2", None), getattr(result, "dof", None), getattr(result, "chi2_p", None)
    noise = guards._chi2_words(chi2 if chi2 is not None and np.isfinite(chi2) else None, dof, p)
    if not a.usable:
        return [f"NOT USABLE ({a.verdict.replace('_', ' ')}): {a.reason}.",
                "Do not compensate a machine with these values."]
    adequacy = (f"the residuals agree with the declared instrument noise ({noise})" if noise else
                "no chi-square test against the declared noise was reported")
    return [f"OK (usable): the fit converged in {it} iterations; {adequacy}."]


#: how reports show a residual of each row unit
MICRO_UNITS = {"mm": (1e3, "µm"), "rad": (1e6, "µrad")}


def residual_lines(result) -> list:
    """Residual rms, largest |residual| and a posteriori sigma, one line per
    unit of the rows: a pose's rotation rows (rad) are never folded into the
    position rows' µm."""
    units = getattr(result, "residual_units", None) or {"mm": {"rms": result.rms, "max_abs": result.max_abs,
                                                               "sigma": result.sigma}}
    out = []
    for unit, u in units.items():
        f, shown = MICRO_UNITS.get(unit, (1.0, unit))
        what = "residual" if unit == "mm" else f"residual of the {unit} rows (rotations):"
        out.append(f"{what} rms {u['rms'] * f:.3f} {shown}, max {u['max_abs'] * f:.3f} {shown}, "
                   f"sigma {u['sigma'] * f:.3f} {shown}")
    return out


def noise_lines(result) -> list:
    """The instrument noise the fit estimated (variance components), one line per group."""
    out = []
    for g, c in sorted((getattr(result, "variance_components", None) or {}).items()):
        # a group of rotation rows (pose_rad, pose_rad.<id>) is in rad
        f, unit = MICRO_UNITS["rad" if g.split(".", 1)[0].endswith("_rad") else "mm"]
        if c["estimated"]:
            out.append(f"noise of {g}: {c['sigma'] * f:.3f} {unit} estimated from {c['rows']} rows "
                       f"(declared {c['declared_sigma'] * f:.3f} {unit}, x{c['factor']:.2f})")
        else:
            out.append(f"noise of {g}: declared {c['declared_sigma'] * f:.3f} {unit} kept "
                       f"(redundancy {c['redundancy']:.1f} of {c['rows']} rows is too little to estimate it)")
    return out


def finding_lines(fd: "guards.Findings") -> list:
    """What was identified, informed in part, not determined, implausible."""
    n = len(fd.identified)
    # an unconverged, non-finite or inadequate fit identified nothing; one that left
    # requested parameters undetermined did determine the others
    trusted = fd.assessment.verdict in ("ok", "undetermined")
    # set-up names are dotted (tip.x, sphere.S1.x); machine errors never are
    setup = sum(1 for x in fd.identified if "." in x)
    split = ("" if not setup else " (set-up values only, no machine error)" if setup == n else
             f" ({n - setup} machine error{'s' if n - setup != 1 else ''}, {setup} set-up value{'s' if setup != 1 else ''})")
    out = [f"identified: {n} parameter{'s' if n != 1 else ''}{split}" if trusted else
           f"identified: none (the fit is not usable; {n} parameter{'s' if n != 1 else ''} estimated "
           "without a trustworthy value)"]
    if fd.left_out:
        out += left_out_lines(fd)
    if fd.partly:
        out.append(f"informed only in part (the data narrowed the prior less than "
                   f"{1 / guards.PARTLY_INFORMED:g}-fold): "
                   + ", ".join(fd.partly))
    if fd.undetermined:
        out += not_determined_lines(fd)
    if fd.absent:
        out.append("error classes the data show no sign of (held near 0 in the point estimate): "
                   + ", ".join(c.replace("_", " ") for c in fd.absent)
                   + (f"; determined there, so held near 0: {guards.name_list(fd.held)}" if fd.held else ""))
    if fd.implausible:
        out.append("implausible (far outside the plausible size; check units and setup): "
                   + ", ".join(fd.implausible))
    if fd.inseparable:
        shown = fd.inseparable[:8]
        out.append(f"pairs the data cannot separate (|r| ≥ {guards.NEAR_SINGULAR_R:g}): "
                   + ", ".join(f"{x}/{y} (r = {r:+.4f})" for x, y, r in shown)
                   + (f" and {len(fd.inseparable) - len(shown)} more" if len(fd.inseparable) > len(shown) else ""))
    return out


def left_out_lines(fd: "guards.Findings") -> list:
    """Which candidates a preset (estimate "location") left out and why: a
    preset never drops an error silently. The plausible sizes are the priors
    of the machine file's kind (docs/formats.md, Machine)."""
    items = list(fd.left_out.items())
    out = [f"left out by the preset (not estimated; plausible sizes are the priors of the machine's kind, "
           f"`fivecal docs formats`): {len(items)}"]
    out += [f"  {n}: {why}" for n, why in items[:8]]
    if len(items) > 8:
        out.append(f"  and {len(items) - 8} more: {guards.name_list([n for n, _ in items[8:]])}")
    carried = fd.carried
    if carried:
        out.append(f"estimates a left-out error of plausible size would move by more than "
                   f"{guards.CARRIED_SIGMAS:g} σ (their σ assumes it is 0; a value it really has is carried "
                   "into them):")
        for c in carried[:8]:
            out.append(f"  {c.name} ({format_value(c.name, c.plausible)}) would move {c.estimate} by "
                       f"{format_value(c.estimate, c.shift)} = {abs(c.sigmas):.3g} σ")
        if len(carried) > 8:
            out.append(f"  and {len(carried) - 8} more")
    return out


def not_determined_lines(fd: "guards.Findings") -> list:
    """What the data could not tell: one line per family of parameters
    (location offsets, location angles, scale gains, error motions of one
    degree, backlash, set-up) with how many of the family it left undetermined
    and the measurement that would determine them (the core's analysis), never
    one line per parameter."""
    families = fd.assessment.not_determined
    head = "not determined by this data (values arbitrary, never used for compensation)"
    if not families:  # a result that does not say per family (an older result file)
        return [f"{head}: {guards.name_list(fd.undetermined)}"]
    out = [f"{head}; per family, with what would determine it:"]
    for f in families:
        n, of = len(f.get("names", [])), f.get("estimated")
        out.append(f"  {f['family']} ({n}{f' of {of}' if of else ''}): {f['why']}")
    return out


#: confounded groups a text report lists (all of them: result.json, "unidentifiable")
SHOWN_GROUPS = 5


def confounded_lines(groups) -> list:
    """The confounded groups, a few and each capped (a single undetermined
    parameter is no group: the family lines cover it)."""
    real = [g for g in groups if len(g) > 1]
    if not real:
        return []
    out = [f"confounded (only combinations are determined): {len(real)} group{'s' if len(real) != 1 else ''}"
           + (f", the first {SHOWN_GROUPS}" if len(real) > SHOWN_GROUPS else "") + ":"]
    out += ["  {" + guards.name_list(g) + "}" for g in real[:SHOWN_GROUPS]]
    return out


def _warn_when_unusable(fit):
    """``identify`` emits a :class:`fivecal.FitWarning` when its result is
    not usable, so a script that goes on learns it at once."""
    @functools.wraps(fit)
    def wrapper(*args, **kwargs):
        return warn_when_unusable(fit(*args, **kwargs))
    return wrapper


def warn_when_unusable(result: "Result", stacklevel: int = 2) -> "Result":
    """``result``, after a :class:`fivecal.FitWarning` when it is not usable:
    what ``identify`` does, for the procedures whose fit runs in the core
    (sphere check, R-test). ``stacklevel`` counts from the caller of this
    function, as :func:`warnings.warn` does (2: its caller's caller)."""
    a = result.assessment()
    if not a.usable:
        warnings.warn(f"fivecal.identify: the result is not usable: {a.reason}", guards.FitWarning,
                      stacklevel=stacklevel + 1)
    return result


identify = _warn_when_unusable(identify)


def resolve_estimate(dataset: Union[Dataset, Mapping], estimate, fix=None, initial=None,
                     priors: Optional[Mapping[str, float]] = None) -> list:
    """The parameter names ``estimate`` resolves to on this dataset (no fit;
    ``location`` is selected at the initial values, ``auto`` lists every candidate)."""
    ds = Dataset.from_dict(dataset)
    return list(_core.resolve_estimate(ds._core, _names(estimate), _names(fix), dict(initial or {}),
                                       {str(k): float(v) for k, v in (priors or {}).items()}))
