"""Statistics of repeated probing (thesis §4.6 eqs. 4-9 to 4-16, ch. 7 eq.
7-1): total variability, repeatability (pooled over windows), surface and
drift, per probing direction, as in Tables 4-3, 7-1, 7-2, 7-4 and 7-5.

The computations are in C++ (``cpp/include/fivecal/procedures/probing_stats.h``); this
module converts arrays and formats the tables::

    from fivecal.procedures import probing_stats
    # P[i, j]: grid point i, cycle j (mm along the approach), per direction
    stats = probing_stats.grid_table({"X": Px, "Y": Py, "Z": Pz}, window=5)
    print(probing_stats.format_table(stats))
    probing_stats.pooled_std(series_300, window=25)   # eq. 7-1, Table 7-2

Units: mm in and out; the tables print µm.
"""
from __future__ import annotations

import json
from typing import Dict, Mapping, Sequence

import numpy as np

from .. import _core

__all__ = ["GridStatistics", "grid_statistics", "grid_table", "format_table", "pooled_std",
           "pooled_std_groups"]


class GridStatistics:
    """Variability of a probed grid (n points x m cycles) in one direction.

    ``total_std`` s_T (4-9) and ``total_range``; ``point_pooled_std`` (4-11,
    4-12, windows of ``window`` cycles), its maximum ``max_pooled_std`` (Table
    4-3) and the pool over all points ``pooled_std``; ``surface_std`` S_k and
    ``surface_range`` of the point means (4-13..4-15); ``drift_std`` and
    ``drift_range`` of the cycle means (4-16); ``point_std`` and
    ``point_std_pooled`` (Table 7-5); the variance components
    ``repeatability``, ``surface_component``, ``drift_component`` of the
    additive model P_ij = mu + s_i + d_j + e_ij (two-way ANOVA)."""

    def __init__(self, core: "_core.GridStatistics"):
        self._core = core
        for k in ("points", "cycles", "window", "mean", "total_std", "total_range", "max_pooled_std",
                  "pooled_std", "pooled_dof", "surface_std", "surface_range", "drift_std", "drift_range",
                  "point_std_pooled", "repeatability", "surface_component", "drift_component"):
            setattr(self, k, getattr(core, k))
        self.point_pooled_std = np.asarray(core.point_pooled_std)
        self.point_means = np.asarray(core.point_means)
        self.cycle_means = np.asarray(core.cycle_means)
        self.point_std = np.asarray(core.point_std)

    def to_dict(self) -> dict:
        return json.loads(self._core.to_json())

    def __repr__(self) -> str:
        return (f"GridStatistics({self.points} points x {self.cycles} cycles: total {self.total_std * 1e3:.3f} µm, "
                f"repeatability {self.repeatability * 1e3:.3f} µm, surface {self.surface_component * 1e3:.3f} µm, "
                f"drift {self.drift_component * 1e3:.3f} µm)")


def grid_statistics(P, window: int = 5) -> GridStatistics:
    """Statistics of one direction's grid data ``P`` (n points x m cycles, mm,
    cycles in time order); ``window``: cycles per repeatability window
    (thesis: 5 of 25)."""
    P = np.asarray(P, float)
    if P.ndim != 2:
        raise ValueError("probing grid: expected a 2-D array (points x cycles)")
    return GridStatistics(_core.analyze_grid(P, int(window)))


def grid_table(directions: Mapping[str, object], window: int = 5) -> Dict[str, GridStatistics]:
    """:func:`grid_statistics` for each direction (``{"X": P, "Y": P, ...}``)."""
    return {k: grid_statistics(v, window) for k, v in directions.items()}


_ROWS = [
    ("Total variability (4-9): s_T", "total_std"),
    ("Total range", "total_range"),
    ("Repeatability: max pooled s over points (4-12)", "max_pooled_std"),
    ("Repeatability: pooled s over all points", "pooled_std"),
    ("Surface: s of the point means S_k (4-14)", "surface_std"),
    ("Surface: range of the point means", "surface_range"),
    ("Drift: s of the cycle means (4-16)", "drift_std"),
    ("Drift: range of the cycle means", "drift_range"),
    ("Component: repeatability sigma_e", "repeatability"),
    ("Component: surface sigma_s", "surface_component"),
    ("Component: drift sigma_d", "drift_component"),
]


def format_table(stats: Mapping[str, GridStatistics]) -> str:
    """Table 4-3 style text (µm), one column per direction."""
    keys = list(stats)
    w = max(len(r[0]) for r in _ROWS) + 2
    lines = [f"{'(µm)':<{w}}" + "".join(f"{k:>9}" for k in keys)]
    for label, attr in _ROWS:
        lines.append(f"{label:<{w}}" + "".join(f"{getattr(stats[k], attr) * 1e3:>9.3f}" for k in keys))
    return "\n".join(lines)


def pooled_std(series, window: int = 25):
    """Eq. 7-1 on a time series of repeated touches cut into consecutive
    windows of ``window`` (thesis: 12 windows of 25 of 300): returns
    ``(pooled_std, dof)`` in the unit of ``series``."""
    r = _core.window_pooled_std(np.asarray(series, float).ravel(), int(window))
    return r.pooled_std, r.dof


def pooled_std_groups(groups: Sequence[Sequence[float]]):
    """Eq. 7-1 over explicit groups: ``(pooled_std, dof)``."""
    r = _core.pooled_std([list(map(float, g)) for g in groups])
    return r.pooled_std, r.dof
