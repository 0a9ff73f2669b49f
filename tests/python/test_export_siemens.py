"""The Siemens swivel data record as a part program (fivecal.io.siemens): the
text parses back to the values written, old values and changes sit beside the
new ones, and malformed programs are refused by line."""
import json
import math
import pathlib

import numpy as np
import pytest

from fivecal import Machine
from fivecal.io import siemens

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples" / "machines"


def _export(record=2):
    """An export of a type P record: I2, I3, I4, V1, V2, the type."""
    vals = []
    news = [0.0123456789, -0.004, -120.0311, 0.0, 0.0021, 120.0277, -0.0123456789, 0.0019, 0.0034,
            1e-5, -0.99999999995, 2e-6, -3.3e-5, 4e-6, -0.99999999945]
    numbers = [4, 5, 6, 15, 16, 17, 18, 19, 20, 7, 8, 9, 10, 11, 12]
    for i, (k, new) in enumerate(zip(numbers, news)):
        unit = "" if 7 <= k <= 12 else "mm"
        old = round(new, 2) if unit == "mm" else round(new)
        sigma = math.nan if i == 4 else (1.1e-3 if unit == "mm" else 2e-6)
        vals.append({"name": f"$TC_CARR{k}[{record}]", "unit": unit, "old": old, "new": new,
                     "change": new - old, "sigma": sigma, "source": "manual", "fixed": False})
    vals.append({"name": f"$TC_CARR23[{record}]", "unit": "", "old": 80.0, "new": 80.0, "change": 0.0,
                 "sigma": 0.0, "source": "manual", "fixed": True})
    return {"values": vals, "result": "result.json", "date": "2026-11-28 05:30 UTC",
            "absorption": {"model": "table-table", "rms": 0.0012, "max": 0.0034, "rms_old": 0.021, "max_old": 0.05},
            "round_trip_max": 2e-10}


def test_the_program_reads_back_as_written(tmp_path):
    exp = _export()
    m = Machine.load(str(EXAMPLES / "hu40t.json"))
    out = siemens.write(exp, m)
    assert list(out) == [".MPF"]
    text = out[".MPF"]
    back = siemens.parse(text)
    assert set(back) == {v["name"] for v in exp["values"]}
    for v in exp["values"]:
        tol = 5e-7 if v["unit"] == "mm" else 5e-10
        assert back[v["name"]] == pytest.approx(v["new"], abs=tol), v["name"]
    assert back["$TC_CARR23[2]"] == ord("P")
    # old beside new, the change and its sigma, the header's facts
    assert "$TC_CARR4[2]=0.012346 ; old 0.010000, change +2.35 um +- 1.10 um (1 sigma)" in text
    assert "1 sigma not determined" in text
    assert '$TC_CARR23[2]="P" ; kinematics type, old "P"' in text
    for fact in ("HU40T-like (wCBXfZYSt)", "type P (swivel table)", "result result.json",
                 "rms 1.20 um, max 3.40 um", "rms 21.00 um, max 50.00 um", "within 0.00 um", "table-table"):
        assert fact in text, fact
    assert text.rstrip().endswith("M30 ; end of program")
    # every statement is a comment, an assignment or the end
    for line in text.splitlines():
        assert line.startswith(";") or line.startswith("$TC_CARR") or line.startswith("M30"), line


def test_read_takes_a_file_with_block_numbers_and_several_assignments(tmp_path):
    p = tmp_path / "OLD.MPF"
    p.write_text("%_N_OLD_MPF\n;PATH=/_N_MPF_DIR\nN100 $TC_CARR10[2]=0 $TC_CARR11[2]=0\n"
                 "N110 $TC_CARR12[2]=1 ; C axis\nN120 $TC_CARR21[2]=X\nN130 $TC_CARR23[2]=\"m\"\n"
                 "N135 $TC_CARR34[2]=\"HEAD\"\n\nN140 $TC_CARR4[2]=-1.5E2\nN150 $TC_CARR13[2]=30\n"
                 "N160 $TC_CARR41[2]=0.002 $TC_CARR24[2]=0\nM30\n")
    # the record's geometry; angles, fine offsets, names are not what --old compares
    assert siemens.read(p) == {"$TC_CARR10[2]": 0.0, "$TC_CARR11[2]": 0.0, "$TC_CARR12[2]": 1.0,
                               "$TC_CARR23[2]": float(ord("M")), "$TC_CARR4[2]": -150.0}
    # a vector the type does not use: dropped when 0, refused otherwise
    p.write_text('$TC_CARR23[1]="P"\n$TC_CARR1[1]=0\n$TC_CARR4[1]=5\n')
    assert siemens.read(p) == {"$TC_CARR23[1]": float(ord("P")), "$TC_CARR4[1]": 5.0}
    p.write_text('$TC_CARR23[1]="T"\n$TC_CARR19[1]=2.5\n')
    with pytest.raises(ValueError, match=r"line 2: \$TC_CARR19\[1\]=2.5: I4 of a type T record is not 0"):
        siemens.read(p)


@pytest.mark.parametrize("text,message", [
    ("$TC_CARR4[1]=1\nG0 X10\n", "line 2: 'G0 X10' is not an assignment"),
    ("$TC_CARR4[1]=1 X10\n", "line 1: '$TC_CARR4[1]=1 X10' is not an assignment"),
    ("$TC_CARR4[1]=abc\n", "line 1: $TC_CARR4[1]=abc: not a number"),
    ("$TC_CARR4[1]=nan\n", "line 1: $TC_CARR4[1]=nan: not a finite number"),
    ("$TC_CARR23[1]=\"Q\"\n", "the kinematics type T, P or M"),
    ("$TC_CARR4[1]=1\n$TC_CARR4[1]=2\n", "line 2: $TC_CARR4[1] is set again (first on line 1)"),
    ("$TC_CARR24[1]=90\n", "line 1: $TC_CARR24[1]=90: a rotary axis offset other than 0"),
    ("; only a comment\n", "no $TC_CARRk[n]=value assignment"),
])
def test_malformed_programs_are_refused_by_line(tmp_path, text, message):
    p = tmp_path / "BAD.MPF"
    p.write_text(text)
    with pytest.raises(ValueError) as e:
        siemens.read(p)
    assert message in str(e.value)
    assert "BAD.MPF" in str(e.value)


def test_an_export_without_a_type_letter_is_refused():
    exp = _export()
    exp["values"][-1]["new"] = 81.0
    with pytest.raises(ValueError, match="codes no kinematics type T, P or M"):
        siemens.write(exp, Machine.load(str(EXAMPLES / "hu40t.json")))


def test_an_export_naming_two_records_is_refused():
    exp = _export()
    exp["values"][0]["name"] = "$TC_CARR4[3]"
    with pytest.raises(ValueError, match="swivel data records; one expected"):
        siemens.write(exp, Machine.load(str(EXAMPLES / "hu40t.json")))


# ---- end to end: a simulated identification through the record and back ----

TRUE = {"EX0C": 0.03, "EY0C": -0.02, "EY0A": 0.015, "EZ0A": -0.012,
        "EA0C": 3e-5, "EB0C": -2e-5, "EB0A": 2.5e-5, "EC0A": -1.5e-5}
RECORD = {"record": "1"}


def _identification(m, seed):
    """R-test K1..K4 at three nests (positions measured, so fixed) on a c600u
    with pivot and direction errors, 0.5 um noise; identify them."""
    import fivecal
    from fivecal.procedures import rtest
    plan, setups = [], ("R1", "R2", "R3")
    for ball, setup in zip(([80, 30, 10], [-60, -50, 150], [0, 90, 80]), setups):
        for t in rtest.TESTS:
            plan += rtest.plan(m, t, table_ball=ball, step=30, setup=setup)
    ds = fivecal.simulate(m, plan, errors=TRUE, sigma={"ball3d": 0.0005}, seed=seed)
    r = fivecal.identify(ds, estimate=list(TRUE), fix=[f"ball3d.{s}.table.{c}" for s in setups for c in "xyz"])
    assert r.converged and not r.undetermined
    return r


def _identified(m, seed):
    """The identified errors and their covariance (machine parameters)."""
    r = _identification(m, seed)
    nt = m._core.num_parameters
    idx = [m._core.parameter_index(n) for n in r.estimated]
    cov = np.zeros((nt, nt))
    cov[np.ix_(idx, idx)] = r.covariance
    return m.theta(r.values), cov


def _rigid_fit(a, b):
    """a moved onto b by the best rigid motion (the work offset a user probes)."""
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((b - cb).T @ (a - ca))
    rot = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    return (rot @ (a - ca).T).T + cb


def _as_export(ex):
    values = [dict(v, old=o, new=n, change=c, sigma=s) for v, o, n, c, s in
              zip(ex["values"], ex["old"], ex["new"], ex["change"], ex["sigma"])]
    return {"values": values, "absorption": ex["absorption"], "round_trip_max": ex["round_trip_max"],
            "result": "simulated"}


def test_a_simulated_identification_exported_reproduces_the_machine(tmp_path):
    from fivecal import _core
    from fivecal.io import controllers as K
    m = Machine.load(str(EXAMPLES / "c600u.json"))
    theta, cov = _identified(m, seed=1)
    grid = K.pose_grid(m)
    q = m.axes_matrix(grid)
    ex = _core.vendor_export("siemens", m._core, theta, cov, q, RECORD, np.zeros(0))
    assert ex["round_trip_max"] < 1e-9 and ex["absorption"]["max"] < 1e-9
    p = tmp_path / "siemens.MPF"
    p.write_text(siemens.write(_as_export(ex), m)[".MPF"])
    back = siemens.read(p)
    new = np.array([back[v["name"]] for v in ex["values"]])
    assert np.abs(new - np.asarray(ex["new"])).max() < 1e-6
    # the file's values, through the record's own transformation, are the
    # erroneous machine up to the work offset; the old record misses by ~50 um
    truth = m.tool_point(grid, errors=TRUE)
    sie = np.asarray(_core.vendor_tool_points("siemens", m._core, new, q, RECORD))
    assert np.linalg.norm(sie - _rigid_fit(truth, sie), axis=1).max() < 1e-3
    old = np.asarray(_core.vendor_tool_points("siemens", m._core, np.asarray(ex["old"]), q, RECORD))
    assert np.linalg.norm(old - _rigid_fit(truth, old), axis=1).max() > 0.02


def test_the_records_sigma_covers_the_true_record():
    """Over repeated simulations the new values sit within 3 sigma of the
    record of the true machine (the record Map gives for the true errors)."""
    from fivecal import _core
    from fivecal.io import controllers as K
    m = Machine.load(str(EXAMPLES / "c600u.json"))
    q = m.axes_matrix(K.pose_grid(m))
    truth = np.asarray(_core.vendor_values("siemens", m._core, m.theta(TRUE), RECORD)["map"])
    z = []
    for seed in range(1, 9):
        theta, cov = _identified(m, seed)
        ex = _core.vendor_export("siemens", m._core, theta, cov, q, RECORD, np.zeros(0))
        s = np.asarray(ex["sigma"])
        live = s > 0
        z.extend(((np.asarray(ex["new"]) - truth)[live] / s[live]).tolist())
    z = np.abs(np.array(z))
    assert len(z) == 8 * 15
    assert np.mean(z < 3) >= 0.95 and z.max() < 5, np.sort(z)[-5:]
    assert np.mean(z < 1) > 0.5  # and sigma is not inflated


def test_the_export_refuses_without_a_record_number_or_with_an_unknown_option():
    from fivecal import _core
    m = Machine.load(str(EXAMPLES / "hu40t.json"))
    th = np.zeros(m._core.num_parameters)
    q = np.zeros((3, len(m.axis_names)))
    with pytest.raises(ValueError, match="option record: state the number n"):
        _core.vendor_export("siemens", m._core, th, np.zeros((0, 0)), q, {}, np.zeros(0))
    with pytest.raises(ValueError, match="option 'sign'"):
        _core.vendor_export("siemens", m._core, th, np.zeros((0, 0)), q, {"record": "1", "sign": "-"}, np.zeros(0))


def test_cli_export_siemens_end_to_end(tmp_path, capsys):
    """fivecal export siemens on a simulated identification's result document:
    exit 0, the .MPF reads back, its values reproduce the erroneous machine
    up to the work offset through the record's own transformation; --old with
    that file gives the same change; a missing or unknown option exits 2."""
    from fivecal import _core
    from fivecal.cli import main
    from fivecal.identification import result_document
    from fivecal.io import controllers as K
    m = Machine.load(str(EXAMPLES / "c600u.json"))
    # the identification's result document, as `fivecal identify --out` writes it
    r = _identification(m, seed=3)
    res = tmp_path / "result.json"
    res.write_text(json.dumps(result_document(r)))
    machine = str(EXAMPLES / "c600u.json")
    out = tmp_path / "out"
    rc = main(["export", "siemens", str(res), "--machine", machine, "--out", str(out), "--set", "record=1"])
    text = capsys.readouterr().out
    assert rc == 0, text
    mpf = (out / "siemens.MPF").read_text()
    assert "swivel data record 1" in mpf and "result " + str(res) in mpf
    # the kinematics type as the record and the .MPF show it: the letter, not its code
    assert '$TC_CARR23[1]="P"' in mpf.replace(" ", "")
    type_line = next(ln for ln in text.splitlines() if ln.startswith("$TC_CARR23[1]"))
    assert type_line.split()[1] == "P" and "80" not in type_line, type_line
    assert "within 0.00 um" in mpf and "nan" not in mpf and "=-0.000000 " not in mpf
    rec = json.loads((out / "export.json").read_text())
    back = siemens.read(out / "siemens.MPF")
    assert set(back) == {v["name"] for v in rec["values"]}
    new = np.array([back[v["name"]] for v in rec["values"]])
    grid = K.pose_grid(m)
    q = m.axes_matrix(grid)
    sie = np.asarray(_core.vendor_tool_points("siemens", m._core, new, q, RECORD))
    truth = m.tool_point(grid, errors=TRUE)
    assert np.linalg.norm(sie - _rigid_fit(truth, sie), axis=1).max() < 1e-3
    # the controller now runs that file: exporting the same result against it changes the same
    out2 = tmp_path / "out2"
    rc = main(["export", "siemens", str(res), "--machine", machine, "--out", str(out2), "--set", "record=1",
               "--old", str(out / "siemens.MPF"), "--force"])
    assert rc == 0, capsys.readouterr().out
    rec2 = json.loads((out2 / "export.json").read_text())
    for a, b in zip(rec["values"], rec2["values"]):
        assert b["change"] == pytest.approx(a["change"], abs=1e-12) and b["old"] == pytest.approx(a["new"], abs=1e-6)
    # refusals: exit 2 with the message
    for extra, message in (([], "option record: state the number n"), (["--set", "record=1", "--set", "sign=-"],
                                                                       "option 'sign'"),
                           (["--set", "record=first"], "'first' is not a swivel data record number")):
        rc = main(["export", "siemens", str(res), "--machine", machine, "--out", str(tmp_path / "bad"), *extra])
        err = capsys.readouterr().err
        assert rc == 2 and message in err, (rc, err)
    # a machine without a swivel data record's topology
    one = tmp_path / "4axis.json"
    one.write_text(json.dumps({"name": "4ax", "topology": "wCfXYZSt", "axes": {
        "C": {"type": "rotary", "direction": [0, 0, -1]}, "X": {"type": "linear", "direction": [1, 0, 0]},
        "Y": {"type": "linear", "direction": [0, 1, 0]}, "Z": {"type": "linear", "direction": [0, 0, 1]},
        "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [0, 0, 100]}}))
    errs = tmp_path / "errors.json"
    errs.write_text(json.dumps({"EX0C": 0.01}))
    rc = main(["export", "siemens", str(errs), "--machine", str(one), "--out", str(tmp_path / "bad"),
               "--set", "record=1", "--force"])
    err = capsys.readouterr().err
    assert rc == 2 and "has 1 rotary axes" in err, err
