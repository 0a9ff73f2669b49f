"""Bad input and data safety of the calibration history (issue 27): no
output over the store, no result of another machine, no NaN, no repeats,
no comparison across machines, tolerances with units and plausible sizes."""
from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

import fivecal
from fivecal import files, history, tolerances
from fivecal.cli import main
from fivecal.history import fleet, fleetsim
from fivecal.procedures import sphere_test

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
C600U = os.path.join(ROOT, "examples", "machines", "c600u.json")


def _sha(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


@pytest.fixture(scope="module")
def shop(tmp_path_factory):
    """Two nights of an HU40T (HU1) recorded through the CLI, a C600U
    dataset, the result files of all three."""
    d = tmp_path_factory.mktemp("shop")
    m = fleetsim.machine()
    paths = []
    for night in range(2):
        ds = fivecal.simulate(m, fleetsim.sphere_check_plan(m), errors={"EX0C": -0.108},
                              artefact={"spheres": [fleetsim.SPHERE]}, tip_radius=3.0, sigma=0.0006, seed=night)
        p = d / f"hu1_2026-01-0{night + 1}.json"
        fivecal.save_dataset(ds, p)
        paths.append(str(p))
    c = fivecal.Machine.load(C600U)
    idx = [{"A": float(a), "C": float(x)} for a in (0, 30, -30) for x in (0, 90, 180, 270)]
    ds = fivecal.simulate(c, sphere_test.sphere_plan(c, fleetsim.SPHERE, idx, tip_radius=3.0), errors={"EX0C": 0.01},
                          artefact={"spheres": [fleetsim.SPHERE]}, tip_radius=3.0, sigma=0.0006, seed=7)
    c600 = d / "c600u_2026-01-03.json"
    fivecal.save_dataset(ds, c600)
    store = str(d / "shop.fcdb")
    for p in paths:
        assert main(["identify", p, "--estimate", "location", "--history", store, "--machine-id", "HU1",
                     "--record", "--out", p.replace(".json", ".result.json")]) == 0
    assert main(["identify", str(c600), "--estimate", "location", "--out", str(d / "c600u.result.json")]) == 0
    return SimpleNamespace(dir=d, hu=paths, c600=str(c600), store=store,
                           hu_results=[p.replace(".json", ".result.json") for p in paths],
                           c600_result=str(d / "c600u.result.json"))


@pytest.fixture
def store(shop, tmp_path):
    """A copy of the shop's store this test may change."""
    p = tmp_path / "s.fcdb"
    with sqlite3.connect(shop.store) as src, sqlite3.connect(p) as dst:
        src.backup(dst)
    return str(p)


def _count(store) -> int:
    with history.Store(store, create=False) as s:
        return len(s)


def _refused(capsys, *words):
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    for w in words:
        assert w in err, (w, err)
    return err


# ---------------------------------------------------------------------------
# data loss: no output over the store
# ---------------------------------------------------------------------------
def test_history_export_over_the_store_is_refused_and_the_store_kept(store, tmp_path, capsys):
    pytest.importorskip("pyarrow")
    before = _sha(store)
    os.symlink(store, tmp_path / "link.parquet")
    os.link(store, tmp_path / "hard.parquet")
    for out in (store, str(tmp_path / "link.parquet"), str(tmp_path / "hard.parquet")):
        capsys.readouterr()
        assert main(["history", "export", "--store", store, out]) == 2, out
        _refused(capsys, "OUT", out, "--store", store, "overwrite")
        assert _sha(store) == before
    assert _count(store) == 2


def test_history_trend_plot_over_the_store_is_refused_and_the_store_kept(store, capsys):
    before = _sha(store)
    capsys.readouterr()
    assert main(["history", "trend", "--store", store, "--machine-id", "HU1", "--plot", store]) == 2
    _refused(capsys, "--plot", store, "--store", "overwrite")
    assert _sha(store) == before and _count(store) == 2


def test_identify_outputs_over_the_history_store_are_refused(shop, store, tmp_path, capsys):
    before = _sha(store)
    for extra in (["--out", store], ["--record", "--out", store]):
        capsys.readouterr()
        assert main(["identify", shop.hu[0], "--estimate", "location", "--history", store, "--machine-id", "HU1",
                     *extra]) == 2
        _refused(capsys, "--out", "--history", store)
        assert _sha(store) == before


def test_an_open_store_is_an_input_to_every_writer(shop, store, tmp_path):
    """The one guard holds in Python too, outside any command: while a store
    is open no writer of the package overwrites it, by name or by link."""
    pytest.importorskip("pyarrow")
    before = _sha(store)
    os.symlink(store, tmp_path / "link")
    ds = fivecal.load_dataset(shop.hu[0])
    with history.Store(store) as s:
        cals = s.list("HU1")
        for target in (store, str(tmp_path / "link")):
            for write in (lambda p: history.write_parquet(cals, p), lambda p: s.export_parquet(p),
                          lambda p: history.plot_trend(cals, p), lambda p: fivecal.save_dataset(ds, p),
                          lambda p: files.write_text(p, "lost?"), lambda p: fleet._write_parquet_part(p, cals)):
                with pytest.raises(ValueError, match="refusing to overwrite an input"):
                    write(target)
    assert _sha(store) == before and _count(store) == 2
    # closed, it is a file like any other (the caller's to overwrite)
    history.write_parquet(cals, tmp_path / "x.parquet")
    assert len(history.read_parquet(tmp_path / "x.parquet")) == 2


def test_a_file_read_by_the_command_is_not_opened_as_its_store(shop, tmp_path):
    """Inside a command, a file read as an input is not opened (and written) as a store."""
    p = tmp_path / "ds.json"
    p.write_bytes(b"")          # SQLite would make an empty file a database
    with files.transaction():
        files.read_bytes(p)
        with pytest.raises(ValueError, match="ds.json: is the input"):
            history.Store(p)
    assert p.read_bytes() == b""


# ---------------------------------------------------------------------------
# a result of another machine
# ---------------------------------------------------------------------------
def test_a_result_of_another_machine_is_refused_naming_both(shop, store, capsys):
    before = _sha(store)
    capsys.readouterr()
    assert main(["identify", shop.c600, "--estimate", "location", "--history", store, "--machine-id", "HU1",
                 "--record"]) == 2
    err = _refused(capsys, "HU1", "HU40T-like", "C600U-like", "--rebuilt")
    assert "fitting" not in err                        # said before the fit
    for extra in ([], ["--dataset", shop.c600]):       # without a machine: its parameter names give it away
        assert main(["history", "add", "--store", store, shop.c600_result, "--machine-id", "HU1", *extra]) == 2
        _refused(capsys, "HU1", "HU40T-like", *(["C600U-like"] if extra else ["EB0A"]))
    with history.Store(store) as s, pytest.raises(ValueError, match="C600U-like"):
        s.add(shop.c600_result, machine_id="HU1", machine=C600U)
    assert _sha(store) == before


def test_a_rebuilt_machine_is_recorded_and_its_trend_starts_again(shop, store, capsys):
    assert main(["identify", shop.c600, "--estimate", "location", "--history", store, "--machine-id", "HU1",
                 "--record", "--rebuilt"]) == 0
    with history.Store(store) as s:
        (t,) = s.rebuilds("HU1")
        assert t == history.utc_time("2026-01-03") and s.machine("HU1").name == "C600U-like"
        assert len(s.list("HU1")) == 3
    capsys.readouterr()
    assert main(["history", "trend", "--store", store, "--machine-id", "HU1"]) == 0
    out = capsys.readouterr().out
    assert "rebuilt at 2026-01-03" in out and "EB0A" in out and "EB0C" in out and "EC0B " not in out
    # the new machine is the one now: an HU40T result is refused in turn
    assert main(["history", "add", "--store", store, shop.hu_results[0], "--machine-id", "HU1",
                 "--dataset", shop.hu[0]]) == 2
    _refused(capsys, "C600U-like", "HU40T-like")
    assert main(["identify", shop.c600, "--history", store, "--machine-id", "HU1", "--rebuilt",
                 "--report", "r"]) == 2
    _refused(capsys, "--rebuilt", "--record")


# ---------------------------------------------------------------------------
# non-finite values
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("field, bad", [("value", float("nan")), ("value", float("inf")), ("std", float("nan"))])
def test_a_result_with_a_non_finite_value_or_std_is_refused(shop, store, tmp_path, capsys, field, bad):
    d = json.loads(open(shop.hu_results[0]).read())
    d["parameters"]["EB0C"][field] = bad
    (tmp_path / "bad.json").write_text(json.dumps(d))       # NaN / Infinity literals, as Python writes them
    before = _sha(store)
    capsys.readouterr()
    assert main(["history", "add", "--store", store, str(tmp_path / "bad.json"), "--machine-id", "HU9"]) == 2
    _refused(capsys, "EB0C", "not finite")
    with history.Store(store) as s, pytest.raises(ValueError, match="EB0C"):
        s.add(d, machine_id="HU9")
    assert _sha(store) == before


def test_a_non_finite_fit_of_a_fleet_run_is_a_failure_not_a_record(shop):
    cal = history.calibration_from_result(shop.hu_results[0], "HU1")
    cal.values[cal.names.index("EX0C")] = np.nan
    with pytest.raises(ValueError, match="EX0C"):
        cal.check()


# ---------------------------------------------------------------------------
# recording the same dataset again
# ---------------------------------------------------------------------------
def test_recording_a_dataset_again_changes_nothing_unless_replaced(shop, store, capsys):
    before = _sha(store)
    for _ in range(2):
        capsys.readouterr()
        assert main(["identify", shop.hu[0], "--estimate", "location", "--history", store, "--machine-id", "HU1",
                     "--record"]) == 0
        _refused(capsys, "already recorded", "calibration #1", "--replace")
        assert main(["history", "add", "--store", store, shop.hu_results[0], "--machine-id", "HU1",
                     "--dataset", shop.hu[0]]) == 0
        _refused(capsys, "already recorded", "#1")
        assert main(["history", "add", "--store", store, shop.hu_results[0], "--machine-id", "HU1"]) == 0
        _refused(capsys, "already recorded", "#1")     # no digest: the same values bit for bit
    with history.Store(store) as s:
        assert [c.id for c in s.list("HU1")] == [1, 2]
    capsys.readouterr()
    assert main(["identify", shop.hu[0], "--estimate", "location", "--history", store, "--machine-id", "HU1",
                 "--record", "--replace", "--procedure", "sphere"]) == 0
    assert "already" not in capsys.readouterr().err
    with history.Store(store) as s:
        cals = s.list("HU1")
        assert len(cals) == 2 and [c.procedure for c in cals] == ["sphere", ""]
    assert _sha(store) != before
    # another machine id may hold the same dataset (a copy of a file is not the machine's history)
    assert main(["history", "add", "--store", store, shop.hu_results[0], "--machine-id", "HU2"]) == 0


def test_the_python_api_says_a_repeat_and_returns_the_stored_id(shop, store):
    r = history.calibration_from_result(shop.hu_results[1], "HU1", digest=history.dataset_digest(shop.hu[1]))
    with history.Store(store) as s:
        with pytest.warns(history.AlreadyRecorded, match="already recorded"):
            i = s.add(r, machine_id="HU1")
        assert i == 2 and len(s) == 2
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            j = s.add(history.calibration_from_result(shop.hu_results[1], "HU1", digest=r.digest), "HU1",
                      replace=True)
        assert j != 2 and len(s) == 2


# ---------------------------------------------------------------------------
# compare across machines
# ---------------------------------------------------------------------------
def test_compare_refuses_calibrations_of_different_machines(shop, store, capsys):
    capsys.readouterr()
    assert main(["history", "compare", shop.hu_results[0], shop.c600_result]) == 2
    _refused(capsys, "different machines", "A C", "B C")
    assert main(["history", "compare", shop.hu_results[0], shop.c600_result, "--machine", C600U]) == 2
    _refused(capsys, "different machines", "C600U-like")
    assert main(["history", "add", "--store", store, shop.c600_result, "--machine-id", "C1",
                 "--machine", C600U]) == 0
    assert main(["history", "add", "--store", store, shop.hu_results[0], "--machine-id", "HU2",
                 "--dataset", shop.hu[0]]) == 0
    capsys.readouterr()
    for a, b, words in (("1", "3", ["HU1", "C1"]), ("1", "4", ["machine HU1", "machine HU2"])):
        assert main(["history", "compare", "--store", store, a, b]) == 2
        _refused(capsys, "different machines", *words)
    assert main(["history", "compare", "--store", store, "1", "2"]) == 0          # one machine, two nights


# ---------------------------------------------------------------------------
# tolerances: units, sizes, names
# ---------------------------------------------------------------------------
def test_a_bare_tolerance_in_micrometres_is_refused_and_units_are_read(shop, store, capsys):
    """EX0C is −108 µm: 'EX0C=12' meant 12 µm and must not pass as 12 mm."""
    capsys.readouterr()
    assert main(["history", "trend", "--store", store, "--machine-id", "HU1", "--tolerance", "EX0C=12"]) == 2
    _refused(capsys, "--tolerance EX0C", "12um", "implausibly large")
    for tol in ("EX0C=12um", "EX0C=12µm", "EX0C=0.012mm", "EX0C=0.012"):
        assert main(["history", "trend", "--store", store, "--machine-id", "HU1", "--tolerance", tol]) == 1, tol
        assert "FAIL" in capsys.readouterr().out
    assert main(["history", "trend", "--store", store, "--machine-id", "HU1", "--tolerance",
                 "EX0C=150um,EB0C=200urad", "--volumetric-tolerance", "0.5mm"]) == 0
    out = capsys.readouterr().out
    assert "PASS" in out and "tolerance 150" in out


@pytest.mark.parametrize("tol, words", [("EX0C=-0.01", ["EX0C", "positive"]), ("EX0C=0", ["EX0C", "positive"]),
                                        ("EX0C=nan", ["EX0C", "positive"]), ("EX0C=inf", ["EX0C", "positive"]),
                                        ("EA0C=20", ["EA0C", "20urad"]), ("EX0C=12ft", ["EX0C", "'ft'"]),
                                        ("EX0C=5um/m", ["EX0C", "'um/m'"]), ("EX0Q=5um", ["EX0Q", "not a parameter"]),
                                        ("EX0C", ["NAME=VALUE"])])
def test_bad_tolerances_are_refused_by_every_command_naming_the_parameter(shop, store, capsys, tol, words):
    cmds = [["history", "trend", "--store", store, "--machine-id", "HU1"],
            ["history", "compare", "--store", store, "1", "2"],
            ["identify", shop.hu[1], "--estimate", "location", "--history", store, "--machine-id", "HU1",
             "--report", str(store) + ".rep"]]
    for cmd in cmds:
        capsys.readouterr()
        assert main([*cmd, "--tolerance", tol]) == 2, (cmd, tol)
        err = _refused(capsys, "--tolerance", *words)
        assert "fitting" not in err


@pytest.mark.parametrize("vt, word", [("-1", "positive"), ("0", "positive"), ("nan", "positive"),
                                      ("12", "12um"), ("3ft", "'ft'")])
def test_bad_volumetric_tolerances_are_refused_naming_the_option(shop, store, capsys, vt, word):
    for cmd in (["history", "trend", "--store", store, "--machine-id", "HU1"],
                ["identify", shop.hu[1], "--estimate", "location", "--history", store, "--machine-id", "HU1",
                 "--report", str(store) + ".rep"]):
        capsys.readouterr()
        assert main([*cmd, "--volumetric-tolerance", vt]) == 2, cmd
        _refused(capsys, "--volumetric-tolerance", word)


def test_identify_checks_tolerance_names_before_the_fit(shop, store, capsys):
    capsys.readouterr()
    assert main(["identify", shop.hu[1], "--estimate", "location", "--history", store, "--machine-id", "HU1",
                 "--record", "--tolerance", "EX0C=20um,EX0Q=5um"]) == 2
    err = _refused(capsys, "--tolerance", "EX0Q", "HU40T-like")
    assert "fitting" not in err
    # a parameter of the machine the fit does not estimate: said before the fit too
    assert main(["identify", shop.hu[1], "--estimate", "location", "--history", store, "--machine-id", "HU1",
                 "--record", "--tolerance", "EXX1=5um/m"]) == 2
    err = _refused(capsys, "--tolerance", "EXX1", "--estimate location")
    assert "fitting" not in err
    assert _count(store) == 2


def test_grade_and_compare_check_their_tolerances_in_python_too():
    c = history.Calibration("M", history.utc_time("2026-01-01"), ["EX0C"], np.array([-0.108]), np.eye(1) * 1e-8)
    for bad in (-0.012, 0.0, float("nan"), 12.0):
        with pytest.raises(ValueError, match="EX0C"):
            history.grade(c, {"EX0C": bad})
        with pytest.raises(ValueError, match="EX0C"):
            history.compare(c, c, tolerances={"EX0C": bad})
    assert history.grade(c, {"EX0C": "12um"}).verdict == "fail"
    assert history.grade(c, {"EX0C": 0.2}).verdict == "pass"
    with pytest.raises(ValueError, match="volumetric tolerance"):
        history.grade(c, {}, volumetric_tolerance=-1)


def test_one_tolerance_parser_reads_every_unit():
    t = tolerances.parse_tolerances(["EX0C=12um,EA0C=20urad", "EXX1=5um/m", "ECC2=10urad/rad^2",
                                     "EA0B=0.01deg", "EY0C=0.5 µm", "EXB1=3um/deg"])
    np.testing.assert_allclose([t["EX0C"], t["EA0C"], t["EXX1"], t["ECC2"], t["EA0B"], t["EY0C"], t["EXB1"]],
                               [0.012, 2e-5, 5e-6, 1e-5, np.radians(0.01), 5e-4, 3e-3 / np.radians(1)])
    with pytest.raises(ValueError, match="EX0C is given twice"):
        tolerances.parse_tolerances(["EX0C=1um", "EX0C=2um"])
    # the single-value options of other commands: rtest and ball bar programs read bare µm
    assert tolerances.parse_value("20", "--tolerance", bare_unit="um") == pytest.approx(0.02)
    assert tolerances.parse_value("0.02mm", "--tolerance", bare_unit="um") == pytest.approx(0.02)
    with pytest.raises(ValueError, match="--tolerance.*positive"):
        tolerances.parse_value("-5", "--tolerance", bare_unit="um")


def test_rtest_tolerance_reads_units_and_refuses_bad_values(capsys):
    for bad, word in (("-5", "positive"), ("5ft", "'ft'")):
        capsys.readouterr()
        assert main(["rtest", "missing.json", "--tolerance", bad]) == 2
        _refused(capsys, "--tolerance", word)


# ---------------------------------------------------------------------------
# fleet runs: a dataset of another machine fails, the run goes on
# ---------------------------------------------------------------------------
def test_a_fleet_dataset_of_another_machine_is_a_failure(shop, store, tmp_path):
    pytest.importorskip("pyarrow")
    c600 = history.calibration_from_result(shop.c600_result, "HU1", time="2026-01-05",
                                           digest=history.dataset_digest(shop.c600), source=shop.c600)
    hu = history.calibration_from_result(shop.hu_results[0], "HU3", time="2026-01-05", digest="x" * 64)
    fut = SimpleNamespace(key="k", result=lambda: ([("ok", c600, (0.0, 0.0), fivecal.Machine.load(C600U).to_dict()),
                                                    ("ok", hu, (0.0, 0.0), fleetsim.machine().to_dict())], 0.0, 0.0))
    run = fleet.FleetRun(done=0)
    with history.Store(store) as s:
        fleet._collect([fut], s, str(tmp_path / "pq"), run, 200, False, {"k": []})
        assert getattr(run, "_error", None) is None
        assert [c.machine_id for c in s.list()] == ["HU1", "HU1", "HU3"]
        assert "C600U-like" in s.failures()[-1]["error"]
    assert run.failed == 1 and "HU40T-like" in run.failures[0][1]
    back = history.read_parquet(tmp_path / "pq")          # the Parquet part went through fivecal.files
    assert [c.machine_id for c in back] == ["HU3"] and back[0].values.tobytes() == hu.values.tobytes()
    assert fleet._parquet_digests(str(tmp_path / "pq")) == {"x" * 64}


def test_identify_record_of_a_non_finite_fit_says_so_and_records_nothing(shop, store, capsys):
    from fivecal.cli.history import record_identify
    from fivecal.report.history import History

    r = fivecal.identify(fivecal.load_dataset(shop.hu[0]), "location")
    bad = SimpleNamespace(estimated=r.estimated, values={**r.values, "EB0C": float("nan")},
                          covariance=r.covariance, prior_std=r.prior_std, rms=r.rms, chi2=r.chi2, dof=r.dof,
                          chi2_p=r.chi2_p, verdict="non_finite", converged=True, undetermined=[], dataset=r.dataset)
    before = _sha(store)
    args = SimpleNamespace(procedure="", dataset=shop.hu[0], replace=False, rebuilt=False)
    capsys.readouterr()
    record_identify(args, bad, History(store, "HU1"))
    _refused(capsys, "not recorded", "EB0C")
    assert _sha(store) == before


def test_a_file_refused_as_a_store_is_not_held_as_one(tmp_path):
    junk = tmp_path / "junk.fcdb"
    junk.write_bytes(b"not a database at all" * 100)
    with pytest.raises(ValueError, match="not a calibration store"):
        history.Store(junk)
    files.write_text(junk, "replaced")          # the caller's file again, once refused
    assert junk.read_text() == "replaced"
