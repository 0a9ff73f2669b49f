"""Importing a 6D tracker's table (issue 14, item 5: tracker poses): axes,
the measured position and orientation per row, units from the headers; the
import feeds an identification that recovers the truth, and unit mistakes
are refused naming the line."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal
from fivecal.cli import main

import test_pose_kind as P

# the tool-side fiducial only: the table-side target's offsets are not in this plan
TOOL_SETUP = {k: v for k, v in P.SETUP.items() if ".work_" not in k}


def _table(ds, path, rot_deg=False):
    axes = [a for a in ds.machine.axis_names if a != "S"]
    rot = "measured_rx_deg measured_ry_deg measured_rz_deg" if rot_deg else "measured_rx measured_ry measured_rz"
    lines = [" ".join(axes) + " measured_x measured_y measured_z " + rot + " id"]
    for k, o in enumerate(ds.observations):
        r = np.degrees(o["measured_rotation"]) if rot_deg else o["measured_rotation"]
        lines.append(" ".join(f"{o['axes'][a]:.9f}" for a in axes) + " "
                     + " ".join(f"{v:.9f}" for v in o["measured"]) + " " + " ".join(f"{v:.12g}" for v in r)
                     + f" p{k}")
    path.write_text("\n".join(lines) + "\n")


def test_pose_table_imports_and_identifies(tmp_path):
    m = fivecal.Machine.from_dict(P.MACHINE)
    rng = np.random.default_rng(7)
    plan = P._plan(rng, targets=("tool",))
    ds = fivecal.simulate(m, plan, errors=P.TRUTH, setup=TOOL_SETUP, sigma=P.NOISE, seed=7)
    table = tmp_path / "camera.txt"
    _table(ds, table, rot_deg=True)
    (tmp_path / "machine.json").write_text(json.dumps(P.MACHINE))
    out = tmp_path / "pose.json"
    args = ["import", "pose", str(table), "--machine", str(tmp_path / "machine.json"), "--out", str(out),
            "--target", "tool", "--target-point", "0,0,150", "--target-rotation", ",".join(map(str, P.TOOL_ROT)),
            "--instrument-origin", ",".join(map(str, P.ORIGIN)),
            "--instrument-angles", ",".join(map(str, P.ANGLES))]
    assert main(args) == 0
    got = fivecal.load_dataset(str(out))
    assert len(got) == len(ds) and got.observations[3]["id"] == "p3"
    np.testing.assert_allclose(got.observations[3]["measured_rotation"], ds.observations[3]["measured_rotation"],
                               atol=1e-9)
    truth = {k: v for k, v in P.TRUTH.items() if not k.endswith("C")}  # the table's C is not seen by a tool target
    r = fivecal.identify(got, list(truth), fix=P.FIXED)
    for n, v in truth.items():
        assert abs(r.values[n] - v) < 3 * r.std[n], (n, r.values[n], v, r.std[n])


def test_pose_import_refuses_unit_mistakes_and_point_options(tmp_path):
    m = fivecal.Machine.from_dict(P.MACHINE)
    ds = fivecal.simulate(m, P._plan(np.random.default_rng(1), n=4, targets=("tool",)), errors={},
                          setup=TOOL_SETUP, sigma=P.NOISE, seed=1)
    table = tmp_path / "t.txt"
    _table(ds, table, rot_deg=True)
    text = table.read_text().replace("_deg", "")  # degrees under rad headers
    table.write_text(text)
    with pytest.raises(ValueError, match=r"t\.txt:\d+.*longer than π rad.*degrees"):
        fivecal.io.import_dataset(table, "pose", P.MACHINE, target="tool", target_point=[0, 0, 150])
    with pytest.raises(ValueError, match="target_rotation belongs to a pose import"):
        fivecal.io.import_dataset(table, "point", P.MACHINE, target="tool", target_rotation=[0, 0, 0])
    table.write_text(text.replace("measured_rz", "measured_q"))
    with pytest.raises(ValueError, match="unknown column 'measured_q'"):
        fivecal.io.import_dataset(table, "pose", P.MACHINE, target="tool")
