"""The command line a user meets (issue 6, items 1, 3 and 4): every command's
--help carries an example, errors are one line (never a traceback), `fivecal
demo` says where its report is, `fivecal compensate` round-trips G-code byte
for byte at zero errors and writes the error tables; the progress helper.
"""
import io
import json
import os
import re
import subprocess
import sys

import pytest

from fivecal.progress import Progress, busy, progress, progress_enabled

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
HU40T = os.path.join(ROOT, "examples", "machines", "hu40t.json")
PROGRAM = os.path.join(ROOT, "examples", "gcode", "hu40t_5axis.nc")
SPEC = os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json")


def fivecal(*args, cwd=None, env=None, timeout=300):
    e = dict(os.environ)
    e.pop("FIVECAL_DEBUG", None)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "fivecal", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=e, timeout=timeout)


def commands():
    out = fivecal("--help").stdout
    m = re.search(r"\{([a-z_,-]+)\}", out)
    assert m, out
    return m.group(1).split(",")


def test_every_command_has_help_with_an_example():
    cmds = commands()
    assert {"identify", "simulate", "demo", "compensate"} <= set(cmds)
    for c in cmds:
        proc = fivecal(c, "--help")
        assert proc.returncode == 0, (c, proc.stderr)
        assert re.search(r"^examples?:\s*\n\s+fivecal " + re.escape(c), proc.stdout, re.M), \
            f"`fivecal {c} --help` has no example starting with 'fivecal {c}'"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    proc = fivecal("simulate", SPEC, "--out", d / "ds.json")
    assert proc.returncode == 0, proc.stderr
    proc = fivecal("identify", d / "ds.json", "--estimate", "location", "--out", d / "result.json")
    assert proc.returncode == 0, proc.stderr
    (d / "bad.json").write_text("{not json")
    (d / "list.json").write_text("[1, 2]")
    (d / "g91.nc").write_text("G90 G0 X0 Y0 Z0 B0 C0\nG91\nG1 X10\n")
    (d / "zero.json").write_text(json.dumps({"EX0C": 0.0}))
    return d


def bad_invocations(d):
    return [
        ("identify", [], "required: dataset"),                       # usage errors too
        ("compensate", ["r.json", "m.json", "--decimals", "x"], "--decimals"),
        ("identify", ["/no/such/file.json"], "/no/such/file.json"),
        ("identify", [d / "bad.json"], "bad.json"),
        ("identify", [d / "list.json"], "list.json"),
        ("identify", [d / "ds.json", "--estimate", "EQ0C"], "EQ0C"),
        ("identify", [d / "ds.json", "--estimate", "EX0Y,EX0S"], "{EX0Y, EX0S}"),
        ("simulate", [d / "bad.json", "--out", d / "x.json"], "bad.json"),
        ("simulate", [d / "list.json", "--out", d / "x.json"], "list.json"),
        ("simulate", ["/no/such/spec.json", "--out", d / "x.json"], "spec.json"),
        ("compensate", [d / "result.json", HU40T], "nothing to do"),
        ("compensate", [d / "result.json", HU40T, d / "g91.nc", "--out", d / "o.nc"], "g91.nc:3"),
        ("compensate", [d / "result.json", HU40T, d / "g91.nc"], "--out"),
        ("compensate", [d / "bad.json", HU40T, "--table", d / "t.csv"], "bad.json"),
        ("compensate", [d / "result.json", d / "bad.json", "--table", d / "t.csv"], "bad.json"),
        ("compensate", [d / "result.json", d / "list.json", "--table", d / "t.csv"], "list.json"),
        ("compensate", [d / "result.json", os.path.join(ROOT, "examples", "machines", "kx8.json"),
                        "--table", d / "t.csv"], "KX8"),
        ("compensate", [d / "result.json", HU40T, PROGRAM, "--out", d / "o.nc", "--start", "X=abc"],
         "--start"),
        ("compensate", [d / "result.json", HU40T, "/no/such/prog.nc", "--out", d / "o.nc"], "prog.nc"),
        ("demo", ["--out", "/proc/fivecal_cannot_write_here"], "/proc/fivecal_cannot_write_here"),
    ]


def test_errors_are_one_line_naming_the_problem(files):
    for cmd, args, needle in bad_invocations(files):
        proc = fivecal(cmd, *args)
        where = f"fivecal {cmd} {' '.join(map(str, args))}"
        assert proc.returncode == 2, (where, proc.returncode, proc.stderr)
        assert "Traceback" not in proc.stderr, where
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1, (where, proc.stderr)
        assert lines[0].startswith(f"fivecal {cmd}: error: "), (where, lines[0])
        assert needle in lines[0], (where, lines[0])


def test_unexpected_failures_are_one_line_too(files, tmp_path):
    # a spec whose plan is not a list: reaches code that does not expect it
    spec = tmp_path / "odd.json"
    spec.write_text(json.dumps({"machine": "../no.json", "plan": 5}))
    proc = fivecal("simulate", spec, "--out", tmp_path / "x.json")
    assert proc.returncode in (2, 3) and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_compensate_cli_zero_errors_byte_for_byte_and_tables(files, tmp_path):
    d = files
    out = tmp_path / "same.nc"
    proc = fivecal("compensate", d / "zero.json", HU40T, PROGRAM, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes() == open(PROGRAM, "rb").read()
    assert "0 lines changed" in proc.stdout
    # real errors: the program changes, the summary says by how much
    out2 = tmp_path / "comp.nc"
    proc = fivecal("compensate", d / "result.json", HU40T, PROGRAM, "--out", out2, "--decimals", "5")
    assert proc.returncode == 0, proc.stderr
    assert out2.read_bytes() != open(PROGRAM, "rb").read()
    assert re.search(r"tool-point error [\d.]+ µm max before, [\d.e-]+ µm max after", proc.stdout)
    # tables: CSV with the convention in its header, JSON with all kinds
    proc = fivecal("compensate", d / "result.json", d / "ds.json", "--table", tmp_path / "e.csv")
    assert proc.returncode == 0, proc.stderr
    text = (tmp_path / "e.csv").read_text(encoding="utf-8")
    assert text.startswith("# fivecal machine errors") and "# Sign convention" in text
    assert "\nname,kind,axis,component,value,std,unit," in text and "EX0C,location,C,X," in text
    proc = fivecal("compensate", d / "result.json", HU40T, "--table", tmp_path / "e.json", "--table-all")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "e.json").read_text(encoding="utf-8"))
    assert doc["format"] == "fivecal-error-table" and doc["errors"]


def test_refuses_to_overwrite_the_program(files, tmp_path):
    src = tmp_path / "p.nc"
    src.write_bytes(open(PROGRAM, "rb").read())
    proc = fivecal("compensate", files / "result.json", HU40T, src, "--out", src)
    assert proc.returncode == 2 and "refusing to overwrite" in proc.stderr
    assert src.read_bytes() == open(PROGRAM, "rb").read()


def test_demo_prints_summary_and_report_location(tmp_path):
    proc = fivecal("demo", "--out", "demo_out", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "true vs identified" in out and "validation on" in out
    m = re.search(r"report: (\S+report\.html)", out)
    assert m and os.path.isfile(m.group(1)) and m.group(1) == str(tmp_path / "demo_out" / "report.html")
    assert len(out.splitlines()) < 45  # a summary, not the full 60-parameter report


# ---------------------------------------------------------------- progress
class FakeTTY(io.StringIO):
    def __init__(self, tty):
        super().__init__()
        self._tty = tty

    def isatty(self):
        return self._tty


def test_progress_draws_only_on_a_tty_or_when_forced(monkeypatch):
    monkeypatch.delenv("FIVECAL_PROGRESS", raising=False)
    pipe = FakeTTY(False)
    assert list(progress(range(5), label="x", stream=pipe)) == list(range(5))
    assert pipe.getvalue() == ""
    tty = FakeTTY(True)
    with Progress(4, "Monte Carlo", stream=tty, min_interval=0) as bar:
        for _ in range(4):
            bar.update()
    text = tty.getvalue()
    assert "Monte Carlo: [" in text and "100% 4/4" in text and text.endswith("\n")
    monkeypatch.setenv("FIVECAL_PROGRESS", "1")
    assert progress_enabled(stream=FakeTTY(False))
    monkeypatch.setenv("FIVECAL_PROGRESS", "0")
    assert not progress_enabled(stream=FakeTTY(True))
    assert progress_enabled(True, FakeTTY(False))


def test_busy_indicator_shows_elapsed_time_for_long_calls():
    import time

    tty = FakeTTY(True)
    with busy("fitting", stream=tty, enabled=True, delay=0.05, interval=0.02):
        time.sleep(0.3)
    assert "fitting: done in" in tty.getvalue()
    quick = FakeTTY(True)
    with busy("fitting", stream=quick, enabled=True, delay=1.0):
        pass
    assert quick.getvalue() == ""
