"""Report and plots for every kind of data (issue 14, item 7).

Datasets of each kind come from fivecal's own simulation on the C600U-like
machine: touch probing of a sphere, double ball bar (the Jiang & Cripps four
steps with 100 and 150 mm bars plus planar circles in XY, YZ and ZX),
R-test / 3D ball (ball3d) at 13 x 18 A/C indexations, and a mix of all
three. The figures are inspected as matplotlib Figure objects (the same
functions the report saves): legends, plane labels, data inside the axes,
the angle convention.
"""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import fivecal
from fivecal.procedures import dbb
from fivecal.report import plots, polar
from fivecal.demo import example_machine_path
from fivecal.report import write_report

TRUE = {"EY0A": 0.020, "EZ0A": -0.015, "EB0A": 30e-6, "EC0A": -25e-6,
        "EX0C": 0.030, "EY0C": -0.012, "EA0C": 40e-6, "EB0C": -20e-6}
ART = {"spheres": [{"id": "S1", "center": [60.0, 40.0, 30.0], "radius": 12.5}]}
SIGMA = {"probe": 0.0005, "dbb": 0.0003, "ball3d": 0.0005}
CONVENTION = "counter-clockwise from +"


@pytest.fixture(scope="module")
def c600u():
    return fivecal.Machine.load(example_machine_path("c600u"))


def sphere_plan(m, a_values=(-60, -30, 0, 30, 60), c_step=30, per=5):
    rng = np.random.default_rng(0)
    plan = []
    for a in a_values:
        for c in range(0, 360, c_step):
            _, ax = m.tool_pose({"X": 0, "Y": 0, "Z": 0, "A": a, "C": c})
            for _ in range(per):
                v = ax[0] + 0.6 * rng.normal(size=3)  # touch the side facing the probe
                plan.append({"type": "sphere", "target": "S1", "axes": {"A": a, "C": c},
                             "normal": (v / np.linalg.norm(v)).tolist()})
    return plan


def dbb_plan(m):
    plan = dbb.four_step_plan(m, step=5.0)  # A1, A2 (YZ), C1, C2 (XY); 100 and 150 mm bars
    for plane in ("XY", "YZ", "ZX"):
        plan += dbb.planar_plan(m, plane, 100.0, step=5.0, setup_prefix=plane)
    return plan


def ball3d_plan(m, setup="M1", ball=(50.0, 0.0, 80.0), a_values=np.arange(-90, 91, 15.0)):
    plan = []
    for a in a_values:
        for c in np.arange(0, 360, 20.0):
            e = {"type": "ball3d", "axes": {"X": 0.0, "Y": 0.0, "Z": 0.0, "A": float(a), "C": float(c)},
                 "tool_ball": [0, 0, 150.0], "table_ball": list(ball), "setup": setup}
            cmd = m.inverse([list(ball)], start=e["axes"])  # nominal commands keep the balls together
            e["axes"] = {k: float(v[0]) for k, v in cmd.items()}
            plan.append(e)
    return plan


def _identify(m, plan):
    ds = fivecal.simulate(m, plan, errors=TRUE, artefact=ART, tip_radius=3.0, sigma=SIGMA, seed=3)
    return fivecal.identify(ds, "location", allow_unidentifiable=True)


@pytest.fixture(scope="module")
def results(c600u):
    m = c600u
    mixed = (sphere_plan(m) + dbb.planar_plan(m, "XY", 100.0, step=10.0)
             + ball3d_plan(m, "R2", (0.0, 60.0, 50.0), (-30.0, 0.0, 30.0)))
    return {"probing": _identify(m, sphere_plan(m)), "dbb": _identify(m, dbb_plan(m)),
            "ball3d": _identify(m, ball3d_plan(m)), "mixed": _identify(m, mixed)}


EXPECTED = {  # PNGs the report must write for each kind, and those it must not
    "probing": ({"residual_vectors.png"}, {"dbb_polar.png", "dbb_residuals.png", "ball3d_components.png"}),
    "dbb": ({"dbb_polar.png", "dbb_residuals.png"}, {"residual_vectors.png", "ball3d_components.png"}),
    "ball3d": ({"ball3d_components.png"}, {"residual_vectors.png", "dbb_polar.png", "dbb_residuals.png"}),
    "mixed": ({"residual_vectors.png", "dbb_polar.png", "dbb_residuals.png", "ball3d_components.png"}, set()),
}
COMMON = {"residual_histogram.png", "parameters.png", "correlation.png"}


def figures_of(result):
    """The kind-specific figures the report draws for this result, by name."""
    kinds = set(result.dataset.observation_types)
    figs = {}
    if kinds & set(plots.PROBING):
        figs["residual_vectors"] = plots.residual_vectors_figure(result, kinds=plots.PROBING)
    if "ball3d" in kinds:
        figs["ball3d_components"] = plots.component_figure(result, "ball3d")
    if "dbb" in kinds:
        figs["dbb_polar"] = polar.dbb_figure(result)
        figs["dbb_residuals"] = polar.dbb_residual_figure(result)
    return figs


# ---- checks on Figure objects ---------------------------------------------------------------------
def all_axes(fig):
    """The figure's axes and their inset axes (a colour bar may sit in one)."""
    out = []
    for ax in fig.axes:
        out += [ax] + list(getattr(ax, "child_axes", []))
    return out


def legend_sizes(fig):
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return [len(lg.get_texts()) for lg in legends]


def _inside(values, lo, hi, what):
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    lo, hi = min(lo, hi), max(lo, hi)
    tol = 1e-9 * max(1.0, abs(lo), abs(hi))
    bad = v[(v < lo - tol) | (v > hi + tol)]
    assert bad.size == 0, f"{what}: {bad.size} values outside [{lo:g}, {hi:g}], e.g. {bad[:3]}"


def assert_data_inside(fig):
    """Every line, marker set and arrow of every panel lies inside its
    axes limits (2D: x and y; polar: radius and, for a sector, angle; 3D:
    x, y, z)."""
    from matplotlib.collections import LineCollection, PathCollection
    from matplotlib.quiver import Quiver

    fig.canvas.draw()  # the limits as drawn (equal aspect, layout engines)
    for ax in fig.axes:
        name = getattr(ax, "name", "rectilinear")
        if not ax.get_visible() or ax.get_label() == "<colorbar>":
            continue
        if name == "polar":
            r0, r1 = ax.get_ylim()
            t0, t1 = math.radians(ax.get_thetamin()), math.radians(ax.get_thetamax())
            full = t1 - t0 >= 2 * math.pi - 1e-9
            for ln in ax.get_lines():
                th, r = np.asarray(ln.get_xdata(), float), np.asarray(ln.get_ydata(), float)
                _inside(r, r0, r1, f"polar radius of {ln.get_label()!r} in {ax.get_title()!r}")
                if not full:
                    _inside(th, t0, t1, f"polar angle of {ln.get_label()!r} in {ax.get_title()!r}")
            continue
        if name == "3d":
            lims = [ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()]
            for col in ax.collections:
                if isinstance(col, LineCollection) and hasattr(col, "_segments3d"):
                    seg = np.asarray(col._segments3d, float).reshape(-1, 3)
                    for k in range(3):
                        _inside(seg[:, k], *lims[k], f"3D arrows, axis {k}")
                elif hasattr(col, "_offsets3d"):
                    for k, v in enumerate(col._offsets3d):
                        _inside(np.asarray(v, float), *lims[k], f"3D points, axis {k}")
            continue
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        for ln in ax.get_lines():
            if ln.get_transform() != ax.transData:  # axhline etc. span the axes by construction
                continue
            _inside(ln.get_xdata(), x0, x1, f"x of a line in {ax.get_title()!r}")
            _inside(ln.get_ydata(), y0, y1, f"y of a line in {ax.get_title()!r}")
        for col in ax.collections:
            if isinstance(col, Quiver):
                tips = np.column_stack([col.X + col.U, col.Y + col.V])
                _inside(np.r_[col.X, tips[:, 0]], x0, x1, f"arrows (x) in {ax.get_title()!r}")
                _inside(np.r_[col.Y, tips[:, 1]], y0, y1, f"arrows (y) in {ax.get_title()!r}")
            elif isinstance(col, PathCollection):
                off = np.asarray(col.get_offsets(), float).reshape(-1, 2)
                _inside(off[:, 0], x0, x1, f"markers (x) in {ax.get_title()!r}")
                _inside(off[:, 1], y0, y1, f"markers (y) in {ax.get_title()!r}")


def figure_text(fig):
    parts = [t.get_text() for t in fig.texts]
    parts += [fig._suptitle.get_text()] if fig._suptitle is not None else []
    for ax in fig.axes:
        parts += [ax.get_title(loc) for loc in ("left", "center", "right")]
    return "\n".join(parts)


def polar_axes(fig):
    return [ax for ax in fig.axes if getattr(ax, "name", "") == "polar"]


# ---- the report per kind ----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["probing", "dbb", "ball3d", "mixed"])
def test_report_per_kind_writes_the_figures_the_kind_calls_for(kind, results, tmp_path):
    result = results[kind]
    path = write_report(result, tmp_path / kind)
    files = set(os.listdir(tmp_path / kind))
    want, not_want = EXPECTED[kind]
    assert want | COMMON <= files, sorted(files)
    assert not (not_want & files), sorted(not_want & files)
    doc = open(path, encoding="utf-8").read()
    assert "could not be drawn" not in doc
    for png in want:
        assert os.path.getsize(tmp_path / kind / png) > 20000 and png in doc


@pytest.mark.parametrize("kind", ["probing", "dbb", "ball3d", "mixed"])
def test_figures_legends_planes_limits_and_convention(kind, results):
    figs = figures_of(results[kind])
    assert figs
    for name, fig in figs.items():
        assert fig is not None, name
        assert all(n <= plots.MAX_LEGEND for n in legend_sizes(fig)), (name, legend_sizes(fig))
        assert_data_inside(fig)
        pol = polar_axes(fig)
        if name == "dbb_polar":
            text = figure_text(fig)
            assert pol
            for ax in pol:
                assert getattr(ax, "fivecal_plane", "") in ("XY", "YZ", "ZX"), ax.get_title("left")
                assert f"plane {ax.fivecal_plane}" in ax.get_title("left")
                assert polar.angle_convention(ax.fivecal_plane) in text
        if name == "dbb_residuals":
            titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
            assert titles and all(re_plane(t) for t in titles), titles


def re_plane(title):
    import re

    return re.search(r"plane (XY|YZ|ZX)\b", title) is not None


def test_dbb_panels_never_mix_setups_planes_or_bar_lengths(results):
    result = results["dbb"]
    fig = polar.dbb_figure(result)
    titles = [ax.get_title("left") for ax in polar_axes(fig)]
    # ten setups (A1 A2 C1 C2 and CW/CCW circles in three planes), one panel each
    assert len(titles) == 10 and len(set(titles)) == 10
    expect = {"A1": ("YZ", 100), "A2": ("YZ", 150), "C1": ("XY", 100), "C2": ("XY", 150),
              "XY+": ("XY", 100), "YZ-": ("YZ", 100), "ZX+": ("ZX", 100)}
    for sid, (plane, length) in expect.items():
        hit = [t for t in titles if t.startswith(f"setup {sid} ")]
        assert hit == [f"setup {sid} · plane {plane} · bar {length} mm"], (sid, titles)
    # each polar panel holds the traces of one group only
    for ax in polar_axes(fig):
        labels = [ln.get_label() for ln in ax.get_lines() if not ln.get_label().startswith("_")]
        assert sorted(labels)[-2:] == ["recorded reading", "residual after the fit"], labels


def test_data_table_lists_the_setups_of_each_kind(results, tmp_path):
    doc = open(write_report(results["mixed"], tmp_path / "m"), encoding="utf-8").read()
    assert "double ball bar setups (2)" in doc
    assert "P+ (36 samples, plane XY, bar 100 mm)" in doc and "P- (36 samples, plane XY, bar 100 mm)" in doc
    assert "R-test / 3D ball setups (1)" in doc and "R2 (54 samples)" in doc
    doc = open(write_report(results["dbb"], tmp_path / "d"), encoding="utf-8").read()
    assert "A2 (19 samples, plane YZ, bar 150 mm)" in doc and "ZX- (72 samples, plane ZX, bar 100 mm)" in doc
    assert "probe tip radius" not in doc  # no touch probing in this data
    assert "rotary indexations" not in doc  # a ball bar sweeps the axes: no indexations


# ---- legends: a colour bar beyond 12 groups ----------------------------------------------------------
def test_many_indexations_get_a_colour_bar_few_get_a_legend(results, c600u):
    many = plots.residual_vectors_figure(results["probing"])  # 5 x 12 = 60 indexations
    assert legend_sizes(many) == []
    bars = [ax for ax in all_axes(many) if "groups" in ax.get_ylabel()]
    assert len(bars) == 1 and "60 groups" in bars[0].get_ylabel()
    few = _identify(c600u, sphere_plan(c600u, a_values=(-30, 0, 30), c_step=90, per=8))  # 12 indexations
    fig = plots.residual_vectors_figure(few)
    assert legend_sizes(fig) == [12]
    assert_data_inside(fig)
    b3 = plots.component_figure(results["ball3d"], "ball3d")  # 13 A positions
    assert legend_sizes(b3) == [] and any("13 groups" in ax.get_ylabel() for ax in all_axes(b3))


def test_residual_vectors_of_dbb_data_stay_inside_and_have_no_huge_legend(results):
    """Called on ball bar data (every observation drawn), the figure that
    had 600 legend entries and arrows outside the axes."""
    fig = plots.residual_vectors_figure(results["dbb"])
    assert all(n <= plots.MAX_LEGEND for n in legend_sizes(fig))
    assert_data_inside(fig)


# ---- one angle convention ----------------------------------------------------------------------------
def _captured(monkeypatch):
    figs = []
    monkeypatch.setattr(polar, "save_figure", lambda fig, path, **kw: figs.append(fig))
    return figs


def _trace_theta(ax, label=None):
    for ln in ax.get_lines():
        if ln.get_label() not in ("_child0",) and not ln.get_label().startswith("nominal") and \
                np.asarray(ln.get_xdata()).size > 2 and (label is None or ln.get_label() == label):
            return np.asarray(ln.get_xdata(), float)
    raise AssertionError("no trace on the panel")


def test_same_trace_same_angles_in_every_plot(results, c600u, monkeypatch):
    """C1 of the four-step test: the report's panel, the four-step plot and
    `dbb plot` draw it at the same angles, counter-clockwise from +X seen
    from +Z. The C axis of this machine points along -Z, so its command
    angle runs the other way: +5 deg of C puts the ball at -5 deg."""
    ds = results["dbb"].dataset
    expect = np.radians(dbb.trace_from_dataset(ds, "C1").angles)
    c_cmd = np.array([o["axes"]["C"] for o in ds.observations if o.get("setup") == "C1"])
    assert c_cmd[1] == pytest.approx(5.0) and np.degrees(expect[1] - expect[0]) == pytest.approx(-5.0, abs=1e-6)
    report_ax = [ax for ax in polar_axes(polar.dbb_figure(results["dbb"]))
                 if ax.get_title("left").startswith("setup C1 ")][0]
    np.testing.assert_allclose(_trace_theta(report_ax, "recorded reading"), expect, atol=1e-9)

    figs = _captured(monkeypatch)
    polar.plot_four_step(dbb.jiang_cripps(ds, engine=False), "unused.png")
    four = [ax for ax in polar_axes(figs[-1]) if ax.get_title("left").startswith("C1:")][0]
    np.testing.assert_allclose(_trace_theta(four), expect, atol=1e-9)
    assert four.fivecal_plane == "XY" and polar.angle_convention("XY") in figure_text(figs[-1])


def test_angle_convention_text_and_no_blank_plane():
    assert polar.angle_convention("XY") == "angle: counter-clockwise from +X towards +Y, seen from +Z"
    assert polar.angle_convention(("Y", "Z")).endswith("seen from +X")
    assert polar.angle_convention("ZX").endswith("from +Z towards +X, seen from +Y")
    for blank in ("", ("", ""), "X", "XX", "QY"):
        with pytest.raises(ValueError, match="plane"):
            polar.plane_name(blank)
    t = dbb.Trace(np.arange(0, 360, 10.0), np.zeros(36))
    fig = polar.polar_figure([t], 100.0, "t", plane="YZ")
    assert polar.angle_convention("YZ") in figure_text(fig)
    with pytest.raises(ValueError, match="plane"):
        polar.polar_figure([t], 100.0, "t", plane=("", ""))


def test_polar_plot_of_many_traces_has_no_long_legend():
    a = np.arange(0, 360, 5.0)
    traces = [dbb.Trace(a, 0.001 * k * np.cos(np.radians(a)), label=f"run {k}") for k in range(20)]
    assert legend_sizes(polar.polar_figure(traces, 100.0, "20 runs")) == []
    assert legend_sizes(polar.polar_figure(traces[:3], 100.0, "3 runs")) == [4]  # and the nominal circle


def test_sector_plot_keeps_the_nominal_circle_inside_the_sector():
    t = dbb.Trace(np.arange(-20, 71, 5.0), 0.01 * np.sin(np.radians(np.arange(-20, 71, 5.0))))
    fig = polar.polar_figure([t], 100.0, "arc", plane="YZ")
    assert polar_axes(fig)[0].get_thetamax() - polar_axes(fig)[0].get_thetamin() < 180
    assert_data_inside(fig)


# ---- fivecal dbb plot ------------------------------------------------------------------------------
def _cli(*args):
    return subprocess.run([sys.executable, "-m", "fivecal", "dbb", "plot", *args], capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": os.path.dirname(fivecal.__path__[0])})


def test_dbb_plot_cli_one_panel_per_setup(results, tmp_path, monkeypatch):
    from fivecal.cli import dbb as dbb_cli
    from fivecal.dataset import save_dataset

    save_dataset(results["dbb"].dataset, tmp_path / "ds.json")
    figs = _captured(monkeypatch)
    args = dbb_cli.argparse.Namespace(inputs=[str(tmp_path / "ds.json")], radius=None, setup=None, plane=None,
                                      scale=None, title=None, out=str(tmp_path / "all.png"))
    assert dbb_cli._plot(args) == 0
    axes = polar_axes(figs[-1])
    assert len(axes) == 10
    assert {ax.fivecal_plane for ax in axes} == {"XY", "YZ", "ZX"}
    for ax in axes:
        assert f"plane {ax.fivecal_plane}" in ax.get_title("left")
    assert_data_inside(figs[-1])
    # through the real command line: the file is written; a wrong --plane and a CSV without
    # --radius are refused with exit code 2
    r = _cli(str(tmp_path / "ds.json"), "--setup", "A1,C2", "--out", str(tmp_path / "two.png"))
    assert r.returncode == 0 and "2 panels" in r.stdout, r.stderr
    assert os.path.getsize(tmp_path / "two.png") > 20000
    r = _cli(str(tmp_path / "ds.json"), "--setup", "A1", "--plane", "XY", "--out", str(tmp_path / "x.png"))
    assert r.returncode == 2 and "YZ plane" in r.stderr
    dbb.write_trace_csv(dbb.Trace(np.arange(0, 360, 5.0), np.zeros(72)), tmp_path / "t.csv")
    r = _cli(str(tmp_path / "t.csv"), "--out", str(tmp_path / "c.png"))
    assert r.returncode == 2 and "--radius" in r.stderr
