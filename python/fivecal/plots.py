"""Plots: parameter bars with uncertainty, residual vectors in the table frame."""
from __future__ import annotations

from typing import Mapping, Optional

import numpy as np

from .files import save_figure
from .units import display_scale


def _pyplot():
    """The part of pyplot the plots use, on private ``Figure`` objects with
    an Agg canvas: no pyplot global state, and the caller's matplotlib
    backend (a notebook's, a GUI's) is left alone."""
    return _Figures


class _Figures:
    @staticmethod
    def figure(**kw):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(**kw)
        FigureCanvasAgg(fig)
        return fig

    @staticmethod
    def subplots(nrows: int = 1, ncols: int = 1, squeeze: bool = True, subplot_kw=None, **kw):
        fig = _Figures.figure(**kw)
        return fig, fig.subplots(nrows, ncols, squeeze=squeeze, subplot_kw=subplot_kw)

    @staticmethod
    def get_cmap(name: str):
        import matplotlib

        return matplotlib.colormaps[name]

    @staticmethod
    def close(fig) -> None:
        """Nothing to release: the figure is not registered with pyplot."""


def plot_parameters(result, path: str, names=None, truth: Optional[Mapping[str, float]] = None,
                    title: str = "Identified parameters (±2σ)") -> str:
    """Horizontal bars of the identified values in report units with ±2σ error
    bars, one panel per unit, and the true values when known."""
    plt = _pyplot()
    names = [n for n in (names or result.estimated) if n in result.std]
    groups = {}
    for n in names:
        groups.setdefault(display_scale(n)[1], []).append(n)
    fig, axes = plt.subplots(1, len(groups), figsize=(4.2 * len(groups), 0.35 * max(map(len, groups.values())) + 1.6),
                             squeeze=False)
    for ax, (unit, ns) in zip(axes[0], groups.items()):
        f = np.array([display_scale(n)[0] for n in ns])
        v = np.array([result.values[n] for n in ns]) * f
        s = np.array([result.std[n] for n in ns]) * f
        y = np.arange(len(ns))
        ax.barh(y, v, xerr=2 * s, color="#4c78a8", ecolor="#222", capsize=3, label="identified")
        if truth is not None:
            t = np.array([truth.get(n, 0.0) for n in ns]) * f
            ax.scatter(t, y, marker="|", s=300, color="#e45756", zorder=3, label="true")
        ax.set_yticks(y, ns)
        ax.invert_yaxis()
        ax.axvline(0, color="#888", lw=0.8)
        ax.set_xlabel(unit)
        ax.grid(axis="x", alpha=0.3)
    axes[0][0].legend(loc="best", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return path


def _nice_floor(x: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above x."""
    if not np.isfinite(x) or x <= 0:
        return 1.0
    e = 10.0 ** np.floor(np.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * e <= x * (1 + 1e-12):
            return float(m * e)
    return float(e)


def indexation_labels(dataset) -> tuple:
    """Per observation, the rotary indexation it was taken at (a tuple of
    degrees over the machine's rotary axes, spindle included), and the axis
    letters."""
    rot = [a for a in dataset.machine.axis_names if a in "ABCS"]
    keys = [tuple(round(float(o["axes"].get(a, 0.0)), 1) for a in rot) for o in dataset.observations]
    return keys, rot


def _indexation_colors(plt, keys):
    uniq = list(dict.fromkeys(keys))
    if len(uniq) <= 10:
        palette = plt.get_cmap("tab10")(np.arange(10))
    elif len(uniq) <= 20:
        palette = plt.get_cmap("tab20")(np.arange(20))
    else:
        palette = np.vstack([plt.get_cmap("tab20")(np.arange(20)), plt.get_cmap("tab20b")(np.arange(20)),
                             plt.get_cmap("Dark2")(np.arange(8))])
    index = {k: i for i, k in enumerate(uniq)}
    return uniq, palette, np.array([palette[index[k] % len(palette)] for k in keys])


def plot_residual_vectors(result, path: str, magnification: Optional[float] = None,
                          title: str = "Unexplained residual vectors", legend: bool = True) -> str:
    """Residual vectors (mm) drawn at the touch points in the table
    (workpiece) frame, magnified, coloured by rotary indexation (thesis
    Figure 4-7 style): a 3D view plus a plan (x-y) and an elevation (x-z) view
    with a scale arrow. ``magnification`` defaults to the largest 1-2-5 step
    that keeps the largest vector within 12 % of the artefact size (10000x or
    20000x for micrometre residuals on a 400 mm table)."""
    plt = _pyplot()
    obs_rows = np.array([i for i, o in enumerate(result.dataset.observations)])
    P = np.asarray(result.points)[obs_rows]
    V = np.asarray(result.residual_vectors)[obs_rows]
    keys, rot = indexation_labels(result.dataset)
    uniq, palette, colors = _indexation_colors(plt, keys)
    span = float(np.ptp(P, axis=0).max()) or 1.0
    norms = np.linalg.norm(V, axis=1)
    vmax = float(norms.max()) if norms.size else 0.0
    vmax = vmax or 1e-9
    mag = magnification or _nice_floor(0.12 * span / vmax)
    W = V * mag

    fig = plt.figure(figsize=(13.5, 7.6))
    gs = fig.add_gridspec(2, 3, width_ratios=[1.45, 1, 0.34], height_ratios=[1.3, 1], wspace=0.22,
                          hspace=0.32, left=0.01, right=0.99, top=0.88, bottom=0.07)
    ax3 = fig.add_subplot(gs[:, 0], projection="3d")
    ax3.scatter(P[:, 0], P[:, 1], P[:, 2], s=3, color="#aaa", depthshade=False)
    ax3.quiver(P[:, 0], P[:, 1], P[:, 2], W[:, 0], W[:, 1], W[:, 2], colors=colors,
               arrow_length_ratio=0.25, linewidth=1.6, normalize=False)
    ax3.set_xlabel("x (mm)")
    ax3.set_ylabel("y (mm)")
    ax3.set_title("3D view (table frame; z up, mm)", fontsize=12)
    ax3.view_init(elev=28, azim=-60)
    try:
        ax3.set_box_aspect(tuple(np.maximum(np.ptp(P, axis=0), 0.45 * span)))
    except (AttributeError, TypeError):
        pass

    def flat(ax, i, j, label_i, label_j, name):
        ax.scatter(P[:, i], P[:, j], s=4, color="#aaa", zorder=1)
        ax.quiver(P[:, i], P[:, j], W[:, i], W[:, j], color=colors, angles="xy", scale_units="xy",
                  scale=1.0, width=0.004, headwidth=3.5, headlength=4, zorder=2)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"{label_i} (mm)")
        ax.set_ylabel(f"{label_j} (mm)")
        ax.set_title(name, fontsize=11)
        ax.grid(alpha=0.3)

    axp = fig.add_subplot(gs[0, 1])
    flat(axp, 0, 1, "x", "y", "plan view (x-y components)")
    axe = fig.add_subplot(gs[1, 1])
    flat(axe, 0, 2, "x", "z", "elevation (x-z components)")
    # scale arrow: a round residual length at the same magnification
    ref_um = _nice_floor(vmax * 1e3)
    x0, x1 = axp.get_xlim()
    y0, y1 = axp.get_ylim()
    axp.annotate("", xy=(x0 + 0.05 * (x1 - x0) + ref_um * 1e-3 * mag, y0 + 0.06 * (y1 - y0)),
                 xytext=(x0 + 0.05 * (x1 - x0), y0 + 0.06 * (y1 - y0)),
                 arrowprops=dict(arrowstyle="->", color="k", lw=1.5))
    axp.text(x0 + 0.05 * (x1 - x0), y0 + 0.09 * (y1 - y0), f"{ref_um:g} µm", fontsize=9)

    if legend:
        axl = fig.add_subplot(gs[:, 2])
        axl.axis("off")
        from matplotlib.lines import Line2D

        handles = [Line2D([0], [0], color=palette[i % len(palette)], lw=3) for i in range(len(uniq))]
        labels = ["(" + ", ".join(f"{v:g}" for v in k) + ")" for k in uniq]
        ncol = 1 if len(uniq) <= 28 else 2
        axl.legend(handles, labels, loc="upper left", fontsize=8 if len(uniq) <= 28 else 7, ncol=ncol,
                   title=f"{', '.join(rot)} (deg)", title_fontsize=9, frameon=False,
                   handlelength=1.2, columnspacing=0.8)
    rms = float(np.sqrt(np.mean(np.square(result.residuals)))) if np.size(result.residuals) else 0.0
    fig.suptitle(f"{title}\nmagnified {mag:g}x; residual rms {rms * 1e3:.2f} µm, largest vector "
                 f"{vmax * 1e3:.2f} µm; colour = indexation", fontsize=12)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_residual_histogram(result, path: str) -> str:
    """Histogram of the residuals (µm) with the normal density of the
    a-posteriori sigma; writes ``path`` (PNG) and returns it."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.5))
    r = result.residuals * 1e3
    counts, edges, _ = ax.hist(r, bins=max(10, int(np.sqrt(r.size))), color="#4c78a8", label="residuals")
    sig = result.sigma * 1e3
    if sig > 0 and r.size:
        x = np.linspace(min(edges[0], -4 * sig), max(edges[-1], 4 * sig), 200)
        ax.plot(x, r.size * (edges[1] - edges[0]) * np.exp(-0.5 * (x / sig) ** 2) / (sig * np.sqrt(2 * np.pi)),
                color="#e45756", lw=1.5, label="normal, σ̂")
        ax.legend(fontsize=8)
    ax.set_xlabel("residual (µm)")
    ax.set_ylabel("count")
    ax.set_title(f"Residuals: rms {result.rms * 1e3:.3f} µm, σ̂ {result.sigma * 1e3:.3f} µm")
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return path


def plot_correlation(result, path: str, names=None, title: str = "Parameter correlation") -> str:
    """The correlation matrix of the estimated parameters (or of ``names``,
    a subset of them) as a colour map from -1 (blue) to +1 (red); for up to
    30 parameters, pairs beyond ±0.9 are marked with their value."""
    plt = _pyplot()
    est = list(result.estimated)
    names = [n for n in (names or est) if n in est]
    idx = [est.index(n) for n in names]
    C = np.asarray(result.correlation)[np.ix_(idx, idx)] if idx else np.zeros((0, 0))
    n = len(names)
    size = min(13.0, max(5.0, 0.22 * n + 2.5))
    fig, ax = plt.subplots(figsize=(size + 1.2, size))
    im = ax.imshow(C, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
    fs = 9 if n <= 25 else (7 if n <= 45 else 5.5)
    ax.set_xticks(np.arange(n), names, rotation=90, fontsize=fs)
    ax.set_yticks(np.arange(n), names, fontsize=fs)
    for i in range(n):
        for j in range(n):
            if n <= 30 and i != j and abs(C[i, j]) >= 0.9:
                ax.text(j, i, f"{C[i, j]:.2f}", ha="center", va="center", fontsize=max(fs - 2, 4),
                        color="w")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03, label="correlation coefficient")
    ax.set_title(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
