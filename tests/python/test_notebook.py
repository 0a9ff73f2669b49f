"""Notebooks (issue 31): Result, Dataset, Machine and the procedures' results
show the report's verdict and parameter table as HTML (``_repr_html_``) and
return matplotlib Figures from ``plot()`` without pyplot and without
switching the user's backend; examples/notebook.ipynb runs clean, from an
instrument's log through identify to the LinuxCNC export."""
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.figure import Figure

import fivecal
from fivecal import views
from fivecal.procedures import dbb, rtest
from fivecal.procedures import sphere_check as sc
from fivecal.report import notebook, plots

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
EXAMPLES = os.path.join(ROOT, "examples")
C600U = os.path.join(EXAMPLES, "machines", "c600u.json")
BALL = [50.0, 0.0, 80.0]
TRUTH = {"EX0C": 0.02, "EY0C": -0.015, "EA0C": 25e-6, "EB0C": -40e-6, "EZ0A": -0.008, "EB0A": 30e-6}


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.load(C600U)


@pytest.fixture(scope="module")
def rtest_data(machine):
    plan = [e for t in rtest.TESTS for e in rtest.plan(machine, t, table_ball=BALL, step=30, setup="R1")]
    return fivecal.simulate(machine, plan, errors=TRUTH, sigma={"ball3d": 0.0005}, seed=5)


@pytest.fixture(scope="module")
def result(rtest_data):
    return fivecal.identify(rtest_data, estimate="location")


def _value_cell(result, name):
    """The parameter's value as the report's table writes it (µm or µrad)."""
    f = 1e6 if name[1] in "ABC" else 1e3
    return f"<td class='num'>{result.values[name] * f:.3f}</td>"


def test_result_html_has_the_verdict_and_the_parameter_table(result):
    assert result.usable
    h = result._repr_html_()
    assert "<div class='box " in h and "<b>OK" in h and "NOT USABLE" not in h
    assert "<th>parameter</th>" in h and "<th>u (1σ)</th>" in h
    for n in ("EY0C", "EA0C", "EB0C", "EZ0A", "EB0A"):
        assert f"<code>{n}</code>" in h and _value_cell(result, n) in h, n
    # a notebook page shows many results: no element id that a second view would repeat
    assert " id=" not in h
    # the notebook page keeps its own style: every rule is scoped to the view
    style = h.split("<style>", 1)[1].split("</style>", 1)[0]
    assert all(r.startswith(".fivecal-view ") for r in style.split("}") if r)


def test_a_result_that_is_not_usable_says_so_first(machine, rtest_data):
    # the same readings declared ten times less noisy than they are: the
    # residuals contradict the declared noise (chi-square), not usable
    d = rtest_data.to_dict()
    for o in d["observations"]:
        o["sigma"] = 0.00005
    with pytest.warns(fivecal.FitWarning):
        bad = fivecal.identify(fivecal.Dataset.from_dict(d), estimate="location")
    assert not bad.usable
    h = bad._repr_html_()
    assert "NOT USABLE" in h and "box bad" in h and "box ok" not in h


def test_dataset_and_machine_html(machine, rtest_data):
    h = rtest_data._repr_html_()
    assert f"{len(rtest_data)} observations on {machine.name}" in h
    assert f"{len(rtest_data)} ball3d" in h and "R1 (" in h
    h = machine._repr_html_()
    assert machine.name in h and "wCAfXYZSt" in h and "<td>A</td><td>rotary</td>" in h


def test_procedure_results_show_the_verdict_and_their_report(machine, rtest_data):
    r = rtest.evaluate(rtest_data)
    h = r._repr_html_()
    assert "<div class='box " in h and "R-test report" in h and "R1  " in h and _value_cell(r.result, "EY0C") in h
    bare = rtest.evaluate(rtest_data, identify=False)
    h = bare._repr_html_()
    assert "No identification" in h and "R1  " in h
    with pytest.raises(ValueError, match="no fit to draw"):
        bare.plot()
    ball = {"id": "S1", "center": [60.0, 40.0, 30.0], "radius": 12.5}
    truth = {"EX0C": 0.01, "EY0C": -0.008}
    ds = fivecal.simulate(machine, sc.plan(machine, ball, tip_radius=3.0), errors=truth,
                          artefact={"spheres": [ball]}, tip_radius=3.0, sigma=0.001, seed=3)
    check = sc.evaluate(ds)
    h = check._repr_html_()
    assert "<div class='box " in h and "Sphere check report" in h and "dispersion" in h
    assert all(isinstance(f, Figure) for f in check.plot())


def _circle(direction, seed):
    rng = np.random.default_rng(seed)
    a = np.arange(0.0, 360.0, 1.0) * direction % 360
    t = np.radians(a)
    # out-of-squareness and scale mismatch of a 100 mm circle, 0.5 µm noise
    r = 0.004 * np.sin(2 * t) + 0.002 * np.cos(2 * t) + rng.normal(0, 0.0005, a.size)
    return dbb.Trace(a, r, label="CCW" if direction > 0 else "CW")


def test_circular_test_html_and_plot():
    res = dbb.circular_test([_circle(+1, 1), _circle(-1, 2)], 100.0, "XY", 1000)
    h = res._repr_html_()
    assert "Circular test" in h and "circular deviation G" in h and "No identification" in h
    figs = res.plot()
    assert len(figs) == 1 and isinstance(figs[0], Figure)


def test_plot_returns_figures_and_leaves_the_backend_alone(tmp_path):
    """In a fresh interpreter with a backend chosen by the user: plot() of
    each object returns Figures, pyplot is never imported and the backend is
    the user's; the PNGs are written for a look."""
    code = f"""
import sys, json, matplotlib
matplotlib.use("svg")
import fivecal
from fivecal.procedures import rtest
from matplotlib.figure import Figure
m = fivecal.Machine.load({C600U!r})
plan = [e for t in rtest.TESTS for e in rtest.plan(m, t, table_ball={BALL!r}, step=30, setup="R1")]
ds = fivecal.simulate(m, plan, errors={TRUTH!r}, sigma={{"ball3d": 0.0005}}, seed=5)
r = fivecal.identify(ds, estimate="location")
out = {{}}
for name, obj in (("machine", m), ("dataset", ds), ("result", r), ("rtest", rtest.evaluate(ds))):
    figs = obj.plot()
    assert figs and all(isinstance(f, Figure) for f in figs), (name, figs)
    for i, f in enumerate(figs):
        f.savefig({str(tmp_path)!r} + f"/{{name}}_{{i}}.png", dpi=60)
    out[name] = len(figs)
out["backend"] = matplotlib.get_backend()
out["pyplot"] = "matplotlib.pyplot" in sys.modules
print(json.dumps(out))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["backend"] == "svg" and out["pyplot"] is False
    # the machine sketch, the axis commands, and for a 3D-ball fit: the
    # components, the residual histogram and the machine errors
    assert out["machine"] == 1 and out["dataset"] == 1 and out["result"] == 3 and out["rtest"] == 3
    assert len(list(tmp_path.glob("*.png"))) == 8


def test_an_object_nobody_registered_says_so():
    class Other(views.Viewable):
        pass

    with pytest.raises(NotImplementedError):  # IPython then shows the plain repr
        Other()._repr_html_()
    with pytest.raises(TypeError, match="no figures of a Other"):
        Other().plot()


# ---------------------------------------------------------------------------
# the example notebook
# ---------------------------------------------------------------------------

def test_example_notebook_runs_clean(tmp_path, monkeypatch):
    """examples/notebook.ipynb executed by nbclient in a kernel running this
    interpreter (a kernelspec made for it), from a copy of the examples so the
    export writes beside the copy: no cell errors, the identification is
    usable and the LinuxCNC pins are written."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    work = tmp_path / "examples"
    shutil.copytree(EXAMPLES, work, ignore=shutil.ignore_patterns("cpp", "sscanss_table", "__pycache__"))
    spec = tmp_path / "jupyter" / "kernels" / "fivecal-test"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "fivecal test", "language": "python"}))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in sys.path if p))  # the fivecal under test
    monkeypatch.delenv("MPLBACKEND", raising=False)
    nb = nbformat.read(os.path.join(EXAMPLES, "notebook.ipynb"), as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "commit the notebook without outputs"
    client = nbclient.NotebookClient(nb, kernel_name="fivecal-test", timeout=600,
                                     resources={"metadata": {"path": str(work)}})
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors, "\n".join(f"{e.ename}: {e.evalue}" for e in errors)
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    html = "".join(o.get("data", {}).get("text/html", "") for o in outputs)
    assert "<div class='box " in html and "<b>OK" in html and "NOT USABLE" not in html
    assert sum("image/png" in o.get("data", {}) for o in outputs) >= 4  # machine, dataset, the fit's figures
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "setp xyzac-trt-kins.x-rot-point" in text
    assert (work / "lcnc" / "fivecal-kins.hal").is_file()
    # the printed comparison with the truth: every value within 3 sigma
    sig = [float(line.rsplit("(", 1)[1].split(" ")[0]) for line in text.splitlines() if " σ)" in line]
    assert len(sig) == 8 and max(sig) < 3, text


def test_group_labels_of_a_k4_path_are_rounded(rtest_data):
    """The inverse puts the tilt at 1e-14° where the plan said 0°: the
    figure's group key reads "A 0°", once (seen on the R-test figure)."""
    _, _, labels = plots._setup_groups(rtest_data, list(range(len(rtest_data))), "setup", False)
    assert labels and not any("e-" in lab or "-0°" in lab for lab in labels), sorted(set(labels))
    assert "A 0°" in labels


def test_four_step_ball_bar_html_and_plot(machine):
    """A procedure whose fit is the general engine's (``engine``): its
    verdict and machine errors, the method's own report, the fit's figures."""
    truth = {"EY0A": 0.0342, "EZ0A": -0.0353, "EX0C": 0.0013, "EY0C": -0.0525}
    ds = fivecal.simulate(machine, dbb.four_step_plan(machine), errors=truth, sigma={"dbb": 0.0003}, seed=11)
    res = dbb.jiang_cripps(ds)
    h = res._repr_html_()
    assert "Four-step ball bar test" in h and "<div class='box " in h and "<code>EY0C</code>" in h
    assert _value_cell(res.engine, "EY0C") in h and "Four-step ball bar test report" in h
    figs = res.plot()
    assert figs and all(isinstance(f, Figure) for f in figs)
    without = dbb.jiang_cripps(ds, engine=False)
    assert "No identification" in without._repr_html_()
    with pytest.raises(ValueError, match="no fit to draw"):
        without.plot()


def test_a_large_dataset_is_counted_not_read(machine, rtest_data, monkeypatch):
    """Beyond LARGE_DATASET observations the view counts them per kind and
    does not read every observation as the report's data table does."""
    monkeypatch.setattr(notebook, "LARGE_DATASET", 10)
    monkeypatch.setattr(notebook, "_data_section", lambda *a: pytest.fail("read every observation"))
    h = rtest_data._repr_html_()
    assert f"{len(rtest_data)} ball3d." in h and "write_report" in h
