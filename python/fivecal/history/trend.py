"""Compare calibrations, grade them against tolerances, watch their trend.

- :func:`compare`: two calibrations parameter by parameter, z = Δ / sqrt(σ_A²
  + σ_B² − 2 cov_AB) with cov_AB = 0 (two identifications from separate
  datasets share no measurement noise, so their estimates are independent),
  and the change of the predicted volumetric error over a grid of poses.
- :func:`grade`: pass / fail / undecided against per-parameter tolerances and a
  volumetric tolerance, as ball bar software grades a test.
- :func:`detect`: self-starting CUSUM charts of each parameter's history,
  with the decision interval set for a stated in-control false-alarm rate
  (Siegmund's approximation of the average run length).
- :func:`pooled_statistics`: the spread of the stored values pooled by days
  or cycles (the pooling of the thesis' eq. 8-3, through fivecal.uncertainty).
- :func:`plot_trend`: values with ±2σ bands, tolerance lines and alarms.

Units: mm and rad in, display units (µm, µrad) in tables and plots.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np

from .. import files
from .. import tolerances as _tolerances
from .. import uncertainty
from ..dataset import load_dataset
from ..figures import _pyplot
from ..files import save_figure
from ..units import _BACKLASH, _LOCATION, _MOTION, display_scale
from .store import Calibration, _kinematics, describe_machine


def machine_error_names(cal: Calibration) -> List[str]:
    """Estimated machine errors of a calibration: setup parameters
    (``tip.x``, ``sphere.P.x``, ``facet.…``, ``dbb.…``: they contain a dot)
    and undetermined ones (the prior decided them) left out."""
    und = set(cal.undetermined)
    return [n for n in cal.names if "." not in n and n not in und]


# ---------------------------------------------------------------------------
# volumetric error
# ---------------------------------------------------------------------------

def default_grid(machine) -> dict:
    """Poses the volumetric error is predicted at when none are given: every
    linear axis at -100, 0, +100 mm, every rotary axis but the spindle at
    -90, -45, 0, 45, 90 degrees (the spindle at 0); the full grid of these."""
    levels = {}
    for a in machine.axes:
        if a["type"] == "linear":
            levels[a["name"]] = [-100.0, 0.0, 100.0]
        elif a["name"] == "S":
            levels[a["name"]] = [0.0]
        else:
            levels[a["name"]] = [-90.0, -45.0, 0.0, 45.0, 90.0]
    mesh = np.meshgrid(*levels.values(), indexing="ij")
    return {k: m.ravel() for k, m in zip(levels, mesh)}


def _errors(machine, cal: Calibration) -> dict:
    names = set(machine.parameter_names())
    und = set(cal.undetermined)
    return {n: v for n, v in cal.as_dict().items() if n in names and not n.startswith("tip.") and n not in und}


def volumetric_errors(machine, cal: Calibration, grid: Optional[Mapping] = None) -> np.ndarray:
    """Length (mm) of the tool-point error each pose of ``grid`` would have
    with the calibration's machine errors (:meth:`fivecal.Machine.volumetric_error`)."""
    grid = default_grid(machine) if grid is None else grid
    return np.linalg.norm(machine.volumetric_error(grid, _errors(machine, cal)), axis=1)


@dataclass
class VolumetricChange:
    max_a: float      #: largest predicted tool-point error with A's values (mm)
    max_b: float
    rms_a: float
    rms_b: float
    max_change: float  #: largest length of (error with B − error with A) over the grid (mm)
    rms_change: float
    poses: int


def volumetric_change(machine, a: Calibration, b: Calibration, grid: Optional[Mapping] = None) -> VolumetricChange:
    grid = default_grid(machine) if grid is None else grid
    ea = machine.volumetric_error(grid, _errors(machine, a))
    eb = machine.volumetric_error(grid, _errors(machine, b))
    na, nb, d = (np.linalg.norm(x, axis=1) for x in (ea, eb, eb - ea))
    rms = lambda x: float(np.sqrt(np.mean(x ** 2)))  # noqa: E731
    return VolumetricChange(float(na.max()), float(nb.max()), rms(na), rms(nb), float(d.max()), rms(d), len(d))


# ---------------------------------------------------------------------------
# compare
# ---------------------------------------------------------------------------

@dataclass
class ParameterChange:
    name: str
    a: float
    b: float
    delta: float
    std_a: float
    std_b: float
    std_delta: float
    z: float
    tolerance: Optional[float] = None

    @property
    def passed(self) -> Optional[bool]:
        """|Δ| within the tolerance (None without one)."""
        return None if self.tolerance is None else abs(self.delta) <= self.tolerance


@dataclass
class Comparison:
    a: Calibration
    b: Calibration
    parameters: List[ParameterChange]
    volumetric: Optional[VolumetricChange] = None
    z_limit: float = 3.0

    def significant(self, z: Optional[float] = None) -> List[str]:
        """Names whose change exceeds ``z`` (default :attr:`z_limit`) joint standard uncertainties."""
        lim = self.z_limit if z is None else z
        return [p.name for p in self.parameters if math.isfinite(p.z) and abs(p.z) > lim]

    def report(self) -> str:
        def label(c):
            return f"{c.machine_id}" + (f" #{c.id}" if c.id else "") + f" ({c.time})"

        lines = [f"fivecal history compare: {label(self.a)} -> {label(self.b)}",
                 "  z = (B - A) / sqrt(u_A^2 + u_B^2): the calibrations are independent (separate datasets), "
                 "so their covariance term is 0",
                 f"  {'parameter':<12}{'A':>11}{'B':>11}{'B-A':>10}{'u(B-A)':>9}{'z':>8}  unit"]
        for p in self.parameters:
            f, unit = display_scale(p.name)
            flag = "  *" if math.isfinite(p.z) and abs(p.z) > self.z_limit else ""
            tol = "" if p.tolerance is None else ("  pass" if p.passed else "  FAIL") + \
                f" (tol {p.tolerance * f:g})"
            lines.append(f"  {p.name:<12}{p.a * f:>11.3f}{p.b * f:>11.3f}{p.delta * f:>10.3f}"
                         f"{p.std_delta * f:>9.3f}{p.z:>8.2f}  {unit}{flag}{tol}")
        sig = self.significant()
        lines.append(f"  changed beyond {self.z_limit:g} sigma: {', '.join(sig) if sig else 'none'}")
        v = self.volumetric
        if v is not None:
            lines.append(f"  predicted volumetric error over {v.poses} poses: max {v.max_a * 1e3:.2f} -> "
                         f"{v.max_b * 1e3:.2f} µm, rms {v.rms_a * 1e3:.2f} -> {v.rms_b * 1e3:.2f} µm; change "
                         f"max {v.max_change * 1e3:.2f} µm, rms {v.rms_change * 1e3:.2f} µm")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        d = {"a": self.a.id, "b": self.b.id, "covariance_ab": 0.0,
             "parameters": {p.name: {"a": p.a, "b": p.b, "delta": p.delta, "std_delta": p.std_delta, "z": p.z,
                                     **({"tolerance": p.tolerance, "pass": p.passed} if p.tolerance is not None
                                        else {})} for p in self.parameters},
             "significant": self.significant()}
        if self.volumetric is not None:
            d["volumetric"] = dict(self.volumetric.__dict__)
        return d


def _axes_of(cal: Calibration) -> set:
    """The axes a calibration's machine errors name (``EX0C`` -> C, ``EXX1`` -> X)."""
    out = set()
    for n in list(cal.names) + list(cal.fixed):
        m = _LOCATION.match(n) or _MOTION.match(n) or _BACKLASH.match(n)
        if m:
            out.add(m.group(2))
    return out


def _label(c: Calibration, which: str) -> str:
    return f"{which} ({c.machine_id}" + (f" #{c.id}" if c.id else "") + ")"


def check_same_machine(a: Calibration, b: Calibration, machine=None, machines=(None, None)) -> None:
    """ValueError saying why when A and B are not calibrations of one
    machine: stored under two machine ids, of two machine definitions
    (``machines``: A's and B's, when known), with machine errors of axes the
    other has not, or of parameters ``machine`` (the one the comparison
    predicts with) does not have. Their z-scores would measure the
    difference between two machines, not a change."""
    why = None
    ma, mb = machines
    if a.id and b.id and a.machine_id != b.machine_id:
        why = f"A is machine {a.machine_id}, B is machine {b.machine_id}"
    elif ma is not None and mb is not None and _kinematics(ma.to_dict()) != _kinematics(mb.to_dict()):
        why = f"A is {describe_machine(ma.to_dict())}, B is {describe_machine(mb.to_dict())}"
    else:
        for c, which, m in ((a, "A", machine or ma), (b, "B", machine or mb)):
            if why is None and m is not None:
                known = set(m.parameter_names())
                foreign = [n for n in c.names if n not in known and "." not in n]
                if foreign:
                    why = (f"{which} has {', '.join(foreign[:4])}, which {describe_machine(m.to_dict())} "
                           "does not have")
        xa, xb = _axes_of(a), _axes_of(b)
        if why is None and not (xa <= xb or xb <= xa):
            why = (f"A's errors are of the axes {' '.join(sorted(xa))}, B's of {' '.join(sorted(xb))}: not "
                   "one machine")
    if why is not None:
        raise ValueError(f"compare: {_label(a, 'A')} and {_label(b, 'B')} are calibrations of different "
                         f"machines ({why}); their differences are not changes of one machine")


def compare(a: Calibration, b: Calibration, machine=None, grid: Optional[Mapping] = None,
            tolerances: Optional[Mapping[str, float]] = None, names: Optional[Sequence[str]] = None,
            z_limit: float = 3.0, machines=(None, None)) -> Comparison:
    """B against A, per machine error both estimated. ``machine``: the
    :class:`fivecal.Machine` for the volumetric change (omitted: none).
    ``tolerances``: name -> largest acceptable |B − A| (mm / rad, or text
    with a unit: ``"5um"``). ``machines``: A's and B's machine definitions
    when known. Calibrations of different machines are refused
    (:func:`check_same_machine`)."""
    check_same_machine(a, b, machine, machines)
    tolerances = _tolerances.check_tolerances(tolerances) if tolerances else None
    if names is None:
        nb = set(machine_error_names(b))
        names = [n for n in machine_error_names(a) if n in nb]
    sa, sb = a.std, b.std
    out = []
    for n in names:
        if n not in a.names or n not in b.names:
            raise ValueError(f"compare: {n} is not estimated in both calibrations")
        i, j = a.names.index(n), b.names.index(n)
        va, vb = float(a.values[i]), float(b.values[j])
        s = math.hypot(sa[i], sb[j])     # independent calibrations: no covariance term
        d = vb - va
        out.append(ParameterChange(n, va, vb, d, float(sa[i]), float(sb[j]), s, d / s if s > 0 else math.inf,
                                   None if tolerances is None else tolerances.get(n)))
    vol = volumetric_change(machine, a, b, grid) if machine is not None else None
    return Comparison(a, b, out, vol, z_limit)


# ---------------------------------------------------------------------------
# grade against tolerances
# ---------------------------------------------------------------------------

@dataclass
class Grade:
    calibration: Calibration
    parameters: Dict[str, dict]
    volumetric: Optional[dict]

    @property
    def verdict(self) -> str:
        """``fail`` if any item fails, else ``undecided`` if any is within
        its expanded uncertainty of the limit, else ``pass``."""
        states = [p["grade"] for p in self.parameters.values()] + \
                 ([self.volumetric["grade"]] if self.volumetric else [])
        if not self.calibration.usable:
            return "fail"
        return "fail" if "fail" in states else "undecided" if "undecided" in states else "pass"

    def report(self) -> str:
        c = self.calibration
        lines = [f"grade of {c.machine_id} #{c.id} ({c.time}): {self.verdict.upper()}"
                 + ("" if c.usable else f" (the fit itself: {c.verdict})")]
        for n, p in self.parameters.items():
            f, unit = display_scale(n)
            lines.append(f"  {n:<12}{p['value'] * f:>10.3f} ± {p['expanded'] * f:.3f} {unit}  tolerance "
                         f"{p['tolerance'] * f:g}  {p['grade']}")
        if self.volumetric:
            v = self.volumetric
            lines.append(f"  volumetric max {v['max'] * 1e3:.2f} µm  tolerance {v['tolerance'] * 1e3:g} µm  "
                         f"{v['grade']}")
        return "\n".join(lines)


def _grade(value: float, expanded: float, tol: float) -> str:
    # ISO 14253-1 style: conformance proven only beyond the expanded uncertainty
    if abs(value) + expanded <= tol:
        return "pass"
    if abs(value) - expanded > tol:
        return "fail"
    return "undecided"


def grade(cal: Calibration, tolerances: Mapping[str, float], volumetric_tolerance: Optional[float] = None,
          machine=None, grid: Optional[Mapping] = None, k: float = 2.0) -> Grade:
    """Each toleranced parameter: ``pass`` when |value| + k·u ≤ tolerance,
    ``fail`` when |value| − k·u > tolerance, else ``undecided`` (ISO 14253-1
    decision with U = k u). The volumetric error (largest predicted tool-point
    error over the grid, mm) is graded on its value. A calibration whose fit
    is not usable fails. Tolerances are numbers in mm / rad or text with a
    unit (``"12um"``), > 0 and plausible (:mod:`fivecal.tolerances`)."""
    tolerances = _tolerances.check_tolerances(tolerances)
    volumetric_tolerance = _tolerances.volumetric_tolerance(volumetric_tolerance, "volumetric tolerance")
    std = cal.std
    params = {}
    for n, tol in tolerances.items():
        if n not in cal.names and n not in cal.fixed:
            raise ValueError(f"tolerance: {n} is not a parameter of calibration #{cal.id}")
        v = cal.value(n)
        u = float(std[cal.names.index(n)]) if n in cal.names else 0.0
        params[n] = {"value": v, "std": u, "expanded": k * u, "tolerance": float(tol),
                     "grade": _grade(v, k * u, float(tol))}
    vol = None
    if volumetric_tolerance is not None:
        if machine is None:
            raise ValueError("volumetric tolerance: the machine definition is needed (none recorded)")
        m = float(volumetric_errors(machine, cal, grid).max())
        vol = {"max": m, "tolerance": float(volumetric_tolerance),
               "grade": "pass" if m <= volumetric_tolerance else "fail"}
    return Grade(cal, params, vol)


# ---------------------------------------------------------------------------
# CUSUM change detection
# ---------------------------------------------------------------------------

def siegmund_arl(h: float, k: float = 0.5, shift: float = 0.0) -> float:
    """Average run length of a one-sided CUSUM S_t = max(0, S_{t-1} + z_t − k),
    alarm at S_t > h, for z ~ N(shift, 1): Siegmund's approximation
    ARL = (exp(−2Δb) + 2Δb − 1) / (2Δ²), Δ = shift − k, b = h + 1.166."""
    d = shift - k
    b = h + 1.166
    if abs(d) < 1e-12:
        return b * b
    return (math.exp(-2 * d * b) + 2 * d * b - 1) / (2 * d * d)


def cusum_interval(arl0: float, k: float = 0.5) -> float:
    """Decision interval h of a one-sided CUSUM whose in-control ARL is
    ``arl0`` (Siegmund's approximation, solved by bisection)."""
    if not arl0 > 1:
        raise ValueError(f"arl0: expected an average run length > 1, got {arl0}")
    lo, hi = 0.0, 1.0
    while siegmund_arl(hi, k) < arl0:
        hi *= 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if siegmund_arl(mid, k) < arl0:
            lo = mid
        else:
            hi = mid
    return hi


@dataclass
class ChartDesign:
    """CUSUM design for charts watching ``charts`` parameters per machine:
    each parameter's two-sided chart has in-control ARL ``arl0`` nights, so
    that a machine-night raises a false alarm with probability about
    ``false_alarm_rate`` (2·charts one-sided charts, each at rate 1/ARL)."""
    false_alarm_rate: float
    charts: int
    k: float
    h: float
    arl0_one_sided: float

    @classmethod
    def for_rate(cls, false_alarm_rate: float = 0.001, charts: int = 1, k: float = 0.5) -> "ChartDesign":
        if not 0 < false_alarm_rate < 1:
            raise ValueError(f"false_alarm_rate: expected a probability in (0, 1), got {false_alarm_rate}")
        arl = 2 * charts / false_alarm_rate
        return cls(false_alarm_rate, charts, k, cusum_interval(arl, k), arl)


@dataclass
class Chart:
    """Self-starting two-sided CUSUM of one parameter: ``z`` the standardized
    innovations (nan for the nights that start a reference), ``upper`` and
    ``lower`` the sums, ``alarms`` the indices where one exceeded ``h``."""
    name: str
    times: List[str]
    values: np.ndarray
    std: np.ndarray
    z: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    alarms: List[int]
    h: float
    k: float


def cusum(values, std, h: float, k: float = 0.5, name: str = "", times: Sequence[str] = ()) -> Chart:
    """Self-starting CUSUM: each value is compared with the σ-weighted mean of
    the values since the last alarm (or the start), z_t = (x_t − m) /
    sqrt(σ_t² + 1/Σw), which is N(0, 1) while the machine does not change
    (the reference's own uncertainty included); S± accumulate z ∓ k. An
    alarm restarts the chart with the alarming value as the new reference
    (the change is accepted as the new state)."""
    x = np.asarray(values, float)
    s = np.asarray(std, float)
    n = len(x)
    z = np.full(n, np.nan)
    up, lo = np.zeros(n), np.zeros(n)
    alarms = []
    sw = swx = 0.0
    su = sl = 0.0
    for t in range(n):
        if not (math.isfinite(x[t]) and math.isfinite(s[t]) and s[t] > 0):
            up[t], lo[t] = su, sl
            continue
        if sw > 0:
            m = swx / sw
            z[t] = (x[t] - m) / math.sqrt(s[t] ** 2 + 1.0 / sw)
            su = max(0.0, su + z[t] - k)
            sl = max(0.0, sl - z[t] - k)
        up[t], lo[t] = su, sl
        if su > h or sl > h:
            alarms.append(t)
            su = sl = 0.0
            sw = swx = 0.0
        w = 1.0 / s[t] ** 2
        sw += w
        swx += w * x[t]
    return Chart(name, list(times), x, s, z, up, lo, alarms, h, k)


def detect(calibrations: Sequence[Calibration], names: Optional[Sequence[str]] = None,
           false_alarm_rate: float = 0.001, k: float = 0.5, design: Optional[ChartDesign] = None,
           usable_only: bool = True) -> Dict[str, Chart]:
    """CUSUM charts of one machine's history (time order), one per machine
    error estimated in every calibration (or ``names``). The decision
    interval is chosen so that, while nothing changes, a calibration raises
    an alarm on any of the charts with probability ``false_alarm_rate``.
    Fits that are not usable are left out (their values are not measurements)."""
    cals = [c for c in calibrations if c.usable or not usable_only]
    if not cals:
        return {}
    if names is None:
        common = set(machine_error_names(cals[0]))
        for c in cals[1:]:
            common &= set(machine_error_names(c))
        names = [n for n in machine_error_names(cals[0]) if n in common]
    design = design or ChartDesign.for_rate(false_alarm_rate, max(1, len(names)), k)
    out = {}
    rows = [({m: i for i, m in enumerate(c.names)}, c.values, c.std) for c in cals]
    times = [c.time for c in cals]
    for n in names:
        v = [vals[ix[n]] if n in ix else math.nan for ix, vals, _ in rows]
        s = [std[ix[n]] if n in ix else math.nan for ix, _, std in rows]
        out[n] = cusum(v, s, design.h, design.k, n, times)
    return out


def first_alarm(charts: Mapping[str, Chart]) -> Optional[int]:
    """Index of the first calibration on which any chart alarmed (None: none did)."""
    firsts = [c.alarms[0] for c in charts.values() if c.alarms]
    return min(firsts) if firsts else None


# ---------------------------------------------------------------------------
# pooled statistics
# ---------------------------------------------------------------------------

def _day(time: str) -> str:
    return time[:10]


@dataclass
class PooledStatistics:
    names: List[str]
    pooling: str
    groups: int
    dof: int
    covariance: np.ndarray
    mean: np.ndarray
    fit_std: np.ndarray     #: rms of the fits' own σ per parameter

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.covariance), 0))

    def report(self) -> str:
        lines = [f"pooled over {self.groups} {self.pooling} ({self.dof} degrees of freedom): the spread of "
                 "repeated calibrations against the fits' own uncertainty",
                 f"  {'parameter':<12}{'mean':>10}{'pooled sd':>11}{'fit u':>9}{'ratio':>7}  unit"]
        for n, m, s, u in zip(self.names, self.mean, self.std, self.fit_std):
            f, unit = display_scale(n)
            lines.append(f"  {n:<12}{m * f:>10.3f}{s * f:>11.3f}{u * f:>9.3f}{s / u if u > 0 else math.nan:>7.2f}"
                         f"  {unit}")
        return "\n".join(lines)


def pooled_statistics(calibrations: Sequence[Calibration], by: str = "days",
                      names: Optional[Sequence[str]] = None) -> PooledStatistics:
    """Covariance of the stored values pooled within groups
    (:func:`fivecal.uncertainty.pooled_covariance`, the pooling of U_x in the
    thesis' eq. 8-3): ``by="days"`` groups the calibrations of one UTC day
    (removes the change between days: what is left is the within-day
    repeatability), ``by="cycles"`` groups the k-th calibration of every day
    (removes the drift through the day). A ratio pooled sd / fit u well above
    1 says the machine varies more than one fit's noise shows. To propagate
    the pooled input covariance of the datasets themselves, pass the datasets
    to :func:`fivecal.uncertainty.gum_input_covariance`."""
    cals = [c for c in calibrations if c.usable]
    if names is None:
        common = set(machine_error_names(cals[0])) if cals else set()
        for c in cals[1:]:
            common &= set(machine_error_names(c))
        names = [n for n in machine_error_names(cals[0]) if n in common] if cals else []
    if len(cals) < 2 or not names:
        raise ValueError("pooled statistics: at least two usable calibrations sharing a parameter are needed")
    X = np.array([[c.values[c.names.index(n)] for n in names] for c in cals])
    U = np.array([[c.std[c.names.index(n)] for n in names] for c in cals])
    days = [_day(c.time) for c in cals]
    if by == "days":
        labels = {d: i for i, d in enumerate(dict.fromkeys(days))}
        groups = [labels[d] for d in days]
    elif by == "cycles":
        seen: Dict[str, int] = {}
        groups = []
        for d in days:
            groups.append(seen.get(d, 0))
            seen[d] = seen.get(d, 0) + 1
    else:
        raise ValueError(f"by: expected 'days' or 'cycles', got '{by}'")
    p = uncertainty.pooled_covariance(X, groups)
    if p.dof < 1:
        raise ValueError(f"pooled statistics by {by}: no group holds two calibrations")
    return PooledStatistics(list(names), by, len(set(groups)), int(p.dof), np.asarray(p.covariance),
                            np.asarray(p.mean), np.sqrt(np.mean(U ** 2, axis=0)))


# ---------------------------------------------------------------------------
# plot
# ---------------------------------------------------------------------------

def plot_trend(calibrations: Sequence[Calibration], path: str, names: Optional[Sequence[str]] = None,
               tolerances: Optional[Mapping[str, float]] = None, charts: Optional[Mapping[str, Chart]] = None,
               title: Optional[str] = None, label: str = "") -> str:
    """One panel per parameter: value against calibration date with a ±2σ
    band, ±tolerance lines (dashed red) and CUSUM alarms (red triangles)."""
    import datetime

    files.guard_output(path, label)
    tolerances = _tolerances.check_tolerances(tolerances) if tolerances else None
    cals = [c for c in calibrations if c.usable]
    if not cals:
        raise ValueError("trend plot: no usable calibration")
    if names is None:
        names = machine_error_names(cals[-1])
    names = list(names)
    plt = _pyplot()
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 1.9 * len(names) + 0.9), squeeze=False, sharex=True)
    t = [datetime.datetime.fromisoformat(c.time.replace("Z", "+00:00")) for c in cals]
    for ax, n in zip(axes[:, 0], names):
        f, unit = display_scale(n)
        idx = [i for i, c in enumerate(cals) if n in c.names]
        tt = [t[i] for i in idx]
        v = np.array([cals[i].values[cals[i].names.index(n)] for i in idx]) * f
        s = np.array([cals[i].std[cals[i].names.index(n)] for i in idx]) * f
        ax.fill_between(tt, v - 2 * s, v + 2 * s, color="#4c78a8", alpha=0.25, lw=0, label="±2σ")
        ax.plot(tt, v, "o-", color="#4c78a8", ms=3, lw=1, label="value")
        lo, hi = float(np.nanmin(v - 2 * s)), float(np.nanmax(v + 2 * s))
        if tolerances and n in tolerances:
            tol = tolerances[n] * f
            for sgn in (1, -1):
                ax.axhline(sgn * tol, color="#e45756", ls="--", lw=1, label="tolerance" if sgn == 1 else None)
            # the view holds the data and the tolerance line on their side, not
            # the far one: a change of a few µm stays visible next to ±30 µm
            near = tol if np.nanmean(v) >= 0 else -tol
            lo, hi = min(lo, near), max(hi, near)
            below = near <= float(np.nanmin(v))      # the note goes to the side away from the line
            ax.text(0.99, 0.9 if below else 0.05, f"tolerance ±{tol:g} {unit}", transform=ax.transAxes,
                    ha="right", fontsize=7, color="#e45756")
        pad = 0.08 * (hi - lo) if hi > lo else 1.0
        ax.set_ylim(lo - pad, hi + pad)
        if charts and n in charts and charts[n].alarms:
            ch = charts[n]
            at = [ch.times[i] for i in ch.alarms]
            ai = [i for i in idx if cals[i].time in at]
            ax.plot([t[i] for i in ai], [cals[i].values[cals[i].names.index(n)] * f for i in ai], "v",
                    color="#e45756", ms=8, label="CUSUM alarm")
        ax.set_ylabel(f"{n} ({unit})")
        ax.grid(alpha=0.3)
    handles = {}
    for ax in axes[:, 0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    axes[-1, 0].set_xlabel("calibration time (UTC)")
    fig.autofmt_xdate()
    # title, then the legend under it, then the panels: fixed inches from the
    # top, so neither overlaps the other whatever the number of panels
    H = fig.get_figheight()
    fig.suptitle(title or f"{cals[0].machine_id}: calibration history", y=1 - 0.12 / H, va="top")
    fig.legend(list(handles.values()), list(handles), loc="upper center", ncol=len(handles), fontsize=8,
               bbox_to_anchor=(0.5, 1 - 0.45 / H), frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.7 / H))
    save_figure(fig, path, label=label, dpi=110)
    plt.close(fig)
    return path


def gum_from_history(calibrations: Sequence[Calibration], estimate="location", by: str = "days",
                     probability: float = 0.95, k: Optional[float] = None):
    """GUM U_y = C U_x Cᵀ (thesis eq. 8-3) with U_x pooled over the stored
    calibrations' own datasets (their ``source`` files, which must exist and
    share one plan) by ``days`` (UTC date) or ``cycles`` (k-th of each day):
    :func:`fivecal.uncertainty.gum_input_covariance`, day labels from the
    stored times. Returns its :class:`fivecal.uncertainty.CyclesUncertainty`."""
    import os

    cals = list(calibrations)
    missing = [c.source or f"#{c.id}" for c in cals if not c.source or not os.path.isfile(c.source)]
    if missing:
        raise ValueError(f"GUM from the history: the dataset of {missing[0]} is not available (its source file)")
    days = [_day(c.time) for c in cals]
    labels = {d: i for i, d in enumerate(dict.fromkeys(days))}
    return uncertainty.gum_input_covariance([load_dataset(c.source) for c in cals], estimate,
                                            day=[labels[d] for d in days],
                                            pooling={"days": "days", "cycles": "cycles"}[by],
                                            probability=probability, k=k)
