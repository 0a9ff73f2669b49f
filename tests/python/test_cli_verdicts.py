"""Every command that fits judges its fit as ``fivecal identify`` does: a fit
that did not converge, is not finite, is inadequate (chi-square against the
declared noise) or left parameters undetermined exits 1 with one line saying
why (the outputs are still written, to inspect), unless ``--force``; a result
file that is not usable is refused (exit 2) by ``fivecal sphere --values``
as by ``fivecal compensate``. Each command: a good and a bad case."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
MACHINES = os.path.join(ROOT, "examples", "machines")


def cli(*args, cwd=None):
    env = dict(os.environ)
    env.pop("FIVECAL_DEBUG", None)
    env["FIVECAL_PROGRESS"] = "0"
    return subprocess.run([sys.executable, "-m", "fivecal", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=cwd, timeout=600)


def one_line(p):
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    return lines[0]


def with_sigma(src, dst, sigma):
    """The dataset ``src`` declaring the noise ``sigma`` (mm) on every
    observation: far below the real noise, its fit is inadequate."""
    d = json.loads(src.read_text())
    for o in d["observations"]:
        o["sigma"] = sigma
    dst.write_text(json.dumps(d))
    return dst


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("verdicts")
    c600u, vmc = os.path.join(MACHINES, "c600u.json"), os.path.join(MACHINES, "vmc0656.json")
    for args in (["dbb", "jiang", "--machine", c600u, "--simulate", "paper", "--sigma", "0.0003",
                  "--save-dataset", d / "jiang.json"],
                 ["dbb", "wang", "--machine", vmc, "--simulate", "paper", "--sigma", "0.0003", "--every", "90",
                  "--save-dataset", d / "wang.json"],
                 ["simulate", os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json"),
                  "--out", d / "spheres.json"],
                 ["identify", d / "spheres.json", "--estimate", "location", "--out", d / "good.json"]):
        p = cli(*args)
        assert p.returncode == 0, (args, p.stderr)
    for name in ("jiang", "wang", "spheres"):
        with_sigma(d / f"{name}.json", d / f"{name}_tiny_sigma.json", 1e-6)
    return d


def test_dbb_jiang(work):
    assert cli("dbb", "jiang", work / "jiang.json").returncode == 0
    out = work / "jiang_result.json"
    p = cli("dbb", "jiang", work / "jiang_tiny_sigma.json", "--out", out)
    assert p.returncode == 1
    line = one_line(p)
    assert line.startswith("fivecal dbb jiang: not usable: general engine: the model does not explain the data "
                           "within the declared instrument noise") and "--force" in line
    assert out.exists()  # written, to inspect why
    p = cli("dbb", "jiang", work / "jiang_tiny_sigma.json", "--force")
    assert p.returncode == 0 and "warning: not usable" in one_line(p)


def test_dbb_wang(work):
    assert cli("dbb", "wang", work / "wang.json").returncode == 0
    p = cli("dbb", "wang", work / "wang_tiny_sigma.json")
    assert p.returncode == 1 and "declared instrument noise" in one_line(p)
    assert cli("dbb", "wang", work / "wang_tiny_sigma.json", "--force").returncode == 0


def test_dbb_circular(work, monkeypatch, capsys):
    from fivecal import cli as fivecal_cli
    from fivecal.procedures import dbb

    args = ["dbb", "circular", "--machine", os.path.join(MACHINES, "c600u.json"), "--simulate",
            "EXX1=1e-4,EC0Y=3e-5", "--radius", "100"]
    assert fivecal_cli.main(args) == 0
    capsys.readouterr()
    real = dbb.circular_test

    def degenerate(*a, **k):  # a diagnosis that came out NaN (a degenerate trace)
        r = real(*a, **k)
        r.diagnosis = {**r.diagnosis, "squareness": float("nan")}
        return r

    monkeypatch.setattr(dbb, "circular_test", degenerate)
    assert fivecal_cli.main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not finite" in err[0] and "diagnosis squareness" in err[0], err
    assert fivecal_cli.main(args + ["--force"]) == 0


def test_sphere(work, monkeypatch, capsys):
    ok = cli("sphere", work / "spheres.json", "--sphere-id", "S1", "--values", work / "good.json")
    assert ok.returncode == 0 and "reduced" in ok.stdout, ok.stderr
    # An unusable result is refused as `fivecal compensate` refuses it.
    bad = json.loads((work / "good.json").read_text())
    bad.update(converged=False, verdict="not_converged", iterations=1)
    (work / "bad.json").write_text(json.dumps(bad))
    p = cli("sphere", work / "spheres.json", "--sphere-id", "S1", "--values", work / "bad.json")
    assert p.returncode == 2 and "refusing to use" in one_line(p) and "did not converge" in p.stderr
    assert cli("sphere", work / "spheres.json", "--sphere-id", "S1", "--values", work / "bad.json",
               "--force").returncode == 0
    # The sphere fit itself stopped before converging.
    from fivecal import cli as fivecal_cli
    from fivecal.cli import sphere as sphere_command  # where the command looks `sphere_test` up
    from fivecal.procedures import sphere_test as cmm

    real = cmm.sphere_test

    def stopped(*a, **k):
        t = real(*a, **k)
        t.fit.converged = False
        return t

    monkeypatch.setattr(sphere_command, "sphere_test", stopped)
    assert fivecal_cli.main(["sphere", str(work / "spheres.json"), "--sphere-id", "S1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sphere fit (nominal model)" in err[0] and "did not converge" in err[0], err


def test_uncertainty_monte_carlo(work):
    args = ["--estimate", "location", "--trials", "20", "--no-progress"]
    assert cli("uncertainty", work / "spheres.json", *args).returncode == 0
    out = work / "mc.json"
    p = cli("uncertainty", work / "spheres_tiny_sigma.json", *args, "--out", out)
    assert p.returncode == 1
    assert "the fit of the dataset: the model does not explain the data" in one_line(p)
    assert out.exists()
    assert cli("uncertainty", work / "spheres_tiny_sigma.json", *args, "--force").returncode == 0


def test_uncertainty_cycles(work):
    cycles = []
    for seed in (1, 2):
        p = cli("simulate", os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json"), "--seed", seed,
                "--out", work / f"cycle{seed}.json")
        assert p.returncode == 0, p.stderr
        cycles.append(work / f"cycle{seed}.json")
    pool = ["--days", "1,1", "--pool", "days"]
    ok = cli("uncertainty", *cycles, "--estimate", "location", *pool)
    assert ok.returncode == 0, ok.stderr
    tiny = [with_sigma(c, work / f"tiny_{c.name}", 1e-6) for c in cycles]
    p = cli("uncertainty", *tiny, "--estimate", "location", *pool)
    assert p.returncode == 1 and "declared instrument noise" in one_line(p)
    assert "tiny_cycle1.json" in p.stderr


def test_force_and_exit_1_are_documented():
    readme = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    for words in ("fivecal dbb", "fivecal uncertainty", "fivecal sphere"):
        assert words in readme[readme.index("**Exit codes**"):readme.index("**Exit codes**") + 4000], words
    for c in (["dbb", "jiang"], ["dbb", "wang"], ["dbb", "circular"], ["uncertainty"], ["sphere"]):
        assert "--force" in cli(*c, "--help").stdout, c
