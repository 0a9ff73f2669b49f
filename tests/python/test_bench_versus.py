"""bench/versus.py, the same-run comparison of two builds: it times the
right thing (each side's own tree), and it says when a case is slower or the
two builds solved different problems."""
import json
import os
import sys

import pytest

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
sys.path.insert(0, os.path.join(ROOT, "bench"))

import run as bench  # noqa: E402
import versus  # noqa: E402


def _fit(values, std, iterations=2):
    return {"kind": "fit", "iterations": iterations, "values": values, "std": std}


def test_two_outputs_agree_only_when_they_are_the_same_problem():
    a = _fit({"EX0C": 1e-3, "EY0C": 2e-3}, {"EX0C": 1e-4, "EY0C": 1e-4})
    assert versus._difference(a, a) == 0.0
    # rounding: far below 1e-4 of a sigma
    near = _fit({"EX0C": 1e-3 + 1e-13, "EY0C": 2e-3}, a["std"])
    assert versus._difference(a, near) < 1e-4
    # a value 0.01 sigma away, another estimated set, another kind: not the same problem
    assert versus._difference(a, _fit({"EX0C": 1e-3 + 1e-6, "EY0C": 2e-3}, a["std"])) == pytest.approx(0.01)
    assert versus._difference(a, _fit({"EX0C": 1e-3}, {"EX0C": 1e-4})) == float("inf")
    assert versus._difference(a, {"kind": "spread", "std": a["std"]}) == float("inf")
    assert versus._difference({"kind": "design", "groups": [1, 2]}, {"kind": "design", "groups": [1, 3]}) \
        == float("inf")
    p = {"kind": "points", "shape": [4, 3], "sum": 10.0, "sum_sq": 30.0}
    assert versus._difference(p, dict(p, sum=10.0 + 1e-6)) == pytest.approx(1e-7)


def test_the_readme_paragraph_names_a_slower_case_and_a_disagreement():
    rows = [{"case": "tango_S3", "this_s": 0.004, "other_s": 0.005, "this_over_other": 0.8, "agree": True},
            {"case": "tango_S4", "this_s": 0.030, "other_s": 0.020, "this_over_other": 1.5, "agree": False}]
    doc = {"versus": {"rounds": 5, "other": {"commit": "abc1234"}, "results": rows}}
    text = " ".join(bench.versus_paragraph(doc))
    assert "abc1234" in text and "Slower by more than 5 %: tango_S4." in text
    assert "tango_S4 30.00 ms against 20.00 ms (1.50) (outputs differ)" in text
    doc["versus"]["results"] = rows[:1]
    assert "No case is slower" in " ".join(bench.versus_paragraph(doc))
    assert bench.versus_paragraph({}) == []


def test_a_tree_without_a_built_module_is_refused_by_name(tmp_path):
    (tmp_path / "python" / "fivecal").mkdir(parents=True)
    with pytest.raises(SystemExit, match="no built _core module"):
        versus.Side("other", str(tmp_path))


def test_versus_times_every_case_of_the_bench():
    """A case bench/run.py measures is one versus compares (a new case
    without its set-up here would go unchecked); unknown names are refused."""
    with open(os.path.join(ROOT, "bench", "results.json")) as f:
        cases = [r["case"] for r in json.load(f)["results"]]
    assert cases == versus.CASES
    with pytest.raises(ValueError, match="unknown case"):
        versus._prepare("no_such_case")
