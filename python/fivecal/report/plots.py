"""Plots: parameter bars with uncertainty, residual vectors in the table frame."""
from __future__ import annotations

from typing import Mapping, Optional, Sequence

import numpy as np

from .. import _core
from ..figures import _pyplot
from ..files import save_figure
from ..units import display_scale


#: the largest width or height of a report figure, in pixels: a figure of
#: many panels gets pages or a smaller resolution, never thousands of pixels
MAX_FIGURE_PX = 2400
#: parameters per page of the parameter bars (each page stays readable)
PARAMETERS_PER_PAGE = 36
#: parameters up to which the correlation is drawn as a matrix; beyond, the
#: strongest pairs as bars (a 130 x 130 matrix has unreadable labels)
CORRELATION_MATRIX_MAX = 40
#: pairs the bar form of the correlation shows
CORRELATION_PAIRS = 30


def save_capped(fig, path: str, dpi: float) -> str:
    """Save ``fig`` at ``dpi``, lowered where needed so that neither side
    exceeds :data:`MAX_FIGURE_PX` pixels."""
    w, h = fig.get_size_inches()
    return save_figure(fig, path, dpi=min(dpi, MAX_FIGURE_PX / max(w, h, 1e-9)))


def parameter_pages(names: Sequence[str], per_page: int = PARAMETERS_PER_PAGE) -> list:
    """``names`` in pages of at most ``per_page`` for :func:`plot_parameters`,
    grouped by display unit first so that a unit's panel is split only when it
    alone exceeds a page."""
    by_unit: dict = {}
    for n in names:
        by_unit.setdefault(display_scale(n)[1], []).append(n)
    pages, page = [], []
    for ns in by_unit.values():
        for k in range(0, len(ns), per_page):
            chunk = ns[k:k + per_page]
            if page and len(page) + len(chunk) > per_page:
                pages.append(page)
                page = []
            page += chunk
    return pages + ([page] if page else [])


def plot_parameters(result, path: str, names=None, truth: Optional[Mapping[str, float]] = None,
                    title: str = "Identified parameters (±2σ)") -> str:
    """Write :func:`parameters_figure` as a PNG; returns the path."""
    save_capped(parameters_figure(result, names, truth, title), path, 120)
    return path


def parameters_figure(result, names=None, truth: Optional[Mapping[str, float]] = None,
                      title: str = "Identified parameters (±2σ)"):
    """Horizontal bars of the identified values in report units with ±2σ error
    bars, one panel per unit (at most three side by side, further units on
    more rows), and the true values when known. At most
    :data:`MAX_FIGURE_PX` pixels a side: give many parameters in pages
    (:func:`parameter_pages`)."""
    plt = _pyplot()
    names = [n for n in (names or result.estimated) if n in result.std]
    groups = {}
    for n in names:
        groups.setdefault(display_scale(n)[1], []).append(n)
    items = list(groups.items()) or [("", [])]
    ncols = min(3, len(items))
    nrows = -(-len(items) // ncols)
    heights = [max(len(ns) for _, ns in items[r * ncols:(r + 1) * ncols]) for r in range(nrows)]
    fig = plt.figure(figsize=(4.6 * ncols + 0.4, sum(0.3 * h + 1.1 for h in heights) + 0.7), layout="constrained")
    grid = fig.add_gridspec(nrows, ncols, height_ratios=[0.3 * h + 1.1 for h in heights])
    axes = [fig.add_subplot(grid[k // ncols, k % ncols]) for k in range(len(items))]
    for ax, (unit, ns) in zip(axes, items):
        f = np.array([display_scale(n)[0] for n in ns])
        v = np.array([result.values[n] for n in ns]) * f
        s = np.array([result.std[n] for n in ns]) * f
        y = np.arange(len(ns))
        ax.barh(y, v, xerr=2 * s, color="#4c78a8", ecolor="#222", capsize=3, label="estimate")
        if truth is not None:
            t = np.array([truth.get(n, 0.0) for n in ns]) * f
            ax.scatter(t, y, marker="|", s=300, color="#e45756", zorder=3, label="true")
        ax.set_yticks(y, ns)
        ax.set_ylim(len(ns) - 0.5, -0.5)
        ax.axvline(0, color="#888", lw=0.8)
        ax.set_xlabel(unit)
        ax.grid(axis="x", alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(title)
    return fig


def _nice_floor(x: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above x."""
    if not np.isfinite(x) or x <= 0:
        return 1.0
    e = 10.0 ** np.floor(np.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * e <= x * (1 + 1e-12):
            return float(m * e)
    return float(e)


#: Beyond this many groups (indexations, setups) a plot shows a colour bar, not a legend.
MAX_LEGEND = 12

#: Observation types of touch probing (the residual-vector figure's data): the
#: registry's probe-touch kinds.
PROBING = tuple(k["name"] for k in _core.observation_kinds() if k["probe_touch"])


def indexation_labels(dataset, rows=None) -> tuple:
    """Per observation (or per observation in ``rows``), the rotary
    indexation it was taken at (a tuple of degrees over the machine's rotary
    axes, spindle included), and the axis letters."""
    rot = [a for a in dataset.machine.axis_names if a in "ABCS"]
    obs = dataset.observations
    rows = range(len(obs)) if rows is None else rows
    keys = [tuple(round(float(obs[i]["axes"].get(a, 0.0)), 1) for a in rot) for i in rows]
    return keys, rot


def group_colors(n: int):
    """``n`` colours for groups: distinct categorical colours up to
    :data:`MAX_LEGEND` (a legend names them), a sequential colour map beyond
    (a colour bar orders them)."""
    import matplotlib

    if n <= MAX_LEGEND:
        # tab10 and two more dark ones (Paired's pale yellow vanished on white)
        extra = [matplotlib.colors.to_rgba(c) for c in ("#222222", "#a6761d")]
        return (list(matplotlib.colormaps["tab10"](np.arange(10))) + extra)[:n]
    return list(matplotlib.colormaps["viridis"](np.linspace(0.0, 0.95, n)))


def add_group_key(fig, axes, labels, colors, title: str, legend_ax=None):
    """A legend of the groups when there are at most :data:`MAX_LEGEND`,
    else a colour bar with (at most 12) ticks labelled by group: never
    hundreds of legend entries. ``axes``: the axes the key belongs to;
    ``legend_ax``: an empty axes to hold the legend (default: the figure)."""
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.cm import ScalarMappable
    from matplotlib.lines import Line2D

    n = len(labels)
    if n == 0:
        return None
    if n <= MAX_LEGEND:
        handles = [Line2D([0], [0], color=c, lw=2.5) for c in colors]
        where = legend_ax if legend_ax is not None else fig
        kw = dict(loc="upper left", fontsize=8, title=title, title_fontsize=9, frameon=False, handlelength=1.4)
        if legend_ax is None:
            kw.update(loc="outside right upper") if fig.get_layout_engine() is not None else \
                kw.update(loc="upper right")
        return where.legend(handles, list(labels), **kw)
    sm = ScalarMappable(norm=BoundaryNorm(np.arange(n + 1) - 0.5, n), cmap=ListedColormap(colors))
    if legend_ax is not None:
        legend_ax.axis("off")
        cax = legend_ax.inset_axes([0.05, 0.02, 0.12, 0.96])
        cb = fig.colorbar(sm, cax=cax)
    else:
        cb = fig.colorbar(sm, ax=axes, fraction=0.025, pad=0.015)
    # every group named while the labels fit beside the bar, else 12 of them
    ticks = np.arange(n) if n <= 24 else np.unique(np.round(np.linspace(0, n - 1, 12)).astype(int))
    cb.set_ticks(ticks)
    cb.set_ticklabels([labels[i] for i in ticks], fontsize=7)
    cb.ax.minorticks_off()
    cb.set_label(f"{title} ({n} groups)", fontsize=9)
    return cb


def _indexation_colors(plt, keys):
    uniq = list(dict.fromkeys(keys))
    palette = group_colors(len(uniq))
    index = {k: i for i, k in enumerate(uniq)}
    return uniq, palette, np.array([palette[index[k]] for k in keys]) if keys else np.zeros((0, 4))


def _limits(ax, xs, ys, margin: float = 0.06, equal: bool = False) -> None:
    """Axes limits from the data (every point inside, with a margin)."""
    xs, ys = np.asarray(xs, float).ravel(), np.asarray(ys, float).ravel()
    xs, ys = xs[np.isfinite(xs)], ys[np.isfinite(ys)]
    if not xs.size or not ys.size:
        return
    (x0, x1), (y0, y1) = (xs.min(), xs.max()), (ys.min(), ys.max())
    if equal:
        half = 0.5 * max(x1 - x0, y1 - y0, 1e-9) * (1 + 2 * margin)
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        ax.set_xlim(cx - half, cx + half)
        ax.set_ylim(cy - half, cy + half)
        return
    dx = (x1 - x0) * margin or max(abs(x0) * 0.05, 1e-9)
    dy = (y1 - y0) * margin or max(abs(y0) * 0.05, 1e-9)
    ax.set_xlim(x0 - dx, x1 + dx)
    ax.set_ylim(y0 - dy, y1 + dy)


def residual_vectors_figure(result, magnification: Optional[float] = None,
                            title: str = "Unexplained residual vectors", legend: bool = True,
                            kinds: Optional[Sequence[str]] = None):
    """The Figure of :func:`plot_residual_vectors` (not saved).

    ``kinds``: observation types drawn (default: the touch-probing ones,
    facet, sphere and cylinder, when the data has any, else every observation)."""
    plt = _pyplot()
    ds = result.dataset
    types = list(ds.observation_types)
    if kinds is None:
        kinds = PROBING if any(t in PROBING for t in types) else tuple(set(types))
    obs_rows = np.array([i for i, t in enumerate(types) if t in kinds], dtype=int)
    if obs_rows.size == 0:
        raise ValueError(f"residual vectors: no observations of type {', '.join(kinds)}")
    P = np.asarray(result.points)[obs_rows]
    V = np.asarray(result.residual_vectors)[obs_rows]
    keys, rot = indexation_labels(ds, obs_rows)
    uniq, palette, colors = _indexation_colors(plt, keys)
    span = float(np.ptp(P, axis=0).max()) or 1.0
    norms = np.linalg.norm(V, axis=1)
    vmax = float(norms.max()) if norms.size else 0.0
    vmax = vmax or 1e-9
    mag = magnification or _nice_floor(0.12 * span / vmax)
    W = V * mag
    T = P + W

    fig = plt.figure(figsize=(13.5, 7.6))
    gs = fig.add_gridspec(2, 3, width_ratios=[1.45, 1, 0.34], height_ratios=[1.3, 1], wspace=0.22,
                          hspace=0.32, left=0.01, right=0.97, top=0.88, bottom=0.07)
    ax3 = fig.add_subplot(gs[:, 0], projection="3d")
    ax3.scatter(P[:, 0], P[:, 1], P[:, 2], s=3, color="#aaa", depthshade=False)
    ax3.quiver(P[:, 0], P[:, 1], P[:, 2], W[:, 0], W[:, 1], W[:, 2], colors=colors,
               arrow_length_ratio=0.25, linewidth=1.6, normalize=False)
    # 3D axes do not clip: the limits hold every arrow (tail and tip)
    lo, hi = np.minimum(P.min(axis=0), T.min(axis=0)), np.maximum(P.max(axis=0), T.max(axis=0))
    pad = 0.05 * np.maximum(hi - lo, 0.05 * span)
    ax3.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
    ax3.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
    ax3.set_zlim(lo[2] - pad[2], hi[2] + pad[2])
    ax3.set_xlabel("x (mm)")
    ax3.set_ylabel("y (mm)")
    ax3.set_title("3D view (table frame; z up, mm)", fontsize=12)
    ax3.view_init(elev=28, azim=-60)
    try:
        ax3.set_box_aspect(tuple(np.maximum(hi - lo + 2 * pad, 0.45 * span)))
    except (AttributeError, TypeError):
        pass

    def flat(ax, i, j, label_i, label_j, name, strip=0.0):
        ax.scatter(P[:, i], P[:, j], s=4, color="#aaa", zorder=1)
        ax.quiver(P[:, i], P[:, j], W[:, i], W[:, j], color=colors, angles="xy", scale_units="xy",
                  scale=1.0, width=0.004, headwidth=3.5, headlength=4, zorder=2)
        _limits(ax, np.r_[P[:, i], T[:, i]], np.r_[P[:, j], T[:, j]])
        if strip:  # an empty strip at the bottom for the scale arrow
            y0, y1 = ax.get_ylim()
            ax.set_ylim(y0 - strip * (y1 - y0), y1)
        # equal scales by shaping the box: the limits (hence what is inside) stay as set
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel(f"{label_i} (mm)")
        ax.set_ylabel(f"{label_j} (mm)")
        ax.set_title(name, fontsize=11)
        ax.grid(alpha=0.3)

    axp = fig.add_subplot(gs[0, 1])
    flat(axp, 0, 1, "x", "y", "plan view (x-y components)", strip=0.14)
    axe = fig.add_subplot(gs[1, 1])
    flat(axe, 0, 2, "x", "z", "elevation (x-z components)")
    # scale arrow: a round residual length at the same magnification
    ref_um = _nice_floor(vmax * 1e3)
    x0, x1 = axp.get_xlim()
    y0, y1 = axp.get_ylim()
    axp.annotate("", xy=(x0 + 0.05 * (x1 - x0) + ref_um * 1e-3 * mag, y0 + 0.04 * (y1 - y0)),
                 xytext=(x0 + 0.05 * (x1 - x0), y0 + 0.04 * (y1 - y0)),
                 arrowprops=dict(arrowstyle="->", color="k", lw=1.5))
    axp.text(x0 + 0.07 * (x1 - x0) + ref_um * 1e-3 * mag, y0 + 0.04 * (y1 - y0), f"{ref_um:g} µm (scale)",
             fontsize=9, va="center")

    if legend:
        axl = fig.add_subplot(gs[:, 2])
        axl.axis("off")
        labels = ["(" + ", ".join(f"{v:g}" for v in k) + ")" for k in uniq]
        add_group_key(fig, [ax3, axp, axe], labels, palette,
                      f"{', '.join(rot)} (deg)" + (", in measurement order" if len(uniq) > MAX_LEGEND else ""),
                      legend_ax=axl)
    res = np.asarray(result.residuals)
    src = np.asarray(result.residual_source)
    mine = res[np.isin(src, obs_rows)] if src.shape == res.shape else res
    rms = float(np.sqrt(np.mean(np.square(mine)))) if mine.size else 0.0
    what = "touches" if set(kinds) <= set(PROBING) else ", ".join(sorted(set(kinds)))
    fig.suptitle(f"{title}\nmagnified {mag:g}x; {len(obs_rows)} {what}, residual rms {rms * 1e3:.2f} µm, "
                 f"largest vector {vmax * 1e3:.2f} µm; colour = indexation", fontsize=12)
    return fig


def plot_residual_vectors(result, path: str, magnification: Optional[float] = None,
                          title: str = "Unexplained residual vectors", legend: bool = True,
                          kinds: Optional[Sequence[str]] = None) -> str:
    """Residual vectors (mm) drawn at the touch points in the table
    (workpiece) frame, magnified, coloured by rotary indexation (thesis
    Figure 4-7 style): a 3D view plus a plan (x-y) and an elevation (x-z) view
    with a scale arrow. ``magnification`` defaults to the largest 1-2-5 step
    that keeps the largest vector within 12 % of the artefact size (10000x or
    20000x for micrometre residuals on a 400 mm table). Up to 12 indexations
    get a legend, more a colour bar. Only touch-probing observations are
    drawn when there are any (``kinds`` chooses others)."""
    fig = residual_vectors_figure(result, magnification, title, legend, kinds)
    save_capped(fig, path, 110)
    return path


# ---- R-test / 3D ball and fixed-frame point data -------------------------------------------------
# The kinds whose first three residual rows are a 3D deviation (the registry's
# report pieces): the key that names their setup or instrument, what the
# figure calls them, and the frame those components are in.
_COMPONENTS = {k["name"]: k["report"] for k in _core.observation_kinds() if k["report"]["components"]}
COMPONENT_KINDS = {n: (r["setup_key"], r["component_label"], r["component_frame"]) for n, r in _COMPONENTS.items()}


def _component_kind(dataset, kind: Optional[str]) -> str:
    """``kind``, or the first component kind the dataset holds (the first registered without any)."""
    if kind is not None:
        return kind
    types = set(dataset.observation_types)
    return next((n for n in COMPONENT_KINDS if n in types), next(iter(COMPONENT_KINDS)))


def _natural(label: str) -> tuple:
    """Sort key that orders "B -30°" before "B 5°" and "B 5°" before "B 45°"."""
    import re

    out = []
    for part in re.split(r"(-?\d+(?:\.\d+)?)", label):
        try:
            out.append((0, float(part), ""))
        except ValueError:
            out.append((1, 0.0, part))
    return tuple(out)


def _setup_groups(dataset, rows, who: str, sides: bool) -> tuple:
    """For the observations ``rows`` of one setup: the rotary axis on the
    horizontal axis (the one taking the most distinct positions), its angles,
    and each observation's group label (target side, and the positions of
    another moving rotary axis when it steps through a few values, as
    indexations, each holding several samples; an axis that moves along with
    the key, K4-like, is part of the path, not a group)."""
    obs = dataset.observations
    rot = [a for a in dataset.machine.axis_names if a in "ABC"]
    pos = {a: np.array([float(obs[i]["axes"].get(a, 0.0)) for i in rows]) for a in rot}
    moving = [a for a in rot if rows and np.ptp(pos[a]) > 1e-9]
    key = max(moving, key=lambda a: (len(np.unique(np.round(pos[a], 3))), np.ptp(pos[a]))) if moving else None
    angles = pos[key] if key else np.arange(len(rows), dtype=float)
    # indexations: values that repeat (three samples or more per value on average)
    steps = [a for a in moving if a != key and 3 * len(np.unique(np.round(pos[a], 3))) <= len(rows)]
    labels = []
    for n, i in enumerate(rows):
        parts = [f"{obs[i]['target']} target"] if sides else []
        # rounded as the groups are: an inverse's 1e-14° is 0°, and one group
        parts += [f"{a} {round(float(pos[a][n]), 3) + 0.0:g}°" for a in steps]
        labels.append(", ".join(parts))
    return key, angles, labels


def component_groups(dataset, kind: Optional[str] = None) -> tuple:
    """How the 3D observations of ``kind`` (one of :data:`COMPONENT_KINDS`;
    None: the first the dataset holds) are plotted: per setup or instrument,
    ``(name, rows, angle axis or None, angles, group labels)`` (see
    :func:`_setup_groups`)."""
    kind = _component_kind(dataset, kind)
    who = COMPONENT_KINDS[kind][0]
    obs = dataset.observations
    rows = [i for i, o in enumerate(obs) if o.get("type") == kind]
    by = {}
    for i in rows:
        by.setdefault(obs[i].get(who, "") or f"(no {who})", []).append(i)
    out = []
    for name, rs in by.items():
        sides = who == "instrument" and len({obs[i].get("target", "") for i in rs}) > 1
        key, angles, labels = _setup_groups(dataset, rs, who, sides)
        out.append((name, rs, key, angles, labels))
    return out


def _first_rows(res, src, rows, k: int = 3) -> np.ndarray:
    """The first ``k`` residual rows of each observation in ``rows`` (NaN
    where it has fewer), in one pass over the rows (a scan of every row per
    observation is quadratic: 3 x 10^10 comparisons for 10^5 R-test samples)."""
    src, res = np.asarray(src), np.asarray(res)
    out = np.full((len(rows), k), np.nan)
    if not src.size:
        return out
    firsts = np.flatnonzero(np.r_[True, src[1:] != src[:-1]])  # an observation's rows are consecutive
    counts = np.diff(np.r_[firsts, src.size])
    where = dict(zip(src[firsts].tolist(), zip(firsts.tolist(), counts.tolist())))
    for n, i in enumerate(rows):
        first, count = where.get(int(i), (0, 0))
        if count >= k:
            out[n] = res[first:first + k]
    return out


def _recorded_deviation(result, kind: str, rows) -> np.ndarray:
    """What the instrument saw beyond the nominal machine, µm. An R-test
    records deviations itself. A tracker records absolute positions in its own
    frame, so its deviation is taken against the nominal machine seen through
    the fitted instrument pose and target (every setup value of the fit, no
    machine error): the machine's error signature, not the tracker's placement."""
    obs = result.dataset.observations
    field = _COMPONENTS[kind]["recorded_deviation"]
    if field:
        return np.array([obs[i][field] for i in rows], float) * 1e3
    machine = set(result.dataset.machine.parameter_names())
    setup = {k: v for k, v in result.values.items() if k not in machine}
    res, src = _core.predict_residuals(result.dataset._core, setup)
    return -_first_rows(res, src, rows) * 1e3


def component_figure(result, kind: Optional[str] = None, title: Optional[str] = None):
    """Per-component deviation of the 3D observations of ``kind`` against the
    rotary angle: for each setup (instrument) a row of what was recorded (for
    a tracker, against the nominal machine) and a row of the residual the fit
    leaves, one panel per component, each setup against its own moving axis;
    one line per indexation group (legend up to 12 groups, colour bar
    beyond). None without such data."""
    plt = _pyplot()
    ds = result.dataset
    kind = _component_kind(ds, kind)
    setups = component_groups(ds, kind)
    if not setups:
        return None
    who, what_kind, frame = COMPONENT_KINDS[kind]
    title = title or f"{what_kind}: deviation per component"
    all_rows = [i for _, rs, *_ in setups for i in rs]
    rec_all = dict(zip(all_rows, _recorded_deviation(result, kind, all_rows)))
    comps = _COMPONENTS[kind]["components"]
    top = "recorded" if _COMPONENTS[kind]["recorded_deviation"] else "recorded − nominal machine"
    labels_all = sorted({l for *_, labels in setups for l in labels if l}, key=_natural)
    colors = group_colors(max(len(labels_all), 1))
    n = len(setups)
    fig, axes = plt.subplots(2 * n, 3, figsize=(14.5, 1.4 + 3.1 * n), squeeze=False, layout="constrained")
    for s_i, (name, rows, key, angles, labels) in enumerate(setups):
        rec = np.array([rec_all[i] for i in rows])
        left = _first_rows(result.residuals, result.residual_source, rows) * 1e3
        groups = list(dict.fromkeys(labels))
        for row, (data, what) in enumerate(((rec, top), (left, "residual after the fit"))):
            for c, comp in enumerate(comps):
                ax = axes[2 * s_i + row][c]
                for g in groups:
                    sel = np.flatnonzero(np.array(labels) == g)
                    # a line only where the group was recorded as a sweep of
                    # the angle (monotonic in recording order): scattered
                    # poses joined by a line would read as a trend
                    steps = np.diff(angles[sel])
                    sweep = len(np.unique(np.round(angles[sel], 6))) >= 3 and \
                        ((steps >= -1e-9).all() or (steps <= 1e-9).all())
                    sel = sel[np.argsort(angles[sel], kind="stable")]
                    color = colors[labels_all.index(g)] if g else "#1f4e9a"
                    style = "-o" if sweep else "o"
                    ax.plot(angles[sel], data[sel, c], style, ms=2.5 if style == "-o" else 3.5, lw=1.1,
                            color=color)
                _limits(ax, angles, data[:, c], margin=0.05)
                ax.axhline(0, color="#888", lw=0.7)
                ax.set_title(f"{name}: {comp} {what}" if n > 1 else f"{comp} {what}", fontsize=10)
                ax.grid(alpha=0.3)
                if c == 0:
                    ax.set_ylabel("deviation (µm)")
                if row == 1 or n > 1:
                    ax.set_xlabel(f"{key} axis command (deg)" if key else "sample", fontsize=9)
    if labels_all:
        add_group_key(fig, axes.ravel().tolist(), labels_all, colors, "group")
    names = [name for name, *_ in setups]
    plural = "s" if n != 1 else ""
    samples = sum(len(rs) for _, rs, *_ in setups)
    fig.suptitle(f"{title}: {samples} samples, {n} {who}{plural} ({', '.join(names)}); "
                 f"components in the {frame}", fontsize=12)
    return fig


def plot_components(result, path: str, kind: Optional[str] = None, title: Optional[str] = None) -> Optional[str]:
    """Write :func:`component_figure` as a PNG; returns the path (None without such data)."""
    fig = component_figure(result, kind, title)
    if fig is None:
        return None
    save_capped(fig, path, 110)
    return path


def plot_residual_histogram(result, path: str) -> str:
    """Write :func:`residual_histogram_figure` as a PNG; returns the path."""
    save_capped(residual_histogram_figure(result), path, 120)
    return path


def residual_histogram_figure(result):
    """Histogram of the residuals of the mm rows (µm) with the normal density
    of their a-posteriori sigma (a pose's rotation rows, in rad, are left
    out: in µm they would pile up at 0)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.5))
    r = np.asarray(result.residuals) * 1e3
    units = result.row_units() if hasattr(result, "row_units") else None
    of = ""
    if units is not None and units.size == r.size and (units != "mm").any():
        r, of = r[units == "mm"], " (mm rows)"
    counts, edges, _ = ax.hist(r, bins=max(10, int(np.sqrt(r.size))), color="#4c78a8", label="residuals")
    sig = result.sigma * 1e3
    if sig > 0 and r.size:
        x = np.linspace(min(edges[0], -4 * sig), max(edges[-1], 4 * sig), 200)
        ax.plot(x, r.size * (edges[1] - edges[0]) * np.exp(-0.5 * (x / sig) ** 2) / (sig * np.sqrt(2 * np.pi)),
                color="#e45756", lw=1.5, label="normal, σ̂")
        ax.legend(fontsize=8)
    ax.set_xlabel("residual (µm)")
    ax.set_ylabel("count")
    ax.set_title(f"Residuals{of}: rms {result.rms * 1e3:.3f} µm, σ̂ {result.sigma * 1e3:.3f} µm")
    fig.tight_layout()
    return fig


def plot_correlation(result, path: str, names=None, title: str = "Parameter correlation") -> str:
    """The correlation of the estimated parameters (or of ``names``, a subset
    of them). Up to :data:`CORRELATION_MATRIX_MAX` parameters, the matrix as a
    colour map from -1 (blue) to +1 (red), every pair marked with its value up
    to 12 parameters and pairs beyond ±0.9 up to 30; beyond, the :data:`CORRELATION_PAIRS` pairs of
    largest |r| as bars (a matrix of a hundred names has unreadable labels)."""
    plt = _pyplot()
    est = list(result.estimated)
    names = [n for n in (names or est) if n in est]
    idx = [est.index(n) for n in names]
    C = np.nan_to_num(np.asarray(result.correlation)[np.ix_(idx, idx)]) if idx else np.zeros((0, 0))
    n = len(names)
    if n > CORRELATION_MATRIX_MAX:
        ii, jj = np.triu_indices(n, 1)
        top = np.argsort(-np.abs(C[ii, jj]), kind="stable")[:CORRELATION_PAIRS]
        r = C[ii[top], jj[top]]
        labels = [f"{names[i]} / {names[j]}" for i, j in zip(ii[top], jj[top])]
        fig, ax = plt.subplots(figsize=(9.0, 0.3 * len(top) + 1.6), layout="constrained")
        y = np.arange(len(top))
        ax.barh(y, r, color=np.where(r >= 0, "#d6604d", "#4393c3"))
        ax.set_yticks(y, labels, fontsize=8)
        ax.set_ylim(len(top) - 0.5, -0.5)
        ax.set_xlim(-1.05, 1.05)
        ax.axvline(0, color="#888", lw=0.8)
        ax.set_xlabel("correlation coefficient r")
        ax.grid(axis="x", alpha=0.3)
        ax.set_title(f"{title}: the {len(top)} pairs of largest |r| among {n} parameters", fontsize=11)
        save_capped(fig, path, 110)
        plt.close(fig)
        return path
    size = min(13.0, max(5.0, 0.22 * n + 2.5))
    fig, ax = plt.subplots(figsize=(size + 1.2, size))
    im = ax.imshow(C, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
    fs = 9 if n <= 25 else 7
    ax.set_xticks(np.arange(n), names, rotation=90, fontsize=fs)
    ax.set_yticks(np.arange(n), names, fontsize=fs)
    for i in range(n):
        for j in range(n):
            if i != j and (n <= 12 or (n <= 30 and abs(C[i, j]) >= 0.9)):
                ax.text(j, i, f"{C[i, j]:.2f}", ha="center", va="center", fontsize=max(fs - 2, 4),
                        color="w" if abs(C[i, j]) >= 0.6 else "k")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03, label="correlation coefficient")
    ax.set_title(title)
    fig.tight_layout()
    save_capped(fig, path, 110)
    plt.close(fig)
    return path


def axes_figure(dataset, title: Optional[str] = None):
    """Each axis' command (mm, degrees) at every observation of a dataset,
    one panel per axis, one colour per observation kind: where the test
    moved the machine."""
    plt = _pyplot()
    names = list(dataset.machine.axis_names)
    types = list(dataset.observation_types)
    kinds = list(dict.fromkeys(types))
    Q = np.asarray(dataset._core.columns()["axes"], float)  # machine axis order, no dict per observation
    rotary = {a["name"] for a in dataset.machine.axes if a["type"] == "rotary"}
    ncols = min(3, max(1, len(names)))
    nrows = -(-len(names) // ncols)
    fig, axes = plt.subplots(nrows, ncols, squeeze=False, figsize=(4.2 * ncols, 2.6 * nrows + 0.6),
                             layout="constrained")
    colors = group_colors(len(kinds))
    index = np.arange(len(types))
    T = np.asarray(types)
    for k, a in enumerate(names):
        ax = axes[k // ncols][k % ncols]
        q = Q[:, k]
        for kind, c in zip(kinds, colors):
            sel = T == kind
            ax.plot(index[sel], q[sel], ".", ms=3, color=c, label=kind)
        unit = "deg" if a in rotary else "mm"
        ax.set_title(f"{a} ({unit})", fontsize=10)
        ax.set_xlabel("observation")
        ax.grid(alpha=0.3)
    for k in range(len(names), nrows * ncols):
        axes[k // ncols][k % ncols].set_visible(False)
    if kinds:
        axes[0][0].legend(fontsize=8, markerscale=3)
    fig.suptitle(title or f"Axis commands of {len(types)} observations on {dataset.machine.name}")
    return fig


def machine_figure(machine, title: Optional[str] = None):
    """The machine at its zero pose, in the machine frame F, in three views
    (x-y, x-z, y-z): each rotary axis as a solid line through its point along
    its direction, each linear axis as a dashed arrow from the origin along
    its positive direction, the tool tip as a red dot."""
    plt = _pyplot()
    fig, axs = plt.subplots(1, 3, figsize=(13, 4.6), layout="constrained")
    tip = np.asarray(machine.tip, float)
    pts = [np.zeros(3), tip] + [np.asarray(a.get("point", [0, 0, 0]), float) for a in machine.axes]
    span = max(float(np.ptp(np.array(pts), axis=0).max()), 100.0)
    colors = group_colors(len(machine.axes))
    planes = ((0, 1), (0, 2), (1, 2))
    for k, (a, c) in enumerate(zip(machine.axes, colors)):
        d = np.asarray(a["direction"], float)
        # axes along one line (C, Z and the spindle on a vertical machine)
        # get different lengths so each name stays readable at its end
        size = span * (0.35 + 0.08 * k)
        if a["type"] == "rotary":
            p = np.asarray(a.get("point", [0, 0, 0]), float)
            seg, style, label = np.array([p - size * d, p + size * d]), "-", f"{a['name']}: rotary axis line"
        else:
            seg, style, label = np.array([np.zeros(3), size * d]), "--", f"{a['name']}: linear, + direction"
        for n, (ax, (i, j)) in enumerate(zip(axs, planes)):
            ax.plot(seg[:, i], seg[:, j], style, color=c, lw=2, label=label if n == 0 else None)
            if np.hypot(*(seg[1, [i, j]] - seg[0, [i, j]])) > 1e-9:  # not seen end-on
                ax.annotate(a["name"], seg[1, [i, j]], color=c, fontsize=10, fontweight="bold",
                            xytext=(3, 3), textcoords="offset points")
            else:
                ax.plot(*seg[1, [i, j]], "o", mfc="none", color=c, ms=6 + 3 * k)
    for ax, (i, j) in zip(axs, planes):
        ax.plot(tip[i], tip[j], "o", color="#d62728", ms=6, label="tool tip" if ax is axs[0] else None)
        ax.set_xlabel(f"{'xyz'[i]} (mm)")
        ax.set_ylabel(f"{'xyz'[j]} (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{'xyz'[i]}-{'xyz'[j]} view", fontsize=10)
        ax.grid(alpha=0.3)
    fig.legend(loc="outside right center", fontsize=8)
    fig.suptitle(title or f"{machine.name} ({machine.topology}) at its zero pose, machine frame F "
                 "(an axis seen end-on: a circle)")
    return fig
