"""The test-only observation kind of tests/cpp/kind_plugin/stylus3d.cc through
the Python layer: simulate, save, load, identify and the HTML report, with no
edit anywhere else (issue 29: "a test-only kind registers itself and runs
through load, identify and report without any other change").

The kind registers itself from its own C++ file. A Python process sees it
through a test-only build of the module (CMake target ``_core_kind_plugin``:
the bindings, the core and stylus3d.cc, written to
``build/dev/kind_plugin/_core*.so``). The test copies the package next to that
module and runs the pipeline in a subprocess, so this process's ``fivecal``
keeps the module without the test kind.
"""
from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
PLUGIN = sorted((ROOT / "build" / "dev" / "kind_plugin").glob("_core*.so"))

SCRIPT = r'''
import json, sys, warnings
import numpy as np
import fivecal
from fivecal import _core

assert "stylus3d" in [k["name"] for k in _core.observation_kinds()]
machine = {"name": "c600u", "topology": "wCAfXYZSt", "axes": {
  "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
  "A": {"type": "rotary", "direction": [-1, 0, 0], "point": [0, 0, 0]},
  "X": {"type": "linear", "direction": [1, 0, 0]}, "Y": {"type": "linear", "direction": [0, 1, 0]},
  "Z": {"type": "linear", "direction": [0, 0, 1]},
  "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]}}, "tool": {"tip": [0, 0, 150]}}
plan = [{"type": "stylus3d", "setup": "M1" if (c // 45) % 2 else "M2",
         "axes": {"A": a, "C": c, "X": 50 + c / 10, "Y": -20, "Z": 10 - a / 3}}
        for a in (-60, -30, 0, 30) for c in range(0, 360, 45)]
errors = {"EY0C": 0.02, "EZ0C": -0.01, "EB0C": 4e-5, "EXX1": 2e-5}
setup = {"stylus3d.M1.x": 0.03, "stylus3d.M1.z": -0.05, "stylus3d.M2.y": 0.02}
ds = fivecal.simulate(machine, plan, errors=errors, setup=setup, sigma={"stylus3d": 0.002}, seed=4)
out = sys.argv[1]
fivecal.save_dataset(ds, out + "/data.json")
ds = fivecal.load_dataset(out + "/data.json")
r = fivecal.identify(ds, estimate=list(errors))
truth = dict(errors, **setup)
z = {n: (r.values[n] - truth.get(n, 0.0)) / r.std[n] for n in r.std}
html = fivecal.write_report(r, out + "/report", truth=truth)
print(json.dumps({"z": z, "html": html, "converged": bool(r.converged)}))
'''


@pytest.mark.skipif(not PLUGIN, reason="the test-only module is built by scripts/dev_build.sh "
                                        "(CMake target _core_kind_plugin)")
def test_test_only_kind_runs_through_load_identify_and_report(tmp_path):
    pkg = tmp_path / "site" / "fivecal"
    shutil.copytree(ROOT / "python" / "fivecal", pkg,
                    ignore=shutil.ignore_patterns("_core*.so", "__pycache__"))
    shutil.copy(PLUGIN[0], pkg / PLUGIN[0].name)
    env = dict(os.environ, PYTHONPATH=str(tmp_path / "site"), MPLBACKEND="Agg")
    p = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path)], env=env, capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["converged"]
    # the fit recovers the truth (errors and the kind's own set-up parameters)
    assert set(out["z"]) >= {"EY0C", "EXX1", "stylus3d.M1.x", "stylus3d.M2.z"}
    assert all(abs(v) < 4 for v in out["z"].values()), out["z"]
    # the report shows the kind from the registry's report pieces alone
    html = pathlib.Path(out["html"]).read_text(encoding="utf-8")
    assert "stylus mountings (2)" in html
    assert "3D stylus: deviation and residual per component." in html
    assert (tmp_path / "report" / "stylus3d_components.png").is_file()


def test_the_package_module_does_not_have_the_test_kind():
    from fivecal import _core

    assert "stylus3d" not in [k["name"] for k in _core.observation_kinds()]
