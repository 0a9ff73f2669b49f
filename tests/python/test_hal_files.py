"""The LinuxCNC files fivecal reads and writes (issue 27): the old pins read
from a HAL file as halcmd reads it (setp, sets, net in the style of
LinuxCNC's sample configurations, comments, continuations, INI
substitutions refused by line), the pin lines it writes (no NaN, no pin
left out silently), and the export folder (a second export replaces the
first, all or nothing)."""
import os
import re
import shutil
import subprocess
import tempfile

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.io import linuxcnc as L

import linuxcnc_harness as harness
from test_linuxcnc import ERRORS, MACHINES, _write_inputs

KINS = "xyzac-trt"
#: LinuxCNC's halcmd checks what the reader makes of the files (when installed)
REASON = harness.unavailable_reason()

# configs/sim/axis/vismach/5axis/table-rotary-tilting/xyzac-trt.ini's HALCMD
# lines as a HAL file, with a GUI pin on the offsets' signals
SAMPLE = """\
# xyzac-trt kinematics (LinuxCNC sample configuration style)
loadrt [KINS]KINEMATICS
loadrt [EMCMOT]EMCMOT servo_period_nsec=[EMCMOT]SERVO_PERIOD num_joints=[KINS]JOINTS
addf motion-command-handler servo-thread
net  :tool-offset  motion.tooloffset.z
net  :tool-offset  xyzac-trt-kins.tool-offset xyzac-trt-gui.tool-offset
net  :y-offset     xyzac-trt-kins.y-offset    xyzac-trt-gui.y-offset
net  :z-offset     xyzac-trt-kins.z-offset    xyzac-trt-gui.z-offset
sets :y-offset     20
sets :z-offset     10
setp xyzac-trt-kins.x-rot-point 0.031
setp xyzac-trt-kins.y-rot-point -0.012
setp xyzac-trt-kins.z-rot-point 0
setp xyzac-trt-kins.conventional-directions 0
"""


def _hal(tmp_path, text, name="current.hal"):
    p = tmp_path / name
    p.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return str(p)


def test_sample_configuration_pins_set_through_signals(tmp_path):
    # before: only 'setp' lines were read; :y-offset and :z-offset (sets on a
    # signal) were dropped and taken as 0
    got = L.read_hal_pins(_hal(tmp_path, SAMPLE), KINS)
    assert got == {"x-rot-point": 0.031, "y-rot-point": -0.012, "z-rot-point": 0.0, "y-offset": 20.0,
                   "z-offset": 10.0}  # tool-offset: motion.tooloffset.z drives it at run time


@pytest.mark.parametrize("text,expected", [
    # arrows in either direction, or none; the signal named first
    ("net :y-offset => xyzac-trt-kins.y-offset\nsets :y-offset 0.020\n", {"y-offset": 0.02}),
    ("net :y-offset <= xyzac-trt-kins.y-offset\nsets :y-offset 0.020\n", {"y-offset": 0.02}),
    ("net :y-offset xyzac-trt-kins.y-offset\nsets :y-offset 0.020\n", {"y-offset": 0.02}),
    ("newsig :y float\nlinksp :y xyzac-trt-kins.y-offset\nsets :y 0.5\n", {"y-offset": 0.5}),
    ("newsig :y float\nlinkps xyzac-trt-kins.y-offset => :y\nsets :y 0.5\n", {"y-offset": 0.5}),
    # setp before the net: the first pin on a new signal puts its value on it (hal_link)
    ("setp xyzac-trt-kins.y-offset 0.25\nnet :y => xyzac-trt-kins.y-offset\n", {"y-offset": 0.25}),
    # ... and overwrites a value the signal was given before it had a pin
    ("newsig :y float\nsets :y 0.5\nnet :y => xyzac-trt-kins.y-offset\n", {"y-offset": 0.0}),
    # several net lines adding readers to one signal, the sets after them
    ("net :off xyzac-trt-kins.y-offset\nnet :off xyzac-trt-kins.z-offset\nsets :off 7.5\n",
     {"y-offset": 7.5, "z-offset": 7.5}),
    # a later sets wins; unlinkp keeps the signal's value on the pin
    ("net :y xyzac-trt-kins.y-offset\nsets :y 1\nsets :y 2\nunlinkp xyzac-trt-kins.y-offset\n", {"y-offset": 2.0}),
    # comments, a continuation line, 'PIN = VALUE', a '#' in a quoted word
    ("setp xyzac-trt-kins.x-rot-point \\\n  0.125   # mm\nxyzac-trt-kins.y-rot-point = -3\n"
     "print 'gui #1'\n", {"x-rot-point": 0.125, "y-rot-point": -3.0}),
    # a comment line ending in a backslash swallows the next line, as in halcmd
    ("setp xyzac-trt-kins.x-rot-point 1\n# old value \\\nsetp xyzac-trt-kins.x-rot-point 2\n",
     {"x-rot-point": 1.0}),
    # pins of the other kinematics and the unused x-offset of xyzac are not read
    ("setp xyzac-trt-kins.z-rot-point 4\nsetp xyzbc-trt-kins.x-offset 9\nsetp xyzac-trt-kins.x-offset 9\n",
     {"z-rot-point": 4.0}),
])
def test_hal_syntax_as_halcmd_reads_it(tmp_path, text, expected):
    assert L.read_hal_pins(_hal(tmp_path, text), KINS) == expected
    if REASON is None and "xyzbc" not in text:
        # the same file in LinuxCNC's own halcmd gives the pins the same values
        rc, values = _halcmd(text)
        assert rc == 0, values
        assert values == {n: expected.get(n, 0.0) for n in L.MODULE_PINS if n != "conventional-directions"}


@pytest.mark.parametrize("text,line,fragment", [
    # halcmd refuses setp on a pin linked to a signal
    ("net :y => xyzac-trt-kins.y-offset\nsetp xyzac-trt-kins.y-offset 0.02\n", 2, "linked to signal :y"),
    # and sets on a signal that does not exist yet
    ("sets :y 0.02\nnet :y => xyzac-trt-kins.y-offset\n", 1, "comes before the signal exists"),
    # an INI substitution: its value is not in the HAL file
    ("setp xyzac-trt-kins.x-rot-point [KINS]X_ROT_POINT\n", 1, "[KINS]X_ROT_POINT"),
    ("net :y => xyzac-trt-kins.y-offset\nsets :y $(Y_OFFSET)\n", 2, "$(Y_OFFSET)"),
    ("setp [KINS]KINEMATICS.x-rot-point 3\n", 1, "substitution"),
    # a pin the module does not have, or spelt as halcmd would not find it
    ("setp xyzac-trt-kins.x-rot-pnt 0.1\n", 1, "'xyzac-trt-kins.x-rot-pnt' is not a pin"),
    ("setp xyzac-trt-kins.X-ROT-POINT 0.1\n", 1, "case-sensitive"),
    # a fitted pin driven by another component at run time
    ("net :x motion.analog-out-05 => xyzac-trt-kins.x-rot-point\n", 1, "at run time"),
    ("net :x xyzac-trt-kins.x-rot-point\nnet :x some.pin\n", 2, "may drive it"),
    # values that are no numbers
    ("setp xyzac-trt-kins.x-rot-point abc\n", 1, "'abc' is not a number"),
    ("setp xyzac-trt-kins.x-rot-point 1e999\n", 1, "not finite"),
    ("setp xyzac-trt-kins.x-rot-point 'unterminated\n", 1, "unterminated quoted string"),
    ("net xyzac-trt-kins.y-offset :y\n", 1, "the first word after 'net' is the signal"),
    ("setp xyzac-trt-kins.conventional-directions 1\n", 1, "conventional-directions is on"),
    ("loadrt xyzac-trt-kins\n", None, "no value for a pin"),
])
def test_hal_lines_fivecal_cannot_read_are_refused_by_line(tmp_path, text, line, fragment):
    path = _hal(tmp_path, text)
    with pytest.raises(ValueError) as e:
        L.read_hal_pins(path, KINS)
    msg = str(e.value)
    assert msg.startswith(f"{path}:{line}: " if line else f"{path}: "), msg
    assert fragment in msg, msg
    if REASON is None and "halcmd refuses" in msg:
        assert _halcmd(text)[0] != 0  # and LinuxCNC's halcmd stops there too


def _halcmd(text):
    """(exit status, pin values of xyzac-trt-kins) of LinuxCNC's halcmd
    (halrun, non-realtime) running ``text`` after loading the module."""
    harness._ensure_user()
    d = tempfile.mkdtemp(prefix="fivecal-hal-")
    try:
        os.chmod(d, 0o755)
        path = os.path.join(d, "t.hal")
        with open(path, "w") as f:
            f.write("loadrt xyzac-trt-kins\n" + text + "\nshow pin xyzac-trt-kins\n")
        os.chmod(path, 0o644)
        r = subprocess.run(harness._as_user(["halrun", "-f", path]), capture_output=True, text=True, timeout=120)
    finally:
        shutil.rmtree(d, ignore_errors=True)
    values = {m.group(2): float(m.group(1)) for m in
              re.finditer(r"float\s+IN\s+(\S+)\s+xyzac-trt-kins\.([a-z-]+)", r.stdout)}
    return r.returncode, values if r.returncode == 0 else r.stdout + r.stderr


def test_non_utf8_hal_names_the_file_and_line(tmp_path):
    # before: a bare "'utf-8' codec can't decode byte 0xe9" without the file
    bad = _hal(tmp_path, b"setp xyzac-trt-kins.x-rot-point 1\nsetp xyzac-trt-kins.y-rot-point 2 \xb5m\n")
    with pytest.raises(ValueError, match=rf"^{bad}:2: not UTF-8 text outside a comment \(byte 0xb5"):
        L.read_hal_pins(bad, KINS)
    # a Latin-1 comment is not read (halcmd ignores comments)
    ok = _hal(tmp_path, b"# r\xe9glage du caf\xe9\nsetp xyzac-trt-kins.x-rot-point 1 # \xb5m\n", "ok.hal")
    assert L.read_hal_pins(ok, KINS) == {"x-rot-point": 1.0}


def test_source_reads_the_other_file(tmp_path):
    _hal(tmp_path, "sets :y 0.75\n", "offsets.hal")
    main_hal = _hal(tmp_path, "net :y => xyzac-trt-kins.y-offset\nsource offsets.hal\n")
    assert L.read_hal_pins(main_hal, KINS) == {"y-offset": 0.75}


def _cli_export(tmp_path, out, *extra, errors=None):
    mp, rp = _write_inputs(tmp_path, errors or ERRORS[KINS])
    return main(["export", "linuxcnc", rp, "--machine", mp, "--kins", KINS, "--out", str(out), *extra])


def test_cli_export_reads_old_pins_set_through_signals(tmp_path, capsys):
    m = fivecal.Machine.from_dict(MACHINES[KINS])
    nominal = L.nominal_pins(m, KINS)
    text = SAMPLE.replace("sets :y-offset     20", f"sets :y-offset     {nominal['y-offset']!r}")
    text = text.replace("sets :z-offset     10", f"sets :z-offset     {nominal['z-offset']!r}")
    text = "\n".join(ln for ln in text.splitlines() if "-rot-point" not in ln) + "\n"
    text += "".join(f"setp xyzac-trt-kins.{n}-rot-point {nominal[n + '-rot-point']!r}\n" for n in "xyz")
    old = _hal(tmp_path, text)
    assert _cli_export(tmp_path, tmp_path / "lcnc", "--old", old) == 0
    hal = (tmp_path / "lcnc" / "fivecal-kins.hal").read_text()
    line = next(ln for ln in hal.splitlines() if ln.startswith("setp xyzac-trt-kins.y-offset"))
    assert f"# old {nominal['y-offset']:.6f}" in line, line


def test_cli_export_refuses_an_unreadable_old_file(tmp_path, capsys):
    old = _hal(tmp_path, b"# caf\xe9\nsets :y-offset 0.02 \xe9\n")
    assert _cli_export(tmp_path, tmp_path / "lcnc", "--old", old) == 2
    err = capsys.readouterr().err
    assert f"{old}:2: not UTF-8 text" in err and len(err.strip().splitlines()) == 1, err
    old = _hal(tmp_path, "setp xyzac-trt-kins.x-rot-point [KINS]X\n", "ini.hal")
    assert _cli_export(tmp_path, tmp_path / "lcnc", "--old", old) == 2
    assert f"{old}:1: xyzac-trt-kins.x-rot-point:" in capsys.readouterr().err
    assert not (tmp_path / "lcnc").exists()


# ---- the pin lines fivecal writes -----------------------------------------------

@pytest.mark.parametrize("pins,fragment", [
    ({"x-rot-point": float("nan")}, "xyzac-trt-kins.x-rot-point: expected a finite number"),
    ({"x-rot-point": float("inf"), "y-rot-point": 0.0}, "xyzac-trt-kins.x-rot-point"),
    ({"x-rot-pont": 0.1}, "'x-rot-pont' is not a pin of xyzac-trt-kins"),
    ({"x-offset": 0.1}, "'x-offset' is not a pin of xyzac-trt-kins fivecal sets"),
])
def test_hal_and_ini_text_refuse_what_they_cannot_write(pins, fragment):
    # before: 'setp xyzac-trt-kins.x-rot-point nan', and a file without a setp
    # line for an unknown pin
    for write in (lambda: L.hal_text(KINS, pins), lambda: L.ini_text(KINS, pins),
                  lambda: L.hal_text(KINS, {"y-rot-point": 1.0}, old=pins)):
        with pytest.raises(ValueError, match="^(pins|old): ") as e:
            write()
        assert fragment in str(e.value)


# ---- the export folder --------------------------------------------------------------

def test_second_export_replaces_the_first(tmp_path, capsys):
    # before: '--out lcnc: is a folder, expected a file name' the second time
    out = tmp_path / "lcnc"
    assert _cli_export(tmp_path, out, "--comp-step", "10", errors=dict(ERRORS[KINS], EXX1=2e-5)) == 0
    assert (out / "comp-X.txt").exists()
    capsys.readouterr()
    assert _cli_export(tmp_path, out) == 0
    assert "replaced the earlier export" in capsys.readouterr().out
    # the stale compensation file of the first export is gone with it
    assert sorted(p.name for p in out.iterdir()) == ["fivecal-kins-ini.hal", "fivecal-kins.hal", "fivecal-kins.ini",
                                                     "linuxcnc-report.txt"]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".lcnc")] == []


def test_export_that_fails_midway_leaves_the_old_folder(tmp_path, monkeypatch, capsys):
    out = tmp_path / "lcnc"
    assert _cli_export(tmp_path, out) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    from fivecal import files
    real, calls = files.write_text, []

    def failing(path, text, *a, **k):
        calls.append(path)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return real(path, text, *a, **k)

    monkeypatch.setattr(files, "write_text", failing)
    assert _cli_export(tmp_path, out, errors={"EX0C": 0.05}) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_export_refuses_a_folder_holding_other_files(tmp_path, capsys):
    out = tmp_path / "cfg"
    out.mkdir()
    (out / "my-machine.hal").write_text("loadrt trivkins\n")
    assert _cli_export(tmp_path, out) == 2
    assert "holds my-machine.hal" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["my-machine.hal"]


def test_check_change_names_the_pin_and_the_option():
    m = fivecal.Machine.from_dict(MACHINES[KINS])
    ab = L.absorb(m, KINS, {"EX0C": 0.8})
    with pytest.raises(fivecal.guards.CorrectionLimitError) as e:
        L.check_change(ab.old_pins, ab.pins, 0.5)
    assert "x-rot-point would change by" in str(e.value) and "--max-change" in str(e.value)
    # a change that is not a number is beyond any limit
    with pytest.raises(ValueError, match="y-rot-point"):
        L.check_change({"y-rot-point": 0.0}, {"y-rot-point": np.nan}, 0.5)
    assert os.path.basename(L.__file__) == "linuxcnc.py"
