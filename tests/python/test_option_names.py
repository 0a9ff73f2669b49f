"""Same words, same meaning in every command (issue 28, item 6): one name per
option concept in every `fivecal <cmd> --help`, the old spellings only as
hidden deprecated aliases, tolerances named for what they grade and read by
one rule (bare = file unit, an implausible bare number refused naming the
option and the unit), a FAIL or an alarm exits 1."""
import argparse
import os
import re

import pytest

import fivecal.cli as cli
from fivecal import tolerances as T
from fivecal.cli import main

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")


def _parser(monkeypatch):
    """The parser `fivecal` builds (every command registered by main itself)."""
    got = {}

    def capture(self, argv=None, namespace=None):
        got["p"] = self
        raise SystemExit(0)

    monkeypatch.setattr(cli._Parser, "parse_args", capture)
    with pytest.raises(SystemExit):
        main([])
    return got["p"]


def _commands(parser, name="fivecal"):
    """(command path, parser) of every command and sub-command."""
    out = [(name, parser)]
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for n, sp in a.choices.items():
                out += _commands(sp, f"{name} {n}")
    return out


def _visible(parser):
    return {s: a for a in parser._actions if a.help != argparse.SUPPRESS for s in a.option_strings}


#: concept -> (the one name, spellings no command may show)
ONE_NAME = {
    "calibration store": ("--store", ["--history", "--db", "--database"]),
    "a sphere (id or centre)": ("--sphere-id / --sphere-centre", ["--sphere", "--sphere-center"]),
    "plausibility limit on a change": ("--max-change", ["--max-correction", "--max-modification"]),
    "tolerance on a change": ("--change-tolerance", ["--delta-tolerance", "--drift-tolerance"]),
    "tolerance of a path": ("--path-tolerance", []),
    "output file": ("--out", ["--output", "-o", "--out-file"]),
    "machine file": ("--machine", ["--machine-file", "--machine-json"]),
    "angle units": ("--angle-units", ["--angle-unit", "--angles", "--deg"]),
    "length units": ("--units", ["--unit", "--length-units"]),
    "override a refusal": ("--force", ["--yes", "--overwrite", "--no-check"]),
}


def test_every_command_shows_one_name_per_concept(monkeypatch):
    cmds = _commands(_parser(monkeypatch))
    assert len(cmds) > 25
    for path, p in cmds:
        opts = _visible(p)
        text = p.format_help()
        for concept, (name, others) in ONE_NAME.items():
            for o in others:
                assert o not in opts, f"{path}: {o} for the {concept}: the one name is {name}"
                # nor in a help text pointing at it
                assert not re.search(re.escape(o) + r"(?![\w-])", text), f"{path} --help names {o} ({concept})"


def test_tolerance_options_are_named_for_what_they_grade(monkeypatch):
    seen = {}
    for path, p in _commands(_parser(monkeypatch)):
        for o, a in _visible(p).items():
            if "tolerance" not in o:
                continue
            seen.setdefault(o, []).append(path)
            h = a.help.lower()
            if o == T.VALUE_OPTION:     # a value: a parameter's |value| or a K test's range
                assert "change" not in h, (path, a.help)
            elif o == T.CHANGE_OPTION:
                assert "change |b - a|" in h, (path, a.help)
            elif o == T.PATH_OPTION:
                assert "between two blocks" in h, (path, a.help)
            else:
                assert o == "--volumetric-tolerance", (path, o)
            # every tolerance takes a unit and says a bare number is in the file unit
            assert re.search(r"\bum\b|µm|urad|unit", h), (path, o, a.help)
    assert set(seen[T.VALUE_OPTION]) == {"fivecal identify", "fivecal history trend", "fivecal rtest", "fivecal dbb circular",
                                          "fivecal dbb volumetric"}
    assert seen[T.CHANGE_OPTION] == ["fivecal history compare"]
    assert seen[T.PATH_OPTION] == ["fivecal export program"]


@pytest.mark.parametrize("argv, old, new", [
    (["history", "compare", "a.json", "b.json", "--tolerance", "EX0C=5um"], "--tolerance", "--change-tolerance"),
    (["identify", "ds.json", "--history", "s.fcdb"], "--history", "--store"),
    (["compensate", "r.json", "m.json", "--max-correction", "off"], "--max-correction", "--max-change"),
    (["export", "program", "spec.json", "--tolerance", "0.1um"], "--tolerance", "--path-tolerance"),
    (["sphere-check", "ds.json", "--sphere", "S1"], "--sphere", "--sphere-id"),
    (["plan", "sphere-check", "m.json", "--out", "p.json", "--sphere", "1,2,3", "--radius", "5", "--tip-radius",
      "1"], "--sphere", "--sphere-centre"),
])
def test_old_spellings_are_hidden_aliases_that_warn(monkeypatch, capsys, argv, old, new):
    p = _parser(monkeypatch)
    monkeypatch.undo()
    args = p.parse_args(argv)
    err = capsys.readouterr().err
    assert f"{old} is deprecated, write {new}" in err
    dest = {"--change-tolerance": "change_tolerance", "--store": "history", "--max-change": "max_change",
            "--path-tolerance": "path_tolerance", "--sphere-id": "sphere", "--sphere-centre": "sphere"}[new]
    assert getattr(args, dest) in (["EX0C=5um"], "s.fcdb", "off", "0.1um", "S1", "1,2,3")


def test_a_bare_tolerance_is_in_the_file_unit_everywhere_and_an_implausible_one_is_refused():
    # the same rule for a parameter's, a K test's range and a ball bar path's tolerance
    assert T.parameter_tolerance("EX0C", "0.012") == pytest.approx(0.012)
    assert T.parameter_tolerance("EX0C", "12um") == pytest.approx(0.012)
    assert T.parameter_tolerance("EA0C", "20urad") == pytest.approx(2e-5)
    assert T.range_tolerance("0.02") == pytest.approx(0.02)
    assert T.range_tolerance("20um") == pytest.approx(0.02)
    assert T.path_tolerance("1e-4") == pytest.approx(1e-4)
    assert T.path_tolerance("0.1um") == pytest.approx(1e-4)
    for f, bare, option in ((lambda v: T.parse_tolerances([f"EX0C={v}"]), "12", "--tolerance EX0C"),
                            (lambda v: T.parse_tolerances([f"EX0C={v}"], option=T.CHANGE_OPTION), "12",
                             "--change-tolerance EX0C"),
                            (T.range_tolerance, "20", "--tolerance"),
                            (T.path_tolerance, "0.02", "--path-tolerance")):
        with pytest.raises(ValueError, match="implausibly large") as e:
            f(bare)
        assert str(e.value).startswith(option + ":") and f"{bare}um" in str(e.value), str(e.value)


def test_export_program_path_tolerance_default_is_the_ball_bar_resolution(monkeypatch):
    from fivecal.cli import export
    p = _parser(monkeypatch)
    monkeypatch.undo()
    args = p.parse_args(["export", "program", "spec.json"])
    # 0.02 µm before: five times finer than a ball bar reads, twice the blocks for nothing
    assert T.path_tolerance(args.path_tolerance) == pytest.approx(1e-4)
    assert export.DEFAULT_PATH_TOLERANCE == "0.1um"


def test_docs_use_the_one_names():
    texts = {}
    for d in ("docs",):
        for f in os.listdir(os.path.join(ROOT, d)):
            if f.endswith(".md"):
                texts[f"{d}/{f}"] = open(os.path.join(ROOT, d, f), encoding="utf-8").read()
    texts["README.md"] = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    texts.pop("docs/commands.md")   # the page that lists the old spellings, as such
    for name, text in texts.items():
        # the one paragraph that lists the old spellings, as such
        text = re.sub(r"The old spellings are hidden aliases.*?\n\n", "", text, flags=re.S)
        assert "--max-correction" not in text, name
        for line in text.splitlines():
            if re.search(r"history compare[^,`]*--tolerance", line):
                raise AssertionError(f"{name}: {line.strip()}: history compare grades the change: "
                                     "--change-tolerance")
            if re.search(r"identify .*--history\b", line):
                raise AssertionError(f"{name}: {line.strip()}: the store is --store")


# ---- small defects fixed with item 6 ------------------------------------------

def test_python_plans_are_bounded_in_the_function_not_only_by_the_cli():
    import fivecal
    from fivecal.procedures import rtest, sphere_check
    from test_linuxcnc import MACHINES
    m = fivecal.Machine.from_dict(MACHINES["xyzac-trt"])
    for step in (1e-9, 0.0, float("nan"), True):
        with pytest.raises(ValueError, match=r"^step: .*at most 100000 samples a turn"):
            rtest.plan(m, "K1", table_ball=[60, 20, 30], step=step)
    assert len(rtest.plan(m, "K1", table_ball=[60, 20, 30], step=30)) == 13
    ball = {"id": "S1", "center": [60, 30, 40], "radius": 12.5}
    for n in (10 ** 9, 2, 5.5, float("nan"), True):
        with pytest.raises(ValueError, match=r"^n: .*from 3 .* to 360"):
            sphere_check.plan(m, ball, tip_radius=3, n=n)
    with pytest.raises(ValueError, match=r"axis_positions.C: 361 positions; at most 360"):
        sphere_check.plan(m, ball, tip_radius=3, axis_positions={"C": list(range(361))})
    assert sphere_check.plan(m, ball, tip_radius=3, n=5.0) == sphere_check.plan(m, ball, tip_radius=3, n=5)


def test_compensate_names_its_options(tmp_path, capsys):
    import json
    from fivecal.procedures import tango
    m = tango.hu40t_machine()
    mf, rf, prog = tmp_path / "m.json", tmp_path / "r.json", tmp_path / "p.nc"
    mf.write_text(json.dumps(m.to_dict()))
    rf.write_text(json.dumps({"EX0C": 0.01}))
    prog.write_text("G90 G1 X10 Y0 Z0 B0 C0\n")
    for tip in ("0,0", "0,0,nan", "a,b,c"):
        capsys.readouterr()
        assert main(["compensate", str(rf), str(mf), str(prog), "--out", str(tmp_path / "o.nc"),
                     "--tool-tip", tip]) == 2
        err = capsys.readouterr().err
        assert "--tool-tip:" in err and "tool_tip:" not in err, err
    assert main(["compensate", str(rf), str(mf), str(prog), "--out", str(tmp_path / "o.nc"),
                 "--max-change", "-1"]) == 2
    assert "--max-change:" in capsys.readouterr().err


# ---- a FAIL or an alarm exits 1 ------------------------------------------------

def _store_with_a_step(path, nights, step_at):
    import numpy as np
    from fivecal import history
    from fivecal.history import fleetsim
    rng = np.random.default_rng(4)
    cals = []
    for n in range(nights):
        x = 0.004 + (0.003 if n >= step_at else 0.0) + rng.normal(0, 2e-4)
        cals.append(history.Calibration("M1", fleetsim.night_time(n), ["EX0C"], np.array([x]),
                                        np.eye(1) * 4e-8))
    with history.Store(str(path)) as s:
        s.add_many(cals)


def test_history_trend_exits_1_on_an_alarm_of_the_latest_calibration(tmp_path, capsys):
    db = tmp_path / "s.fcdb"
    _store_with_a_step(db, 13, 12)          # EX0C steps by 3 µm on the latest night
    capsys.readouterr()
    assert main(["history", "trend", "--store", str(db), "--machine-id", "M1"]) == 1
    out, err = capsys.readouterr()
    assert "ALARM on the latest calibration" in out and "CUSUM ALARM" in err, (out, err)
    # the night after, the chart has taken the step as its reference: listed, no longer news
    db2 = tmp_path / "s2.fcdb"
    _store_with_a_step(db2, 14, 12)
    assert main(["history", "trend", "--store", str(db2), "--machine-id", "M1"]) == 0
    out, err = capsys.readouterr()
    assert "EX0C" in out and "no alarm" not in out.split("EX0C", 1)[1].splitlines()[0] and "ALARM" not in err
    # with no step at all: no alarm, exit 0
    db3 = tmp_path / "s3.fcdb"
    _store_with_a_step(db3, 13, 99)
    assert main(["history", "trend", "--store", str(db3), "--machine-id", "M1"]) == 0


def test_history_compare_exits_1_when_a_change_is_beyond_its_tolerance(tmp_path, capsys):
    import json
    rs = []
    for i, x in enumerate((0.010, 0.013)):
        p = tmp_path / f"r{i}.json"
        p.write_text(json.dumps({"parameters": {"EX0C": {"value": x, "std": 1e-4}}}))
        rs.append(str(p))
    capsys.readouterr()
    assert main(["history", "compare", *rs, "--change-tolerance", "EX0C=5um"]) == 0
    assert main(["history", "compare", *rs, "--change-tolerance", "EX0C=2um"]) == 1
    assert "FAIL: EX0C changed by more than --change-tolerance" in capsys.readouterr().err
    # the old spelling still grades the change (hidden, with a warning), never the value
    assert main(["history", "compare", *rs, "--tolerance", "EX0C=5um"]) == 0
    assert "--tolerance is deprecated, write --change-tolerance" in capsys.readouterr().err
    # and a bare 12 (meant µm) is refused naming the option and the unit
    assert main(["history", "compare", *rs, "--change-tolerance", "EX0C=12"]) == 2
    err = capsys.readouterr().err
    assert "--change-tolerance EX0C" in err and "12um" in err, err


def test_identify_store_exits_1_on_an_alarm_of_this_result(tmp_path, capsys):
    """The trend identify --store --record shows: a 3 µm step of EX0C on this
    night's check alarms, exit 1 (as history trend); the same machine
    unchanged exits 0."""
    import fivecal
    from fivecal import history
    from fivecal.history import fleetsim
    m = fleetsim.machine()
    plan = fleetsim.sphere_check_plan(m)

    def dataset(ex, seed, path=None):
        ds = fivecal.simulate(m, plan, errors={"EX0C": ex}, artefact={"spheres": [fleetsim.SPHERE]},
                              tip_radius=3.0, sigma=0.0006, seed=seed)
        if path is not None:
            fivecal.save_dataset(ds, str(path))
        return ds

    db = str(tmp_path / "s.fcdb")
    with history.Store(db) as s:
        for night in range(8):
            r = fivecal.identify(dataset(0.010, night), "location")
            s.add(r, machine_id="M1", time=f"2026-01-{night + 1:02d}T02:00:00Z", digest=f"n{night}")
    capsys.readouterr()
    same, step = tmp_path / "2026-01-10.json", tmp_path / "2026-01-11.json"
    dataset(0.010, 100, same)
    dataset(0.013, 101, step)
    assert main(["identify", str(same), "--estimate", "location", "--store", db, "--machine-id", "M1",
                 "--record"]) == 0, capsys.readouterr().err
    capsys.readouterr()
    assert main(["identify", str(step), "--estimate", "location", "--store", db, "--machine-id", "M1",
                 "--record"]) == 1
    err = capsys.readouterr().err
    assert "CUSUM ALARM on this result: EX0C" in err, err
