"""Whether an identification result may be used: the verdict of a fit and
the refusal every consumer (report, compensation, error table, G-code, the
command line) applies before it hands values to a machine.

A result is usable when the solver converged, every value and uncertainty
is finite, no machine error the data determined lies far beyond its
plausible size (a 100 mm pivot says the machine file is wrong, not the
machine), the residuals agree with the declared instrument noise (chi-square
test, when the fit reports it), every parameter the user asked for was
determined by the data and, for a fit for machine errors, the data
identified at least one of them: determined it to a tenth of its plausible
size, or found it beyond 2σ of 0 (set-up values alone, a stylus tip or a
sphere centre, are no calibration; nor is a value held near 0 because its
whole class shows no sign in the data). Anything else is refused with the reason in plain
words unless the caller forces it (``force=True``, ``--force``).

Works on a :class:`fivecal.Result`, on the result JSON (a dict or a file
path) and, for plain ``{name: value}`` mappings given by hand, accepts them
as they are (they carry no fit to judge).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, List, Mapping, Optional

from . import _core

__all__ = ["FitWarning", "UnusableResultError", "CorrectionLimitError", "Assessment", "assess",
           "require_usable", "VERDICTS"]

#: the verdicts of a fit, best first
VERDICTS = ("ok", "not_converged", "non_finite", "implausible", "inadequate", "undetermined")


class FitWarning(UserWarning):
    """:func:`fivecal.identify` returned a result that is not usable (not
    converged, non-finite, implausible, inadequate or undetermined); the
    message says why."""


class UnusableResultError(ValueError):
    """A consumer refused a result that is not usable; ``force=True`` (the
    command line's ``--force``) uses it anyway."""

    def __init__(self, message: str, verdict: str = ""):
        super().__init__(message)
        self.verdict = verdict


class CorrectionLimitError(ValueError):
    """A compensated command differs from the nominal one by more than the
    plausibility limit (``max_correction`` / ``max_correction_deg``)."""

    def __init__(self, where: str, index: int, axis: str, size: float, limit: float, unit: str):
        self.where, self.index, self.axis, self.size, self.limit, self.unit = where, index, axis, size, limit, unit
        option = ("max_correction" if unit == "mm" else "max_correction_deg") + ", --max-change"
        super().__init__(
            f"{where}: the correction of axis {axis} is {size:.4g} {unit}, more than the plausibility "
            f"limit of {limit:g} {unit} ({option}); errors this large are more likely a bad "
            "identification (wrong units, an unconverged or ill-posed fit) than the machine: check "
            "the result, or raise the limit if the machine really is that far off")

    def at(self, where: str) -> "CorrectionLimitError":
        """The same error located at ``where`` (a program line instead of a pose)."""
        return CorrectionLimitError(where, self.index, self.axis, self.size, self.limit, self.unit)


@dataclass
class Assessment:
    """The verdict of a fit and what follows from it."""

    verdict: str                      # one of VERDICTS
    reason: str = ""                  # plain words; empty when usable
    undetermined: List[str] = field(default_factory=list)  # never export these as measured
    implausible: List[str] = field(default_factory=list)
    judged: bool = True               # False for a plain name -> value mapping
    #: what the data could not tell, one dict per family of parameters (family,
    #: machine, estimated, names, why: the measurement that would tell it)
    not_determined: List[dict] = field(default_factory=list)
    #: a fit for machine errors that identified none of them
    nothing_identified: bool = False

    @property
    def usable(self) -> bool:
        return self.verdict == "ok"


def _flat(groups) -> List[str]:
    out: List[str] = []
    for g in groups or []:
        for n in ([g] if isinstance(g, str) else g):
            if n not in out:
                out.append(n)
    return out


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


#: names a refusal lists before "and N more": a refusal about hundreds of
#: parameters stays one readable line
SHOWN_NAMES = 10


def name_list(names, limit: int = SHOWN_NAMES) -> str:
    """``a, b, c`` or, beyond ``limit`` names, the first ``limit`` and ``and N more``."""
    names = list(names)
    if len(names) <= limit:
        return ", ".join(names)
    return ", ".join(names[:limit]) + f" and {len(names) - limit} more"


def _chi2_words(chi2: Optional[float], dof: Optional[float], p: Optional[float]) -> str:
    if chi2 is None or dof is None:
        return ""
    s = f"chi-square {chi2:.4g} for {dof:g} degrees of freedom"
    if p is not None:
        s += f" (p = {p:.2g})"
    return s


def _fields(source) -> Optional[dict]:
    """The fields a verdict is judged on, from a Result or a result dict;
    None for a plain name -> value mapping."""
    if hasattr(source, "estimated") and hasattr(source, "values") and hasattr(source, "converged"):
        values = dict(source.values)
        std = dict(getattr(source, "std", {}) or {})
        chi2 = getattr(source, "chi2", None)
        return {"verdict": getattr(source, "verdict", None), "converged": bool(source.converged),
                "iterations": getattr(source, "iterations", None), "values": values, "std": std,
                "rms": getattr(source, "rms", None),
                "unidentifiable": getattr(source, "unidentifiable", []) or [],
                "undetermined": getattr(source, "undetermined", None),
                "implausible": list(getattr(source, "implausible", []) or []),
                "adequate": getattr(source, "adequate", None), "adequacy": getattr(source, "adequacy", ""),
                "plausible": getattr(source, "plausible", None),
                "plausibility": getattr(source, "plausibility", "") or "",
                "noise_estimated": bool(getattr(source, "variance_components", None)),
                "chi2": chi2 if _finite(chi2) else None, "dof": getattr(source, "dof", None),
                "p": getattr(source, "chi2_p", None),
                "identified": getattr(source, "identified_machine_errors", None),
                "map_fit": bool(getattr(source, "map_fit", False)),
                "not_determined": list(getattr(source, "not_determined", None) or [])}
    if isinstance(source, Mapping) and isinstance(source.get("parameters"), Mapping) and (
            "converged" in source or "verdict" in source):
        values, std = {}, {}
        for n, p in source["parameters"].items():
            if isinstance(p, Mapping):
                values[n] = p.get("value")
                if p.get("std") is not None:
                    std[n] = p.get("std")
            else:
                values[n] = p
        c = source.get("chi2")
        c = c if isinstance(c, Mapping) else {"value": c}
        return {"verdict": source.get("verdict"), "converged": bool(source.get("converged", True)),
                "iterations": source.get("iterations"), "values": values, "std": std,
                "rms": source.get("residual_rms"),
                "unidentifiable": source.get("unidentifiable") or [],
                "undetermined": source.get("undetermined"),
                "implausible": list(source.get("implausible") or []),
                "adequate": source.get("adequate"), "adequacy": source.get("adequacy") or "",
                "plausible": source.get("plausible"), "plausibility": source.get("plausibility") or "",
                "noise_estimated": bool(source.get("variance_components")),
                "chi2": c.get("value") if _finite(c.get("value")) else None, "dof": c.get("dof"),
                "p": c.get("p"), "identified": source.get("identified_machine_errors"),
                "map_fit": bool(source.get("map_fit")),
                "not_determined": [f for f in source.get("not_determined") or [] if isinstance(f, Mapping)]}
    return None


def assess(source: Any) -> Assessment:
    """The :class:`Assessment` of a Result, a result dict or a result JSON
    path. A plain mapping name -> value is accepted as given (verdict "ok",
    ``judged`` False)."""
    if isinstance(source, (str, os.PathLike)):
        path = os.fspath(source)
        try:
            with open(path) as f:
                source = json.load(f)
        except OSError as e:
            raise ValueError(f"{path}: cannot read ({e.strerror})") from None
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not valid JSON ({e.msg}, line {e.lineno})") from None
    f = _fields(source)
    if f is None:
        return Assessment("ok", judged=False)
    confounded = _flat(f["unidentifiable"])
    undetermined = _flat(f["undetermined"]) if f["undetermined"] is not None else []
    if not f["map_fit"] or f["undetermined"] is None:
        # A least-squares fit's confounded groups are undetermined as a whole. A
        # MAP fit's groups are of the data alone: its posterior (undetermined)
        # already says which members the data, with the others' priors, narrowed.
        undetermined += [n for n in confounded if n not in undetermined]
    bad = [n for n, v in f["values"].items() if not _finite(v)] + \
          [n for n, s in f["std"].items() if not _finite(s) and _finite(f["values"].get(n))]
    if f["rms"] is not None and not _finite(f["rms"]):
        bad.append("the residuals")
    verdict = f["verdict"]
    if verdict == "ok" and (bad or not f["converged"]):
        verdict = None  # a file edited after the fit, or a verdict that missed it: judge the values
    if verdict not in VERDICTS:
        # Results written before the fit reported a verdict: judge what they hold.
        if bad:
            verdict = "non_finite"
        elif not f["converged"]:
            verdict = "not_converged"
        elif f["plausible"] is False:
            verdict = "implausible"
        elif f["adequate"] is False:
            verdict = "inadequate"
        elif confounded or (f["undetermined"] is None and undetermined):
            verdict = "undetermined"
        else:
            verdict = "ok"
    reason = ""
    if verdict == "non_finite":
        reason = ("the fit produced values that are not finite numbers (NaN or infinity)"
                  + (f" for {name_list(bad)}" if bad else ""))
    elif verdict == "not_converged":
        it = f["iterations"]
        reason = ("the fit did not converge" + (f" in {it} iterations" if it else "")
                  + ": its values are not a solution of the problem")
    elif verdict == "implausible":
        reason = ("values far outside their plausible size: "
                  + (f["plausibility"] or (name_list(f["implausible"]) + ": likely cause: the machine file's "
                                           "nominal geometry (axis points and directions) is not the machine's, "
                                           "or a value is in the wrong unit; correct the machine file and fit "
                                           "again")))
    elif verdict == "inadequate":
        words = _chi2_words(f["chi2"], f["dof"], f["p"])
        if f.get("noise_estimated"):
            # the chi-square passes by construction once the noise is estimated
            reason = "the model does not explain the data with a plausible instrument noise"
        else:
            reason = ("the model does not explain the data within the declared instrument noise"
                      + (f" ({words})" if words else ""))
        if f["adequacy"]:
            reason += f"; likely cause: {f['adequacy']}"
    nothing = verdict == "undetermined" and f["identified"] == 0
    if nothing:
        machine = sum(int(x.get("estimated", 0)) for x in f["not_determined"] if x.get("machine", True))
        reason = ("no machine error identified: the data determined none of the "
                  + (f"{machine} machine errors estimated" if machine else "machine errors")
                  + f" to a tenth of its plausible size or beyond {SIGNIFICANT_SIGMAS:g}σ of 0 (set-up values "
                  "alone are no calibration)")
        if undetermined and not f["map_fit"]:
            # an explicit request: the parameters asked for and not determined come first
            reason = (f"the data did not determine {name_list(undetermined)} (their values are arbitrary, "
                      f"not measured); {reason}")
    elif verdict == "undetermined":
        names = undetermined or confounded
        reason = ("the data did not determine "
                  + (name_list(names) if names else "some of the requested parameters")
                  + " (their values are arbitrary, not measured)")
    return Assessment(verdict, reason, undetermined, f["implausible"], not_determined=f["not_determined"],
                      nothing_identified=nothing)


def require_usable(source: Any, force: bool = False, what: str = "this result") -> Assessment:
    """Raise :class:`UnusableResultError` naming the reason unless ``source``
    is usable or ``force`` is set; returns the :class:`Assessment`."""
    a = assess(source)
    if not a.usable and not force:
        raise UnusableResultError(f"refusing to use {what}: {a.reason}; force it (force=True, --force) "
                                  "only to inspect the values", a.verdict)
    return a


#: posterior σ / prior σ above which a determined parameter counts as informed
#: only in part: the data narrowed its plausible range less than tenfold (the
#: fit itself calls a parameter undetermined above about 0.45); the core's
#: kIdentifiedRatio
PARTLY_INFORMED = _core.identified_ratio()
#: |value| / σ below which a value does not differ from 0 (kSignificantSigmas): a
#: machine error informed only in part and not significant identifies nothing
SIGNIFICANT_SIGMAS = _core.significant_sigmas()
#: class scale (estimate 'auto') below which the data show no sign of a class of
#: errors (the core's kAbsentClassScale): its parameters' values are held near 0
ABSENT_CLASS_SCALE = _core.absent_class_scale()
#: |r| at or above which two estimates are treated as not separable in practice
NEAR_SINGULAR_R = 0.999


@dataclass
class Findings:
    """What a result says, sorted for a reader: identified, informed only in
    part, not determined, implausible, and pairs the data could not separate."""

    assessment: Assessment
    identified: List[str]
    partly: List[str]
    undetermined: List[str]
    implausible: List[str]
    inseparable: List[tuple]          # (name, name, r) with |r| >= NEAR_SINGULAR_R
    informed: dict                    # name -> posterior σ / prior σ (empty without priors)
    absent: List[str] = field(default_factory=list)  # auto: classes the data show no sign of
    held: List[str] = field(default_factory=list)    # determined there, values held near 0
    #: estimate "location": candidates its selection left out -> why (never silently)
    left_out: dict = field(default_factory=dict)
    #: left-out candidates that, at their plausible size, would move an estimate
    #: by more than CARRIED_SIGMAS of its σ, largest first
    carried: List["Carried"] = field(default_factory=list)


#: a left-out error of plausible size that moves an estimate by more than this
#: many of its σ is named: the estimate's σ assumes that error is 0
CARRIED_SIGMAS = 3.0


@dataclass
class Carried:
    """A left-out candidate ``name`` of plausible size ``plausible`` would move
    estimate ``estimate`` by ``shift`` (``sigmas`` of its σ)."""
    name: str
    plausible: float
    estimate: str
    shift: float
    sigmas: float


def carried(result) -> List[Carried]:
    """The left-out candidates whose plausible size moves a machine-error
    estimate beyond CARRIED_SIGMAS of its σ (``Result.left_out_moves``; the result
    document's ``left_out_moves``), largest first."""
    std = dict(getattr(result, "std", None) or {})
    out = []
    for name, (plausible, moves) in (getattr(result, "left_out_moves", None) or {}).items():
        for est, a in moves.items():
            if "." in est:  # a set-up quantity (instrument pose, tip): not compensated, it may absorb
                continue
            s = std.get(est)
            shift = a * plausible
            if s is not None and _finite(s) and s > 0 and abs(shift) > CARRIED_SIGMAS * s:
                out.append(Carried(name, plausible, est, shift, shift / s))
    return sorted(out, key=lambda c: -abs(c.sigmas))


def findings(result) -> Findings:
    """Sort the estimated parameters of a :class:`fivecal.Result` for the reports."""
    import numpy as np

    a = assess(result)
    est = list(result.estimated)
    informed = {n: float(v) for n, v in (getattr(result, "informed", None) or {}).items() if _finite(v)}
    undetermined = [n for n in est if n in set(a.undetermined)] + \
                   [n for n in a.undetermined if n not in est]
    # determined in a class the data show no sign of: the value is the class prior's 0, not measured
    held = [n for n in getattr(result, "held", None) or [] if n in est and n not in set(undetermined)]
    und = set(undetermined) | set(held)
    # A placed set-up quantity is judged against its placement, not against its
    # plausible size: one the data narrowed little below what its placement
    # already told is known from the placement, not identified by the data.
    std = dict(getattr(result, "std", None) or {})
    for n, s in (getattr(result, "placement_std", None) or {}).items():
        if n in std and s > 0 and _finite(std[n]):
            informed[n] = max(informed.get(n, 0.0), float(std[n]) / float(s))
    partly = [n for n in est if n not in und and informed.get(n, 0.0) > PARTLY_INFORMED]
    identified = [n for n in est if n not in und and n not in set(partly)]
    pairs = []
    C = np.asarray(getattr(result, "correlation", np.zeros((0, 0))), dtype=float)
    if C.shape == (len(est), len(est)):
        ii, jj = np.nonzero(np.triu(np.abs(np.nan_to_num(C, nan=1.0)) >= NEAR_SINGULAR_R, 1))
        pairs = sorted(((est[i], est[j], float(C[i, j])) for i, j in zip(ii, jj)), key=lambda p: -abs(p[2]))
    # a class whose prior the evidence shrank to the floor (see docs/identification.md)
    absent = sorted(c for c, f in (getattr(result, "class_scales", None) or {}).items() if f < ABSENT_CLASS_SCALE)
    left_out = {str(n): str(w) for n, w in getattr(result, "left_out", None) or []}
    return Findings(a, identified, partly, undetermined, list(a.implausible), pairs, informed, absent, held,
                    left_out, carried(result))
