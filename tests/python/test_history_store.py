"""Calibration store (issue 18, item 1): bit-exact round trip, two writers at
once, versioned migrations, result.json input, Parquet export, CLI."""
from __future__ import annotations

import copy
import json
import multiprocessing as mp
import sqlite3

import numpy as np
import pytest

import fivecal
from fivecal import history
from fivecal.cli import main
from fivecal.history import fleetsim


@pytest.fixture(scope="module")
def result():
    m = fleetsim.machine()
    ds = fivecal.simulate(m, fleetsim.sphere_check_plan(m), errors={"EX0C": 0.01},
                          artefact={"spheres": [fleetsim.SPHERE]}, tip_radius=3.0, sigma=0.0006, seed=3)
    return fivecal.identify(ds, "location")


def test_round_trip_is_bit_exact(tmp_path, result):
    path = tmp_path / "s.fcdb"
    with history.Store(path) as s:
        i = s.add(result, machine_id="M1", procedure="sphere", time="2026-01-02T03:04:05Z")
    with history.Store(path) as s:
        c = s.get(i)
        assert s.schema_version == history.SCHEMA_VERSION
        assert s.machine("M1").to_dict() == result.dataset.machine.to_dict()
    assert c.names == result.estimated
    assert c.values.tobytes() == np.array([result.values[n] for n in result.estimated]).tobytes()
    assert c.covariance.tobytes() == np.ascontiguousarray(result.covariance, dtype=float).tobytes()
    assert c.prior_std.tobytes() == np.array([result.prior_std[n] for n in result.estimated]).tobytes()
    assert c.time == "2026-01-02T03:04:05Z" and c.procedure == "sphere" and c.machine_id == "M1"
    assert c.digest == history.dataset_digest(result.dataset) and len(c.digest) == 64
    assert c.verdict == result.verdict and c.converged and c.chi2 == result.chi2 and c.dof == result.dof
    assert c.fivecal_version == fivecal.__version__


def test_times_order_by_instant_not_by_text(tmp_path, result):
    """'...:05.5Z' is after '...:05Z' although it sorts before it as text."""
    with history.Store(tmp_path / "t.fcdb") as s:
        # two datasets (digests): the same one twice would be one calibration
        late = s.add(result, machine_id="M1", time="2026-01-02T03:04:05.500000Z", digest="a" * 64)
        early = s.add(result, machine_id="M1", time="2026-01-02T03:04:05Z", digest="b" * 64)
        assert [c.id for c in s.list(machine_id="M1")] == [early, late]
        assert [c.id for c in s.list(since="2026-01-02T03:04:05.2Z")] == [late]
        assert [c.id for c in s.list(until="2026-01-02T03:04:05.2Z")] == [early]


def test_digest_ignores_layout_not_content(tmp_path, result):
    d = copy.deepcopy(result.dataset.to_dict())     # to_dict hands out the dataset's own cached dict
    (tmp_path / "a.json").write_text(json.dumps(d, indent=4))
    (tmp_path / "b.json").write_text(json.dumps(d, sort_keys=True, separators=(",", ":")))
    assert history.dataset_digest(tmp_path / "a.json") == history.dataset_digest(tmp_path / "b.json")
    (tmp_path / "c.json").write_text(json.dumps({k: d[k] for k in reversed(list(d))}))   # key order
    assert history.dataset_digest(tmp_path / "c.json") == history.dataset_digest(result.dataset)
    d["observations"][0]["axes"]["X"] += 1e-6
    assert history.dataset_digest(d) != history.dataset_digest(tmp_path / "a.json")


def test_result_json_is_accepted(tmp_path, result):
    result.save(tmp_path / "r.json")
    with history.Store(tmp_path / "s.fcdb") as s:
        i = s.add(str(tmp_path / "r.json"), machine_id="M1", time="2026-01-01")
        c = s.get(i)
    j = result.estimated.index("EX0C")
    assert c.values[j] == result.values["EX0C"]
    np.testing.assert_allclose(c.covariance, result.covariance, rtol=1e-9, atol=1e-30)
    assert c.time == "2026-01-01T00:00:00Z" and c.source.endswith("r.json")


def _writer(path, tag, n):
    rng = np.random.default_rng(tag)
    with history.Store(path, timeout=60) as s:
        for i in range(n):
            v = rng.normal(size=3)
            s.add_many([history.Calibration(machine_id=f"W{tag}", time=f"2026-01-01T00:00:{i % 60:02d}Z",
                                            names=["EX0C", "EY0C", "EB0C"], values=v, covariance=np.diag(v ** 2),
                                            digest=f"{tag}-{i}")])


def test_two_processes_writing_at_once_lose_nothing(tmp_path):
    path = str(tmp_path / "s.fcdb")
    history.Store(path).close()
    ctx = mp.get_context("spawn")
    ps = [ctx.Process(target=_writer, args=(path, t, 150)) for t in (1, 2)]
    for p in ps:
        p.start()
    for p in ps:
        p.join(120)
        assert p.exitcode == 0
    with history.Store(path) as s:
        assert len(s) == 300
        assert {c.digest for c in s.list("W1")} == {f"1-{i}" for i in range(150)}
        assert {c.digest for c in s.list("W2")} == {f"2-{i}" for i in range(150)}
        assert s._db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_a_store_of_the_previous_schema_opens_and_is_migrated(tmp_path):
    # what fivecal with schema 1 wrote: its creation SQL is kept in MIGRATIONS
    path = tmp_path / "v1.fcdb"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE schema_version (version INTEGER NOT NULL, applied TEXT NOT NULL, "
               "fivecal_version TEXT NOT NULL)")
    db.executescript(dict(history.MIGRATIONS)[1])
    db.execute("INSERT INTO schema_version VALUES (1, '2026-01-01T00:00:00Z', '0.0.9')")
    v = np.array([0.0123, -4.5e-6])
    C = np.array([[1e-8, 2e-13], [2e-13, 4e-12]])
    db.execute("INSERT INTO calibrations (machine_id, time, procedure, digest, names, \"values\", covariance, "
               "fixed, rms, chi2, verdict, converged, undetermined, fivecal_version) "
               "VALUES ('M7', '2026-01-01T00:00:00Z', 'sphere', 'abc', ?, ?, ?, '{}', 0.0006, 250.0, 'ok', 1, "
               "'[]', '0.0.9')", (json.dumps(["EX0C", "EB0C"]), v.tobytes(), C.tobytes()))
    db.commit()
    db.close()
    with history.Store(path) as s:
        assert s.schema_version == history.SCHEMA_VERSION == 4
        (c,) = s.list("M7")
        assert c.values.tobytes() == v.tobytes() and c.covariance.tobytes() == C.tobytes()
        assert c.prior_std is None and c.dof is None and c.fivecal_version == "0.0.9"
        assert c.uncertainty == "gum"                   # v3's default for older rows
        assert s.failures() == []                       # the v2 table exists
        assert s.rebuilds("M7") == []                   # and v4's
        s.add_many([history.Calibration("M7", "2026-01-02", ["EX0C"], np.array([0.0124]), np.eye(1) * 1e-8,
                                        prior_std=np.array([0.1]), dof=3)])
        assert [c.dof for c in s.list("M7")] == [None, 3]
    versions = [r[0] for r in sqlite3.connect(path).execute("SELECT version FROM schema_version ORDER BY version")]
    assert versions == [1, 2, 3, 4]


def test_a_store_of_a_newer_fivecal_is_refused(tmp_path):
    path = tmp_path / "s.fcdb"
    history.Store(path).close()
    db = sqlite3.connect(path)
    db.execute("INSERT INTO schema_version VALUES (99, 'x', '9.0')")
    db.commit()
    db.close()
    with pytest.raises(ValueError, match="newer fivecal"):
        history.Store(path)
    (tmp_path / "junk.fcdb").write_bytes(b"not a database at all" * 100)
    with pytest.raises(ValueError, match="not a calibration store"):
        history.Store(tmp_path / "junk.fcdb")


def test_parquet_export_round_trip(tmp_path, result):
    pytest.importorskip("pyarrow")
    with history.Store(tmp_path / "s.fcdb") as s:
        s.add(result, machine_id="M1", time="2026-01-01")
        s.add(result, machine_id="M2", time="2026-01-02")
        s.export_parquet(tmp_path / "x.parquet")
        back = history.read_parquet(tmp_path / "x.parquet")
        orig = s.list()
    assert [c.machine_id for c in back] == ["M1", "M2"]
    for a, b in zip(orig, back):
        assert a.values.tobytes() == b.values.tobytes() and a.covariance.tobytes() == b.covariance.tobytes()


def test_missing_pyarrow_names_the_extra(tmp_path, monkeypatch):
    import builtins

    real = builtins.__import__

    def no_arrow(name, *a, **k):
        if name.startswith("pyarrow"):
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_arrow)
    with history.Store(tmp_path / "s.fcdb") as s, pytest.raises(ValueError, match=r"fivecal\[arrow\]"):
        s.export_parquet(tmp_path / "x.parquet")


@pytest.fixture(scope="module")
def result2():
    """Another night of the same machine (another noise draw)."""
    m = fleetsim.machine()
    ds = fivecal.simulate(m, fleetsim.sphere_check_plan(m), errors={"EX0C": 0.01},
                          artefact={"spheres": [fleetsim.SPHERE]}, tip_radius=3.0, sigma=0.0006, seed=4)
    return fivecal.identify(ds, "location")


def test_cli_add_list_show_export(tmp_path, result, result2, capsys):
    pytest.importorskip("pyarrow")
    result.save(tmp_path / "r.json")
    result2.save(tmp_path / "r2.json")
    db = str(tmp_path / "s.fcdb")
    assert main(["history", "add", "--store", db, str(tmp_path / "r.json"), "--machine-id", "M9", "--procedure", "sphere",
                 "--time", "2026-03-01T02:00:00Z", "--machine", str(tmp_path / "m.json")]) == 2
    assert main(["history", "add", "--store", db, str(tmp_path / "r.json"), "--machine-id", "M9", "--procedure", "sphere",
                 "--time", "2026-03-01T02:00:00Z"]) == 0
    assert main(["history", "add", "--store", db, str(tmp_path / "r2.json"), "--machine-id", "M9",
                 "--time", "2026-03-02T02:00:00Z"]) == 0
    capsys.readouterr()
    assert main(["history", "list", "--store", db]) == 0
    out = capsys.readouterr().out
    assert "M9" in out and "2026-03-01T02:00:00Z" in out and "2026-03-02" in out
    assert main(["history", "show", "--store", db, "1", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["parameters"]["EX0C"]["value"] == result.values["EX0C"]
    assert main(["history", "compare", "--store", db, "1", "2"]) == 0
    out = capsys.readouterr().out
    assert "EX0C" in out and "covariance term is 0" in out
    assert main(["history", "export", "--store", db, str(tmp_path / "o.parquet")]) == 0
    assert len(history.read_parquet(tmp_path / "o.parquet")) == 2
    # the result of night 2 again, now with its dataset: the same values, so already recorded ...
    fivecal.save_dataset(result2.dataset, tmp_path / "ds.json")
    capsys.readouterr()
    assert main(["history", "add", "--store", db, str(tmp_path / "r2.json"), "--machine-id", "M9",
                 "--dataset", str(tmp_path / "ds.json")]) == 0
    assert "already recorded (calibration #2" in capsys.readouterr().err
    # ... unless replaced: then it carries the digest
    assert main(["history", "add", "--store", db, str(tmp_path / "r2.json"), "--machine-id", "M9",
                 "--dataset", str(tmp_path / "ds.json"), "--replace", "--time", "2026-03-02T02:00:00Z"]) == 0
    capsys.readouterr()
    assert main(["history", "list", "--store", db, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["digest"] for r in rows] == ["", history.dataset_digest(result2.dataset)]
    with history.Store(db) as s:      # the dataset's machine is kept for volumetric comparisons
        assert s.machine("M9").to_dict() == result2.dataset.machine.to_dict()
    assert main(["history", "show", "--store", db, "7"]) == 2
    assert "no calibration with id 7" in capsys.readouterr().err


def test_cli_trend_grades_and_failures(tmp_path, result, capsys):
    db = str(tmp_path / "s.fcdb")
    with history.Store(db) as s:
        for night in range(4):
            s.add(result, machine_id="M1", time=f"2026-01-0{night + 1}T02:00:00Z", digest=f"night{night}")
        s.add_failure("abc", "ValueError: broken", "x/2026-01-05.json", "M1")
    ex = result.values["EX0C"]
    assert main(["history", "trend", "--store", db, "--machine-id", "M1", "--tolerance", f"EX0C={ex * 2}",
                 "--plot", str(tmp_path / "t.png")]) == 0
    out = capsys.readouterr().out
    assert "EX0C        no alarm" in out and "PASS" in out and (tmp_path / "t.png").exists()
    assert main(["history", "trend", "--store", db, "--machine-id", "M1", "--tolerance", f"EX0C={ex / 2}"]) == 1
    assert "FAIL" in capsys.readouterr().out
    assert main(["history", "trend", "--store", db, "--machine-id", "M1", "--tolerance", "EX0C=-1"]) == 2
    assert main(["history", "failures", "--store", db]) == 0
    assert "x/2026-01-05.json: ValueError: broken" in capsys.readouterr().out
    assert main(["history", "list", "--store", str(tmp_path / "none.fcdb")]) == 2
    assert not (tmp_path / "none.fcdb").exists()      # reading never creates a store
