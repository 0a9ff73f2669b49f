"""The FANUC parameter list: what write() prints, read() reads back (the new
values at the increment's resolution), old beside new with the change's 1σ
and the header a user needs; a malformed list is refused by line."""
from __future__ import annotations

import math
import re
from types import SimpleNamespace

import pytest

from fivecal.io import fanuc

NAMES = ["19680", "19681", "19682", "19684", "19686", "19687", "19689",
         "rotary table position X", "rotary table position Y", "rotary table position Z",
         "19703", "19704", "19705"]


def _export(increment="IS-C", change=None):
    old = [12, 4, 1, 1, 5, 3, 1, 0.0, 0.0, -350.0, 0.0, 0.0, 100.0]
    change = change or [0] * 7 + [0.01234, -0.00456, 0.02, 0.0, 0.0151, -0.003]
    values = []
    for i, (n, o, c) in enumerate(zip(NAMES, old, change)):
        fixed = i < 7
        values.append({"name": n, "unit": "" if fixed else "mm", "old": float(o), "new": float(o + c),
                       "change": float(c), "sigma": math.nan if fixed else 0.0007 + 0.0001 * i,
                       "source": f"meaning of {n}; FANUC A-79348E, sheet 82/88", "fixed": fixed})
    ab = SimpleNamespace(model="table-table", rms=0.0021, max=0.0057)
    return SimpleNamespace(values=values, absorption=ab, options={"increment": increment, "path": "1"},
                           round_trip_max_mm=3e-10, result="result.json")


MACHINE = SimpleNamespace(name="VMC-0656-like", topology="wCAfXYZSt")


def test_write_read_round_trip(tmp_path):
    exp = _export()
    files = fanuc.write(exp, MACHINE)
    assert list(files) == [".txt"]
    text = files[".txt"]
    p = tmp_path / "fanuc.txt"
    p.write_text(text)
    back = fanuc.read(str(p))
    assert list(back) == NAMES
    for v in exp.values:
        assert back[v["name"]] == pytest.approx(round(v["new"], 4), abs=1e-12)
    # Old beside new, the change with its 1σ, the codes never called a change.
    line = next(x for x in text.splitlines() if x.startswith("19704 |"))
    assert line.split(" | ")[:6] == ["19704", "1", "0.0151", "0.0000", "+0.0151 ± 0.0018", "mm"]
    assert next(x for x in text.splitlines() if x.startswith("19680 |")).split(" | ")[2:5] == ["12", "12", "(code)"]
    # The header: machine, result, date, model, what the controller cannot absorb.
    head = "\n".join(x for x in text.splitlines() if x.startswith("#"))
    assert "VMC-0656-like (wCAfXYZSt)" in head and "result: result.json" in head
    assert re.search(r"written: \d{4}-\d\d-\d\d \d\d:\d\d UTC", head)
    assert "model: table-table (No. 19680 = 12)" in head
    assert "rms 2.10 µm, max 5.70 µm" in head
    assert "increment: IS-C (0.0001 mm)" in head


def test_is_b_rounds_to_a_micrometre(tmp_path):
    p = tmp_path / "fanuc.txt"
    p.write_text(fanuc.write(_export("IS-B"), MACHINE)[".txt"])
    back = fanuc.read(str(p))
    assert back["rotary table position X"] == pytest.approx(0.012)
    assert back["19703"] == 0.0


def test_write_needs_the_increment():
    exp = _export()
    exp.options = {}
    with pytest.raises(ValueError, match="increment=None: expected IS-B or IS-C"):
        fanuc.write(exp, MACHINE)


@pytest.mark.parametrize("body, message", [
    ("19680 | 1 | 12\n19703 | 1\n", r":2: expected 'No. \| path \| value"),
    ("# c\n19703 | 1 | 0.01O\n", r":2: parameter 19703: value '0.01O' is not a number"),
    ("19703 | 1 | 0.01\n\n19703 | 1 | 0.02\n", r":3: parameter 19703 given twice"),
    ("19703 | 1 | nan\n", r":1: parameter 19703: value 'nan' is not finite"),
    ("# only comments\n", r"no parameter lines"),
])
def test_read_refuses_a_malformed_list(tmp_path, body, message):
    p = tmp_path / "old.txt"
    p.write_text(body)
    with pytest.raises(ValueError, match=message):
        fanuc.read(str(p))
