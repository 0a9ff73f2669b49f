"""History sections of the HTML report (``write_report(..., history=store,
machine_id=...)``): the trend of every machine error with CUSUM alarms, the
comparison with the previous calibration, and pass / fail against the
tolerances."""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import List, Mapping, Optional, Tuple, Union

from ..history.store import Store, calibration_from_result, dataset_digest, time_key
from ..history.trend import compare, detect, grade, plot_trend
from ..units import display_scale
from .markup import _e, _img_tag, table_html


@dataclass
class History:
    """What the report needs: a store (or its path), the machine, and
    optionally tolerances (name -> mm / rad) and a volumetric tolerance (mm)."""
    store: Union[str, Store]
    machine_id: str
    tolerances: Optional[Mapping[str, float]] = None
    volumetric_tolerance: Optional[float] = None
    false_alarm_rate: float = 0.001
    #: when the reported result was measured (ISO 8601 or datetime; default now),
    #: where it sits in the trend when it is not in the store yet
    time: Optional[object] = None


@dataclass
class Standing:
    """Where the report's calibration stands in its history, for the banner
    at the top of the report: its grade against the tolerances (``pass``,
    ``fail``, ``undecided``; None without tolerances), the failing items, and
    the parameters whose CUSUM alarm fires at this calibration."""
    grade: Optional[str] = None
    failed: Tuple[str, ...] = ()
    alarms: Tuple[str, ...] = ()


def sections(history, machine_id: Optional[str], out_dir: str, result=None,
             embed: bool = True) -> List[Tuple[str, str]]:
    """(title, HTML) sections for the report; empty when the store holds no
    calibration of the machine. ``result``: the identification the report is
    about; when it is not in the store it is shown as the newest entry."""
    return sections_and_standing(history, machine_id, out_dir, result, embed)[0]


def sections_and_standing(history, machine_id: Optional[str], out_dir: str, result=None,
                          embed: bool = True) -> Tuple[List[Tuple[str, str]], Standing]:
    """:func:`sections` and the :class:`Standing` of the report's
    calibration (a FAIL 7,000 pixels below a green banner was missed)."""
    h = history if isinstance(history, History) else History(history, machine_id)
    if machine_id:
        h.machine_id = machine_id
    if not h.machine_id:
        raise ValueError("report history: machine_id is required")
    own = not isinstance(h.store, Store)
    st = Store(h.store, create=False) if own else h.store
    try:
        # a rebuilt machine's history starts at its rebuild: nothing before it is compared or charted
        cals = st.list(h.machine_id, since=st.rebuilt_at(h.machine_id))
        machine = st.machine(h.machine_id)
    finally:
        if own:
            st.close()
    this = None                 # the calibration the report is about
    if result is not None:
        digest = dataset_digest(result.dataset)
        this = next((c for c in reversed(cals) if c.digest == digest), None)
        if this is None:
            cur = calibration_from_result(result, h.machine_id, time=h.time, digest=digest, source="this report")
            cur.id = 0
            cals.append(cur)
            cals.sort(key=lambda c: time_key(c.time))         # stable: the store's order among equal times
            this = cur
        if machine is None:
            machine = result.dataset.machine
    if not cals:
        return [], Standing()
    out = []
    standing = Standing()
    usable = [c for c in cals if c.usable]
    charts = detect(usable, false_alarm_rate=h.false_alarm_rate) if len(usable) >= 2 else {}
    parts = [f"<p>{len(cals)} calibrations of <b>{_e(h.machine_id)}</b> from {_e(cals[0].time)} to "
             f"{_e(cals[-1].time)} ({len(cals) - len(usable)} not usable, left out of the trend)"
             + ("" if this is None else f"; this report's is the one of {_e(this.time)}"
                + (" (not in the store)" if this.id == 0 else f" (#{this.id} in the store)")) + ".</p>"]
    if charts:
        alarmed = {n: [c.times[i] for i in c.alarms] for n, c in charts.items() if c.alarms}
        d = next(iter(charts.values()))
        parts.append(f"<div class='box {'warn' if alarmed else 'ok'}'>Change detection (self-starting CUSUM, "
                     f"k = {d.k:g}, h = {d.h:.2f}, designed for {h.false_alarm_rate:g} false alarms per "
                     f"calibration over {len(charts)} parameters): "
                     + ("; ".join(f"{_e(n)} changed at {', '.join(map(_e, t))}" for n, t in alarmed.items())
                        if alarmed else "no change detected") + ".</div>")
    if usable:
        p = os.path.join(out_dir, "history_trend.png")
        plot_trend(usable, p, tolerances=h.tolerances, charts=charts)
        parts.append(f"<figure>{_img_tag(p, out_dir, embed, 'trend')}<figcaption>Each machine error against "
                     "calibration time with its ±2σ band, tolerance lines (dashed) and CUSUM alarms "
                     "(triangles).</figcaption></figure>")
    out.append(("Calibration history", "\n".join(parts)))

    # this report's calibration against the usable one before it in time (the
    # newest two without a result); the tolerances are on values, not on
    # changes, so the comparison is not graded
    if this is None:
        this = usable[-1] if usable else cals[-1]
    if any(c is this for c in usable):  # identity: a Calibration holds arrays
        standing.alarms = tuple(n for n, c in charts.items() if any(c.times[i] == this.time for i in c.alarms))
    before = [c for c in usable if c is not this and time_key(c.time) <= time_key(this.time)]
    if any(c is this for c in usable) and before:       # identity: a Calibration holds arrays
        cmp = compare(before[-1], this, machine=machine)
        rows = []
        for q in cmp.parameters:
            f, unit = display_scale(q.name)
            rows.append([q.name, f"{q.a * f:.3f}", f"{q.b * f:.3f}", f"{q.delta * f:.3f}", f"{q.std_delta * f:.3f}",
                         f"{q.z:.2f}", unit])
        html_ = [f"<p>{_e(before[-1].time)} → {_e(this.time)}. z = Δ / √(u_A² + u_B²): the two "
                 "calibrations come from separate datasets, so their covariance term is 0. Changes beyond "
                 f"{cmp.z_limit:g}σ: <b>{_e(', '.join(cmp.significant()) or 'none')}</b>.</p>",
                 table_html(["parameter", "before", "this", "change", "u(change)", "z", "unit"], rows,
                            [False, True, True, True, True, True, False])]
        v = cmp.volumetric
        if v is not None:
            html_.append(f"<p>Predicted volumetric error over {v.poses} poses: largest {v.max_a * 1e3:.2f} → "
                         f"{v.max_b * 1e3:.2f} µm, rms {v.rms_a * 1e3:.2f} → {v.rms_b * 1e3:.2f} µm; the "
                         f"tool point moved by up to {v.max_change * 1e3:.2f} µm (rms {v.rms_change * 1e3:.2f} µm)."
                         "</p>")
        out.append(("Compared with the previous calibration", "\n".join(html_)))

    if h.tolerances or h.volumetric_tolerance is not None:
        g = grade(this, h.tolerances or {}, h.volumetric_tolerance, machine=machine)
        rows = []
        for n, p in g.parameters.items():
            f, unit = display_scale(n)
            rows.append([n, f"{p['value'] * f:.3f}", f"{p['expanded'] * f:.3f}", f"{p['tolerance'] * f:g}", unit,
                         p["grade"]])
        if g.volumetric:
            rows.append(["volumetric (largest)", f"{g.volumetric['max'] * 1e3:.3f}", "",
                         f"{g.volumetric['tolerance'] * 1e3:g}", "µm", g.volumetric["grade"]])
        standing.grade = g.verdict
        standing.failed = tuple([n for n, p in g.parameters.items() if p["grade"] == "fail"]
                                + (["volumetric"] if g.volumetric and g.volumetric["grade"] == "fail" else []))
        cls = {"pass": "ok", "fail": "bad"}.get(g.verdict, "warn")
        which = "This calibration" if result is not None else "Latest calibration"
        out.append(("Pass / fail", f"<div class='box {cls}' id='history-grade'>{which} ({_e(this.time)}): <b>{g.verdict.upper()}</b>"
                    + ("" if this.usable else f" (the fit itself is not usable: {_e(this.verdict)})")
                    + " (pass: |value| + 2u within the tolerance; fail: |value| − 2u beyond it; otherwise "
                    "undecided).</div>" + table_html(["item", "value", "U = 2u", "tolerance", "unit", "grade"],
                                                     rows, [False, True, True, True, False, False])))
    return out, standing
