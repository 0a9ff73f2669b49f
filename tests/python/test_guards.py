"""Never confidently wrong (issue 13, items 3-6): a fit that did not converge,
is not finite, is inadequate or left requested parameters undetermined is
refused by every consumer unless forced; the probe stylus offsets and
undetermined parameters never reach the machine; a correction beyond the
plausibility limit stops compensation; the reports say all of it in plain
words; the command line's exit codes are 0/1/2/3 as documented.
"""
import json
import os
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import fivecal
from fivecal import guards
from fivecal.procedures import tango
from fivecal.compensation import compensate_gcode, compensate_gcode_file, error_table
from fivecal.simulation import simulate

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
HU40T = os.path.join(ROOT, "examples", "machines", "hu40t.json")
PROGRAM = os.path.join(ROOT, "examples", "gcode", "hu40t_5axis.nc")
POSES = {"X": [0, 100], "Y": [0, 50], "Z": [0, 20], "B": [0, 30], "C": [0, 90]}


def fivecal_cli(*args, env=None, cwd=None):
    e = dict(os.environ)
    e.pop("FIVECAL_DEBUG", None)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "fivecal", *map(str, args)], capture_output=True, text=True,
                          env=e, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.load(HU40T)


@pytest.fixture(scope="module")
def dataset(machine):
    """The README quick start's data: the Table 4-2 plan on the TANGO table,
    S3 truth, a probe stylus offset, 0.6 µm noise."""
    art = tango.octagonal_table()
    plan = tango.hu40t_plan(art, machine)
    truth = {**tango.thesis_s3_errors(), "tip.x": 0.004, "tip.y": -0.006, "tip.z": 0.012}
    return simulate(machine, plan, errors=truth, artefact=art, tip_radius=3.0, sigma=0.0006, seed=1)


@pytest.fixture(scope="module")
def good(dataset):
    with warnings.catch_warnings():
        warnings.simplefilter("error", fivecal.FitWarning)  # a usable fit warns nothing
        return fivecal.identify(dataset, "S3")


@pytest.fixture(scope="module")
def unconverged(dataset):
    """A fit stopped before it converged (one iteration from a rough start)."""
    with pytest.warns(fivecal.FitWarning, match="did not converge"):
        r = fivecal.identify(dataset, "S3", max_iterations=1, initial={"EX0C": 3.0, "EB0C": 0.05})
    assert not r.converged
    return r


@pytest.fixture(scope="module")
def ill_posed(dataset):
    """Every other touch (the old README example): sphere S2 keeps two touches,
    so its centre and with it the length reference are lost. Fitted anyway
    (allow_unidentifiable), the fit either runs into its iteration limit with
    r = 1.000 between facets or says what it could not determine."""
    with pytest.warns(fivecal.FitWarning):
        r = fivecal.identify(dataset.subset(range(0, len(dataset), 2)), "S3", allow_unidentifiable=True)
    assert not r.usable
    return r


@pytest.fixture(scope="module")
def confounded(dataset):
    """EX0B and EX0S move the tool the same way on this plan."""
    with pytest.warns(fivecal.FitWarning, match="did not determine"):
        r = fivecal.identify(dataset, "S3,EX0B", allow_unidentifiable=True)
    assert r.converged and r.unidentifiable
    return r


# --- item 1: verdict, usable, require_usable ---------------------------------------------------------

def test_exported_names():
    assert issubclass(fivecal.UnusableResultError, ValueError)
    assert issubclass(fivecal.FitWarning, Warning)
    assert {"UnusableResultError", "FitWarning", "CorrectionLimitError"} <= set(fivecal.__all__)


def test_usable_and_require_usable(good, unconverged, confounded):
    assert good.usable and good.assessment().verdict == "ok"
    good.require_usable()
    assert not unconverged.usable and unconverged.assessment().verdict == "not_converged"
    with pytest.raises(fivecal.UnusableResultError, match=r"did not converge in \d+ iterations"):
        unconverged.require_usable()
    unconverged.require_usable(force=True)
    a = confounded.assessment()
    assert a.verdict == "undetermined" and {"EX0B", "EX0S"} <= set(a.undetermined)
    with pytest.raises(fivecal.UnusableResultError, match="did not determine .*EX0B"):
        confounded.require_usable()


def test_verdict_from_result_json(good, unconverged, tmp_path):
    """`fivecal compensate` judges the file: a result JSON carries what is needed."""
    assert guards.assess(good.to_dict()).usable
    d = unconverged.to_dict()
    assert guards.assess(d).verdict == "not_converged"
    p = tmp_path / "r.json"
    p.write_text(json.dumps(d))
    assert guards.assess(str(p)).verdict == "not_converged"
    # a verdict written by the fit wins; non-finite values are caught either way
    assert guards.assess({**good.to_dict(), "verdict": "inadequate", "adequacy": "no length reference"}) \
        .reason.endswith("likely cause: no length reference")
    bad = good.to_dict()
    bad["parameters"]["EX0C"]["value"] = float("nan")
    a = guards.assess(bad)
    assert a.verdict == "non_finite" and "EX0C" in a.reason
    # a plain name -> value mapping given by hand is not a fit: accepted as it is
    assert guards.assess({"EX0C": 0.01}).usable


# --- item 1: every consumer refuses an unusable result unless forced ---------------------------------

def test_consumers_refuse_an_unconverged_result(unconverged, machine, tmp_path):
    program = open(PROGRAM).read()
    calls = {
        "compensate_poses": lambda **k: fivecal.compensate_poses(machine, unconverged, POSES, **k),
        "compensate_gcode": lambda **k: compensate_gcode(program, machine, unconverged, **k),
        "compensate_gcode_file": lambda **k: compensate_gcode_file(PROGRAM, tmp_path / "o.nc", machine,
                                                                   unconverged, **k),
        "write_error_table": lambda **k: fivecal.write_error_table(tmp_path / "e.csv", unconverged, machine,
                                                                   **k),
        "error_table": lambda **k: error_table(unconverged, machine, **k),
    }
    for name, call in calls.items():
        with pytest.raises(fivecal.UnusableResultError, match="did not converge"):
            call()
    assert not (tmp_path / "o.nc").exists() and not (tmp_path / "e.csv").exists()
    # force=True: the values are used
    comp = fivecal.compensate_poses(machine, unconverged, POSES, force=True, max_correction=None,
                                    max_correction_deg=None)
    assert len(comp) == 2
    res = compensate_gcode_file(PROGRAM, tmp_path / "o.nc", machine, unconverged, force=True,
                                max_correction=None, max_correction_deg=None)
    assert res.moves > 0 and (tmp_path / "o.nc").is_file()
    fivecal.write_error_table(tmp_path / "e.csv", unconverged, machine, force=True)
    head = [line for line in open(tmp_path / "e.csv") if line.startswith("#")]
    assert any("NOT USABLE" in line and "did not converge" in line for line in head)


def test_report_of_an_unusable_fit_is_written_with_a_red_banner(unconverged, tmp_path):
    # what was refused before the guards: the report of this fit looked fine
    path = fivecal.write_report(unconverged, tmp_path / "rep")
    doc = open(path, encoding="utf-8").read()
    body = doc[doc.index("<main>"):]
    first_box = re.search(r"<div class='box (\w+)'[^>]*>(.*?)</div>", body, re.S)
    assert first_box.group(1) == "bad" and "NOT USABLE" in first_box.group(2)
    assert "did not converge" in first_box.group(2)
    assert "NOT USABLE" in re.search(r"<title>(.*?)</title>", doc).group(1)
    assert not re.search(r"class=['\"]box ok['\"]", doc), "a green box in the report of an unusable fit"
    assert "No confounded groups" not in doc
    assert "not usable" in unconverged.report().lower().splitlines()[1]


def test_no_green_box_beside_r_of_one(ill_posed, confounded, tmp_path):
    """The old report: a green 'No confounded groups' under a red non-convergence
    box, next to pairs with r = 1.000."""
    C = np.abs(ill_posed.correlation[np.triu_indices(len(ill_posed.estimated), 1)])
    assert C.max() >= 0.999
    for r, name in ((ill_posed, "u"), (confounded, "c")):
        doc = open(fivecal.write_report(r, tmp_path / name), encoding="utf-8").read()
        assert "No confounded groups" not in doc and "box ok" not in doc
        ident = doc[doc.index("id='identifiability'"):doc.index("id='parameters'")]
        assert "cannot separate" in ident
        assert "NOT USABLE" in doc[:doc.index("id='findings'")]
    # the pairs are named in the text report too
    assert re.search(r"pairs the data cannot separate \(\|r\| ≥ 0.999\)|confounded", ill_posed.report())


def test_report_of_a_good_fit_says_what_was_identified(good, tmp_path):
    doc = open(fivecal.write_report(good, tmp_path / "g"), encoding="utf-8").read()
    body = doc[doc.index("<main>"):]
    first_box = re.search(r"<div class='box (\w+)'[^>]*>(.*?)</div>", body, re.S)
    assert first_box.group(1) == "ok" and first_box.group(2).startswith("<b>OK.</b> Usable: the fit converged")
    findings = doc[doc.index("id='findings'"):doc.index("id='machine'")]
    assert "Identified" in findings and "EX0C" in findings and "Not determined by this data" in findings
    assert "No confounded groups" in doc
    text = good.report()
    assert text.splitlines()[1].startswith("  OK (usable)") and "identified: 52 parameters" in text


def test_reports_name_undetermined_and_implausible(good, tmp_path):
    """Fields a fit with priors adds (undetermined, implausible, informed) are
    shown where they exist (set by hand here)."""
    keys = ("undetermined", "implausible", "informed", "prior_std", "verdict")
    saved = {k: good.__dict__[k] for k in keys if k in good.__dict__}
    good.undetermined = ["EYYb"]
    good.implausible = ["EX0C"]
    good.informed = {n: (0.3 if n == "EA0Y" else 0.01) for n in good.estimated}
    good.prior_std = {n: 0.01 for n in good.estimated}
    good.verdict = "ok"
    try:
        text = good.report()
        assert "not determined by this data" in text and "EYYb" in text.split("not determined by this data")[1]
        assert re.search(r"implausible.*EX0C", text) and re.search(r"informed only in part.*EA0Y", text)
        assert "EYYb" not in good.machine_errors()
        doc = open(fivecal.write_report(good, tmp_path / "p"), encoding="utf-8").read()
        assert "box ok" not in doc.split("id='findings'")[0]  # amber, not green
        assert "IMPLAUSIBLE" in doc and "NOT DETERMINED" in doc and "informed (σ/prior σ)" in doc
    finally:
        for k in keys:
            good.__dict__.pop(k, None)
        good.__dict__.update(saved)


# --- undetermined never exported; item 2: machine_errors without tip.* ----------------------------

def test_machine_errors_exclude_tip_and_undetermined(good, confounded, machine):
    assert "tip.x" in good.values and not any(n.startswith("tip.") for n in good.machine_errors())
    # the stylus offset must not appear in the machine's error map
    e = good.machine_errors()
    with_tip = {**e, "tip.z": good.values["tip.z"]}
    assert not np.allclose(machine.volumetric_error(POSES, e), machine.volumetric_error(POSES, with_tip))
    with pytest.raises(fivecal.UnusableResultError):
        confounded.machine_errors()  # the plain dict would carry no verdict to the consumers
    assert {"EX0B", "EX0S"}.isdisjoint(confounded.machine_errors(force=True))
    assert "EX0S" in confounded.machine_errors(force=True, include_undetermined=True)


def test_undetermined_left_out_of_tables_and_compensation(confounded, machine, tmp_path):
    rows = fivecal.write_error_table(tmp_path / "e.csv", confounded, machine, force=True)
    assert "EX0S" not in {r["name"] for r in rows} and "EX0C" in {r["name"] for r in rows}
    head = "".join(line for line in open(tmp_path / "e.csv") if line.startswith("#"))
    assert re.search(r"Not determined by the measurement, left out of this table.*EX0S", head)
    fivecal.write_error_table(tmp_path / "e.json", confounded, machine, force=True)
    doc = json.load(open(tmp_path / "e.json"))
    assert "EX0S" in doc["not_determined"] and doc["usable"] is False
    from fivecal.compensation import load_errors

    assert "EX0S" not in load_errors(confounded.to_dict(), machine)


# --- item 3: plausibility limit -----------------------------------------------------------------

def implausible_result(good) -> dict:
    """A usable result whose EX0C has a unit mistake (2 mm instead of 2 µm)."""
    d = good.to_dict()
    d["parameters"]["EX0C"]["value"] = 2.0
    return d


def test_max_correction_stops_compensation(good, machine):
    bad = implausible_result(good)
    assert guards.assess(bad).usable
    with pytest.raises(fivecal.CorrectionLimitError, match=r"pose [01]: the correction of axis \w is [\d.]+ mm, "
                                                           r"more than the plausibility limit of 0.5 mm \(max_correction, --max-change\)"):
        fivecal.compensate_poses(machine, bad, POSES)
    with pytest.raises(fivecal.CorrectionLimitError, match=r"part.nc:\d+: the correction of axis \w"):
        compensate_gcode(open(PROGRAM).read(), machine, bad, name="part.nc")
    assert len(fivecal.compensate_poses(machine, bad, POSES, max_correction=None)) == 2
    # a usable fit of a machine in working order stays far inside the default limit
    fivecal.compensate_poses(machine, good, POSES)
    with pytest.raises(fivecal.CorrectionLimitError) as e:
        fivecal.compensate_poses(machine, good, POSES, max_correction=1e-4)
    assert e.value.unit == "mm" and e.value.size > 1e-4 and e.value.index in (0, 1)
    with pytest.raises(fivecal.CorrectionLimitError, match=r"axis [BC] .* deg"):
        fivecal.compensate_poses(machine, {"EB0C": 0.02}, POSES, orientation=True, max_rotary_correction=5,
                                 max_correction_deg=0.1)


# --- item 5: exit codes --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def files(dataset, good, unconverged, tmp_path_factory):
    d = tmp_path_factory.mktemp("guards_cli")
    fivecal.save_dataset(dataset, d / "full.json")
    fivecal.save_dataset(dataset.subset(range(0, len(dataset), 2)), d / "half.json")
    good.save(d / "good.json")
    unconverged.save(d / "bad.json")
    (d / "implausible.json").write_text(json.dumps(implausible_result(good)))
    return d


def test_identify_exit_codes(files):
    d = files
    ok = fivecal_cli("identify", d / "full.json", "--estimate", "S3", "--out", d / "good_cli.json")
    assert ok.returncode == 0, ok.stderr
    bad = fivecal_cli("identify", d / "half.json", "--estimate", "S3", "--allow-unidentifiable",
                      "--out", d / "half_result.json", "--report", d / "bad_report")
    assert bad.returncode == 1, bad.stderr
    lines = bad.stderr.strip().splitlines()
    assert len(lines) == 1 and "not usable" in lines[0], bad.stderr
    assert "Warning" not in bad.stderr
    # still written, marked: a user can inspect why
    assert not guards.assess(str(d / "half_result.json")).usable
    assert "NOT USABLE" in (d / "bad_report" / "report.html").read_text(encoding="utf-8")
    assert "NOT USABLE" in bad.stdout
    conf = fivecal_cli("identify", d / "full.json", "--estimate", "S3,EX0B", "--allow-unidentifiable")
    assert conf.returncode == 1 and "EX0B" in conf.stderr
    refused = fivecal_cli("identify", d / "full.json", "--estimate", "S3,EX0B")
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
    missing = fivecal_cli("identify", d / "nope.json")
    assert missing.returncode == 2


def test_compensate_exit_codes(files, tmp_path):
    d = files
    base = [HU40T, PROGRAM, "--out", tmp_path / "o.nc"]
    p = fivecal_cli("compensate", d / "bad.json", *base)
    assert p.returncode == 2 and "refusing to use" in p.stderr and "did not converge" in p.stderr
    assert "--force" in p.stderr and not (tmp_path / "o.nc").exists()
    p = fivecal_cli("compensate", d / "bad.json", HU40T, "--table", tmp_path / "t.csv")
    assert p.returncode == 2 and not (tmp_path / "t.csv").exists()
    p = fivecal_cli("compensate", d / "bad.json", *base, "--force", "--max-correction", "off")
    assert p.returncode == 0, p.stderr
    p = fivecal_cli("compensate", d / "implausible.json", *base)
    assert p.returncode == 2 and "plausibility limit" in p.stderr and re.search(r"\.nc:\d+:", p.stderr)
    p = fivecal_cli("compensate", d / "good.json", *base)
    assert p.returncode == 0, p.stderr
    p = fivecal_cli("compensate", d / "good.json", *base, "--max-correction", "0.001")
    assert p.returncode == 2 and "0.001 mm" in p.stderr
    p = fivecal_cli("compensate", d / "good.json", *base, "--max-correction", "-1")
    assert p.returncode == 2 and "--max-change" in p.stderr


def test_every_command_exits_2_on_bad_input_and_0_on_help(tmp_path):
    out = fivecal_cli("--help").stdout
    commands = re.search(r"\{([a-z_,-]+)\}", out).group(1).split(",")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    for c in commands:
        assert fivecal_cli(c, "--help").returncode == 0, c
        args = {"demo": ["--seed", "x"], "design": [bad, "-k", "3"], "uncertainty": [bad],
                "compensate": [bad, bad, "--table", tmp_path / "t.csv"]}.get(c, [bad])
        p = fivecal_cli(c, *args)
        if p.returncode != 2 and c not in ("demo",):
            # subcommand groups (e.g. `dbb`) take a further command first
            p = fivecal_cli(c, "no-such-command")
        assert p.returncode == 2, (c, p.returncode, p.stderr)
        assert "Traceback" not in p.stderr, c


def test_internal_error_exits_3_and_debug_shows_the_traceback(files, monkeypatch, capsys):
    from fivecal import cli
    from fivecal.cli import identify as identify_command  # where the command looks `identify` up

    def broken(*a, **k):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(identify_command, "identify", broken)
    monkeypatch.delenv("FIVECAL_DEBUG", raising=False)
    assert cli.main(["identify", str(files / "full.json")]) == 3
    err = capsys.readouterr().err
    assert "internal error" in err and "FIVECAL_DEBUG=1" in err and "Traceback" not in err
    monkeypatch.setenv("FIVECAL_DEBUG", "1")
    with pytest.raises(ZeroDivisionError):
        cli.main(["identify", str(files / "full.json")])


def test_exit_codes_are_documented():
    readme = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    sec = readme[readme.index("## Quick start (command line)"):]
    sec = sec[:sec.index("\n## ", 5)]
    for code, words in ((0, "success"), (1, "not converge"), (2, "bad input"), (3, "internal")):
        assert re.search(rf"`{code}`[^\n]*{words}", sec), (code, words)
    assert "--force" in sec and "--max-change" in sec


@pytest.mark.parametrize("fault, words", [
    ({"adequate": False, "verdict": "inadequate", "chi2": 5400.0, "dof": 340, "chi2_p": 0.0,
      "adequacy": "instrument setup not estimated"}, "likely cause: instrument setup not estimated"),
    ({"verdict": "non_finite", "values": "nan"}, "not finite"),
])
def test_identify_exits_1_on_inadequate_or_non_finite(files, monkeypatch, capsys, fault, words):
    """The fit's own verdict (chi-square against the declared noise, finiteness)
    drives the exit status; the faults are injected into a real fit's result."""
    from fivecal import cli, identification
    from fivecal.cli import identify as identify_command  # where the command looks `identify` up

    real = identification.identify

    def faulty(*a, **k):
        r = real(*a, **k)
        for key, v in fault.items():
            if key == "values":
                r.values = {**r.values, "EX0C": float("nan")}
            else:
                setattr(r, key, v)
        return r

    monkeypatch.setattr(identify_command, "identify", faulty)
    assert cli.main(["identify", str(files / "full.json"), "--estimate", "S3"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err


def test_identify_exits_1_when_the_fit_does_not_converge(files, monkeypatch, capsys):
    """The solver stopped at its iteration limit: exit 1, one line, the result
    still written and marked."""
    from fivecal import cli, identification
    from fivecal.cli import identify as identify_command  # where the command looks `identify` up

    real = identification.identify
    monkeypatch.setattr(identify_command, "identify", lambda *a, **k: real(*a, **{**k, "max_iterations": 1}))
    out = files / "stopped.json"
    assert cli.main(["identify", str(files / "full.json"), "--estimate", "S3", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "did not converge in 1 iterations" in err[0], err
    assert guards.assess(str(out)).verdict == "not_converged"


# --- refusals stay readable: hundreds of names are cut to the first ten and a count --------------------

def test_refusal_about_hundreds_of_undetermined_parameters_is_capped(good):
    d = good.to_dict()
    names = [f"sphere.S{i}.y" for i in range(300)]
    d.update(verdict="undetermined", undetermined=names)
    a = guards.assess(d)
    assert a.undetermined == names  # every one is still kept out of the tables
    assert ", ".join(names[:10]) + " and 290 more" in a.reason and "S10." not in a.reason
    with pytest.raises(fivecal.UnusableResultError) as e:
        guards.require_usable(d)
    assert len(str(e.value)) < 400 and "and 290 more" in str(e.value)
    d = good.to_dict()
    for n in list(d["parameters"])[:30]:
        d["parameters"][n]["value"] = float("nan")
    a = guards.assess(d)
    assert a.verdict == "non_finite" and "and 20 more" in a.reason


def test_identify_refusal_of_many_undetermined_groups_is_capped():
    """120 spheres touched only in the XZ plane: 120 centres' y undetermined,
    one group each; the refusal names the first groups and counts the rest.
    The x and the z translations of the tip against every centre are two
    separate free directions, so two groups (the grouping follows the free
    subspace, not the basis an SVD picks in it)."""
    m = tango.hu40t_machine()
    s2 = 0.5 ** 0.5
    spheres = [{"id": f"S{i}", "center": [float(-200 + 13 * (i % 30)), float(-100 + 40 * (i // 30)), 30.0],
                "radius": 5.0} for i in range(120)]
    plan, pts = [], []
    for s in spheres:
        for n in ([0, 0, 1], [1, 0, 0], [-1, 0, 0], [s2, 0, s2], [-s2, 0, s2]):
            pts.append(np.array(s["center"]) + 8.0 * np.array(n, float))
            plan.append({"type": "sphere", "target": s["id"], "normal": n})
    ax = m.inverse(np.array(pts), np.tile([0, 0, 1.0], (len(pts), 1)))
    for i, e in enumerate(plan):
        e["axes"] = {a: float(v[i]) for a, v in ax.items()}
    ds = simulate(m, plan, artefact={"spheres": spheres}, tip_radius=3.0, sigma=0.001, seed=1)
    with pytest.raises(ValueError, match="not determined by this data") as e:
        fivecal.identify(ds, ["EX0C"])
    msg = str(e.value)
    assert len(msg) < 1000, msg
    assert "sphere.S119.y" not in msg
    assert re.search(r"and 2\d\d more parameters in 12\d more groups\. Fix one parameter", msg), msg
    with pytest.warns(fivecal.FitWarning):
        r = fivecal.identify(ds, ["EX0C"], allow_unidentifiable=True)
    groups = sorted(sorted(g) for g in r.unidentifiable)
    assert len(groups) == 123, groups
    for i in range(120):
        assert [f"sphere.S{i}.y"] in groups
    assert ["tip.y"] in groups
    assert sorted(["EX0C", "tip.x"] + [f"sphere.S{i}.x" for i in range(120)]) in groups
    assert sorted(["tip.z"] + [f"sphere.S{i}.z" for i in range(120)]) in groups
