"""A kind's table checks are its table's rules in the registry (issue 29):
the kind declares them (``KindTable::rules``: defaults, allowed values, keys
that must or must not come together, vector sizes, nonzero vectors,
plausible sizes), ``_core.observation_kinds()`` exports them, and the
importer (fivecal.io.tables) applies them to every row without naming any
kind's key. Taken out of the registry, a kind's checks are gone from the
import; planted into it, they apply to a kind that never had them, naming
the cell. (tests/python/test_kind_plugin.py does the same with the
test-only kind, which declares its own rules from its own file.)"""
from __future__ import annotations

import copy
import pathlib

import pytest

import fivecal
from fivecal import _core
from fivecal.io import tables

from test_generic_table import every_kind_dataset

ROOT = pathlib.Path(__file__).resolve().parents[2]
C600U = ROOT / "examples" / "machines" / "c600u.json"
RULES = {"default", "one_of", "no_char", "excludes", "requires", "size", "nonzero", "limit"}
REAL = _core.observation_kinds


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.load(C600U)


def _with_rules(monkeypatch, change):
    """The registry as ``change(kinds)`` leaves a copy of it."""
    kinds = copy.deepcopy(REAL())
    change(kinds)
    monkeypatch.setattr(_core, "observation_kinds", lambda: copy.deepcopy(kinds))


def _ruled():
    """The kinds whose table declares rules."""
    return [k for k in REAL() if k["table"]["rules"]]


def test_the_registry_exports_each_kinds_rules():
    ruled = _ruled()
    assert ruled, "no kind declares table rules"
    for k in ruled:
        keys = set(k["json_keys"])
        for r in k["table"]["rules"]:
            assert r["rule"] in RULES, r
            assert set(r["keys"]) <= keys, (k["name"], r)
            assert not r["if_key"] or r["if_key"] in keys, (k["name"], r)
            if r["rule"] == "limit":
                assert r["limit"] > 0 and r["message"].format(value=1.0, column="c")
            if r["rule"] in ("excludes", "requires", "no_char", "nonzero"):
                assert r["message"], r


HEAD = "id,X,Y,Z,A,C,point_x,point_y,point_z,normal_x,normal_y,normal_z,measured_um"


def test_without_its_rules_the_import_checks_nothing_of_the_kind(machine, tmp_path, monkeypatch):
    """The importer holds no check of its own for the kind: with the kind's
    rules taken out of the registry a feature the kind refuses passes the
    import (the dataset's own validation, in the core, still refuses it),
    and no default is filled in."""
    name = _ruled()[0]["table"]["name"]
    f = tmp_path / "r.csv"
    f.write_text(HEAD + ",feature\nf1,0,-60,0,-90,0,0,150,60,0,0,1,-8.5,fase\n")
    with pytest.raises(ValueError, match=r"r\.csv:2: column 'feature': 'fase' is neither face nor step"):
        tables.read_table(f, name, machine)
    _with_rules(monkeypatch, lambda ks: [k["table"].update(rules=[]) for k in ks])
    d = tables.read_table(f, name, machine)
    o = d["observations"][0]
    assert o["feature"] == "fase" and "part" not in o
    with pytest.raises(ValueError):
        fivecal.Dataset.from_dict(d)


@pytest.mark.parametrize("rule,match", [
    ({"rule": "no_char", "keys": ["id"], "chars": "1", "message": "id '{value}': no ones here"},
     r"x\.csv:2: column 'id': id '\w+1': no ones here"),
    ({"rule": "requires", "keys": ["tag"], "if_key": "type", "message": "a tag is wanted (axes {axes})"},
     r"x\.csv:\d+: a tag is wanted \(axes X Y Z A C\)"),  # the first row whose kind owns its table
    ({"rule": "default", "keys": ["id"], "value": "never"}, None),
])
def test_a_rule_planted_in_the_registry_applies_naming_the_cell(machine, tmp_path, monkeypatch, rule, match):
    """Every kind read by the generic table gets the rule planted in its
    registry entry (a ``requires`` rule triggered by the row's own type):
    the first row is refused with the rule's message; a default does not
    replace a value the row gives."""
    f = tmp_path / "x.csv"
    side = tables.write_table(fivecal.Dataset.from_dict(every_kind_dataset(machine)), f)
    before = tables.read_table(f, tables.GENERIC, machine, sidecar=side)
    full = dict({"values": [], "value": "", "option": "", "if_key": "", "then": "", "chars": "", "size": 0,
                 "limit": 0.0, "message": ""}, **rule)
    _with_rules(monkeypatch, lambda ks: [k["table"]["rules"].append(dict(full, value=full["value"] or k["name"]))
                                         for k in ks])
    if match is None:
        assert tables.read_table(f, tables.GENERIC, machine, sidecar=side) == before
        return
    with pytest.raises(ValueError, match=match):
        tables.read_table(f, tables.GENERIC, machine, sidecar=side)
