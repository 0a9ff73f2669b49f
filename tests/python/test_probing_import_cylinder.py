"""A probing log whose touches hit a cylinder section (the KX8 table's
periphery) imports like facet and sphere touches: the target column names
the cylinder, the sidecar gives the artefact, and the dataset equals the one
the log was written from."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal
from fivecal.procedures import tango


def _log(ds, path):
    axes = [a for a in ds.machine.axis_names if a != "S"]
    dirs = sorted({a for o in ds.observations for a in o.get("direction", {})})
    lines = [",".join(["id", "target"] + axes + [f"dir_{a}" for a in dirs])]
    for k, o in enumerate(ds.observations):
        lines.append(",".join([o.get("id", f"t{k}"), o["target"]] + [f"{o['axes'][a]:.10f}" for a in axes]
                              + [str(o.get("direction", {}).get(a, 0)) for a in dirs]))
    path.write_text("\n".join(lines) + "\n")


def test_cylinder_touches_import_from_a_probing_log(tmp_path):
    ds = tango.kx8_curved_dataset(seed=3)
    cyl = [o for o in ds.observations if o["type"] == "cylinder"]
    assert cyl
    log = tmp_path / "kx8.csv"
    _log(ds, log)
    side = tmp_path / "kx8.json"
    d = ds.to_dict()
    side.write_text(json.dumps({"probe": d["probe"], "artefact": d["artefact"]}))
    got = fivecal.io.import_dataset(log, "probing", ds.machine, sidecar=str(side))
    assert got.observation_types == ds.observation_types
    for a, b in zip(got.observations, ds.observations):
        assert a["type"] == b["type"] and a["target"] == b["target"]
        assert all(abs(a["axes"][k] - b["axes"][k]) < 1e-9 for k in b["axes"] if k != "S")
    assert [a["id"] for a in got.observations if a["type"] == "cylinder"] == [o["id"] for o in cyl]
    rows = log.read_text().splitlines()
    cells = rows[1].split(",")
    cells[1] = "NOPE"
    rows[1] = ",".join(cells)
    log.write_text("\n".join(rows) + "\n")
    with pytest.raises(ValueError, match=r"kx8\.csv:2: column 'target': 'NOPE' is not a facet, sphere or cylinder"):
        fivecal.io.import_dataset(log, "probing", ds.machine, sidecar=str(side))


def test_a_file_with_the_artefact_after_the_cylinder_touches_loads():
    """The streaming loader reads observations before an artefact that comes
    later in the file only through the document path; cylinder touches (a
    probe-touch kind added later) must take it too, as facets and spheres do."""
    ds = tango.kx8_curved_dataset(seed=4)
    d = ds.to_dict()
    late = {"machine": d["machine"], "observations": d["observations"], "probe": d["probe"],
            "artefact": d["artefact"]}
    again = fivecal.Dataset.from_dict(late)
    assert again.observation_types == ds.observation_types
