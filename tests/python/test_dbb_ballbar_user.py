"""What a ballbar user expects (issue 31): readings-only traces from the
command line, the diagnosis ranked by % of circularity with backlash split at
each end of the axes, thermal compensation, pass/fail per diagnostic, the
standards, the HTML report in Chromium, the history, and Renishaw .b5r files.

The trace is simulated from axis errors (the reading is the exact distance of
the moved ball from the pivot), not from the linear model the diagnosis fits,
and goes through the real command line in each exported form: two columns,
readings only (µm, as ballbar software exports) and a .b5r-style XML built
from the documented elements.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from fivecal import _core
from fivecal.io import b5r
from fivecal.procedures import dbb

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
R = 100.0
SIGMA = 0.0003
#: the machine: X backlash 3 µm, Y 1.5 µm, squareness 40 µrad, scale mismatch X-Y 15 µm/m
B1, B2, PSI, M = 0.003, 0.0015, 40e-6, 15e-6


def sgn(x):
    return np.where(np.abs(x) < 1e-12, 0.0, np.sign(x))


def run(s, seed, step=0.5, b1=B1, b2=B2, psi=PSI, m=M):
    n = int(round(360 / step)) + 1
    deg = s * step * np.arange(n)
    phi = np.radians(deg)
    x1c, x2c = R * np.cos(phi), R * np.sin(phi)
    v1, v2 = -s * sgn(np.sin(phi)), s * sgn(np.cos(phi))
    x1 = x1c * (1 + m) - psi * x2c + b1 * v1
    x2 = x2c + b2 * v2
    return deg, np.hypot(x1, x2) - R + np.random.default_rng(seed).normal(0.0, SIGMA, deg.size)


def cli(*args, cwd=None):
    env = dict(os.environ, PYTHONPATH=os.path.dirname(os.path.dirname(_core.__file__)))
    p = subprocess.run([sys.executable, "-m", "fivecal", *map(str, args)], capture_output=True, text=True,
                       env=env, cwd=cwd, timeout=600)
    return p.returncode, p.stdout, p.stderr


def write_forms(tmp, seed=7):
    """The two runs as two-column CSV and as readings-only µm files."""
    out = {}
    for s, name in ((-1, "ren_cw"), (1, "ren_ccw")):
        deg, r = run(s, seed if s < 0 else seed + 1)
        np.savetxt(tmp / f"{name}.csv", np.c_[deg, r], fmt="%.7f", delimiter=",", header="angle_deg,reading_mm",
                   comments="")
        np.savetxt(tmp / f"{name}.txt", r * 1e3, fmt="%.4f")  # readings only, µm, no header
        out[name] = (deg, r)
    return out


def truth_ranking():
    """The diagnoses ranked by the contribution of the true values alone."""
    t = {"backlash.1+": B1, "backlash.1-": B1, "backlash.2+": B2, "backlash.2-": B2, "squareness": PSI,
         "scale_mismatch": M}
    return sorted(t, key=lambda n: -_core.diagnosis_contribution(n, t[n], R)), t


def groups(names):
    """Ranking with the + / - ends of one axis (equal in truth) as one group."""
    return [n.rstrip("+-") for n in names]


def check_diagnosis(values, tag):
    d, rank = values["diagnosis"], [r["diagnosis"] for r in values["ranking"]]
    expected, t = truth_ranking()
    for n, v in t.items():
        assert abs(d[n]["value"] - v) < 3 * d[n]["std"] + 1e-3 * abs(v), (tag, n, d[n], v)
    assert groups(rank[:6]) == groups(expected), (tag, rank, expected)
    # % of circularity: the contribution over the largest G
    G = max(r["circular_deviation"] for r in values["runs"])
    for r in values["ranking"]:
        assert r["percent"] == pytest.approx(100 * r["contribution"] / G, rel=1e-9)
    top = values["ranking"][0]
    assert 55 < top["percent"] < 80, top  # backlash X: a 6 µm step of a ~9 µm circularity


def test_each_exported_form_gives_the_diagnosis_and_the_ranking_through_the_cli(tmp_path):
    write_forms(tmp_path)
    rc, out, err = cli("dbb", "circular", "ren_cw.csv", "ren_ccw.csv", "--radius", R, "--out", "two.json",
                       cwd=tmp_path)
    assert rc == 0, err
    two = json.loads((tmp_path / "two.json").read_text())["procedure"]["values"]
    check_diagnosis(two, "two columns")
    # the command line, which failed before: readings only, µm, the sweep and the directions
    rc, out, err = cli("dbb", "circular", "ren_cw.txt", "ren_ccw.txt", "--radius", R, "--sweep", 360,
                       "--units", "um", "--out", "only.json", cwd=tmp_path)
    assert rc == 0, err
    only = json.loads((tmp_path / "only.json").read_text())["procedure"]["values"]
    check_diagnosis(only, "readings only")
    # same samples, same angles: the same numbers (to the µm-file's 0.1 nm rounding)
    for n, v in two["diagnosis"].items():
        assert only["diagnosis"][n]["value"] == pytest.approx(v["value"], abs=2e-7), n
    assert "% " in out and "backlash X+" in out and "backlash X-" in out
    # the .b5r form: the diagnostics a ballbar program wrote, built from the documented elements;
    # the lengths are each term's effect on the trace (its contribution), rounded as such files are
    expected, t = truth_ranking()
    feats = {"AF_SQUARENESS": ("UT_SQUARENESS", PSI * 1e6),
             "AF_SCALE_MISMATCH": ("UT_LENGTH_UM", _core.diagnosis_contribution("scale_mismatch", M, R) * 1e3)}
    for ax, b in (("A", B1), ("B", B2)):
        for end in ("POS", "NEG"):
            feats[f"AF_BACKLASH_{ax}_{end}"] = ("UT_LENGTH_UM",
                                                _core.diagnosis_contribution("backlash.1+", b, R) * 1e3)
    G = max(r["circular_deviation"] for r in two["runs"])
    (tmp_path / "test.b5r").write_text(b5r_xml(feats, G * 1e3), encoding="utf-8")
    rc, out, err = cli("dbb", "circular", "test.b5r", "--out", "b5r.json", cwd=tmp_path)
    assert rc == 0, err
    doc = json.loads((tmp_path / "b5r.json").read_text())["procedure"]["values"]["b5r"]
    assert doc["header"]["machine"] == "VMC-7" and doc["header"]["plane"] == "XY"
    assert doc["header"]["test"] == "100mm XY 1000" and doc["header"]["nominal_length"] == 100.0
    got = {d["element"]: d for d in doc["diagnostics"]}
    assert got["AF_SQUARENESS"]["value"] == pytest.approx(PSI, abs=0.05e-6)
    assert got["AF_BACKLASH_A_POS"]["value"] == pytest.approx(2 * B1, abs=0.05e-3)
    # the same ranking as fivecal's own diagnosis of the trace
    b_rank = [{"AF_SQUARENESS": "squareness", "AF_SCALE_MISMATCH": "scale_mismatch"}.get(
        d["element"], "backlash.1" if "_A_" in d["element"] else "backlash.2") for d in doc["diagnostics"]]
    assert b_rank == groups(expected), b_rank
    assert "backlash X+" in out and "squareness XY" in out and "raw trace is not read" in out


def b5r_xml(features, circularity_um, extra=""):
    rows = "\n".join(f'    <FEATURE NAME="{n}" DT="{dt}">{v:.1f}</FEATURE>' for n, (dt, v) in features.items())
    return f"""<?xml version="1.0" encoding="utf-8" standalone="yes"?>
<TEST_DOCUMENT>
  <TEST_SPEC NAME="100mm XY 1000" version="2.0">
    <INSTRUMENT MANUFACTURER="Renishaw" MODEL="QC20-W">
      <DYNAMIC_BALLBAR>
        <NOMINAL_LENGTH>100</NOMINAL_LENGTH>
        <PROGRAMMED_FEEDRATE>1000</PROGRAMMED_FEEDRATE>
        <PLANE VIEW="+A+B" TEST_PLANE="XY"><A_AXIS_NAME>X</A_AXIS_NAME><B_AXIS_NAME>Y</B_AXIS_NAME></PLANE>
      </DYNAMIC_BALLBAR>
    </INSTRUMENT>
  </TEST_SPEC>
  <OPERATOR>QA</OPERATOR>
  <DATE_STARTED>20261128-010000</DATE_STARTED>
  <MACHINE_TESTED NAME="VMC-7" />
  <RUN_RESULTS>
    <BALLBAR_RUN><RUN_DIRECTION>CCW</RUN_DIRECTION>
      <FEATURE NAME="AF_CIRCULARITY" DT="UT_LENGTH_MM">{circularity_um / 1e3:.4f}</FEATURE></BALLBAR_RUN>
  </RUN_RESULTS>
  <ANALYSIS NAME="RENISHAW_DIAGNOSTICS" version="2.1">
    <FEATURE NAME="AF_CIRCULARITY" DT="UT_LENGTH_UM">{circularity_um:.1f}</FEATURE>
{rows}
{extra}
  </ANALYSIS>
</TEST_DOCUMENT>
"""


def test_b5r_reads_what_is_documented_and_refuses_by_element(tmp_path):
    feats = {"AF_SQUARENESS": ("UT_SQUARENESS", 40.0), "AF_SERVO_MISMATCH": ("UT_SERVO_MISMATCH", 0.5)}
    p = tmp_path / "a.b5r"
    p.write_text(b5r_xml(feats, 9.0, '    <FEATURE NAME="AF_SECRET_THING" DT="UT_RANKING">1</FEATURE>'))
    doc = b5r.read_b5r(p)
    assert doc.not_read == ["FEATURE AF_SECRET_THING (DT UT_RANKING: not documented)"]
    servo = next(d for d in doc.diagnostics if d.element == "AF_SERVO_MISMATCH")
    assert servo.value == pytest.approx(0.5e-3) and servo.unit == "s"
    # 0.5 ms at 1000 mm/min is 8.3 µm of lag difference
    assert servo.contribution == pytest.approx(_core.diagnosis_contribution("servo_mismatch", 0.5e-3 * 1000 / 60, R))
    sq = next(d for d in doc.diagnostics if d.element == "AF_SQUARENESS")
    assert sq.contribution == pytest.approx(R * 40e-6) and sq.percent == pytest.approx(100 * R * 40e-6 / 9e-3)
    for bad, msg in (
            (b5r_xml({"AF_SQUARENESS": ("UT_LENGTH_UM", 4.0)}, 9.0),
             "FEATURE AF_SQUARENESS: DT 'UT_LENGTH_UM' is not a documented unit"),
            (b5r_xml(feats, 9.0).replace(">40.0<", ">forty<"), "FEATURE AF_SQUARENESS: 'forty' is not a number"),
            ('<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "b">]><TEST_DOCUMENT/>', "DOCTYPE / ENTITY"),
            ("<TRACE/>", "root element <TRACE>"),
            ("<TEST_DOCUMENT><oops></TEST_DOCUMENT>", "not well-formed XML")):
        p.write_text(bad)
        with pytest.raises(ValueError, match=msg):
            b5r.read_b5r(p)
    p.write_text(b5r_xml(feats, 9.0))
    with pytest.raises(ValueError, match=r"--radius 150: the file's <NOMINAL_LENGTH> is 100 mm"):
        b5r.read_b5r(p, nominal_radius=150)
    rc, out, err = cli("dbb", "circular", str(p), "--tolerance", "G=5um")
    assert rc == 2 and "a .b5r file's diagnostics are Renishaw's" in err


def test_readings_only_needs_sweep_and_direction_and_says_so(tmp_path):
    write_forms(tmp_path)
    (tmp_path / "run1.txt").write_text((tmp_path / "ren_cw.txt").read_text())
    cases = [
        (["ren_cw.txt", "ren_ccw.txt", "--radius", R, "--units", "um"], "give the sweep angle"),
        (["run1.txt", "--radius", R, "--sweep", 360, "--units", "um"], "--direction cw|ccw"),
        (["ren_cw.txt", "ren_ccw.txt", "--radius", R, "--sweep", 360, "--units", "um", "--direction", "cw"],
         "--direction cw: give cw or ccw for each of the 2"),
        (["ren_cw.txt", "--radius", R, "--sweep", 360], "readings look like µm"),
        (["ren_cw.txt", "--radius", R, "--sweep", 5], "--sweep"),
        (["ren_cw.csv", "--radius", R, "--units", "um"], "column 'reading_mm' is in mm but --units says um"),
        (["ren_cw.csv", "--radius", R, "--direction", "ccw"], "--direction says CCW but its angles run CW"),
        (["--sweep", 360, "--radius", R], "--sweep: for readings-only run files"),
        (["ren_cw.csv", "ren_ccw.csv"], "--radius: required"),
    ]
    for argv, msg in cases:
        rc, out, err = cli("dbb", "circular", *argv, cwd=tmp_path)
        assert rc == 2 and msg in err, (argv, rc, err)
    # the direction named on the command line makes an unnamed file usable
    rc, out, err = cli("dbb", "circular", "run1.txt", "--radius", R, "--sweep", 360, "--units", "um",
                       "--direction", "cw", "--start", 90, cwd=tmp_path)
    assert rc == 0, err
    assert "CW " in out
    # recorded with 90 deg of feed-in and feed-out: the whole arc as --sweep, the arcs removed as usual
    deg, r = run(1, 21, step=0.5)
    full = np.r_[r[-181:-1], r, r[1:181]]  # the circle is periodic: the overshoot repeats its ends
    np.savetxt(tmp_path / "over_ccw.txt", full * 1e3, fmt="%.4f")
    rc, out, err = cli("dbb", "circular", "over_ccw.txt", "--radius", R, "--sweep", 540, "--start", -90,
                       "--units", "um", "--out", "over.json", cwd=tmp_path)
    assert rc == 0, err
    assert "feed-in 90.0° (180 samples) and feed-out 90.0° (180 samples) removed" in out
    over = json.loads((tmp_path / "over.json").read_text())["procedure"]["values"]
    one = dbb.circular_test([dbb.Trace(deg, r, 1, "CCW")], R)
    for n in ("backlash.1+", "squareness", "scale_mismatch"):
        assert over["diagnosis"][n]["value"] == pytest.approx(one.diagnosis[n], abs=2e-7), n


def test_tolerances_per_diagnostic_grade_and_exit_1_on_fail(tmp_path):
    write_forms(tmp_path)
    base = ["dbb", "circular", "ren_cw.csv", "ren_ccw.csv", "--radius", R]
    rc, out, err = cli(*base, "--tolerance", "backlash=4um,squareness=50urad,scale_mismatch=20um/m,G=12um",
                       cwd=tmp_path)
    assert rc == 0, err
    assert "grade against the tolerances: PASS" in out
    rc, out, err = cli(*base, "--tolerance", "backlash.X+=2um", "--out", "r.json", cwd=tmp_path)
    assert rc == 1 and "FAIL against the tolerances: backlash X+" in err
    g = json.loads((tmp_path / "r.json").read_text())["procedure"]["values"]["grade"]
    assert [i["name"] for i in g["items"]] == ["backlash.1+"] and g["grade"] == "FAIL"
    # a diagnosis below 3σ passes only when |value| + 3σ is within the tolerance; one the data did not
    # determine, or not fitted at all (no cyclic pitch given), is never a PASS
    rc, out, err = cli(*base, "--tolerance", "reversal_spike.X+=5um", "--out", "s.json", cwd=tmp_path)
    assert rc == 0, err
    item = json.loads((tmp_path / "s.json").read_text())["procedure"]["values"]["grade"]["items"][0]
    assert item["grade"] == "PASS" and item["shown"].startswith("not significant")
    assert item["value"] + 3 * item["std"] <= 0.005
    for tol in ("reversal_spike.X+=0.001um", "cyclic_error=2um"):
        rc, out, err = cli(*base, "--tolerance", tol, cwd=tmp_path)
        assert rc == 1 and "not determined" in err, (tol, err)
    for tol, msg in (("wobble=3um", "--tolerance wobble: a circular test grades"),
                     ("squareness=20", "implausibly large"), ("backlash.Z+=3um", "'Z' is not an axis of the XY"),
                     ("scale_mismatch=3urad", "unknown or wrong unit")):
        rc, out, err = cli(*base, "--tolerance", tol, cwd=tmp_path)
        assert rc == 2 and msg in err, (tol, err)


def test_thermal_compensation_moves_the_radius_not_the_shape(tmp_path):
    write_forms(tmp_path)
    base = ["dbb", "circular", "ren_cw.csv", "ren_ccw.csv", "--radius", R]
    rc, _, err = cli(*base, "--out", "cold.json", cwd=tmp_path)
    assert rc == 0, err
    (tmp_path / "side.json").write_text(json.dumps({"thermal": {
        "bar_expansion": 1e-6, "bar_temperature": 23.0, "machine_expansion": 11.5e-6,
        "machine_temperature": 23.0}, "machine": "VMC-7"}))
    rc, out, err = cli(*base, "--sidecar", "side.json", "--out", "warm.json", cwd=tmp_path)
    assert rc == 0, err
    a = json.loads((tmp_path / "cold.json").read_text())["procedure"]["values"]
    b = json.loads((tmp_path / "warm.json").read_text())["procedure"]["values"]
    # the bar grew 0.3 µm, the machine's scale 3.45 µm: 3.15 µm less radius at 20 degC
    shift = (R * (1 + 1e-6 * 3) + 0.0) / (1 + 11.5e-6 * 3) - R
    assert b["diagnosis"]["radius"]["value"] - a["diagnosis"]["radius"]["value"] == pytest.approx(shift, rel=1e-3)
    for ra, rb in zip(a["runs"], b["runs"]):
        assert rb["circular_deviation"] == pytest.approx(ra["circular_deviation"], rel=1e-4)
    assert b["thermal"]["machine_expansion"] == 11.5e-6 and b["machine"] == "VMC-7"
    # the same by options; ppm/K accepted with its unit, a bare ppm number refused by the core
    rc, out, err = cli(*base, "--bar-expansion", "1ppm", "--bar-temperature", 23, "--machine-expansion",
                       "11.5ppm", "--machine-temperature", 23, "--out", "opt.json", cwd=tmp_path)
    assert rc == 0, err
    c = json.loads((tmp_path / "opt.json").read_text())["procedure"]["values"]
    assert c["diagnosis"]["radius"]["value"] == pytest.approx(b["diagnosis"]["radius"]["value"], abs=1e-12)
    for argv, msg in ((["--bar-expansion", "11.5", "--bar-temperature", 23, "--machine-expansion", 0,
                        "--machine-temperature", 20], "give it in 1/K, not ppm/K"),
                      (["--bar-expansion", "1ppm", "--bar-temperature", 23], "thermal.machine_expansion: missing"),
                      (["--sidecar", "side.json", "--bar-temperature", 21], "also in side.json"),
                      (["--bar-expansion", "1ppm", "--bar-temperature", 296, "--machine-expansion", 0,
                        "--machine-temperature", 20], "bar temperature = 296")):
        rc, out, err = cli(*base, *argv, cwd=tmp_path)
        assert rc == 2 and msg in err, (argv, err)


def test_standards_whose_definitions_are_not_public_are_refused_with_the_reason(tmp_path):
    write_forms(tmp_path)
    base = ["dbb", "circular", "ren_cw.csv", "ren_ccw.csv", "--radius", R]
    assert cli(*base, "--standard", "iso230-4", cwd=tmp_path)[0] == 0
    for std in ("ASME B5.54", "JIS B 6194", "GB/T 17421.4"):
        rc, out, err = cli(*base, "--standard", std, cwd=tmp_path)
        assert rc == 2 and "not implemented" in err and "not public" in err, (std, err)
    doc = open(os.path.join(ROOT, "docs", "dbb.md"), encoding="utf-8").read()
    for std in ("ASME B5.54", "JIS B 6194", "GB/T 17421.4", "raw trace"):
        assert std in doc, std


def test_one_direction_and_split_backlash_in_the_core():
    """With a CCW run alone the backlash at each end is still recovered;
    lateral play is not (it needs both directions) and says so."""
    deg, r = run(1, 3, b1=0.004, b2=0.0)
    res = dbb.circular_test([dbb.Trace(deg, r, 1, "CCW")], R)
    for n in ("backlash.1+", "backlash.1-"):
        assert abs(res.diagnosis[n] - 0.004) < 3 * res.diagnosis_std[n] + 1e-5, n
    assert abs(res.diagnosis["backlash.1"] - 0.004) < 3 * res.diagnosis_std["backlash.1"]
    # an asymmetric machine: X loses 5 µm at its + end and 1 µm at its - end
    phi_step = 0.5
    out = []
    for s in (-1, 1):
        deg = s * phi_step * np.arange(721)
        phi = np.radians(deg)
        v1 = -s * sgn(np.sin(phi))
        b = np.where(np.cos(phi) > 0, 0.005, 0.001)
        x1, x2 = R * np.cos(phi) + b * v1, R * np.sin(phi)
        out.append(dbb.Trace(deg, np.hypot(x1, x2) - R + np.random.default_rng(s + 5).normal(0, SIGMA, deg.size),
                             s))
    res = dbb.circular_test(out, R)
    assert abs(res.diagnosis["backlash.1+"] - 0.005) < 3 * res.diagnosis_std["backlash.1+"] + 2e-5
    assert abs(res.diagnosis["backlash.1-"] - 0.001) < 3 * res.diagnosis_std["backlash.1-"] + 2e-5
    assert res.ranking[0][0] == "backlash.1+"
    with pytest.raises(ValueError, match="unknown diagnosis 'backlash.3'"):
        _core.diagnosis_contribution("backlash.3", 0.001, R)


def test_html_report_renders_in_chromium_verdict_first_and_goes_into_the_history(tmp_path):
    from test_report import render_check, screenshot

    write_forms(tmp_path)
    rc, out, err = cli("dbb", "circular", "ren_cw.txt", "ren_ccw.txt", "--radius", R, "--sweep", 360,
                       "--units", "um", "--tolerance", "squareness=20urad", "--scale", 5, "--html", "rep",
                       "--out", "r.json", cwd=tmp_path)
    assert rc == 1 and "FAIL" in err
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    # the verdict before the plot, the diagnosis table after it, the stated scale on the plot
    assert page.index("class='verdict fail'") < page.index("Polar plot") < page.index("Diagnosis, ranked")
    assert "— FAIL" in page.split("</title>")[0] and "% of circularity" in page
    found = render_check(tmp_path / "rep" / "report.html", tmp_path)
    assert found["images"] == 1 and found["broken"] == [] and min(found["widths"]) > 800
    assert found["h2"][:2] == ["Polar plot", "Diagnosis, ranked by contribution to circularity"]
    img = screenshot(tmp_path / "rep" / "report.html", tmp_path, height=1600)
    rgb = img[..., :3]
    assert (rgb < 0.9).any(axis=2).mean() > 0.03
    # the red FAIL box at the top of the page
    top = rgb[:250]
    assert ((top[..., 0] > 0.7) & (top[..., 1] < 0.3) & (top[..., 2] < 0.3)).sum() > 200
    # the result document goes into the calibration history like every other result
    rc, out, err = cli("history", "add", "r.json", "--store", "s.fcdb", "--machine-id", "VMC-7", cwd=tmp_path)
    assert rc == 0, err
    rc, out, err = cli("history", "show", "--store", "s.fcdb", 1, cwd=tmp_path)
    assert rc == 0 and "procedure 'circular'" in out


def test_volumetric_takes_what_circular_takes_and_gives_each_plane_the_same_numbers(tmp_path):
    """`dbb volumetric` reads readings-only runs, applies the thermal sidecar and
    grades tolerances exactly as `dbb circular` does for each plane alone; one
    verdict covers every plane, and the HTML report links each plane's own."""
    planes = ("XY", "YZ")
    for k, p in enumerate(planes):
        for s, name in ((-1, "cw"), (1, "ccw")):
            _, r = run(s, 40 + 2 * k + (s > 0))
            np.savetxt(tmp_path / f"{p}_{name}.txt", r * 1e3, fmt="%.4f")
    (tmp_path / "side.json").write_text(json.dumps({"thermal": {
        "bar_expansion": 1e-6, "bar_temperature": 23.0, "machine_expansion": 11.5e-6,
        "machine_temperature": 23.0}, "machine": "VMC-7"}))
    common = ["--radius", R, "--sweep", 360, "--units", "um", "--sidecar", "side.json", "--tolerance", "G=30um"]
    alone = {}
    for p in planes:
        rc, _, err = cli("dbb", "circular", f"{p}_cw.txt", f"{p}_ccw.txt", "--plane", p, *common,
                         "--out", f"{p}.json", cwd=tmp_path)
        assert rc == 0, err
        alone[p] = json.loads((tmp_path / f"{p}.json").read_text())["procedure"]["values"]
    rc, out, err = cli("dbb", "volumetric", "--xy", "XY_cw.txt", "XY_ccw.txt", "--yz", "YZ_cw.txt", "YZ_ccw.txt",
                       *common, "--html", "rep", "--out", "v.json", cwd=tmp_path)
    assert rc == 0, err
    v = json.loads((tmp_path / "v.json").read_text())["procedure"]["values"]
    for p in planes:
        got = v["volumetric"]["planes"][p]
        assert got["thermal"] == alone[p]["thermal"] and got["machine"] == "VMC-7"
        for n, d in alone[p]["diagnosis"].items():
            assert got["diagnosis"][n]["value"] == pytest.approx(d["value"], abs=1e-12), (p, n)
        assert v["grades"][p]["grade"] == alone[p]["grade"]["grade"] == "PASS"
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "<b>PASS</b>" in html and "Thermal compensation" in html and "XY/report.html" in html
    assert (tmp_path / "rep" / "XY" / "report.html").is_file() and (tmp_path / "rep" / "volumetric.png").is_file()
    # a tolerance one plane fails: exit 1, named by plane, and the page says FAIL
    rc, out, err = cli("dbb", "volumetric", "--xy", "XY_cw.txt", "XY_ccw.txt", "--yz", "YZ_cw.txt", "YZ_ccw.txt",
                       *common[:-2], "--tolerance", "backlash=1um", "--html", "bad", cwd=tmp_path)
    assert rc == 1 and "FAIL against the tolerances" in err and "XY backlash" in err, err
    assert "— FAIL" in (tmp_path / "bad" / "report.html").read_text()
    # bad input names the option
    for argv, msg in ((["--xy", "XY_cw.txt", "--simulate", "EXX1=1e-5", "--machine", "m.json", "--radius", R],
                       "--simulate both given"),
                      (["--xy", "XY_cw.txt", "XY_ccw.txt", "--yz", "YZ_cw.txt", "--radius", R, "--sweep", 360,
                        "--units", "um", "--direction", "cw"], "--direction"),
                      (["--xy", "XY_cw.txt", "XY_ccw.txt", "XY_cw.txt", "--radius", R], "give one or two")):
        rc, out, err = cli("dbb", "volumetric", *argv, cwd=tmp_path)
        assert rc == 2 and msg in err, (argv, err)
