"""Writes rtest_log.txt and rtest_log.json, the R-test log the notebook
(examples/notebook.ipynb) starts from: the four K tests of
fivecal.procedures.rtest on the C600U-like trunnion
(examples/machines/c600u.json), one mounting of the ball, simulated with
known location errors of A and C (TRUE_ERRORS) and 0.5 µm sensor noise, and
written as an R-test device exports its table: axis positions and the
sensor displacements in micrometres. Run from the repository root:
python3 examples/notebook/make_rtest_log.py"""
import json
import os

import numpy as np

import fivecal
from fivecal import files
from fivecal.procedures import rtest

HERE = os.path.dirname(os.path.abspath(__file__))
MACHINE = os.path.join(HERE, "..", "machines", "c600u.json")
#: what the notebook should find (mm, rad)
TRUE_ERRORS = {"EY0A": 0.012, "EZ0A": -0.008, "EB0A": 30e-6, "EC0A": -20e-6,
               "EX0C": 0.020, "EY0C": -0.015, "EA0C": 25e-6, "EB0C": -40e-6}
TABLE_BALL = [50.0, 0.0, 80.0]
TOOL_BALL = [0.0, 0.0, 150.0]
SIGMA = 0.0005


def main() -> None:
    m = fivecal.Machine.load(MACHINE)
    plan = [e for test in rtest.TESTS
            for e in rtest.plan(m, test, table_ball=TABLE_BALL, tool_ball=TOOL_BALL, step=30.0, setup="R1")]
    ds = fivecal.simulate(m, plan, errors=TRUE_ERRORS, sigma=SIGMA, seed=31)
    lines = ["# R-test log of a C600U-like trunnion table: sensor displacements in micrometres, workpiece frame",
             f"{'X':>10}{'Y':>11}{'Z':>11}{'A':>9}{'C':>9}{'dx_um':>9}{'dy_um':>9}{'dz_um':>9}"]
    for o in ds.observations:
        ax, d = o["axes"], np.asarray(o["measured"]) * 1e3
        lines.append(f"{ax['X']:10.4f} {ax['Y']:10.4f} {ax['Z']:10.4f} {ax['A']:8.3f} {ax['C']:8.3f}"
                     f"{d[0]:9.2f}{d[1]:9.2f}{d[2]:9.2f}")
    files.write_text(os.path.join(HERE, "rtest_log.txt"), "\n".join(lines) + "\n")
    files.write_text(os.path.join(HERE, "rtest_log.json"), json.dumps(
        {"setup": "R1", "tool_ball": TOOL_BALL, "table_ball": TABLE_BALL, "sigma": SIGMA}, indent=1) + "\n")


if __name__ == "__main__":
    main()
