"""Plots: parameter bars with uncertainty, residual vectors in the table frame."""
from __future__ import annotations

from typing import Mapping, Optional

import numpy as np

from .units import display_scale


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


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
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_residual_vectors(result, path: str, magnification: Optional[float] = None,
                          title: str = "Unexplained residual vectors") -> str:
    """Residual vectors drawn at the touch points in the table (workpiece)
    frame, magnified, coloured by rotary indexation (thesis Figure 4-7 style)."""
    plt = _pyplot()
    P = result.points
    V = result.residual_vectors
    ds = result.dataset
    rot = [a for a in ds.machine.axis_names if a in "ABCS"]
    obs = ds.observations
    keys = [tuple(round(o["axes"].get(a, 0.0), 1) for a in rot) for o in obs]
    uniq = {k: i for i, k in enumerate(dict.fromkeys(keys))}
    colors = plt.get_cmap("tab20")(np.array([uniq[k] % 20 for k in keys]))
    span = np.ptp(P, axis=0).max() or 1.0
    vmax = np.linalg.norm(V, axis=1).max() or 1e-9
    mag = magnification or 10 ** np.floor(np.log10(0.08 * span / vmax))
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection="3d")
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], s=4, color="#999")
    ax.quiver(P[:, 0], P[:, 1], P[:, 2], V[:, 0] * mag, V[:, 1] * mag, V[:, 2] * mag, colors=colors,
              arrow_length_ratio=0.15, linewidth=1.2)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title(f"{title}\nmagnified {mag:g}x, rms {result.rms * 1e3:.2f} µm, max "
                 f"{np.linalg.norm(V, axis=1).max() * 1e3:.2f} µm; colour = ({', '.join(rot)}) indexation")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_residual_histogram(result, path: str) -> str:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.5))
    r = result.residuals * 1e3
    ax.hist(r, bins=max(10, int(np.sqrt(r.size))), color="#4c78a8")
    ax.set_xlabel("residual (µm)")
    ax.set_ylabel("count")
    ax.set_title(f"Residuals: rms {result.rms * 1e3:.3f} µm, σ̂ {result.sigma * 1e3:.3f} µm")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
