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
Angles: 0 deg along the first plane axis, counter-clockwise positive.
"""
from __future__ import annotations

import math
from typing import Iterable, Mapping, Optional, Sequence

import numpy as np

from .dbb import Trace
from .files import save_figure

_NICE = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0)
CW_COLOR, CCW_COLOR = "#1f5fbf", "#d62728"
_PALETTE = ("#d62728", "#1f5fbf", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2")


def _pyplot():
    from .plots import _pyplot as figures

    return figures()


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
    """Draw traces on a matplotlib polar axes; returns the ring spacing (µm)."""
    traces = [_as_trace(t) for t in traces]
    dev = [np.asarray(t.readings) * 1e3 for t in traces]
    big = max([float(np.max(np.abs(d))) for d in dev if d.size] + [1e-6])
    s = scale or nice_scale(big)
    ax.set_rorigin(-3 * s)
    ax.set_rlim(-2 * s, 2 * s)
    ax.set_rticks([-2 * s, -s, 0, s, 2 * s])
    ax.set_yticklabels([f"{-2 * s:g}", f"{-s:g}", "0", f"+{s:g}", f"+{2 * s:g} µm"], fontsize=7,
                       color="#555")
    ax.set_rlabel_position(67.5)
    th = np.linspace(0, 2 * np.pi, 721)
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
        if a.size:
            ax.plot(a[:1], clipped[:1], "o", ms=4, color=c)
            if a.size > 4:  # an arrowhead shows the direction of travel
                j = max(1, a.size // 12)
                ax.annotate("", xy=(a[j], clipped[j]), xytext=(a[j - 1], clipped[j - 1]),
                            arrowprops=dict(arrowstyle="-|>", color=c, lw=1.2, mutation_scale=12))
    p1, p2 = plane[0], plane[1]
    ax.set_xticks(np.radians([0, 45, 90, 135, 180, 225, 270, 315]))
    ax.set_xticklabels([f"+{p1}  0°", "45°", f"+{p2}\n90°", "135°", f"180°  −{p1}", "225°",
                        f"270°\n−{p2}", "315°"], fontsize=8)
    ax.grid(True, color="#ccc", lw=0.6)
    if arc is not None:
        lo, hi = arc
        ax.set_thetamin(lo)
        ax.set_thetamax(hi)
        step = 15 if hi - lo <= 120 else 30
        ticks = np.arange(step * math.ceil(lo / step), hi + 1e-9, step)
        names = {0: f"+{p1} ", 90: f"+{p2} ", 180: f"−{p1} ", 270: f"−{p2} "}
        ax.set_xticks(np.radians(ticks))
        ax.set_xticklabels([f"{names.get(int(t) % 360, '')}{t:g}°" for t in ticks], fontsize=8)
    if title:
        ax.set_title(title, fontsize=10, pad=14)
    if legend:
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 0.08), fontsize=8, frameon=False)
    return s


def _arc(traces) -> Optional[tuple]:
    """Sector limits (deg) for traces covering less than 300 deg."""
    angs = np.concatenate([np.asarray(_as_trace(t).angles) for t in traces])
    if angs.size == 0 or np.ptp(angs) >= 300:
        return None
    lo, hi = float(np.min(angs)), float(np.max(angs))
    lo, hi = 5 * math.floor(lo / 5) - 5, 5 * math.ceil(hi / 5) + 5
    return (lo, hi)


def plot_polar(traces: Iterable, path: str, nominal_radius: float, title: str = "",
               scale: Optional[float] = None, annotations: Sequence[str] = (),
               plane: Sequence[str] = ("X", "Y"), arc="auto", colors=None) -> str:
    """One polar plot with an annotation panel; writes a PNG and returns its path.

    ``traces``: :class:`fivecal.dbb.Trace` objects (labels starting with CW /
    CCW get the ballbar colours), ``scale``: ring spacing in µm (default:
    chosen from the data), ``annotations``: lines printed beside the plot.
    """
    plt = _pyplot()
    traces = [_as_trace(t) for t in traces]
    fig = plt.figure(figsize=(11.5, 7.4))
    ax = fig.add_axes([0.04, 0.10, 0.52, 0.72], projection="polar")
    s = draw_polar(ax, traces, nominal_radius, scale, plane, "", _arc(traces) if arc == "auto" else arc, colors)
    M = magnification(nominal_radius, s)
    fig.suptitle(title, fontsize=13, x=0.03, ha="left", y=0.98)
    fig.text(0.03, 0.915, f"scale {s:g} µm/div   ·   deviations magnified ×{M:,.0f}   ·   "
             f"nominal radius {nominal_radius:g} mm   ·   plane {''.join(plane[:2])}",
             fontsize=9, color="#333")
    y = 0.84
    for line in annotations:
        bold = line.endswith(":") or line.startswith("## ")
        fig.text(0.62, y, line[3:] if line.startswith("## ") else line, fontsize=8.8, family="monospace",
                 weight="bold" if bold else "normal")
        y -= 0.031
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_polar_grid(panels: Sequence[Mapping], path: str, title: str = "", ncols: int = 2,
                    footer: str = "") -> str:
    """Several polar plots on one PNG. Each panel: ``traces``,
    ``nominal_radius``, optional ``title``, ``scale``, ``plane``,
    ``annotations`` (short lines under the plot) and ``arc``."""
    plt = _pyplot()
    n = len(panels)
    nrows = math.ceil(n / ncols)
    top_in, foot_in = 0.6, (0.25 + 0.2 * (footer.count("\n") + 1)) if footer else 0.1
    fig = plt.figure(figsize=(5.6 * ncols, 5.9 * nrows + top_in + foot_in))
    H = fig.get_figheight()
    for i, p in enumerate(panels):
        r, c = divmod(i, ncols)
        w, h = 1.0 / ncols, (1.0 - (top_in + foot_in) / H) / nrows
        left = c * w + 0.09 * w
        bottom = 1.0 - top_in / H - (r + 1) * h + 0.24 * h
        ax = fig.add_axes([left, bottom, 0.78 * w, 0.64 * h], projection="polar")
        traces = [_as_trace(t) for t in p["traces"]]
        arc = p.get("arc", "auto")
        s = draw_polar(ax, traces, p["nominal_radius"], p.get("scale"), p.get("plane", ("X", "Y")), "",
                       _arc(traces) if arc == "auto" else arc, p.get("colors"), legend=False)
        M = magnification(p["nominal_radius"], s)
        fig.text(left - 0.05 * w, bottom + 0.64 * h + 0.07 * h, p.get("title", ""), fontsize=11,
                 weight="bold")
        lines = [f"{s:g} µm/div, ×{M:,.0f}"] + list(p.get("annotations", ()))
        for k, line in enumerate(lines):
            fig.text(left - 0.05 * w, bottom - 0.1 * h - k * 0.045 * h, line, fontsize=8.5,
                     family="monospace", color="#222" if k else "#555")
    if title:
        fig.suptitle(title, fontsize=13, y=0.995)
    if footer:
        fig.text(0.02, 0.12 / H, footer, fontsize=8.5, color="#333", family="monospace", va="bottom")
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def plot_circular_test(result, path: str, title: Optional[str] = None) -> str:
    """CW/CCW polar plot of a :class:`fivecal.dbb.CircularResult` with the
    ISO 230-4 values and the diagnosis beside it."""
    traces = []
    for t in result.traces:
        label = t.label or ("CCW" if t.direction > 0 else "CW")
        if not label.upper().startswith(("CW", "CCW")):
            label = ("CCW " if t.direction > 0 else "CW ") + label
        traces.append(Trace(t.angles, t.readings, t.direction, label))
    notes = ["ISO 230-4:"] + ["  " + l for l in result.summary_lines()]
    notes += ["", "diagnosis (least squares):"]
    a1, a2 = result.plane[0], result.plane[1]
    rows = [("scale_mismatch", f"scale mismatch {a1}-{a2}", 1e6, "µm/m"),
            ("squareness", f"squareness {a1}{a2}", 1e6, "µrad"),
            ("backlash.1", f"backlash {a1}", 1e3, "µm"),
            ("backlash.2", f"backlash {a2}", 1e3, "µm"),
            ("servo_mismatch", "servo mismatch", 1e3, "µm"),
            ("centre.1", f"centre offset {a1}", 1e3, "µm"),
            ("centre.2", f"centre offset {a2}", 1e3, "µm")]
    for n, label, f, unit in rows:
        if n in result.diagnosis:
            notes.append(f"  {label:<18}{result.diagnosis[n] * f:+8.2f} ±{result.diagnosis_std[n] * f:5.2f} {unit}")
            if n == "servo_mismatch" and result.servo_mismatch_ms is not None:
                notes.append(f"  {'  = lag difference':<18}{result.servo_mismatch_ms:+8.3f} ms")
    notes.append(f"  residual rms {result.diagnosis_rms * 1e3:.2f} µm")
    return plot_polar(traces, path, result.nominal_radius,
                      title or f"Circular test {result.plane}, R {result.nominal_radius:g} mm",
                      annotations=notes, plane=(a1, a2))


def plot_four_step(result, path: str) -> str:
    """The four Jiang & Cripps steps as polar plots of the raw readings
    (plane angle of the pivot about the spindle ball), with each step's
    fitted centre, and the PIGEs of both methods underneath."""
    from .units import display_scale

    ds = result.dataset
    panels = []
    planes = {"A": ("Y", "Z"), "C": ("X", "Y")}
    for s in result.steps:
        obs = ds.observations
        r = np.array([obs[i]["reading"] for i in s.observations])
        length = obs[s.observations[0]]["length"]
        c = np.asarray(s.centre) * 1e3
        e1, e2 = planes[s.axis]
        panels.append({"traces": [Trace(np.degrees(np.asarray(s.angles)), r, label=s.setup)],
                       "nominal_radius": length, "plane": planes[s.axis],
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
        if eng is not None and n in eng.values:
            t += f" ({eng.values[n] * f:+.2f})"
        parts.append(t + f" {unit}")
    footer = ("four-step (engine):  " + ",  ".join(parts[:4]) + "\n" + " " * 21 + ",  ".join(parts[4:]))
    return plot_polar_grid(panels, path, f"Jiang & Cripps four-step DBB test: {ds.machine.name}",
                           footer=footer)


def plot_wang_patterns(patterns: Mapping, path: str, wang_path=None) -> str:
    """Polar plots of single-error traces along the Wang path (tracking angle
    90-450 deg), with their Fourier content: centre shift (1st harmonic),
    size change (mean), 2nd and 3rd harmonic amplitudes."""
    from .units import display_scale

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
                  f"bar {wang_path.bar_length:g} mm; angle = tracking angle (from +X)")
    return plot_polar_grid(panels, path, "Wang et al. patterns: one error at a time", footer=footer)
