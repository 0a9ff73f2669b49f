"""Bad input at the command line (issue 12): outputs over inputs refused
naming both, options refused naming the option (never a Python internal),
sample counts bounded, `| head` quiet, unreadable files named, the seed
range, and the Monte Carlo report when the trials are too few to judge."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

import fivecal
from fivecal import simulation, uncertainty
from fivecal.procedures import dbb

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
MACHINES = os.path.join(ROOT, "examples", "machines")
SPEC = os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json")
PROGRAM = os.path.join(ROOT, "examples", "gcode", "hu40t_5axis.nc")
C600U = os.path.join(MACHINES, "c600u.json")


def fivecal_cli(*args, cwd=None, timeout=300, stdout=subprocess.PIPE):
    e = dict(os.environ)
    e.pop("FIVECAL_DEBUG", None)
    e["PYTHONPATH"] = os.path.dirname(os.path.dirname(os.path.abspath(fivecal.__file__))) + os.pathsep + \
        e.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-m", "fivecal", *map(str, args)], stdout=stdout,
                          stderr=subprocess.PIPE, text=True, cwd=cwd, env=e, timeout=timeout)


def one_line_error(r, *words):
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr, r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("ds")
    r = fivecal_cli("simulate", SPEC, "--out", d / "ds.json")
    assert r.returncode == 0, r.stderr
    return d / "ds.json"


# ---------------------------------------------------------------------------
# outputs over inputs
# ---------------------------------------------------------------------------
def test_identify_refuses_to_write_over_its_dataset_by_name_symlink_or_hard_link(dataset, tmp_path):
    before = dataset.read_bytes()
    os.symlink(dataset, tmp_path / "link.json")
    os.link(dataset, tmp_path / "hard.json")
    for out in (dataset, tmp_path / "link.json", tmp_path / "hard.json"):
        r = fivecal_cli("identify", dataset, "--estimate", "S1", "--out", out)
        one_line_error(r, "--out", str(out), "dataset", str(dataset), "overwrite")
        assert dataset.read_bytes() == before


def test_simulate_refuses_to_write_over_its_spec_or_the_machine_it_names(tmp_path):
    spec = tmp_path / "spec.json"
    spec.write_bytes(open(SPEC, "rb").read().replace(b'"../machines/hu40t.json"',
                                                     b'"machine.json"'))
    (tmp_path / "machine.json").write_bytes(open(os.path.join(MACHINES, "hu40t.json"), "rb").read())
    before = spec.read_bytes(), (tmp_path / "machine.json").read_bytes()
    one_line_error(fivecal_cli("simulate", spec, "--out", spec), "--out", "spec")
    one_line_error(fivecal_cli("simulate", spec, "--out", tmp_path / "machine.json"), "machine.json", "input")
    assert (spec.read_bytes(), (tmp_path / "machine.json").read_bytes()) == before


def test_compensate_table_over_the_program_is_refused_and_the_program_kept(tmp_path):
    prog = tmp_path / "part.nc"
    prog.write_bytes(open(PROGRAM, "rb").read())
    result = tmp_path / "errors.json"
    result.write_text('{"EX0C": 0.01}')
    r = fivecal_cli("compensate", result, os.path.join(MACHINES, "hu40t.json"), prog, "--out",
                    tmp_path / "out.nc", "--table", prog)
    one_line_error(r, "--table", "program", "part.nc")
    assert prog.read_bytes() == open(PROGRAM, "rb").read()
    assert not (tmp_path / "out.nc").exists()
    r = fivecal_cli("compensate", result, os.path.join(MACHINES, "hu40t.json"), prog, "--out",
                    tmp_path / "same.nc", "--table", tmp_path / "same.nc")
    one_line_error(r, "--table", "--out", "same.nc")


# ---------------------------------------------------------------------------
# options named, never Python internals
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("args,option", [
    (["--trials", "2.9"], "--trials"), (["--trials", "1"], "--trials"), (["--threads", "x"], "--threads"),
    (["--threads", "-1"], "--threads"), (["--seed", "-1"], "--seed"), (["--seed", "1.5"], "--seed"),
    (["--seed", str(2 ** 64)], "--seed"), (["--sigma", "nan"], "--sigma"), (["--sigma", "-1"], "--sigma"),
    (["--probability", "1.5"], "--probability"), (["--digits", "0"], "--digits"),
    (["--trials", "1000000000"], "--trials"), (["--trials", "2000000"], "--trials"),
    (["--threads", "60000"], "--threads")])
def test_uncertainty_options_are_refused_naming_the_option(args, option):
    one_line_error(fivecal_cli("uncertainty", SPEC, *args), option)


def test_simulate_seed_and_sigma_options(tmp_path):
    for args, opt in ((["--seed", "-3"], "--seed"), (["--seed", "nan"], "--seed"), (["--sigma", "inf"], "--sigma")):
        one_line_error(fivecal_cli("simulate", SPEC, "--out", tmp_path / "x.json", *args), opt)
    assert not (tmp_path / "x.json").exists()


def test_cycles_day_labels_and_compensate_axis_options(dataset, tmp_path):
    one_line_error(fivecal_cli("uncertainty", dataset, dataset, "--days", "a,b"), "--days")
    result = tmp_path / "errors.json"
    result.write_text('{"EX0C": 0.01}')
    hu40t = os.path.join(MACHINES, "hu40t.json")
    for opt, value in (("--start", "X=nan"), ("--start", "1=2"), ("--start", "X=1,X=2"), ("--work-offset", "X=inf"),
                       ("--start", "X")):
        r = fivecal_cli("compensate", result, hu40t, PROGRAM, "--out", tmp_path / "o.nc", opt, value)
        one_line_error(r, opt)


def test_simulate_spec_fields_of_the_wrong_type_are_named(tmp_path):
    import json

    base = json.load(open(SPEC))
    base["machine"] = os.path.join(MACHINES, "hu40t.json")
    for field, value in (("errors", [1, 2]), ("setup", ["a"]), ("probe", [3.0]), ("seed", -1), ("seed", 2.5),
                         ("seed", 2 ** 64)):
        spec = dict(base, **{field: value})
        p = tmp_path / f"{field}.json"
        p.write_text(json.dumps(spec))
        r = fivecal_cli("simulate", p, "--out", tmp_path / "o.json")
        one_line_error(r, field)


# ---------------------------------------------------------------------------
# sample counts
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("step", ["1e-9", "0", "-5", "nan"])
def test_dbb_circular_step_is_bounded_and_named(step):
    r = fivecal_cli("dbb", "circular", "--machine", C600U, "--simulate", "EXX1=2e-5", "--radius", "100",
                    "--step", step, timeout=60)
    one_line_error(r, "--step")


def test_dbb_jiang_tiny_step_is_refused_not_an_abort():
    r = fivecal_cli("dbb", "jiang", "--machine", C600U, "--simulate", "paper", "--step", "1e-7", timeout=60)
    one_line_error(r, "--step", "1000000")


def test_the_core_bounds_sample_counts_too():
    m = fivecal.Machine.load(C600U)
    with pytest.raises(ValueError, match=r"four-step plan\.step: .*at most 1000000"):
        dbb.four_step_plan(m, step=1e-7)
    with pytest.raises(ValueError, match=r"\.step: .*at most 1000000"):
        dbb.wang_path(fivecal.Machine.load(os.path.join(MACHINES, "vmc0656.json")), step=1e-7)
    with pytest.raises(ValueError, match=r"step: .*1000000"):
        dbb.planar_plan(m, step=1e-9)


def test_a_circular_test_in_radians_is_refused():
    import numpy as np

    a = np.linspace(0, 2 * np.pi, 100)  # a full turn written in radians
    runs = [dbb.Trace(a, 0.001 * np.sin(a), label="CCW", direction=1)]
    with pytest.raises(ValueError, match=r"sweep 6.28.*at least 10 degrees"):
        dbb.circular_test(runs, 100.0)


# ---------------------------------------------------------------------------
# pipes and files
# ---------------------------------------------------------------------------
def test_a_closed_pipe_is_quiet_and_the_command_still_succeeds(dataset, tmp_path):
    r_fd, w_fd = os.pipe()
    os.close(r_fd)  # the reader (head) has gone: every write gets EPIPE
    try:
        r = fivecal_cli("identify", dataset, "--estimate", "location", "--out", tmp_path / "r.json", stdout=w_fd)
    finally:
        os.close(w_fd)
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    assert (tmp_path / "r.json").exists()  # the result is still written
    r_fd, w_fd = os.pipe()
    os.close(r_fd)
    try:
        r = fivecal_cli("uncertainty", "--help", stdout=w_fd)
    finally:
        os.close(w_fd)
    assert (r.returncode, r.stderr) == (0, "")


def test_unreadable_inputs_are_named(tmp_path):
    one_line_error(fivecal_cli("identify", "/dev/zero", timeout=60), "/dev/zero", "not a regular file")
    b = tmp_path / "b.json"
    b.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    one_line_error(fivecal_cli("identify", b), "b.json", "byte offset")
    t = tmp_path / "t.json"
    t.write_bytes('{"name": "é"}'.encode("latin-1"))
    one_line_error(fivecal_cli("identify", t), "t.json", "not UTF-8", "byte offset 10")
    one_line_error(fivecal_cli("identify", tmp_path), "is a folder")


def test_a_deeply_nested_spec_is_a_named_error(tmp_path):
    p = tmp_path / "deep.json"
    p.write_text('{"errors": ' + '{"a": ' * 5000 + "1" + "}" * 5000 + "}")
    one_line_error(fivecal_cli("simulate", p, "--out", tmp_path / "o.json"), "deep.json", "nested")


# ---------------------------------------------------------------------------
# seeds and counts in the library
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [-1, 2 ** 64, 2.5, float("nan"), True, "3", None])
def test_bad_seeds_are_refused_naming_seed(seed):
    with pytest.raises(ValueError, match="seed"):
        simulation.seed_value(seed)


def test_integral_seeds_are_accepted_and_equal():
    import numpy as np

    assert simulation.seed_value(3.0) == simulation.seed_value(np.int64(3)) == 3
    assert simulation.seed_value(2 ** 64 - 1) == 2 ** 64 - 1
    m = fivecal.Machine.load(os.path.join(MACHINES, "vmc0656.json"))
    plan = dbb.wang_plan(m)[:20]
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in plan]
    a = fivecal.simulate(m, plan, sigma={"dbb": 0.001}, seed=3.0)
    b = fivecal.simulate(m, plan, sigma={"dbb": 0.001}, seed=3)
    c = fivecal.simulate(m, plan, sigma={"dbb": 0.001}, seed=4)
    assert a.to_dict() == b.to_dict() != c.to_dict()


def test_spec_seed_is_checked_in_the_core():
    import json

    from fivecal import _core

    m = fivecal.Machine.load(os.path.join(MACHINES, "vmc0656.json"))
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in dbb.wang_plan(m)[:10]]
    base = {"machine": m.to_dict(), "plan": plan, "sigma": {"dbb": 0.001}}
    for bad in ("-1", "2.5", "1e30", "18446744073709551616", '"7"'):
        text = json.dumps(base)[:-1] + ', "seed": ' + bad + "}"
        with pytest.raises(ValueError, match="seed"):
            _core.simulate(text)
    ok = json.dumps(base)[:-1] + ', "seed": 3.0}'
    ok3 = json.dumps(base)[:-1] + ', "seed": 3}'
    assert _core.simulate(ok).to_json() == _core.simulate(ok3).to_json()


@pytest.mark.parametrize("kw,name", [({"trials": 2.9}, "trials"), ({"trials": 1}, "trials"),
                                     ({"threads": -1}, "threads"), ({"threads": 1.5}, "threads"),
                                     ({"seed": -1}, "seed"), ({"seed": 2 ** 64}, "seed"),
                                     ({"sigma": float("nan")}, "sigma")])
def test_monte_carlo_arguments_are_checked_before_running(kw, name, dataset):
    with pytest.raises(ValueError, match=name):
        uncertainty.monte_carlo(str(dataset), "S1", progress=False, **kw)


def test_too_few_trials_print_one_line_instead_of_verdicts():
    m = fivecal.Machine.load(os.path.join(MACHINES, "vmc0656.json"))
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in dbb.wang_plan(m)]
    spec = uncertainty.make_spec(m, plan, errors={"EX0C": 0.007, "EY0C": -0.005},
                                 sigma={"dbb": 0.0003}, seed=1)
    mc = uncertainty.monte_carlo(spec, ["EX0C", "EY0C"], trials=30, seed=1, progress=False)
    text = mc.report()
    assert mc.trials_needed() is not None and mc.trials_needed() > 30
    assert "validated" not in text.split("GUM not judged")[0].split("parameter")[-1]
    assert "GUM not judged" in text and f"about {mc.trials_needed()} trials are needed" in text
    assert text.count("not validated") == 0


# ---------------------------------------------------------------------------
# counts and steps that allocate: bounded, the option named (issue #27)
# ---------------------------------------------------------------------------
def test_counts_that_allocate_are_bounded_naming_the_option(tmp_path):
    design_spec = os.path.join(ROOT, "examples", "design", "hu40t_table_4_2.json")
    for args, option in (
            (["design", design_spec, "-k", "10000000000"], "-k"),
            (["design", design_spec, "-k", "3", "--require", "10000000000"], "--require"),
            (["fleet", "identify", tmp_path, "--store", tmp_path / "s.fcdb", "--trials", "1000000000"], "--trials"),
            (["fleet", "identify", tmp_path, "--store", tmp_path / "s.fcdb", "--workers", "100000"], "--workers"),
            (["export", "program", SPEC, "--subdivide", "1000000000"], "--subdivide"),
            (["dbb", "circular", "--machine", C600U, "--simulate", "EXX1=2e-5", "--radius", "100",
              "--step", "1e-4"], "--step")):
        r = fivecal_cli(*args, timeout=120)
        one_line_error(r, option)
        assert r.stderr.count("\n") == 1, r.stderr


# ---------------------------------------------------------------------------
# warnings: one line `fivecal COMMAND: warning: ...`, not Python's (issue #27)
# ---------------------------------------------------------------------------
def _warning_lines(r, command):
    assert "Warning:" not in r.stderr and "sys.exit" not in r.stderr and ".py:" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "warning" in ln]
    assert lines and all(ln.startswith(f"fivecal {command}: warning: ") for ln in lines), r.stderr
    return lines


def test_a_radians_warning_is_one_line_of_the_command(tmp_path):
    import math

    rows = open(os.path.join(ROOT, "examples", "import", "probing.csv")).read().splitlines()
    head = [i for i, ln in enumerate(rows) if ln.startswith("id,")][0]
    cols = rows[head].split(",")
    out = rows[:head + 1]
    for ln in rows[head + 1:]:
        f = ln.split(",")
        for a in ("A", "C"):
            f[cols.index(a)] = f"{math.radians(float(f[cols.index(a)])) + 0.01:.5f}"  # off the π/12 grid, which is refused
        out.append(",".join(f))
    (tmp_path / "rad.csv").write_text("\n".join(out) + "\n")
    r = fivecal_cli("import", "probing", tmp_path / "rad.csv", "--sidecar",
                    os.path.join(ROOT, "examples", "import", "probing.json"), "--machine", C600U,
                    "--out", tmp_path / "ds.json")
    assert r.returncode == 0, r.stderr
    lines = _warning_lines(r, "import")
    assert any("look like radians" in ln for ln in lines), lines


def test_a_fit_warning_is_one_line_of_the_command(tmp_path):
    from fivecal.procedures import sphere_check

    m = fivecal.Machine.load(C600U)
    ball = {"id": "S1", "center": [60.0, 30.0, 40.0], "radius": 12.5}
    plan = sphere_check.plan(m, ball, tip_radius=3.0, n=3)
    ds = fivecal.simulate(m, plan, artefact={"spheres": [ball]}, tip_radius=3.0, sigma=0.01, seed=1).to_dict()
    for o in ds["observations"]:
        o["sigma"] = 1e-4  # declared 100 times smaller than drawn: the fit is inadequate
    import json

    (tmp_path / "ds.json").write_text(json.dumps(ds))
    r = fivecal_cli("sphere-check", tmp_path / "ds.json")
    assert r.returncode == 1, r.stderr
    lines = _warning_lines(r, "sphere-check")
    assert any("the result is not usable" in ln for ln in lines), lines


def test_the_python_api_keeps_standard_warnings():
    import warnings

    from fivecal import cli

    before = warnings.showwarning
    assert cli.main(["docs", "dbb"]) == 0
    assert warnings.showwarning is before
