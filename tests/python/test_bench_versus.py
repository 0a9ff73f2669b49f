"""bench/versus.py, the same-run comparison of two builds: it times the
right thing (each side's own tree), and it says when a case is slower or the
two builds solved different problems."""
import json
import os
import statistics
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


def test_the_ratio_pairs_each_round_and_carries_an_interval():
    """On a machine whose runs are bimodal the two sides' medians do not
    pair: here this side is 4 % faster in every round both ran at the same
    speed (four), and the slow mode hit only this side in three; the medians
    say 1.34, the rounds 0.96."""
    other = [1.4, 1.4, 1.4, 1.0, 1.0, 1.0, 1.0]
    this = [0.96 * 1.4, 0.96 * 1.4, 0.96 * 1.4, 0.96, 0.96 * 1.4, 0.96 * 1.4, 0.96 * 1.4]
    assert statistics.median(this) / statistics.median(other) == pytest.approx(1.344)
    ratio, ci = versus.paired_ratio(this, other)
    assert ratio == pytest.approx(0.96)
    assert ci[0] <= ratio <= ci[1] and ci[1] == pytest.approx(1.344)
    assert versus.paired_ratio(this, other) == (ratio, ci)  # reproducible from the times
    with pytest.raises(ValueError, match="same, non-zero number of rounds"):
        versus.paired_ratio([1.0], [1.0, 2.0])


def test_the_readme_paragraph_shows_the_interval_and_a_comparison_measured_apart():
    row = {"case": "tango_S3", "this_s": 0.004, "other_s": 0.005, "this_over_other": 0.8,
           "ratio_ci95": [0.7, 0.9], "agree": True}
    doc = {"machine": {"date": "2026-11-28 17:14:23"},
           "versus": {"rounds": 9, "other": {"commit": "abc1234"}, "results": [row], "date": "2026-11-29 10:00:00",
                      "measured_apart": True}}
    text = " ".join(bench.versus_paragraph(doc))
    assert "(0.80, 95 % 0.70–0.90)" in text and "measured apart on 2026-11-29 10:00:00" in text
    del doc["versus"]["measured_apart"]
    assert "in the same run" in " ".join(bench.versus_paragraph(doc))


def test_versus_only_puts_the_comparison_into_the_existing_results(tmp_path, monkeypatch):
    """--versus-only replaces the file's comparison and nothing else: the
    cases keep their run's figures and results_previous.json (the run before
    that one) is not overwritten."""
    out = tmp_path / "results.json"
    doc = {"machine": {"date": "2026-11-28 17:14:23"}, "quick": False, "results": [{"case": "tango_S3"}],
           "versus": {"date": "old"}}
    out.write_text(json.dumps(doc))
    fake = {"date": "2026-11-28 18:46:58", "rounds": 9, "results": []}
    monkeypatch.setattr(bench.versus, "compare", lambda tree, rounds: dict(fake, tree=tree, asked=rounds))
    with pytest.raises(SystemExit):
        bench.main(["--versus-only", "--out", str(out)])  # needs --versus TREE
    assert bench.main(["--versus", "/some/tree", "--versus-only", "--versus-rounds", "9", "--out", str(out)]) == 0
    new = json.loads(out.read_text())
    assert new["results"] == doc["results"] and new["machine"] == doc["machine"]
    assert new["versus"] == dict(fake, tree="/some/tree", asked=9, measured_apart=True)
    assert not (tmp_path / "results_previous.json").exists()
    # --versus-recheck keeps a later re-measurement beside it, also without touching results_previous.json
    check = tmp_path / "check.json"
    check.write_text(json.dumps({"date": "d2", "rounds": 15, "other": {"commit": "abc"}, "results": []}))
    with pytest.raises(SystemExit):   # against another commit than the file's comparison
        bench.main(["--versus-recheck", str(check), "--out", str(out)])
    new["versus"]["other"] = {"commit": "abc"}
    out.write_text(json.dumps(new))
    assert bench.main(["--versus-recheck", str(check), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["versus_recheck"]["date"] == "d2"
    assert not (tmp_path / "results_previous.json").exists()


def test_the_jax_ratio_pairs_alternating_runs(monkeypatch):
    """timed_jax_paired alternates the sides (fivecal first in even rounds)
    and jax_result takes the median of each round's JAX / fivecal."""
    order = []

    class FakeJax:
        @staticmethod
        def block(x):
            return x
    monkeypatch.setattr(bench, "jbase", FakeJax)
    first, t_j, runs_j, runs_f, out = bench.timed_jax_paired(lambda: order.append("f"),
                                                              lambda: order.append("j") or "out", 3)
    assert order == ["j", "f", "j", "j", "f", "f", "j"] and out == "out"
    assert len(runs_j) == len(runs_f) == 3
    r = bench.jax_result(1.0, 0.5, 2.0, [2.0, 4.0, 2.2], paired_fivecal=[1.0, 1.0, 2.0])
    assert r["ratio_jax"] == pytest.approx(2.0) and r["ratio_jax_ci95"][0] <= 2.0 <= r["ratio_jax_ci95"][1]
    assert bench.jax_result(1.0, 0.5, 2.0, [2.0])["ratio_jax"] == 2.0
    assert bench.jax_cells({**r, "jax_s": 2.0})[2].startswith("2x (")


def test_a_case_named_slower_and_measured_again_shows_both():
    """The same-run comparison names a case; a later, larger re-measurement
    of it is shown beside it and decides, and a case it does not clear is
    still named."""
    row = lambda case, x, agree=True: {"case": case, "this_s": 1.0, "other_s": 1.0, "this_over_other": x,  # noqa: E731
                                       "ratio_ci95": [x - 0.05, x + 0.05], "agree": agree}
    v = {"rounds": 7, "other": {"commit": "abc1234"}, "date": "d1",
         "results": [row("forward_kinematics", 1.06), row("design_search_10000", 1.13), row("tango_S3", 0.8)]}
    rc = {"rounds": 15, "other": {"commit": "abc1234"}, "date": "d2",
          "results": [row("forward_kinematics", 1.01), row("design_search_10000", 1.08)]}
    text = " ".join(bench.versus_paragraph({"versus": v, "versus_recheck": rc}))
    assert "Slower by more than 5 %: forward_kinematics, design_search_10000." in text
    assert "Measured again on d2 (15 rounds, those cases only): forward_kinematics 1.01" in text
    assert "Slower by more than 5 % in both: design_search_10000." in text
    rc["results"][1] = row("design_search_10000", 0.99)
    assert "None is slower by more than 5 % there." in " ".join(bench.versus_paragraph({"versus": v, "versus_recheck": rc}))
    rc["results"][1] = row("design_search_10000", 0.99, agree=False)
    assert "in both: design_search_10000" in " ".join(bench.versus_paragraph({"versus": v, "versus_recheck": rc}))
    # a re-measurement against another commit is not this comparison's
    rc["other"]["commit"] = "fffffff"
    assert "Measured again" not in " ".join(bench.versus_paragraph({"versus": v, "versus_recheck": rc}))


def test_the_previous_run_paragraph_says_when_its_ratios_were_not_paired():
    doc = {"previous": {"machine": {"date": "d0"}, "results": [{"case": "tango_S3", "ratio_jax": 1.6}]},
           "results": [{"case": "tango_S3", "ratio_jax": 0.81, "ratio_jax_ci95": [0.66, 1.1]}]}
    text = " ".join(bench.previous_paragraph(doc))
    assert "tango_S3 1.6× → 0.81×" in text and "ratios of the two sides' medians" in text
    doc["previous"]["results"][0]["ratio_jax_ci95"] = [1.5, 1.7]
    assert "medians" not in " ".join(bench.previous_paragraph(doc))
