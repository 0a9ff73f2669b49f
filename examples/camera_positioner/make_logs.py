"""Write the two simulated camera logs of this folder (run from it:
``python3 make_logs.py``; the files are committed, this says how they were
made).

A two-axis positioner (machine.json: tilt A, turntable C) with errors of a
positioner's size, a fiducial on its table and a camera that reports the
fiducial's pose: 205 poses (A at 5 tilts, C at 41 angles). The camera's noise
differs per component: depth (its z) is four times noisier than the lateral
directions, and the rotation about its line of sight is better seen than
the tilts. Two logs of the same poses, as two kinds of software write them:

* ``camera_xyzw.txt``: whitespace separated like a TUM trajectory, position
  in metres, quaternion scalar last (``qx qy qz qw``), a timestamp column;
  its noise is in the sidecar (``sigma``, six values);
* ``camera_wxyz.csv``: comma separated like EuRoC ground truth, position in
  millimetres, quaternion scalar first as ``q0 q1 q2 q3`` (the sidecar names
  the order), and the camera's own per-row sigma columns in um and urad.

The truth is ``TRUTH`` and ``SETUP`` below; the camera's noise ``SIGMA``.
"""
from __future__ import annotations

import os

import numpy as np

import fivecal
from fivecal import _core, files

HERE = os.path.dirname(os.path.abspath(__file__))
#: the camera's pose in the machine frame (mm, degrees a b c) as its setup
#: sheet gives it, and where it really is (the fit finds the difference)
ORIGIN, ANGLES = [1400.0, -900.0, 650.0], [-115.0, 8.0, 35.0]
TARGET_POINT, TARGET_ROTATION = [150.0, 40.0, 25.0], [0.0, 0.0, 0.3]
TRUTH = {"EA0C": 1.2e-3, "EB0C": -0.8e-3}
SETUP = {"instrument.CAM.x": 0.6, "instrument.CAM.y": -0.4, "instrument.CAM.z": 0.3,
         "instrument.CAM.a": 2e-3, "instrument.CAM.b": -1e-3, "instrument.CAM.c": 1.5e-3,
         "instrument.CAM.work_x": 0.2, "instrument.CAM.work_y": -0.15, "instrument.CAM.work_z": 0.1,
         "instrument.CAM.work_a": 0.004, "instrument.CAM.work_c": -0.003}
#: one sigma per row: x y z (mm, camera frame; z is depth), rx ry rz (rad)
SIGMA = [0.05, 0.05, 0.2, 4e-4, 4e-4, 1e-4]
TILTS = [-60.0, -30.0, 0.0, 30.0, 60.0]
TURNS = [float(c) for c in np.linspace(-180.0, 180.0, 41)]


def plan() -> list:
    return [{"type": "pose", "instrument": "CAM", "target": "work", "target_point": TARGET_POINT,
             "target_rotation": TARGET_ROTATION, "axes": {"A": a, "C": c},
             "instrument_origin": ORIGIN, "instrument_angles": ANGLES} for a in TILTS for c in TURNS]


def simulate(seed: int = 31):
    """(dataset dicts' observations with noise, the noise-free ones)."""
    m = fivecal.Machine.load(os.path.join(HERE, "machine.json"))
    clean = fivecal.simulate(m, plan(), errors=TRUTH, setup=SETUP, seed=seed)
    rng = np.random.default_rng(seed)
    out = []
    for o in clean.observations:
        p = np.asarray(o["measured"]) + rng.normal(0.0, SIGMA[:3])
        # a small rotation of the reading in the target frame, R exp(e)
        r = _core.rotations_from_vectors(np.array([o["measured_rotation"]]), "matrix").reshape(3, 3)
        e = _core.rotations_from_vectors(rng.normal(0.0, SIGMA[3:]).reshape(1, 3), "matrix").reshape(3, 3)
        v, _ = _core.rotation_vectors((r @ e).reshape(1, 9), "matrix")
        out.append((o["axes"], p, v[0]))
    return out


def write(rows) -> None:
    xyzw = _core.rotations_from_vectors(np.array([v for _, _, v in rows]), "quaternion", order="xyzw")
    wxyz = _core.rotations_from_vectors(np.array([v for _, _, v in rows]), "quaternion", order="wxyz")
    t0 = 1700000000.0
    lines = ["# fiducial pose in the camera frame; position in metres, quaternion x y z w",
             "# positioner axes A C in degrees, as logged with each frame",
             "timestamp A C tx ty tz qx qy qz qw"]
    for k, ((axes, p, _), q) in enumerate(zip(rows, xyzw)):
        lines.append(f"{t0 + 0.5 * k:.3f} {axes['A']:.4f} {axes['C']:.4f} "
                     + " ".join(f"{x / 1000.0:.9f}" for x in p) + " " + " ".join(f"{x:.9f}" for x in q))
    files.write_text(os.path.join(HERE, "camera_xyzw.txt"), "\n".join(lines) + "\n")
    su = [f"{s * 1000.0:g}" for s in SIGMA[:3]] + [f"{s * 1e6:g}" for s in SIGMA[3:]]
    lines = ["time_ns,A_deg,C_deg,tx_mm,ty_mm,tz_mm,q0,q1,q2,q3,"
             "sigma_x_um,sigma_y_um,sigma_z_um,sigma_rx_urad,sigma_ry_urad,sigma_rz_urad"]
    for k, ((axes, p, _), q) in enumerate(zip(rows, wxyz)):
        lines.append(f"{int(round((t0 + 0.5 * k) * 1e3)) * 1000000},{axes['A']:.4f},{axes['C']:.4f},"
                     + ",".join(f"{x:.6f}" for x in p) + "," + ",".join(f"{x:.9f}" for x in q) + ","
                     + ",".join(su))
    files.write_text(os.path.join(HERE, "camera_wxyz.csv"), "\n".join(lines) + "\n")

if __name__ == "__main__":
    write(simulate())
