"""The sphere / probing cycle in each controller's own words (issue 32,
item 5): `fivecal export program --dialect linuxcnc|siemens|fanuc|heidenhain|
beckhoff`. Every dialect runs the same moves as the LinuxCNC program (the
same targets in the same order), probes with its controller's probing move,
writes each probed position as one 'x y z a b c u v w' log line with the
rotary commands of its position, cites its sources, and a controller whose
probing move is not public (Heidenhain) says so."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.io import nc_programs as N
from fivecal.procedures import sphere_check as sc

BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
KINS = "xyzac-trt"
NUM = r"(-?\d+\.\d+)"
PROBE = {"linuxcnc": r"^G38\.2 X{0} Y{0} Z{0} F60$", "siemens": r"^MEAS=1 G01 X{0} Y{0} Z{0} F60$",
         "fanuc": r"^G31 X{0} Y{0} Z{0} F60$", "heidenhain": r"^G38\.2 X{0} Y{0} Z{0} F60$",
         "beckhoff": r"^G100 X{0} Y{0} Z{0} F60$"}


@pytest.fixture(scope="module")
def setup():
    m = fivecal.Machine.load("examples/machines/c600u.json")
    plan = sc.plan(m, BALL, tip_radius=3.0, n=3)
    return m, plan, {"spheres": [BALL]}


def _program(setup, dialect, **kw):
    m, plan, art = setup
    return N.sphere_program(m, KINS, plan, art, 3.0, dialect=dialect, **kw)


def _probes(text, dialect):
    pat = re.compile(PROBE[dialect].format(NUM), re.M)
    return [tuple(float(v) for v in g) for g in pat.findall(text)]


def test_linuxcnc_is_the_default_and_unchanged(setup):
    m, plan, art = setup
    assert _program(setup, "linuxcnc") == N.sphere_program(m, KINS, plan, art, 3.0)


@pytest.mark.parametrize("dialect", ["siemens", "fanuc", "heidenhain", "beckhoff"])
def test_each_dialect_runs_the_same_touches_in_its_own_words(setup, dialect):
    m, plan, _ = setup
    ref, text = _program(setup, "linuxcnc"), _program(setup, dialect)
    lines = text.splitlines()
    probes = _probes(text, dialect)
    # the same probing targets, in the plan's order, one per touch
    assert len(probes) == len(plan) and np.allclose(probes, _probes(ref, "linuxcnc"), atol=1e-9)
    # and the same positioning moves (the G0 blocks, comments stripped)
    g0 = lambda t: [re.sub(r"\s*[;(].*$", "", ln) for ln in t.splitlines() if ln.startswith("G0 ")]  # noqa: E731
    assert g0(text) == g0(ref)
    d = N.DIALECTS[dialect]
    assert any("source: " in ln for ln in lines) and lines[-1] == d.end
    # every comment line is one comment of the dialect's kind (no nested parentheses ending it early)
    for ln in lines:
        if ln.startswith("("):
            assert ln.endswith(")") and ln.count("(") == 1 and ln.count(")") == 1, ln
    first_probe = next(i for i, ln in enumerate(lines) if re.match(PROBE[dialect].format(NUM), ln))
    if dialect == "siemens":
        # the definition comes before any statement; each probe is followed by its WRITE
        first_statement = next(i for i, ln in enumerate(lines) if not ln.startswith(";"))
        assert lines[first_statement] == "DEF INT FCERR" and "TRAORI ; tool centre point kinematics on" in lines
        writes = [ln for ln in lines if ln.startswith("WRITE(FCERR, ")]
        assert len(writes) == len(plan) and lines[-2] == "TRAFOOF"
        # the rotary columns: the joint commands of the touch's position (their values: the read-back test)
        assert re.fullmatch(r'WRITE\(FCERR, "probe-log.txt", \$AA_MW\[X\] << " " << \$AA_MW\[Y\] << " " << '
                            r'\$AA_MW\[Z\] << " -?[\d.]+ 0.000000 -?[\d.]+ 0 0 0"\)', writes[0]), writes[0]
    if dialect == "fanuc":
        assert lines.index("POPEN") < first_probe and lines[-3:] == ["PCLOS", "G49", "M30"]
        dprnt = [i for i, ln in enumerate(lines) if ln.startswith("DPRNT[")]
        assert len(dprnt) == len(plan)
        assert lines[dprnt[0]] == "DPRNT[#5061[44]*#5062[44]*#5063[44]*#1[44]*#2[44]*#3[44]*0*0*0]"
        assert [ln[:3] for ln in lines[dprnt[0] - 3:dprnt[0]]] == ["#1=", "#2=", "#3="]
    if dialect == "beckhoff":
        assert lines.index('#FILE NAME [MSG="probe-log.txt"]') < lines.index("#MEAS [TYPE=1]") < first_probe
        saves = [ln for ln in lines if ln.startswith("#MSG SAVE [")]
        assert len(saves) == len(plan) and "V.A.MEAS.PCS.VALUE.X" in saves[0]
        assert lines[-2] == "#TRAFO OFF"
    if dialect == "heidenhain":
        # not public: G-code with the comment saying so, the log as LinuxCNC's
        assert any("no public source found here" in ln for ln in lines) and "(PROBEOPEN probe-log.txt)" in lines
        assert "Q115-Q117" in text


def _controller_log(text, dialect, positions):
    """What the controller writes running `text`, each probe tripping at the
    given (x, y, z): the dialect's record lines evaluated as its manual
    describes them (Siemens WRITE of a << concatenation, Beckhoff #MSG SAVE
    printf, Fanuc DPRNT fields joined by '*' as spaces, [44] four decimals)."""
    out, k, var = [], 0, {}
    for ln in text.splitlines():
        if re.match(PROBE[dialect].format(NUM), ln):
            x, y, z = positions[k]
            k += 1
        elif dialect == "siemens" and ln.startswith("WRITE("):
            expr = ln[ln.index('", ') + 3:-1]
            parts = []
            for tok in expr.split("<<"):
                tok = tok.strip()
                parts.append(tok[1:-1] if tok.startswith('"') else
                             f"{ {'$AA_MW[X]': x, '$AA_MW[Y]': y, '$AA_MW[Z]': z}[tok]:.6f}")
            out.append("".join(parts))
        elif dialect == "beckhoff" and ln.startswith("#MSG SAVE ["):
            fmt = re.search(r'\["([^"]*)"', ln).group(1)
            assert ln.endswith(", V.A.MEAS.PCS.VALUE.X, V.A.MEAS.PCS.VALUE.Y, V.A.MEAS.PCS.VALUE.Z]")
            out.append(fmt % (x, y, z))
        elif dialect == "fanuc" and re.match(r"^#[123]=", ln):
            n, v = ln[1:].split("=")
            var[f"#{n}"] = float(v)
        elif dialect == "fanuc" and ln.startswith("DPRNT["):
            vals = {"#5061": x, "#5062": y, "#5063": z, **var}
            out.append(" ".join(f"{vals[f[:f.index('[')]]:.4f}" if f.startswith("#") else f
                                for f in ln[6:-1].split("*")))
    assert k == len(positions)
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("dialect", ["siemens", "fanuc", "beckhoff"])
def test_each_dialects_log_reads_back_as_linuxcncs(setup, dialect):
    """Run (emulated) on a machine with a 20 µm pivot error, each dialect's
    log holds per touch the trip position and the rotary commands in
    LinuxCNC's layout: read_probe_log reads it into the same observations
    as LinuxCNC's own log (to the 0.1 µm of Fanuc's [44] format)."""
    from fivecal.io import linuxcnc as L
    m, plan, art = setup
    pins = L.nominal_pins(m, KINS)
    ref = N.sphere_log(m, KINS, plan, art, 3.0, pins, errors={"EY0C": 0.02})
    rows = [[float(v) for v in ln.split()] for ln in ref.splitlines()]
    log = _controller_log(_program(setup, dialect), dialect, [r[:3] for r in rows])
    assert np.allclose([[float(v) for v in ln.split()] for ln in log.splitlines()], rows, atol=6e-5)
    a = L.read_probe_log(ref, m, KINS, plan, pins)
    b = L.read_probe_log(log, m, KINS, plan, pins)
    assert len(a) == len(b) == len(plan)
    for oa, ob in zip(a, b):
        assert oa["target"] == ob["target"]
        assert all(abs(oa["axes"][ax] - ob["axes"][ax]) < 1e-4 for ax in oa["axes"])


def test_cli_dialects_and_refusals(tmp_path, capsys, setup):
    m, plan, art = setup
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"machine": m.to_dict(), "plan": plan, "artefact": art, "probe": {"tip_radius": 3.0}}))
    out = tmp_path / "check.mpf"
    assert main(["export", "program", str(spec), "--kins", KINS, "--dialect", "siemens", "--out", str(out)]) == 0
    assert out.read_text() == _program(setup, "siemens")
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(["export", "program", str(spec), "--kins", KINS, "--dialect", "okuma"])
    assert e.value.code == 2 and "--dialect" in capsys.readouterr().err
    # a program other than a probing cycle is LinuxCNC's only: refused, named
    rspec = tmp_path / "rtest.json"
    from fivecal.procedures import rtest
    rspec.write_text(json.dumps({"machine": m.to_dict(), "plan": rtest.plan(m, "K1", table_ball=[120, -40, 80])}))
    assert main(["export", "program", str(rspec), "--dialect", "fanuc"]) == 2
    assert "--dialect fanuc: written for sphere and mixed facet/sphere probing cycles" in capsys.readouterr().err
    assert main(["export", "program", str(spec), "--kins", KINS, "--dialect", "siemens", "--log", 'a"b']) == 2
    assert "quoted string" in capsys.readouterr().err
    with pytest.raises(ValueError, match="dialect: 'okuma'"):
        _program(setup, "okuma")


@pytest.mark.parametrize("dialect", ["siemens", "fanuc", "beckhoff"])
def test_a_mixed_facet_and_sphere_plan_in_each_dialect(dialect):
    """The TANGO plan (facet touches and the scale bar's spheres, an xyzbc
    table) in each dialect: the same probing targets as LinuxCNC's, one log
    record per touch, the B column carrying the tilt."""
    from fivecal.procedures import tango
    m, art = tango.hu40t_machine(), tango.octagonal_table()
    plan = tango.hu40t_plan(art, m)[:60]
    ref = N.touch_program(m, "xyzbc-trt", plan, art, 3.0)
    text = N.touch_program(m, "xyzbc-trt", plan, art, 3.0, dialect=dialect)
    assert np.allclose(_probes(text, dialect), _probes(ref, "linuxcnc"), atol=1e-9)
    assert len(_probes(text, dialect)) == len(plan)
    rec = {"siemens": "WRITE(FCERR", "fanuc": "DPRNT[", "beckhoff": "#MSG SAVE ["}[dialect]
    assert sum(ln.startswith(rec) for ln in text.splitlines()) == len(plan)
    if dialect == "siemens":
        # xyzbc: the a column 0, the tilt in b
        assert all(re.search(r'<< " 0\.000000 -?[\d.]+ -?[\d.]+ 0 0 0"\)$', ln)
                   for ln in text.splitlines() if ln.startswith("WRITE("))
