"""Importing a laser tracer's table (multilateration, issue 14 item 5 for the
distance kind): one row per reading with the axis positions and the
station; each station's nominal place in the sidecar. The imported data
identify the machine as the simulated ones do; bad rows are named."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal
from fivecal.cli import main

import test_distance_kind as D

TOOL_SETUP = {k: v for k, v in D.SETUP.items() if ".work_" not in k}


def _write(ds, path):
    axes = [a for a in ds.machine.axis_names if a != "S"]
    lines = ["id;station;" + ";".join(axes) + ";reading_um"]
    for k, o in enumerate(ds.observations):
        lines.append(f"r{k};{o['station']};" + ";".join(f"{o['axes'][a]:.9f}".replace(".", ",") for a in axes)
                     + ";" + f"{o['reading'] * 1e3:.6f}".replace(".", ","))
    path.write_text("\n".join(lines) + "\n")


def test_tracer_table_imports_and_identifies(tmp_path):
    m = fivecal.Machine.from_dict(D.MACHINE)
    rng = np.random.default_rng(11)
    plan = [e for e in D._plan(rng) if e["target"] == "tool"]
    ds = fivecal.simulate(m, plan, errors=D.TRUTH, setup=TOOL_SETUP, sigma=D.NOISE, seed=11)
    table = tmp_path / "tracer.csv"
    _write(ds, table)  # a European export: ';' between cells, decimal comma, readings in µm
    side = {"target": "tool", "target_point": [0, 0, 150], "sigma": 0.001,
            "stations": {s: {"position": p, "dead_length": D.DEAD[s]} for s, p in D.STATIONS.items()}}
    (tmp_path / "tracer.json").write_text(json.dumps(side))
    (tmp_path / "machine.json").write_text(json.dumps(D.MACHINE))
    out = tmp_path / "data.json"
    assert main(["import", "distance", str(table), "--machine", str(tmp_path / "machine.json"),
                 "--sidecar", str(tmp_path / "tracer.json"), "--out", str(out)]) == 0
    got = fivecal.load_dataset(str(out))
    assert len(got) == len(ds) and got.observations[5]["id"] == "r5"
    assert abs(got.observations[5]["reading"] - ds.observations[5]["reading"]) < 1e-9
    truth = {k: v for k, v in D.TRUTH.items() if not k.endswith("C")}  # the table's C: no table target here
    r = fivecal.identify(got, list(truth), fix=D.FIXED)
    for n, v in truth.items():
        assert abs(r.values[n] - v) < 3 * r.std[n], (n, r.values[n], v, r.std[n])


def test_tracer_import_refusals(tmp_path):
    m = fivecal.Machine.from_dict(D.MACHINE)
    ds = fivecal.simulate(m, [e for e in D._plan(np.random.default_rng(2), n=2) if e["target"] == "tool"],
                          errors={}, setup=TOOL_SETUP, sigma=D.NOISE, seed=2)
    table = tmp_path / "t.csv"
    _write(ds, table)
    stations = {s: {"position": p} for s, p in D.STATIONS.items()}
    kw = dict(target="tool", target_point=[0, 0, 150])
    with pytest.raises(ValueError, match="needs each station's nominal place"):
        fivecal.io.import_dataset(table, "distance", D.MACHINE, **kw)
    few = {"stations": {"L1": stations["L1"], "L2": stations["L2"]}}
    with pytest.raises(ValueError, match=r"t\.csv:\d+: column 'station': station 'L3' is not in the sidecar"):
        fivecal.io.import_dataset(table, "distance", D.MACHINE, sidecar=few, **kw)
    with pytest.raises(ValueError, match="stations.L1.position"):
        fivecal.io.import_dataset(table, "distance", D.MACHINE, sidecar={"stations": {"L1": {"position": [1, 2]}}},
                                  **kw)
    with pytest.raises(ValueError, match="station belongs to a distance import"):
        fivecal.io.import_dataset(table, "point", D.MACHINE, station="L1", **kw)
    (tmp_path / "um.csv").write_text(table.read_text().replace("reading_um", "reading"))
    with pytest.raises(ValueError, match="readings look like µm"):
        fivecal.io.import_dataset(tmp_path / "um.csv", "distance", D.MACHINE, sidecar={"stations": stations},
                                  units="mm", **kw)


def test_station_places_and_dead_lengths_in_um_are_refused_naming_the_station(tmp_path):
    m = fivecal.Machine.from_dict(D.MACHINE)
    ds = fivecal.simulate(m, [e for e in D._plan(np.random.default_rng(2), n=2) if e["target"] == "tool"],
                          errors={}, setup=TOOL_SETUP, sigma=D.NOISE, seed=2)
    table = tmp_path / "t.csv"
    _write(ds, table)
    stations = {s: {"position": p, "dead_length": D.DEAD[s]} for s, p in D.STATIONS.items()}
    side = tmp_path / "s.json"
    for st, key, match in (({"dead_length": 200000}, "L2", r"s\.json: stations\.L2\.dead_length: 200000"),
                           ({"position": [900, -700, 2e8]}, "L1", r"s\.json: stations\.L1\.position\[2\]: 2e\+08")):
        side.write_text(json.dumps({"stations": {**stations, key: {**stations[key], **st}}}))
        with pytest.raises(ValueError, match=match + r" mm: no .* it looks like µm"):
            fivecal.io.import_dataset(table, "distance", D.MACHINE, sidecar=side, target="tool")
    side.write_text(json.dumps({"stations": stations}))
    with pytest.raises(ValueError, match=r"--target-point\[2\]: 150000 mm: no target"):
        fivecal.io.import_dataset(table, "distance", D.MACHINE, sidecar=side, target="tool",
                                  target_point=[0, 0, 150000])
