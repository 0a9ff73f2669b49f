"""The Beckhoff writer (python/fivecal/io/beckhoff.py): what it writes reads
back to the same values in each of its formats (channel list, ISG CSV,
Etalon exchange), a malformed line is refused by its number, and (with the
common export path on main) a simulated identification exported through the
CLI reproduces the erroneous machine through Beckhoff's own kinematics."""
from __future__ import annotations

import math
import random
from types import SimpleNamespace

import pytest

from fivecal.io import beckhoff as B


def _export(with_tables=True, seed=1):
    rng = random.Random(seed)
    P = "kinematik[91]."
    rows = []

    def add(name, new, unit="", fixed=False, old=None):
        old = new - rng.uniform(-50, 50) if old is None and not fixed else (new if old is None else old)
        rows.append({"name": name, "unit": unit, "old": old, "new": new, "change": new - old,
                     "sigma": 0.0 if fixed else abs(rng.gauss(0, 3)), "source": "test", "fixed": fixed})

    add(P + "number_of_axes", 5, fixed=True)
    for c, i in enumerate((4, 3, 0, 2, 1)):
        add(P + f"chain[{c}]", i, fixed=True)
    for j, v in enumerate((1.3e-5, -2.7e-6, 0.9999999998)):
        add(P + f"zero_orientation[{j}]", v)
    for j, v in enumerate((123.45678, -0.1, 1250003.25)):
        add(P + f"zero_position[{j}]", v, "0.0001mm")
    for i in range(5):
        add(P + f"axis[{i}].type", 2 if i >= 3 else 1, fixed=True)
        for j in range(3):
            add(P + f"axis[{i}].orientation[{j}]", rng.gauss(0, 1e-5) + (1.0 if j == i % 3 else 0.0))
        if i >= 3:
            for j in range(3):
                add(P + f"axis[{i}].point[{j}]", rng.uniform(-2e6, 2e6), "0.0001mm")
    if with_tables:
        for axis, unit, grid in (("X", "mm", [-200 + 50 * i for i in range(9)]), ("C", "deg", [-180 + 30 * i for i in range(13)])):
            for i, g in enumerate(grid):
                add(f"{axis}[{i}]", g, unit, fixed=True)
            for c in "XYZABC":
                for i in range(len(grid)):
                    add(f"E{c}{axis}[{i}]", rng.gauss(0, 10), "um" if c in "XYZ" else "urad", old=0.0)
    absorption = SimpleNamespace(model="table-table", rms=0.0021, max=0.0063)
    return SimpleNamespace(values=rows, absorption=absorption, round_trip_max_mm=3e-10, result_file="result.json",
                           date="2026-11-28 05:00 UTC")


MACHINE = SimpleNamespace(name="HU40T-like")


@pytest.mark.parametrize("with_tables", [True, False])
def test_every_file_reads_back_to_the_values_written(tmp_path, with_tables):
    exp = _export(with_tables)
    out = B.write(exp, MACHINE)
    assert set(out) == ({".lis", "_volcomp.csv", "_etalon.txt"} if with_tables else {".lis"})
    new = {r["name"]: r["new"] for r in exp.values}
    seen = {}
    for suffix, text in out.items():
        p = tmp_path / f"beckhoff{suffix}"
        p.write_text(text)
        got = B.read(p)
        assert got, suffix
        for name, v in got.items():
            assert v == new[name], (suffix, name, v, new[name])  # exact: the shortest round-trip text
        seen.update(got)
    assert set(seen) == set(new)
    lis = out[".lis"]
    for word in ("HU40T-like", "result.json", "2026-11-28", "table-table", "rms 2.100 um, max 6.300 um"):
        assert word in lis, word
    line = next(ln for ln in lis.splitlines() if ln.startswith("kinematik[91].zero_position[2]"))
    r = next(r for r in exp.values if r["name"] == "kinematik[91].zero_position[2]")
    assert f"old {B._num(r['old'])}" in line and "0.0001mm" in line and "+-" in line
    assert "fixed" in next(ln for ln in lis.splitlines() if ln.startswith("kinematik[91].chain[0]"))
    if with_tables:
        csv = out["_volcomp.csv"].splitlines()
        assert "X EXX EYX EZX EAX EBX ECX" in csv and "C EXC EYC EZC EAC EBC ECC" in csv
        assert "#" in csv  # the file break between the axes' blocks
        assert "[EYC]" in out["_etalon.txt"] and "}  // end of EYC" in out["_etalon.txt"]


def test_a_channel_list_reads_with_its_tables_beside_it(tmp_path):
    exp = _export(True)
    out = B.write(exp, MACHINE)
    for suffix, text in out.items():
        (tmp_path / f"beckhoff{suffix}").write_text(text)
    both = B.read(tmp_path / "beckhoff.lis")
    assert set(both) == {r["name"] for r in exp.values}
    assert "EXX[3]" in both and "kinematik[91].zero_position[2]" in both
    (tmp_path / "beckhoff_volcomp.csv").unlink()
    assert not any(n.startswith("E") for n in B.read(tmp_path / "beckhoff.lis"))


@pytest.mark.parametrize("suffix,bad,lineno_of", [
    (".lis", "kinematik[91].zero_position[0]  12x", "kinematik[91].zero_position[0]"),
    (".lis", "kinematik[91].zero_position[0]", "kinematik[91].zero_position[0]"),
    (".lis", "zero_position[0] 5", "kinematik[91].zero_position[0]"),
    ("_volcomp.csv", "-200 1 2 3", "-200 "),
    ("_volcomp.csv", "-200 1 2 3 4 5 nan", "-200 "),
    ("_etalon.txt", "    -200 0.1 0.2", "    -200 "),
    ("_etalon.txt", "    -200 abc", "    -200 "),
])
def test_a_malformed_line_is_refused_by_its_number(tmp_path, suffix, bad, lineno_of):
    text = B.write(_export(True), MACHINE)[suffix]
    lines = text.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.startswith(lineno_of))
    lines[i] = bad
    p = tmp_path / f"bad{suffix}"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"bad{suffix}:{i + 1}:"):
        B.read(p)


def test_a_csv_header_that_is_not_a_table_is_refused(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("// comment\nX EXX EYY\n0 1 2\n")
    with pytest.raises(ValueError, match=r"t.csv:2: expected a header"):
        B.read(p)
    p.write_text("X EXX\n0 1\n#\nX EXX\n0 2\n")
    with pytest.raises(ValueError, match=r"t.csv:5: X\[0\] given twice"):
        B.read(p)


def test_an_etalon_block_left_open_is_refused(tmp_path):
    p = tmp_path / "e.txt"
    p.write_text("[EXX]\nGridpoints = {\n  0 0.1\n  10 0.2\n")
    with pytest.raises(ValueError, match=r"not closed"):
        B.read(p)
    p.write_text("[C0B]\nVALUE = 0.000022355737\n[EXY]\nGridpoints = {\n -280.0 -0.001358635132\n}  // end\n")
    assert B.read(p) == {"C0B": 0.000022355737, "Y[0]": -280.0, "EXY[0]": -0.001358635132}


def test_the_manuals_isg_csv_example_reads():
    """TF5280 'ISG CSV format' (infosys page 296429067): component errors of X."""
    import tempfile, os
    text = ("// The header contains the argument \"X\" and component errors.\n"
            "X EXX EYX EZX EAX EBX ECX\n0.0 0.02 0.01 0.07 0.00 0.0042 0.003\n10.0 0.00 -0.1 0.01 0.00 0.0011 0.002\n")
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "vc.csv")
        with open(p, "w") as f:
            f.write(text)
        got = B.read(p)
    assert got["X[1]"] == 10.0 and got["EYX[1]"] == -0.1 and got["ECX[0]"] == 0.003 and len(got) == 14


def _common_path_present():
    from fivecal import _core
    from fivecal.cli import export as E
    return hasattr(_core, "vendor_export") and "beckhoff" in E.WRITERS and "beckhoff" in _core.vendor_names()


HU40T = "examples/machines/hu40t.json"
OPTS = {"syntax": "kinematik", "axes": "XYZBC", "tool_length": "0"}
TABLES = {"volcomp": "error", "volcomp_units": "um,urad", "volcomp_frame": "carriage", "grid.X": "-200:200:10",
          "grid.Y": "-200:200:10", "grid.Z": "-200:200:10", "grid.B": "-90:90:5", "grid.C": "-180:180:5"}


def _cli(tmp_path, errors, opts, out, *extra, machine=HU40T):
    import subprocess
    import sys
    res = tmp_path / "errors.json"
    import json
    res.write_text(json.dumps(errors))
    sets = [x for k, v in opts.items() for x in ("--set", f"{k}={v}")]
    return subprocess.run([sys.executable, "-m", "fivecal", "export", "beckhoff", str(res), "--machine", machine,
                           "--force", "--out", str(tmp_path / out)] + sets + list(extra),
                          capture_output=True, text=True)


def _check_reproduces(tmp_path, out, errors, opts):
    """The file's new values, through Beckhoff's own kinematics (C++), give the
    erroneous machine's tool points up to the work offset."""
    import json

    import numpy as np

    import fivecal
    from fivecal.io import controllers as K

    vals = B.read(tmp_path / out / "beckhoff.lis")
    names = [v["name"] for v in json.loads((tmp_path / out / "export.json").read_text())["values"]]
    v = np.array([vals[n] for n in names])
    m = fivecal.Machine.load(HU40T)
    rng = np.random.default_rng(1)
    axes = {"X": rng.uniform(-100, 100, 80), "Y": rng.uniform(-100, 100, 80), "Z": rng.uniform(-100, 100, 80),
            "B": rng.uniform(-90, 90, 80), "C": rng.uniform(-180, 180, 80), "S": np.zeros(80)}
    d = K.vendor_tool_points(m, "beckhoff", v, axes, opts) - m.tool_point(axes, errors=errors)
    d -= d.mean(axis=0)
    return np.abs(d).max()


@pytest.mark.skipif(not _common_path_present(), reason="the common vendor export path is not on this branch yet")
def test_cli_export_reproduces_the_erroneous_machine(tmp_path):
    """Pivot errors exported through the CLI: exit 0, and the file's values
    reproduce the erroneous machine through Beckhoff's kinematics to 1 um; a
    wrong option or an unsupported machine exits 2 naming it."""
    errors = {"EX0C": 0.02, "EY0C": -0.015, "EX0B": 0.01, "EZ0B": -0.02}  # tip.* is set-up: never exported
    run = _cli(tmp_path, errors, OPTS, "out")
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["beckhoff.lis", "export.json"]
    assert _check_reproduces(tmp_path, "out", errors, OPTS) < 1e-3
    bad = _cli(tmp_path, errors, dict(OPTS, colour="red"), "o2")
    assert bad.returncode == 2 and "'colour': not a beckhoff option" in bad.stderr
    missing = _cli(tmp_path, errors, {k: v for k, v in OPTS.items() if k != "axes"}, "o3")
    assert missing.returncode == 2 and "--set axes=" in missing.stderr
    import json
    four_axis = tmp_path / "four.json"
    four_axis.write_text(json.dumps({"name": "4ax", "topology": "wCfXYZSt", "axes": {
        "C": {"type": "rotary", "direction": [0, 0, -1]}, "X": {"type": "linear", "direction": [1, 0, 0]},
        "Y": {"type": "linear", "direction": [0, 1, 0]}, "Z": {"type": "linear", "direction": [0, 0, 1]},
        "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [0, 0, 50]}}))
    four = _cli(tmp_path, {"EX0C": 0.02}, dict(OPTS, axes="XYZC"), "o4", machine=str(four_axis))
    assert four.returncode == 2 and "not supported" in four.stderr


@pytest.mark.skipif(not _common_path_present(), reason="the common vendor export path is not on this branch yet")
def test_cli_export_with_tables_reproduces_error_motions(tmp_path):
    """Pivots and error motions: the kinematics take the pivots, the TF5280
    tables the error motions; both files through Beckhoff's kinematics give the
    erroneous machine to 1 um; --old reads the export back (change 0)."""
    errors = {"EX0C": 0.02, "EY0C": -0.015, "EX0B": 0.01, "EXX1": 2e-5, "EYX2": 1e-7, "ECC1": 1e-5,
              "EZY3": 1e-9, "EAZ1": 5e-8}
    opts = dict(OPTS, **TABLES)
    run = _cli(tmp_path, errors, opts, "out")
    assert run.returncode == 0, run.stderr
    assert {"beckhoff.lis", "beckhoff_volcomp.csv", "beckhoff_etalon.txt"} <= {p.name for p in (tmp_path / "out").iterdir()}
    assert _check_reproduces(tmp_path, "out", errors, opts) < 1e-3
    without = _cli(tmp_path, errors, OPTS, "kin_only")
    assert without.returncode == 0, without.stderr
    assert _check_reproduces(tmp_path, "kin_only", errors, OPTS) > 5e-3  # the error motions are left
    again = _cli(tmp_path, errors, opts, "again", "--old", str(tmp_path / "out" / "beckhoff.lis"))
    assert again.returncode == 0, again.stderr
    import json
    rec = json.loads((tmp_path / "again" / "export.json").read_text())
    new = {v["name"]: v["new"] for v in json.loads((tmp_path / "out" / "export.json").read_text())["values"]}
    for v in rec["values"]:
        assert v["old"] == pytest.approx(new[v["name"]], abs=1e-9)


@pytest.mark.skipif(not _common_path_present(), reason="the common vendor export path is not on this branch yet")
def test_a_fine_table_grid_exports_in_seconds_with_every_values_sigma():
    """About 9,000 table values (1 mm linear grid): the export, the files and
    export.json in well under 10 s (42 s when the values x values covariance
    was kept); the σ of each table value is still its definition, the
    polynomial's variance on the grid (EXX on X: 1000 (q, q², q³) C (q, q², q³)ᵀ
    in µm²), and export.json says the tables are not for a sphere check."""
    import json
    import time

    import numpy as np

    import fivecal
    from fivecal.io import controllers as K

    m = fivecal.Machine.load(HU40T)
    names = m.parameter_names()
    opts = {**OPTS, **TABLES, "grid.X": "-200:200:1", "grid.Y": "-200:200:1", "grid.Z": "-200:200:1"}
    errors = {"EX0C": 0.02, "EXX1": 2e-5, "EXX2": 1e-7, "ECC1": 1e-5}
    motions = [i for i, n in enumerate(names) if len(n) == 4 and n[0] == "E" and n[3] in "123"]
    cov = np.zeros((len(names), len(names)))
    cov[motions, motions] = 1e-14
    exx = [names.index(f"EXX{d}") for d in (1, 2, 3)]
    s = np.array([1e-6, 1e-8, 1e-10])
    cov[np.ix_(exx, exx)] = (0.5 + 0.5 * np.eye(3)) * np.outer(s, s)
    cov[names.index("EX0C"), names.index("EX0C")] = 1e-6
    start = time.perf_counter()
    exp = K.vendor_export(m, "beckhoff", errors, cov, options=opts)
    files = B.write(exp, m)
    rec = json.dumps(exp.record())
    took = time.perf_counter() - start
    assert len(exp.values) > 8000
    assert took < 10.0, f"{len(exp.values)} values exported in {took:.1f} s"
    grid = {v["name"]: v["new"] for v in exp.values if v["name"].startswith("X[")}
    checked = 0
    for v in exp.values:
        if v["name"].startswith("EXX["):
            q = grid["X[" + v["name"][4:]]
            g = np.array([q, q * q, q ** 3])
            want = 1e3 * math.sqrt(g @ cov[np.ix_(exx, exx)] @ g)
            assert v["sigma"] == pytest.approx(want, rel=1e-6, abs=1e-9), v["name"]
            checked += 1
    assert checked == 401
    assert len(exp.covariance_names) == len(exp.values) - sum(v["motion_table"] for v in exp.values)
    assert exp.covariance.shape == (len(exp.covariance_names),) * 2
    assert {".lis", "_volcomp.csv", "_etalon.txt"} <= set(files)
    sc = json.loads(rec)["sphere_check"]
    assert sc["verifies"] == "kinematics" and sc["unverifiable_values"] > 7000
    assert "error-motion table" in sc["unverifiable"]
