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


# The kind's instrument table: no table of its own in the registry, so the
# generic reader takes it under its name, a column per file key (axes, setup,
# measured_x|y|z); the CLI and the Python call read it to the simulated data,
# and its bad cells are refused naming the line and the column.
TABLE_SCRIPT = r'''
import csv, io, json, subprocess, sys
import fivecal
from fivecal import io as fio

out = sys.argv[1]
machine = {"name": "c600u", "topology": "wCAfXYZSt", "axes": {
  "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
  "A": {"type": "rotary", "direction": [-1, 0, 0], "point": [0, 0, 0]},
  "X": {"type": "linear", "direction": [1, 0, 0]}, "Y": {"type": "linear", "direction": [0, 1, 0]},
  "Z": {"type": "linear", "direction": [0, 0, 1]},
  "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]}}, "tool": {"tip": [0, 0, 150]}}
json.dump(machine, open(out + "/m.json", "w"))
plan = [{"type": "stylus3d", "setup": "M1" if (c // 45) % 2 else "M2",
         "axes": {"A": a, "C": c, "X": 50 + c / 10, "Y": -20, "Z": 10 - a / 3}}
        for a in (-60, -30, 0, 30) for c in range(0, 360, 45)]
errors = {"EY0C": 0.02, "EZ0C": -0.01, "EB0C": 4e-5, "EXX1": 2e-5}
ds = fivecal.simulate(machine, plan, errors=errors, sigma={"stylus3d": 0.002}, seed=5)
sim = ds.to_dict()["observations"]
rows = [["X", "Y", "Z", "A", "C", "setup", "measured_x_um", "measured_y_um", "measured_z_um"]]
for o in sim:
    rows.append([repr(o["axes"][a]) for a in "XYZAC"] + [o["setup"]] + [repr(v * 1000) for v in o["measured"]])
text = "".join(",".join(r) + "\n" for r in rows)
open(out + "/t.csv", "w").write(text)
got = fio.import_dataset(out + "/t.csv", "stylus3d", machine).to_dict()["observations"]
same = all(g["type"] == "stylus3d" and g["setup"] == o["setup"] and
           max(abs(x - y) for x, y in zip(g["measured"], o["measured"])) < 1e-12 and
           all(abs(g["axes"][a] - o["axes"][a]) < 1e-9 for a in "XYZAC") for g, o in zip(got, sim))
cli = subprocess.run([sys.executable, "-m", "fivecal", "import", "stylus3d", out + "/t.csv", "--machine",
                      out + "/m.json", "--out", out + "/ds.json"], capture_output=True, text=True)
back = fivecal.load_dataset(out + "/ds.json").to_dict()["observations"] if cli.returncode == 0 else []
r = fivecal.identify(fivecal.load_dataset(out + "/ds.json"), estimate=list(errors))
z = {n: (r.values[n] - errors.get(n, 0.0)) / r.std[n] for n in errors}
# the kind's own table rules (stylus3d.cc's Table()): a default mounting, no '.' in it, the stylus's range
open(out + "/d.csv", "w").write(",".join(rows[0]) + "\n" + ",".join(rows[1][:5] + [""] + rows[1][6:]) + "\n")
default = fio.read_table(out + "/d.csv", "stylus3d", machine)["observations"][0].get("setup")
bad = {}
for name, lines in {"cell": [rows[0], rows[1], rows[2][:7] + ["abc"] + rows[2][8:]],
                    "column": [rows[0][:8] + ["measured_w_um"], rows[1]],
                    "dot": [rows[0], rows[1][:5] + ["M.1"] + rows[1][6:]],
                    "range": [rows[0][:6] + ["measured_x"] + rows[0][7:], rows[1][:6] + ["30000"] + rows[1][7:]]}.items():
    open(out + "/bad.csv", "w").write("".join(",".join(r) + "\n" for r in lines))
    try:
        fio.import_dataset(out + "/bad.csv", "stylus3d", machine)
        bad[name] = None
    except ValueError as e:
        bad[name] = str(e)
print(json.dumps({"n": len(got), "same": same, "default": default, "cli": cli.returncode, "cli_out": cli.stdout + cli.stderr,
                  "back": len(back), "z": z, "bad": bad, "kinds": list(fio.KINDS)}))
'''


def _plugin_site(tmp_path):
    """The package beside the test-only module, and the environment that imports it."""
    pkg = tmp_path / "site" / "fivecal"
    shutil.copytree(ROOT / "python" / "fivecal", pkg,
                    ignore=shutil.ignore_patterns("_core*.so", "__pycache__"))
    shutil.copy(PLUGIN[0], pkg / PLUGIN[0].name)
    return dict(os.environ, PYTHONPATH=str(tmp_path / "site"), MPLBACKEND="Agg")


@pytest.mark.skipif(not PLUGIN, reason="the test-only module is built by scripts/dev_build.sh "
                                        "(CMake target _core_kind_plugin)")
def test_test_only_kind_is_imported_from_a_table(tmp_path):
    env = _plugin_site(tmp_path)
    p = subprocess.run([sys.executable, "-c", TABLE_SCRIPT, str(tmp_path)], env=env, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert "stylus3d" in out["kinds"]
    assert out["n"] == 32 and out["same"], out
    assert out["cli"] == 0 and out["back"] == 32, out["cli_out"]
    assert "32 observations (32 stylus3d)" in out["cli_out"]
    # the imported data identify the truth
    assert all(abs(v) < 4 for v in out["z"].values()), out["z"]
    assert out["bad"]["cell"] is not None and "bad.csv:3: column 'measured_y_um': 'abc' is not a number" \
        in out["bad"]["cell"], out["bad"]
    assert out["bad"]["column"] is not None and "column 'measured_w_um': unknown column 'measured_w' for a " \
        "stylus3d import" in out["bad"]["column"], out["bad"]
    # the kind's own table rules, declared in its file alone, applied naming the cell
    assert out["default"] == "M1"
    assert "bad.csv:2: column 'setup': mounting 'M.1': a mounting id has no '.'" in (out["bad"]["dot"] or ""), \
        out["bad"]
    assert "bad.csv:2: column 'measured_x': 30000 mm is beyond the fixture's reach; name the column measured_x_um" \
        in (out["bad"]["range"] or ""), out["bad"]


@pytest.mark.skipif(not PLUGIN, reason="the test-only module is built by scripts/dev_build.sh "
                                        "(CMake target _core_kind_plugin)")
def test_test_only_kind_runs_through_load_identify_and_report(tmp_path):
    env = _plugin_site(tmp_path)
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
