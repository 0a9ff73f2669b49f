"""Polar plots of double ball bar traces, the way ballbar software draws them.

The radial axis is the deviation from the nominal radius, magnified: the
nominal circle is drawn three rings from the centre, the plot spans two
rings either side of it and the rings are ``scale`` µm apart, so a
deviation of one ring moves the trace one ring in or out. The
magnification printed on every plot is

    M = (nominal radius in µm) / (drawn radius of the nominal circle in µm of deviation)
      = 1000 R / (3 scale).

A centre offset e draws as r = 3 scale + e cos(phi), a limacon: at large
magnification a shifted circle turns egg- or pear-shaped (Wang et al.'s
"pear shape gradually" as an error grows at a fixed magnification).

i.e. how many times the deviations are enlarged relative to the drawn circle.

One angle convention for every ball bar plot of the package (stated on each
plot by :func:`angle_convention`): the angle of a sample is measured in the
plane of the trace, counter-clockwise from the first axis of the plane
towards the second, seen from the positive normal (XY: from +X towards +Y,
seen from +Z; YZ: from +Y, seen from +X; ZX: from +Z, seen from +Y). Traces
of a dataset get it from :func:`fivecal.procedures.dbb.trace_from_dataset` (the
geometric angle of the moving ball about the fixed one), never from a
rotary axis command, whose sign depends on the axis direction.
"""
from __future__ import annotations

import math
from typing import Iterable, Mapping, Optional, Sequence

import numpy as np

from ..figures import _pyplot
from ..files import save_figure
from ..procedures.dbb import Trace, trace_from_dataset
from ..units import display_scale
from .plots import _limits, save_capped

_NICE = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0)
CW_COLOR, CCW_COLOR = "#1f5fbf", "#d62728"
_PALETTE = ("#d62728", "#1f5fbf", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2")


_NORMALS = {"XY": "+Z", "YZ": "+X", "ZX": "+Y", "YX": "−Z", "ZY": "−X", "XZ": "−Y"}


def plane_name(plane) -> str:
    """'XY', 'YZ', 'ZX' (or a reversed pair) from a string or a pair of axis
    letters; ValueError for anything else, so that no plot goes out with a
    blank plane."""
    name = "".join(str(p) for p in plane[:2]).upper() if plane is not None else ""
    if name not in _NORMALS:
        raise ValueError(f"plane: {name or plane!r}; expected XY, YZ or ZX")
    return name


def angle_convention(plane) -> str:
    """The angle convention of the package, in words, for one plane."""
    name = plane_name(plane)
    return (f"angle: counter-clockwise from +{name[0]} towards +{name[1]}, "
            f"seen from {_NORMALS[name]}")


def nice_scale(max_abs_um: float) -> float:
    """Ring spacing (µm): the smallest 1-2-5 step with two rings outside the
    largest deviation (the plot spans +-2 rings around the nominal circle)."""
    for s in _NICE:
        if 2 * s >= 1.1 * max_abs_um:
            return s
    return _NICE[-1]


def magnification(nominal_radius: float, scale_um: float) -> float:
    return 1000.0 * nominal_radius / (3.0 * scale_um)


def _as_trace(t) -> Trace:
    if isinstance(t, Trace):
        return t
    if isinstance(t, Mapping):
        return Trace(t["angles"], t["readings"], int(t.get("direction", 0)), t.get("label", ""))
    a, r, *rest = t
    return Trace(a, r, label=rest[0] if rest else "")


def draw_polar(ax, traces: Sequence, nominal_radius: float, scale: Optional[float] = None,
               plane: Sequence[str] = ("X", "Y"), title: str = "", arc: Optional[tuple] = None,
               colors: Optional[Sequence[str]] = None, legend: bool = True) -> float:
    """Draw traces on a matplotlib polar axes; returns the ring spacing (µm).

    ``plane``: the plane of the traces ('XY', 'YZ', 'ZX' or a pair of
    letters); the angles must follow :func:`angle_convention`. Deviations
    beyond the outer ring are drawn on it (clipped), and within a sector
    (``arc``) nothing is drawn outside the sector."""
    name = plane_name(plane)
    traces = [_as_trace(t) for t in traces]
    dev = [np.asarray(t.readings) * 1e3 for t in traces]
    big = max([float(np.nanmax(np.abs(d))) for d in dev if d.size and np.isfinite(d).any()] + [1e-6])
    s = scale or nice_scale(big)
    ax.set_rorigin(-3 * s)
    ax.set_rlim(-2 * s, 2 * s)
    ax.set_rticks([-2 * s, -s, 0, s, 2 * s])
    ax.set_yticklabels([f"{-2 * s:g}", f"{-s:g}", "0", f"+{s:g}", f"+{2 * s:g} µm"], fontsize=7,
                       color="#555")
    ax.set_rlabel_position(67.5)
    lo, hi = arc if arc is not None else (0.0, 360.0)
    th = np.radians(np.linspace(lo, hi, 721))
    ax.plot(th, np.zeros_like(th), ls="--", lw=1.0, color="#333", label=f"nominal R {nominal_radius:g} mm")
    for i, (t, d) in enumerate(zip(traces, dev)):
        if colors is not None:
            c = colors[i % len(colors)]
        elif t.label.upper().startswith("CW"):
            c = CW_COLOR
        elif t.label.upper().startswith("CCW"):
            c = CCW_COLOR
        else:
            c = _PALETTE[i % len(_PALETTE)]
        a = np.radians(np.asarray(t.angles))
        clipped = np.clip(d, -2 * s, 2 * s)
        ax.plot(a, clipped, lw=1.3, color=c, label=t.label or None)
        ok = np.flatnonzero(np.isfinite(clipped))
        if ok.size:
            ax.plot(a[ok[:1]], clipped[ok[:1]], "o", ms=4, color=c)
            if ok.size > 4:  # an arrowhead shows the direction of travel
                j = ok[max(1, ok.size // 12)]
                ax.annotate("", xy=(a[j], clipped[j]), xytext=(a[j - 1], clipped[j - 1]),
                            arrowprops=dict(arrowstyle="-|>", color=c, lw=1.2, mutation_scale=12))
    p1, p2 = name[0], name[1]
    ax.set_xticks(np.radians([0, 45, 90, 135, 180, 225, 270, 315]))
    ax.set_xticklabels([f"+{p1}  0°", "45°", f"+{p2}\n90°", "135°", f"180°  −{p1}", "225°",
                        f"270°\n−{p2}", "315°"], fontsize=8)
    ax.grid(True, color="#ccc", lw=0.6)
    if arc is not None:
        ax.set_thetamin(lo)
        ax.set_thetamax(hi)
        step = 15 if hi - lo <= 120 else 30
        ticks = np.arange(step * math.ceil(lo / step), hi + 1e-9, step)
        names = {0: f"+{p1} ", 90: f"+{p2} ", 180: f"−{p1} ", 270: f"−{p2} "}
        ax.set_xticks(np.radians(ticks))
        ax.set_xticklabels([f"{names.get(int(t) % 360, '')}{t:g}°" for t in ticks], fontsize=8)
    ax.fivecal_plane = name  # read back by tests and callers: the plane this panel shows
    if title:
        ax.set_title(title, fontsize=10, pad=14)
    # beyond 12 traces a legend is a wall of text: the caller names them (titles, annotations)
    if legend and len(ax.get_legend_handles_labels()[1]) <= 12:
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 0.08), fontsize=8, frameon=False)
    return s


def _arc(traces) -> Optional[tuple]:
    """Sector limits (deg) for traces covering less than 300 deg."""
    angs = np.concatenate([np.asarray(_as_trace(t).angles) for t in traces])
    angs = angs[np.isfinite(angs)]
    if angs.size == 0 or np.ptp(angs) >= 300:
        return None
    lo, hi = float(np.min(angs)), float(np.max(angs))
    lo, hi = 5 * math.floor(lo / 5) - 5, 5 * math.ceil(hi / 5) + 5
    return (lo, hi)


def polar_figure(traces: Iterable, nominal_radius: float, title: str = "", scale: Optional[float] = None,
                 annotations: Sequence[str] = (), plane: Sequence[str] = ("X", "Y"), arc="auto",
                 colors=None, header: str = ""):
    """The matplotlib Figure of :func:`plot_polar` (not saved). ``header``:
    a line under the title (the circular test's machine, date, feed, radius
    and sample count)."""
    plt = _pyplot()
    name = plane_name(plane)
    traces = [_as_trace(t) for t in traces]
    fig = plt.figure(figsize=(11.5, 7.4))
    ax = fig.add_axes([0.04, 0.10, 0.52, 0.70], projection="polar")
    s = draw_polar(ax, traces, nominal_radius, scale, name, "", _arc(traces) if arc == "auto" else arc, colors)
    M = magnification(nominal_radius, s)
    fig.suptitle(title, fontsize=13, x=0.03, ha="left", y=0.98)
    if header:
        # the ballbar report's test header; the figure keeps it for readers and tests
        fig.fivecal_header = header
        fig.text(0.03, 0.928, header, fontsize=9.5, weight="bold", color="#222")
    top = 0.895 if header else 0.915
    fig.text(0.03, top, f"plane {name}  ·  scale {s:g} µm/div  ·  deviations magnified ×{M:,.0f}  ·  "
             f"nominal radius {nominal_radius:g} mm", fontsize=9, color="#333")
    fig.text(0.03, top - 0.035, angle_convention(name), fontsize=9, color="#333")
    y = 0.80
    # long panels (the full ballbar diagnosis) close up rather than run off the page
    dy = min(0.031, 0.78 / max(len(annotations), 1))
    for line in annotations:
        bold = line.endswith(":") or line.startswith("## ")
        fig.text(0.665, y, line[3:] if line.startswith("## ") else line, fontsize=8.8, family="monospace",
                 weight="bold" if bold else "normal")
        y -= dy
    return fig


def plot_polar(traces: Iterable, path: str, nominal_radius: float, title: str = "",
               scale: Optional[float] = None, annotations: Sequence[str] = (),
               plane: Sequence[str] = ("X", "Y"), arc="auto", colors=None, header: str = "") -> str:
    """One polar plot with an annotation panel; writes a PNG and returns its path.

    ``traces``: :class:`fivecal.procedures.dbb.Trace` objects (labels starting with CW /
    CCW get the ballbar colours), ``scale``: ring spacing in µm (default:
    chosen from the data), ``annotations``: lines printed beside the plot,
    ``plane``: the plane of the traces (angles as :func:`angle_convention`
    states, which the plot prints).
    """
    fig = polar_figure(traces, nominal_radius, title, scale, annotations, plane, arc, colors, header)
    save_figure(fig, path, dpi=110)
    return path


def polar_grid_figure(panels: Sequence[Mapping], title: str = "", ncols: int = 2, footer: str = ""):
    """The matplotlib Figure of :func:`plot_polar_grid` (not saved): one
    polar axes per panel, the panel's plane in its title, the angle
    convention under it, and one figure legend for the trace labels shared
    by the panels (none beyond 12 labels: the titles name the traces then)."""
    plt = _pyplot()
    n = len(panels)
    if n == 0:
        raise ValueError("polar grid: no panels")
    ncols = max(1, min(ncols, n))
    nrows = math.ceil(n / ncols)
    top_in, foot_in = 0.9, (0.25 + 0.2 * (footer.count("\n") + 1)) if footer else 0.1
    # one column gets a wider page: the figure title and legend need the room
    fig = plt.figure(figsize=(max(5.6 * ncols, 8.4), 6.2 * nrows + top_in + foot_in))
    H = fig.get_figheight()
    handles: dict = {}
    uses: dict = {}
    for i, p in enumerate(panels):
        r, c = divmod(i, ncols)
        w, h = 1.0 / ncols, (1.0 - (top_in + foot_in) / H) / nrows
        left = c * w + 0.09 * w
        bottom = 1.0 - top_in / H - (r + 1) * h + 0.27 * h
        ax = fig.add_axes([left, bottom, 0.78 * w, 0.60 * h], projection="polar")
        traces = [_as_trace(t) for t in p["traces"]]
        arc = p.get("arc", "auto")
        name = plane_name(p.get("plane", ("X", "Y")))
        s = draw_polar(ax, traces, p["nominal_radius"], p.get("scale"), name, "",
                       _arc(traces) if arc == "auto" else arc, p.get("colors"), legend=False)
        M = magnification(p["nominal_radius"], s)
        head = p.get("title", "")
        if f"plane {name}" not in head:
            head = f"{head} · plane {name}" if head else f"plane {name}"
        # the panel title belongs to its axes (tests and readers find the plane there)
        ax.set_title(head, fontsize=11, weight="bold", loc="left", x=-0.12, pad=26)
        lines = [angle_convention(name), f"{s:g} µm/div, ×{M:,.0f}"] + list(p.get("annotations", ()))
        for k, line in enumerate(lines):
            fig.text(left - 0.05 * w, bottom - 0.1 * h - k * 0.042 * h, line, fontsize=8.5,
                     family="monospace", color="#555" if k < 2 else "#222")
        for hd, lb in zip(*ax.get_legend_handles_labels()):
            if not lb.startswith("nominal R"):
                handles.setdefault(lb, hd)
                uses[lb] = uses.get(lb, 0) + 1
    if title:
        fig.suptitle(title, fontsize=13, x=0.02, y=1.0 - 0.1 / H, ha="left", va="top")
    # a legend only for labels shared by panels (CW / CCW, recorded / residual);
    # a label of one panel is in its title already. It goes under the title,
    # where a one-column figure has room for it too.
    if 0 < len(handles) <= 12 and (n == 1 or max(uses.values()) > 1):
        fig.legend(list(handles.values()), list(handles), loc="upper left", fontsize=9, frameon=False,
                   bbox_to_anchor=(0.015, 1.0 - 0.38 / H), ncol=min(len(handles), 4))
    if footer:
        fig.text(0.02, 0.12 / H, footer, fontsize=8.5, color="#333", family="monospace", va="bottom")
    return fig


def plot_polar_grid(panels: Sequence[Mapping], path: str, title: str = "", ncols: int = 2,
                    footer: str = "") -> str:
    """Several polar plots on one PNG. Each panel: ``traces``,
    ``nominal_radius``, ``plane`` (default XY), optional ``title``,
    ``scale``, ``annotations`` (short lines under the plot) and ``arc``."""
    fig = polar_grid_figure(panels, title, ncols, footer)
    save_figure(fig, path, dpi=100)
    return path


def circular_test_figure(result, title: Optional[str] = None, scale: Optional[float] = None):
    """The matplotlib Figure of :func:`plot_circular_test` (not saved)."""
    traces, notes, a1, a2 = _circular_parts(result)
    return polar_figure(traces, result.nominal_radius,
                        title or f"Circular test {result.plane}, R {result.nominal_radius:g} mm",
                        scale=scale, annotations=notes, plane=(a1, a2), header=result.header_line())


def _circular_parts(result):
    traces = []
    for t in result.traces:
        label = t.label or ("CCW" if t.direction > 0 else "CW")
        if not label.upper().startswith(("CW", "CCW")):
            label = ("CCW " if t.direction > 0 else "CW ") + label
        traces.append(Trace(t.angles, t.readings, t.direction, label))
    notes = []
    trimmed = getattr(result, "trimmed", [])
    if trimmed:
        notes += ["overshoot removed: " + ", ".join(f"{t.label or 'run'} {t.arc_start:.0f}°+{t.arc_end:.0f}°"
                                                     for t in trimmed), ""]
    notes += ["ISO 230-4:"] + ["  " + l for l in result.summary_lines()]
    notes += ["", "diagnosis (least squares):"]
    a1, a2 = result.plane[0], result.plane[1]
    rows = [("scale_mismatch", f"scale mismatch {a1}-{a2}", 1e6, "µm/m"),
            ("squareness", f"squareness {a1}{a2}", 1e6, "µrad"),
            ("backlash.1+", f"backlash {a1}+", 1e3, "µm"),
            ("backlash.1-", f"backlash {a1}-", 1e3, "µm"),
            ("backlash.2+", f"backlash {a2}+", 1e3, "µm"),
            ("backlash.2-", f"backlash {a2}-", 1e3, "µm"),
            ("servo_mismatch", "servo mismatch", 1e3, "µm"),
            ("centre.1", f"centre offset {a1}", 1e3, "µm"),
            ("centre.2", f"centre offset {a2}", 1e3, "µm")]
    # the extended diagnoses that survived the significance test (few, usually none)
    for k, ax, other in ((1, a1, a2), (2, a2, a1)):
        rows += [(f"reversal_spike.{k}+", f"reversal spike {ax}+", 1e3, "µm"),
                 (f"reversal_spike.{k}-", f"reversal spike {ax}-", 1e3, "µm"),
                 (f"lateral_play.{k}", f"lateral play {ax}", 1e3, "µm"),
                 (f"straightness.{k}", f"straightness {ax}", 1e3, "µm"),
                 (f"radial_play.{k}", f"radial play {ax}", 1e3, "µm")]
    for n, label, f, unit in rows:
        if n in result.diagnosis:
            notes.append(f"  {label:<18}{result.diagnosis[n] * f:+8.2f} ±{result.diagnosis_std[n] * f:5.2f} {unit}")
            if n == "servo_mismatch" and result.servo_mismatch_ms is not None:
                notes.append(f"  {'  = lag difference':<18}{result.servo_mismatch_ms:+8.3f} ms")
    for k, ax in ((1, a1), (2, a2)):
        amp = result.cyclic_amplitude(k) if hasattr(result, "cyclic_amplitude") else None
        if amp is not None:
            notes.append(f"  {f'cyclic error {ax}':<18}{amp[0] * 1e3:8.2f} ±{amp[1] * 1e3:5.2f} µm "
                         f"({result.cyclic_pitch[k - 1]:.3g} mm)")
    notes.append(f"  residual rms {result.diagnosis_rms * 1e3:.2f} µm")
    ranking = getattr(result, "ranking", [])
    if ranking:
        notes += ["", "contribution to circularity:"] + ["  " + l for l in result.ranking_lines(top=5)]
    return traces, notes, a1, a2


def plot_circular_test(result, path: str, title: Optional[str] = None, scale: Optional[float] = None) -> str:
    """CW/CCW polar plot of a :class:`fivecal.procedures.dbb.CircularResult`: a
    header with machine, date, feed, radius and sample count, the ISO 230-4
    values, the diagnosis and the five largest contributions beside it.
    ``scale``: ring spacing in µm (default automatic); the plot states it."""
    fig = circular_test_figure(result, title, scale)
    save_figure(fig, path, dpi=110)
    return path


def plot_volumetric(vol, path: str, title: str = "Volumetric evaluation: three-plane circular tests") -> str:
    """One panel per plane of a :class:`fivecal.procedures.dbb.VolumetricResult`
    (common ring spacing, so the planes compare at a glance) and the combined
    values underneath."""
    panels = []
    big = 0.0
    for p, r in vol.planes.items():
        for t in r.traces:
            big = max(big, float(np.nanmax(np.abs(t.readings))) * 1e3)
    s = nice_scale(big)
    for p, r in vol.planes.items():
        traces, _, a1, a2 = _circular_parts(r)
        g = max(float(run.circular_deviation) for run in r.runs)
        notes = [f"G {g * 1e3:.2f} µm" + (f", H {r.hysteresis * 1e3:.2f} µm" if r.hysteresis is not None else "")]
        notes += r.ranking_lines(top=2)
        panels.append({"traces": traces, "nominal_radius": r.nominal_radius, "plane": (a1, a2), "scale": s,
                       "annotations": notes})
    # the leading blank line keeps the panels' notes clear of the footer
    footer = (f"\n{vol.header_line()}\ncombined circularity {vol.circularity * 1e3:.2f} µm (largest G)  ·  "
              f"volumetric {vol.volumetric * 1e3:.2f} µm (shell holding every plane's trace)")
    return plot_polar_grid(panels, path, title, ncols=3, footer=footer)


def plot_four_step(result, path: str) -> str:
    """The four Jiang & Cripps steps as polar plots of the raw readings
    against the angle of the moving ball about the fixed one in the plane it
    sweeps (the package's angle convention, not the rotary command: an axis
    whose direction is a negative basis vector turns the other way), with
    each step's fitted centre, and the PIGEs of both methods underneath."""
    ds = result.dataset
    panels = []
    for s in result.steps:
        obs = ds.observations
        length = obs[s.observations[0]]["length"]
        c = np.asarray(s.centre) * 1e3
        e1, e2 = ("XYZ"[int(np.argmax(np.abs(np.asarray(e))))] for e in (s.e1, s.e2))  # centre coordinates
        t = trace_from_dataset(ds, s.setup)
        panels.append({"traces": [Trace(t.angles, t.readings, label=s.setup)],
                       "nominal_radius": length, "plane": t.plane,
                       "title": f"{s.setup}: {s.axis} axis, {length:g} mm bar"
                                + (" (extension)" if s.extended else ""),
                       "annotations": [f"centre {e1} {c[0]:+8.2f} µm, {e2} {c[1]:+8.2f} µm",
                                       f"fit rms {s.rms * 1e3:.2f} µm"
                                       + (f", |S'O'| {s.arm:.1f} mm" if s.extended else "")]})
    eng = result.engine
    parts = []
    for n in result.names:
        f, unit = display_scale(n)
        t = f"{n} {result.values[n] * f:+.2f}"
        ev = result.engine_value(n) if eng is not None else None  # a spindle-named one mapped back
        if ev is not None:
            t += f" ({ev[0] * f:+.2f})"
        parts.append(t + f" {unit}")
    footer = ("four-step (engine):  " + ",  ".join(parts[:4]) + "\n" + " " * 21 + ",  ".join(parts[4:]))
    side = "head" if getattr(result, "tool_side", False) else "table"
    return plot_polar_grid(panels, path, f"Jiang & Cripps four-step DBB test: {ds.machine.name} "
                           f"({result.carried} on {result.carrier}, {side})",
                           footer=footer)


def plot_wang_patterns(patterns: Mapping, path: str, wang_path=None) -> str:
    """Polar plots of single-error traces along the Wang path (tracking angle
    90-450 deg), with their Fourier content: centre shift (1st harmonic),
    size change (mean), 2nd and 3rd harmonic amplitudes."""
    panels = []
    for name, p in patterns.items():
        h = np.asarray(p.harmonics) * 1e3
        f, unit = display_scale(name)
        panels.append({"traces": [Trace(p.tracking, p.readings, label=name)],
                       "nominal_radius": wang_path.bar_length if wang_path is not None else 100.0,
                       "title": f"{name} = {p.value * f:+g} {unit}",
                       "annotations": [f"shift ({h[1, 0]:+.2f}, {h[1, 1]:+.2f}) µm (X, Y)",
                                       f"size {h[0, 0]:+.2f} µm, 2nd {math.hypot(*h[2]):.2f}, "
                                       f"3rd {math.hypot(*h[3]):.2f} µm"]})
    footer = ""
    if wang_path is not None:
        footer = (f"table ball on a circle of radius {wang_path.radius:g} mm at height "
                  f"{wang_path.centre[2]:.1f} mm; spindle ball {wang_path.height:g} mm above its centre; "
                  f"bar {wang_path.bar_length:g} mm;\nangle = tracking angle (from +X, counter-clockwise "
                  "seen from +Z)")
    for p in panels:
        p["plane"] = "XY"  # the table ball's circle is horizontal; the tracking angle is its angle
    return plot_polar_grid(panels, path, "Wang et al. patterns: one error at a time", footer=footer)


# ---- the report's ball bar figures ----------------------------------------------------------
#: A trace sweeping less than this (deg) is no circle: not drawn as a polar plot.
MIN_SWEEP = 10.0


def dbb_groups(dataset) -> list:
    """The DBB observations of a dataset split so that no plot mixes setups,
    planes or bar lengths: a list of ``(setup, length, indices)`` in the
    order the setups first appear."""
    groups: dict = {}
    for i, o in enumerate(dataset.observations):
        if o.get("type") == "dbb":
            groups.setdefault((o.get("setup", ""), float(o.get("length", 0.0))), []).append(i)
    return [(s, L, idx) for (s, L), idx in groups.items()]


def dbb_panels(result) -> tuple:
    """Polar panels of the DBB setups of an identification result: per
    setup and bar length, the recorded readings and the residuals the fit
    leaves, against the plane angle (:func:`angle_convention`). Returns
    ``(panels, skipped)``; ``skipped`` names groups too short for a trace
    (fewer than 3 samples: no plane) or sweeping less than
    :data:`MIN_SWEEP` degrees."""
    ds = result.dataset
    resid = {}
    for k, r in zip(np.asarray(result.residual_source), np.asarray(result.residuals)):
        if k >= 0:
            resid.setdefault(int(k), float(r))
    rms = lambda x: float(np.sqrt(np.nanmean(np.square(x)))) * 1e3  # noqa: E731
    panels, skipped = [], []
    for setup, length, idx in dbb_groups(ds):
        if len(idx) < 3:
            skipped.append(f"{setup or '(no setup id)'} ({len(idx)} samples)")
            continue
        t = trace_from_dataset(ds, setup, idx)
        if np.ptp(t.angles) < MIN_SWEEP:
            skipped.append(f"{setup or '(no setup id)'} (the balls sweep {np.ptp(t.angles):.3g}° about "
                           "each other: no circle to draw)")
            continue
        left = np.array([resid.get(i, np.nan) for i in idx])
        panels.append({"traces": [Trace(t.angles, t.readings, label="recorded reading"),
                                  Trace(t.angles, left, label="residual after the fit")],
                       "nominal_radius": length, "plane": t.plane, "setup": setup,
                       "title": f"setup {setup or '(none)'} · plane {t.plane} · bar {length:g} mm",
                       "annotations": [f"{len(idx)} samples; rms reading {rms(t.readings):.2f} µm, "
                                       f"residual {rms(left):.2f} µm"]})
    return panels, skipped


def dbb_figure(result, title: Optional[str] = None, panels=None):
    """The report's ball bar Figure: one polar panel per DBB setup, plane
    and bar length (never two on one panel). None without DBB data.
    ``panels``: those of :func:`dbb_panels` when already made."""
    if panels is None:
        panels, _ = dbb_panels(result)
    if not panels:
        return None
    ncols = 1 if len(panels) == 1 else (2 if len(panels) in (2, 4) else 3)
    return polar_grid_figure(panels, title or "Double ball bar: recorded readings and residuals after the fit",
                             ncols=ncols)


def report_figures(result, out_dir: str) -> list:
    """Hook of :func:`fivecal.report.write_report` for data with DBB
    observations: ``[(png path, caption)]``: the polar panels and the
    residuals against the sample index, one panel per setup, plane and bar
    length in both."""
    import os

    out = []
    panels, skipped = dbb_panels(result)
    if panels:
        fig = dbb_figure(result, panels=panels)
        path = os.path.join(out_dir, "dbb_polar.png")
        save_capped(fig, path, 100)
        setups = ", ".join(p["setup"] or "(none)" for p in panels)
        cap = (f"Double ball bar setups {setups}: one polar panel per setup, plane and bar length, the recorded "
               "readings and what the identified model leaves unexplained (deviations from the nominal bar "
               "length, magnified; angle counter-clockwise from the first axis of the plane towards the "
               "second, seen from the positive normal).")
        if skipped:
            cap += f" Not drawn as polar plots: {'; '.join(skipped)}."
        out.append((path, cap))
    fig = dbb_residual_figure(result)
    if fig is not None:
        path = os.path.join(out_dir, "dbb_residuals.png")
        save_capped(fig, path, 100)
        cap = ("Double ball bar residuals after the fit against the sample index (recording order), one panel "
               "per setup, plane and bar length.")
        if skipped and not panels:
            cap += f" No polar plot: {'; '.join(skipped)}."
        out.append((path, cap))
    return out


def dbb_residual_figure(result, title: str = "Double ball bar: residuals after the fit"):
    """Residuals of the DBB observations against the sample index (recording
    order), one panel per setup, plane and bar length; the plane named in
    each panel's title. None without DBB data."""
    plt = _pyplot()
    ds = result.dataset
    groups = dbb_groups(ds)
    if not groups:
        return None
    resid = {}
    for k, r in zip(np.asarray(result.residual_source), np.asarray(result.residuals)):
        if k >= 0:
            resid.setdefault(int(k), float(r))
    n = len(groups)
    ncols = min(3, n)
    nrows = -(-n // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(max(4.8 * ncols, 8.0), 2.7 * nrows + 0.9), squeeze=False,
                             layout="constrained")
    for k, (setup, length, idx) in enumerate(groups):
        ax = axes[k // ncols][k % ncols]
        where = "too few samples for a plane"
        if len(idx) >= 3:
            t = trace_from_dataset(ds, setup, idx)
            where = (f"plane {t.plane}" if np.ptp(t.angles) >= MIN_SWEEP else
                     f"no circle (the balls sweep {np.ptp(t.angles):.2g}°)")
        r = np.array([resid.get(i, np.nan) for i in idx]) * 1e3
        x = np.arange(len(idx))
        ax.plot(x, r, "-o", ms=2, lw=1.0, color="#1f5fbf")
        ax.axhline(0, color="#888", lw=0.7)
        _limits(ax, x, np.r_[r, 0.0], margin=0.06)
        rms = float(np.sqrt(np.nanmean(np.square(r)))) if np.isfinite(r).any() else float("nan")
        ax.set_title(f"setup {setup or '(none)'} · {where} · bar {length:g} mm\n"
                     f"{len(idx)} samples, rms {rms:.2f} µm", fontsize=10)
        ax.grid(alpha=0.3)
        ax.set_xlabel("sample (recording order)", fontsize=9)
        ax.set_ylabel("residual (µm)", fontsize=9)
    for k in range(n, nrows * ncols):
        axes[k // ncols][k % ncols].set_visible(False)
    fig.suptitle(title, fontsize=12)
    return fig
