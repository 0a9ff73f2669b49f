"""Identification engine details: robust loss, DBB and ball3d fits, CLI,
result JSON, volumetric error map."""
import json
import subprocess
import sys

import numpy as np
import pytest

import fivecal


def _sphere_plan(machine, n_index=12, seed=0):
    """Touches on a precision sphere on the table at many A/C indexations."""
    rng = np.random.default_rng(seed)
    plan = []
    for a in (-60, -30, 0, 30, 60):
        for c in range(0, 360, 360 // n_index):
            _, ax = machine.tool_pose({"X": 0, "Y": 0, "Z": 0, "A": a, "C": c})
            for _ in range(5):
                v = ax[0] + 0.6 * rng.normal(size=3)  # touch the side facing the probe
                plan.append({"type": "sphere", "target": "S1", "axes": {"A": a, "C": c},
                             "normal": (v / np.linalg.norm(v)).tolist()})
    return plan


ART = {"spheres": [{"id": "S1", "center": [60.0, 40.0, 30.0], "radius": 12.5}]}
TRUE = {"EY0A": 0.020, "EZ0A": -0.015, "EB0A": 30e-6, "EC0A": -25e-6,
        "EX0C": 0.030, "EY0C": -0.012, "EA0C": 40e-6, "EB0C": -20e-6}


def test_sphere_probing_recovers_location_errors_within_3_sigma(c600u):
    ds = fivecal.simulate(c600u, _sphere_plan(c600u), errors=TRUE, artefact=ART, tip_radius=3.0,
                          sigma=0.0005, seed=3, setup={"sphere.S1.x": 0.01})
    r = fivecal.identify(ds, "location")
    found = [n for n in TRUE if n in r.estimated]
    # The A pivot position (EY0A, EZ0A) is confounded with the tip offsets and
    # EX0C lies along A: one sphere cannot separate them; the other five it must.
    assert set(found) == {"EB0A", "EC0A", "EA0C", "EB0C", "EY0C"}, r.estimated
    for n in found:
        assert abs(r.values[n] - TRUE[n]) < 3 * r.std[n], (n, r.values[n], TRUE[n], r.std[n])
    assert 0.7 < r.rms / 0.0005 < 1.3


def test_robust_loss_flags_an_outlier_touch(c600u):
    ds = fivecal.simulate(c600u, _sphere_plan(c600u), errors=TRUE, artefact=ART, tip_radius=3.0,
                          sigma=0.0005, seed=4)
    d = ds.to_dict()
    bad = 17
    # A trigger 50 µm outside the sphere: move the reading radially.
    axes = {k: [v] for k, v in d["observations"][bad]["axes"].items()}
    p = c600u.tool_point(axes)[0]
    u = (p - np.array(ART["spheres"][0]["center"])) / np.linalg.norm(p - ART["spheres"][0]["center"])
    moved = c600u.inverse([p + 0.05 * u], start={k: v[0] for k, v in axes.items()})
    d["observations"][bad]["axes"] = {k: float(v[0]) for k, v in moved.items()}
    plain = fivecal.identify(d, "location")
    robust = fivecal.identify(d, "location", robust="huber")
    assert bad in robust.outliers
    assert len(robust.outliers) < 10
    # Compared in relative error, not in z: the robust fit's sigma leaves the
    # flagged touch out of its chi-square, so it is honest (small) while the
    # plain fit's is inflated by the outlier; the plain fit is also flagged
    # inadequate.
    err = lambda r: max(abs(r.values[n] - TRUE[n]) / abs(TRUE[n]) for n in TRUE if n in r.estimated)
    assert err(robust) < err(plain)
    assert not plain.adequate and robust.adequate


def _dbb_and_ball3d_plan(ball3d: bool):
    plan = []
    for a in np.arange(-90, 91, 15.0):
        for c in np.arange(0, 360, 20.0):
            e = {"axes": {"X": 0.0, "Y": 0.0, "Z": 0.0, "A": float(a), "C": float(c)},
                 "tool_ball": [0, 0, 150.0], "table_ball": [50.0, 0, 80.0], "setup": "M1"}
            plan.append({**e, "type": "ball3d"} if ball3d else {**e, "type": "dbb", "length": 100.0})
    return plan


def test_ball3d_fit_recovers_errors(c600u):
    # Nominal commands keep the tool ball on the table ball: command X Y Z accordingly.
    plan = _dbb_and_ball3d_plan(True)
    for e in plan:
        cmd = c600u.inverse([[50.0, 0.0, 80.0]], start=e["axes"])
        e["axes"] = {k: float(v[0]) for k, v in cmd.items()}
    ds = fivecal.simulate(c600u, plan, errors=TRUE, sigma={"ball3d": 0.0005}, seed=5,
                          setup={"ball3d.M1.table.x": 0.005})
    r = fivecal.identify(ds, ["EY0A", "EZ0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C"],
                         default_setup=False)
    for n in r.estimated:
        assert abs(r.values[n] - TRUE[n]) < 3 * r.std[n], n


def test_unidentifiable_request_names_the_group(c600u):
    ds = fivecal.simulate(c600u, _sphere_plan(c600u), errors=TRUE, artefact=ART, tip_radius=3.0,
                          sigma=0.0005, seed=3)
    with pytest.raises(ValueError, match=r"confounded.*EZ0C"):
        fivecal.identify(ds, ["EX0C", "EZ0C"])  # C about z: its own-axis offset is not observable
    r = fivecal.identify(ds, ["EX0C", "EZ0C"], allow_unidentifiable=True)
    assert any("EZ0C" in g for g in r.unidentifiable)


def test_result_json_follows_design(c600u, tmp_path):
    ds = fivecal.simulate(c600u, _sphere_plan(c600u), errors=TRUE, artefact=ART, tip_radius=3.0,
                          sigma=0.0005, seed=3)
    r = fivecal.identify(ds, "location")
    d = json.loads(r.to_json())
    for key in ("parameters", "residual_rms", "n_observations", "n_parameters", "condition_number",
                "rank", "unidentifiable", "converged", "iterations"):
        assert key in d
    assert d["parameters"]["EY0C"]["std"] == pytest.approx(r.std["EY0C"])
    assert d["n_parameters"] == len(r.estimated)
    assert d["converged"] is True


def test_volumetric_error_matches_tool_point_difference(c600u):
    axes = {"X": [10, -20], "Y": [5, 7], "Z": [0, 3], "A": [30, -45], "C": [10, 200]}
    e = c600u.volumetric_error(axes, TRUE)
    ref = c600u.tool_point(axes, TRUE) - c600u.tool_point(axes)
    np.testing.assert_allclose(e, ref, atol=1e-12)
    assert np.abs(e).max() > 0.01


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fivecal", *args], capture_output=True, text=True,
                          cwd=cwd)


def test_cli_simulate_identify_roundtrip(c600u, tmp_path):
    spec = {"machine": c600u.to_dict(), "errors": TRUE, "probe": {"tip_radius": 3.0},
            "artefact": ART, "plan": _sphere_plan(c600u), "sigma": 0.0005, "seed": 2}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    p = _run("simulate", str(tmp_path / "spec.json"), "--out", str(tmp_path / "ds.json"))
    assert p.returncode == 0, p.stderr
    p = _run("identify", str(tmp_path / "ds.json"), "--estimate", "location",
             "--out", str(tmp_path / "r.json"))
    assert p.returncode == 0, p.stderr
    assert "EY0C" in p.stdout and "µm" in p.stdout
    r = json.loads((tmp_path / "r.json").read_text())
    assert abs(r["parameters"]["EY0C"]["value"] - TRUE["EY0C"]) < 3 * r["parameters"]["EY0C"]["std"]


def test_cli_errors_are_one_line(tmp_path):
    (tmp_path / "bad.json").write_text('{"machine": {"topology": "wCQfXt", "axes": {}}, "observations": []}')
    p = _run("identify", str(tmp_path / "bad.json"))
    assert p.returncode == 2
    assert "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    assert "unknown axis letter 'Q'" in p.stderr
    p = _run("identify", str(tmp_path / "missing.json"))
    assert p.returncode == 2 and "cannot read" in p.stderr


@pytest.mark.parametrize("cmd", ["identify", "simulate", "demo"])
def test_cli_help_has_example(cmd):
    p = _run(cmd, "--help")
    assert p.returncode == 0 and "example" in p.stdout
