"""Verify after loading, through each controller's own file (issue 32, item
5): export the identified kinematics for a vendor, "load" its file into a
simulated machine (the controller then runs what the file says: the file read
back by the vendor's reader and taken through the vendor's own kinematics,
``vendor_to_theta``), run the quick sphere check again, and give fivecal the
old check and the export (``sphere-check --expect``). A file loaded as written
took effect as predicted; a file altered the way a person slips (a value's
change with the wrong sign, a change entered in µm where mm are read, the
change applied twice) is caught and named.
"""
from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.cli.export import WRITERS
from fivecal.io import controllers as K
from fivecal.procedures import sphere_check as sc

from test_export_vendors import BALL, MACHINES, OPTIONS, TIP, TRUTH, _sets

VENDORS = K.vendors()


@pytest.fixture(scope="module")
def first_check(tmp_path_factory):
    d = tmp_path_factory.mktemp("verify_vendor")
    machine_file = os.path.join(MACHINES, "c600u.json")
    m = fivecal.Machine.load(machine_file)
    plan = sc.plan(m, BALL, tip_radius=TIP)
    ds = fivecal.simulate(m, plan, errors=TRUTH, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=0.001, seed=21)
    fivecal.save_dataset(ds, str(d / "before.json"))
    assert main(["sphere-check", str(d / "before.json"), "--out", str(d / "old.json")]) == 0
    return d, m, plan, machine_file


def _load_and_check(d, m, plan, machine_file, vendor, values, tag, capsys, force=False, export=None,
                    options=None, out=None):
    """The machine after the controller loaded ``values``: its apparent errors
    are the truth less what the controller's model now compensates."""
    options = OPTIONS.get(vendor) if options is None else options
    export = d / f"exp-{vendor}" if export is None else export
    ran = K.vendor_to_theta(m, vendor, values, options=options)
    after = m.theta(TRUTH) - ran["theta"]
    names = m.parameter_names()
    errors = {n: float(v) for n, v in zip(names, after) if v != 0.0}
    ds = fivecal.simulate(m, plan, errors=errors, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=0.001,
                          seed=22)
    fivecal.save_dataset(ds, str(d / f"after-{tag}.json"))
    capsys.readouterr()
    rc = main(["sphere-check", str(d / f"after-{tag}.json"), "--previous", str(d / "old.json"),
               "--expect", str(export / "export.json"), *(["--force"] if force else []),
               *(["--out", str(out)] if out else [])])
    return rc, capsys.readouterr().out


def _altered(m, vendor, rec, how):
    """The new values as a person's slip leaves them: every change with its
    sign turned (a convention stated the wrong way), in inch where the
    controller reads mm (µm read as mm puts the simulated machine's touches
    metres away: the export's plausibility guard refuses that change anyway),
    applied on top of itself, not applied; or one value's change with its
    sign turned (one line keyed wrongly): the line whose slip moves what the
    check measures most (a value the work offset absorbs is no slip the
    check can see)."""
    vals = [v["new"] for v in rec["values"]]
    f = {"sign": -1.0, "unit": 25.4, "twice": 2.0, "none": 0.0, "one sign": 1.0}[how]
    for k, v in enumerate(rec["values"]):
        if not v["fixed"]:
            vals[k] = v["old"] + f * v["change"]
    if how == "one sign":
        names = m.parameter_names()
        seen = [names.index(n) for n in rec["absorbed"]["names"]]
        ran = K.vendor_to_theta(m, vendor, vals, options=OPTIONS.get(vendor))["theta"]

        def moved(k):
            trial = list(vals)
            trial[k] = rec["values"][k]["old"] - rec["values"][k]["change"]
            th = K.vendor_to_theta(m, vendor, trial, options=OPTIONS.get(vendor))["theta"]
            return np.abs(th[seen] - ran[seen]).max()
        k = max((i for i, v in enumerate(rec["values"]) if not v["fixed"] and v["change"] != 0.0), key=moved)
        vals[k] = rec["values"][k]["old"] - rec["values"][k]["change"]
    return vals


@pytest.mark.parametrize("vendor", VENDORS)
def test_a_file_loaded_as_written_took_effect(first_check, vendor, capsys):
    d, m, plan, machine_file = first_check
    out = d / f"exp-{vendor}"
    assert main(["export", vendor, str(d / "old.json"), "--machine", machine_file, "--out", str(out),
                 *_sets(vendor)]) == 0
    f = next(out / n for n in sorted(os.listdir(out)) if n.startswith(vendor))
    read = WRITERS[vendor].read(str(f))
    rec = json.load(open(out / "export.json"))
    values = [read.get(v["name"], v["new"]) for v in rec["values"]]
    rc, text = _load_and_check(d, m, plan, machine_file, vendor, values, "asis", capsys)
    assert rc == 0, text
    assert re.search(r"took effect", text, re.I), text


@pytest.mark.parametrize("how,word", [("sign", r"sign"), ("unit", r"unit"), ("twice", r"twice"),
                                      ("none", r"not applied"), ("one sign", r"sign|differs")])
@pytest.mark.parametrize("vendor", VENDORS)
def test_an_altered_file_is_caught_and_named(first_check, vendor, how, word, capsys):
    d, m, plan, machine_file = first_check
    out = d / f"exp-{vendor}"
    if not (out / "export.json").exists():
        assert main(["export", vendor, str(d / "old.json"), "--machine", machine_file, "--out", str(out),
                     *_sets(vendor)]) == 0
    rec = json.load(open(out / "export.json"))
    values = _altered(m, vendor, rec, how)
    # a change 25 times too large makes the check itself implausible (exit 1);
    # with --force it still names the unit
    rc, text = _load_and_check(d, m, plan, machine_file, vendor, values, f"{vendor}-{how.replace(' ', '-')}",
                               capsys, force=how == "unit")
    assert rc == 1, text
    assert re.search(word, text, re.I), text


def test_beckhoff_tables_are_marked_unverifiable_and_the_check_says_it_verified_the_kinematics(first_check, capsys):
    """The TF5280 tables are not in ``absorbed``: export.json says so in a
    field (``sphere_check``), and ``sphere-check --expect`` says it verified
    the kinematics only; an export without tables says nothing of the kind."""
    d, m, plan, machine_file = first_check
    tables = {"volcomp": "error", "volcomp_units": "um,urad", "volcomp_frame": "carriage",
              "grid.X": "-200:200:50", "grid.Y": "-200:200:50", "grid.Z": "-200:200:50", "grid.A": "-90:90:15",
              "grid.C": "-180:180:30"}
    options = dict(OPTIONS["beckhoff"], **tables)
    out = d / "exp-beckhoff-tables"
    sets = [x for k, v in options.items() for x in ("--set", f"{k}={v}")]
    assert main(["export", "beckhoff", str(d / "old.json"), "--machine", machine_file, "--out", str(out), *sets]) == 0
    rec = json.load(open(out / "export.json"))
    tables_n = sum(1 for v in rec["values"] if v["motion_table"])
    assert tables_n > 100
    assert not any(v["motion_table"] for v in rec["values"] if v["name"].startswith("kinematik"))
    assert rec["sphere_check"]["verifies"] == "kinematics"
    assert rec["sphere_check"]["unverifiable_values"] == tables_n
    assert f"the {tables_n} error-motion table values" in rec["sphere_check"]["unverifiable"]
    values = [v["new"] for v in rec["values"]]
    rc, text = _load_and_check(d, m, plan, machine_file, "beckhoff", values, "tables", capsys, export=out,
                               options=options, out=d / "after-tables-result.json")
    assert rc == 0, text
    # the result document keeps it too: a "took effect" record read later must not claim the tables
    verification = json.load(open(d / "after-tables-result.json"))["procedure"]["values"]["verification"]
    assert verification["took_effect"] and f"the {tables_n} error-motion table values" in verification["unverifiable"]
    assert re.search(r"took effect", text, re.I), text
    assert "verified the kinematics only" in text and f"the {tables_n} error-motion table values" in text
    # without tables: nothing unverifiable, and no such line
    plain = d / "exp-beckhoff"
    if not (plain / "export.json").exists():
        assert main(["export", "beckhoff", str(d / "old.json"), "--machine", machine_file, "--out", str(plain),
                     *_sets("beckhoff")]) == 0
    rec = json.load(open(plain / "export.json"))
    rc, text = _load_and_check(d, m, plan, machine_file, "beckhoff", [v["new"] for v in rec["values"]],
                               "no-tables", capsys, out=d / "after-no-tables-result.json")
    assert rc == 0 and "verified the kinematics only" not in text, text
    assert json.load(open(d / "after-no-tables-result.json"))["procedure"]["values"]["verification"]["unverifiable"] is None
