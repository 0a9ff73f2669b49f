"""The file-format schemas (issue 12, "What to build" 1): every shipped example
validates, an unknown key is refused at every level of every file kind with
its JSON path and a did-you-mean, through the loaders users call, and a big
dataset is checked without parsing its observations in Python."""
import copy
import glob
import json
import os
import subprocess
import sys
import time
import warnings

import jsonschema
import pytest

import fivecal
from fivecal import schema

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
HU40T = os.path.join(ROOT, "examples", "machines", "hu40t.json")
SPHERES = os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json")


def fivecal_cli(*args, cwd=None):
    env = dict(os.environ)
    env.pop("FIVECAL_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "fivecal", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=300)


def load(path):
    with open(path) as f:
        return json.load(f)


def machine_doc():
    return load(HU40T)


def spec_doc():
    d = load(SPHERES)
    d["machine"] = machine_doc()
    return d


@pytest.fixture(scope="module")
def dataset_doc():
    spec = spec_doc()
    ds = fivecal.simulate(spec["machine"], spec["plan"][:40], errors=spec["errors"], artefact=spec["artefact"],
                          tip_radius=3.0, sigma=0.0006, seed=3)
    d = ds.to_dict()
    d["observations"].append({"type": "dbb", "setup": "A1", "axes": {a: 0.0 for a in "XYZBC"}, "reading": 0.001,
                              "length": 100.0, "tool_ball": [0, 0, 100], "table_ball": [0, 0, 0]})
    d["observations"].append({"type": "ball3d", "setup": "R1", "axes": {a: 0.0 for a in "XYZBC"},
                              "measured": [0.001, 0, 0], "tool_ball": [0, 0, 100], "table_ball": [0, 0, 0]})
    return d


@pytest.fixture(scope="module")
def result_doc(dataset_doc):
    d = copy.deepcopy(dataset_doc)
    d["observations"] = d["observations"][:40]
    with warnings.catch_warnings():  # only its shape matters here: an unusable fit is still a result file
        warnings.simplefilter("ignore", fivecal.FitWarning)
        return json.loads(fivecal.identify(d, estimate=["EX0C", "EY0C"]).to_json())


def test_schema_files_are_valid_draft_2020_12_and_ship_in_the_package():
    for kind in schema.KINDS + ("common",):
        s = schema.load_schema(kind)
        assert s["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        jsonschema.Draft202012Validator.check_schema(s)
    for kind in schema.KINDS:
        assert os.path.dirname(schema.schema_path(kind)) == os.path.join(os.path.dirname(fivecal.__file__), "schemas")


def _closed(node, where="#"):
    """Every object schema with properties is closed (additionalProperties false)."""
    bad = []
    if isinstance(node, dict):
        if "properties" in node and node.get("additionalProperties") is not False and not where.endswith("/if"):
            bad.append(where)
        for k, v in node.items():
            bad += _closed(v, f"{where}/{k}")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            bad += _closed(v, f"{where}/{i}")
    return bad


def test_every_object_with_named_keys_is_closed():
    for kind in schema.KINDS + ("common",):
        s = schema.load_schema(kind)
        # the observation and plan-item dispatchers only name `type` (as do the
        # `if` tests of their branches); each per-type `then` branch is closed
        open_ = [w for w in _closed(s) if not w.endswith(("$defs/observation", "$defs/plan_item"))]
        assert open_ == [], (kind, open_)


EXAMPLES = sorted(glob.glob(os.path.join(ROOT, "examples", "**", "*.json"), recursive=True)
                  + glob.glob(os.path.join(ROOT, "tests", "data", "*.json")))


def _kind_of_example(path):
    # an example folder of its own (examples/sscanss_table/) names its files by kind
    if os.sep + "machines" + os.sep in path or os.path.basename(path) == "machine.json":
        return "machine"
    if os.sep + "design" + os.sep in path:
        return "design"
    if os.sep + "import" + os.sep in path or os.path.basename(path) == "import.json":
        return "import"
    # an instrument file's sidecar: the JSON named as the file beside it (rtest_log.txt + rtest_log.json)
    stem = os.path.splitext(path)[0]
    if any(os.path.isfile(stem + ext) for ext in (".txt", ".csv", ".tsv", ".dat")):
        return "import"
    if os.path.basename(path).startswith("errors"):
        return "errors"
    return "spec"


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: os.path.relpath(p, ROOT))
def test_every_example_file_validates(path):
    assert schema.validate(load(path), _kind_of_example(path), path) is not None


def test_examples_are_found():
    kinds = {_kind_of_example(p) for p in EXAMPLES}
    assert kinds == {"machine", "design", "errors", "spec", "import"}


def test_what_fivecal_writes_validates(dataset_doc, result_doc):
    schema.validate(dataset_doc, "dataset")
    schema.validate(result_doc, "result")
    schema.validate(result_doc, "errors")
    schema.validate(fivecal.Machine.load(HU40T).to_dict(), "machine")


def test_result_schema_takes_the_fields_of_a_fit_with_priors(result_doc):
    r = copy.deepcopy(result_doc)
    name = next(iter(r["parameters"]))
    r["parameters"][name].update({"prior_std": 0.05, "informed": 0.1})
    r.update({"verdict": "ok", "adequate": True, "adequacy": "", "undetermined": ["EZ0C"], "implausible": [],
              "map_fit": True, "finite": True, "chi2": {"value": 35.2, "dof": 30, "p": 0.23}})
    schema.validate(r, "result")


def test_a_map_fit_result_validates_with_its_prior_fields(dataset_doc):
    d = copy.deepcopy(dataset_doc)
    d["observations"] = d["observations"][:40]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fivecal.FitWarning)
        r = json.loads(fivecal.identify(d, estimate="auto").to_json())
    assert r["map_fit"] is True
    assert all("prior_std" in p and "informed" in p for p in r["parameters"].values() if not p.get("fixed"))
    assert set(r["chi2"]) == {"value", "dof", "p"}
    schema.validate(r, "result")
    r["chi2"]["dofs"] = r["chi2"].pop("dof")
    with pytest.raises(ValueError, match=r"^result\.chi2\.dofs: unknown key; did you mean 'dof'\?"):
        schema.validate(r, "result")


# ---- unknown keys, at every level -------------------------------------------------
def _set(doc, path, key, value):
    node = doc
    for p in path:
        node = node[p]
    node[key] = value


# (kind, document factory name, path to the object, misspelt key, expected message)
UNKNOWN = [
    ("machine", "machine", [], "topolgy", "machine.topolgy: unknown key; did you mean 'topology'?"),
    ("machine", "machine", ["axes", "B"], "dirction", "machine.axes.B.dirction: unknown key; did you mean 'direction'?"),
    ("machine", "machine", ["axes"], "C2", "machine.axes.C2: unknown key; did you mean 'C'?"),
    ("machine", "machine", ["tool"], "tipp", "machine.tool.tipp: unknown key; did you mean 'tip'?"),
    ("machine", "machine", [], "prior", "machine.prior: unknown key; did you mean 'priors'?"),
    ("dataset", "dataset", [], "artifact", "dataset.artifact: unknown key; did you mean 'artefact'?"),
    ("dataset", "dataset", ["machine", "axes", "X"], "pont", "dataset.machine.axes.X.pont: unknown key; did you mean 'point'?"),
    ("dataset", "dataset", ["probe"], "tip_radus", "dataset.probe.tip_radus: unknown key; did you mean 'tip_radius'?"),
    ("dataset", "dataset", ["artefact"], "sphere", "dataset.artefact.sphere: unknown key; did you mean 'spheres'?"),
    ("dataset", "dataset", ["artefact", "spheres", 1], "radious",
     "dataset.artefact.spheres[1].radious: unknown key; did you mean 'radius'?"),
    ("dataset", "dataset", ["artefact", "scale_bars", 0], "lenght",
     "dataset.artefact.scale_bars[0].lenght: unknown key; did you mean 'length'?"),
    ("dataset", "dataset", ["observations", 3], "dirction",
     "dataset.observations[3].dirction: unknown key; did you mean 'direction'?"),
    ("dataset", "dataset", ["observations", 5], "sigm", "dataset.observations[5].sigm: unknown key; did you mean 'sigma'?"),
    ("dataset", "dataset", ["observations", 40], "lenght",
     "dataset.observations[40].lenght: unknown key; did you mean 'length'?"),
    ("dataset", "dataset", ["observations", 41], "measure",
     "dataset.observations[41].measure: unknown key; did you mean 'measured'?"),
    ("dataset", "dataset", ["observations", 2, "axes"], "BB", "dataset.observations[2].axes.BB: unknown key; did you mean 'B'?"),
    ("spec", "spec", [], "sead", "spec.sead: unknown key; did you mean 'seed'?"),
    ("spec", "spec", ["plan", 7], "norml", "spec.plan[7].norml: unknown key; did you mean 'normal'?"),
    ("spec", "spec", ["artefact", "spheres", 0], "centre", "spec.artefact.spheres[0].centre: unknown key; did you mean 'center'?"),
    ("design", "design", [], "candidate", "spec.candidate: unknown key; did you mean 'candidates'?"),
    ("design", "design", ["candidates"], "min_dott", "spec.candidates.min_dott: unknown key; did you mean 'min_dot'?"),
    ("result", "result", [], "residual_rm", "result.residual_rm: unknown key; did you mean 'residual_rms'?"),
    ("result", "result", ["parameters", "EX0C"], "valu", "result.parameters.EX0C.valu: unknown key; did you mean 'value'?"),
]


@pytest.fixture
def docs(dataset_doc, result_doc):
    design = spec_doc()
    design["candidates"] = {"indexations": [{"B": 0, "C": 0}], "min_dot": 0.0}
    return {"machine": machine_doc(), "dataset": copy.deepcopy(dataset_doc), "spec": spec_doc(), "design": design,
            "result": copy.deepcopy(result_doc)}


@pytest.mark.parametrize("kind,doc,path,key,message", UNKNOWN, ids=[u[4].split(":")[0] for u in UNKNOWN])
def test_unknown_key_is_refused_with_path_and_did_you_mean(docs, kind, doc, path, key, message):
    d = docs[doc]
    _set(d, path, key, 1)
    with pytest.raises(ValueError) as e:
        schema.validate(d, kind, "f.json")
    assert str(e.value) == "f.json: " + message


def test_unknown_key_without_a_close_match_lists_the_allowed_keys(docs):
    d = docs["machine"]
    d["colour"] = "red"
    with pytest.raises(ValueError, match=r"^machine\.colour: unknown key \(allowed: \$schema, name, topology, axes"):
        schema.validate(d, "machine")


def test_loaders_refuse_unknown_keys_before_the_cpp_loader(docs, tmp_path):
    m = docs["machine"]
    m["axes"]["B"]["dirction"] = m["axes"]["B"].pop("direction")
    with pytest.raises(ValueError, match=r"machine\.axes\.B\.dirction: unknown key; did you mean 'direction'\?"):
        fivecal.Machine.from_dict(m)
    p = tmp_path / "m.json"
    p.write_text(json.dumps(m))
    with pytest.raises(ValueError, match=r"^.*m\.json: machine\.axes\.B\.dirction: unknown key"):
        fivecal.Machine.load(p)

    d = docs["dataset"]
    d["observations"][3]["dirction"] = d["observations"][3].pop("direction")
    with pytest.raises(ValueError, match=r"dataset\.observations\[3\]\.dirction: unknown key; did you mean"):
        fivecal.Dataset.from_dict(d)
    p = tmp_path / "ds.json"
    p.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"ds\.json: dataset\.observations\[3\]\.dirction: unknown key"):
        fivecal.load_dataset(p)

    s = docs["spec"]
    plan = s["plan"]
    plan[2]["targt"] = plan[2].pop("target")
    with pytest.raises(ValueError, match=r"spec\.plan\[2\]\.targt: unknown key; did you mean 'target'\?"):
        fivecal.simulate(s["machine"], plan, artefact=s["artefact"], tip_radius=3.0)


def test_cli_refuses_unknown_keys_in_spec_design_spec_machine_and_result(docs, tmp_path):
    s = load(SPHERES)
    s["machine"] = HU40T
    s["plan"][4]["axis"] = s["plan"][4].pop("axes")
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(s))
    r = fivecal_cli("simulate", spec, "--out", tmp_path / "ds.json")
    assert r.returncode == 2, r.stderr
    assert "spec.plan[4].axis: unknown key; did you mean 'axes'?" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "ds.json").exists()

    d = docs["design"]
    d["candidates"]["indexation"] = d["candidates"].pop("indexations")
    design = tmp_path / "design.json"
    design.write_text(json.dumps(d))
    r = fivecal_cli("design", design, "-k", "1")
    assert r.returncode == 2 and "spec.candidates.indexation: unknown key; did you mean 'indexations'?" in r.stderr

    res = docs["result"]
    res["parameters"]["EX0C"]["vlaue"] = res["parameters"]["EX0C"].pop("value")
    result = tmp_path / "result.json"
    result.write_text(json.dumps(res))
    r = fivecal_cli("compensate", result, HU40T, "--table", tmp_path / "t.csv")
    assert r.returncode == 2 and "result.parameters.EX0C.vlaue: unknown key; did you mean 'value'?" in r.stderr

    m = docs["machine"]
    m["tool"]["tip "] = m["tool"].pop("tip")
    mp = tmp_path / "m.json"
    mp.write_text(json.dumps(m))
    r = fivecal_cli("compensate", os.path.join(ROOT, "examples", "cpp", "errors_example.json"), mp,
                    "--table", tmp_path / "t.csv")
    assert r.returncode == 2 and "machine.tool.tip : unknown key; did you mean 'tip'?" in r.stderr


# ---- types, values and names -----------------------------------------------------
@pytest.mark.parametrize("mutate,message", [
    (lambda d: d["observations"][0]["axes"].__setitem__("B", float("nan")),
     "dataset.observations[0].axes.B: value is not finite (NaN or inf)"),
    (lambda d: d["observations"][0]["axes"].__setitem__("B", "30"),
     "dataset.observations[0].axes.B: expected a number, got a string"),
    # Every registered kind is named, in registration order.
    (lambda d: d["observations"][1].__setitem__("type", "sphre"),
     "dataset.observations[1].type: \"sphre\" is not one of "
     + ", ".join(f'"{k["name"]}"' for k in fivecal._core.observation_kinds()) + "; did you mean 'sphere'?"),
    (lambda d: d["observations"][2]["direction"].__setitem__("X", 2),
     "dataset.observations[2].direction.X: must be -1, 0 or +1 (got 2)"),
    (lambda d: d["observations"][2]["direction"].__setitem__("X", 0.5),
     "dataset.observations[2].direction.X: must be -1, 0 or +1 (got 0.5)"),
    (lambda d: d["observations"][1].pop("target"), "dataset.observations[1].target: missing"),
    (lambda d: d["observations"][40].__setitem__("setup", "A.1"),
     "dataset.observations[40].setup: 'A.1' must not contain '.'"),
    (lambda d: d["observations"][40].__setitem__("table_ball", [0, 0]),
     "dataset.observations[40].table_ball: expected 3 values, got 2"),
    (lambda d: d["observations"][3].__setitem__("sigma", -1.0),
     "dataset.observations[3].sigma: must be > 0, got -1.0"),
    (lambda d: d.__setitem__("observations", {}), "dataset.observations: expected an array, got an object"),
    (lambda d: d.pop("machine"), "dataset.machine: missing"),
])
def test_wrong_values_are_named(dataset_doc, mutate, message):
    d = copy.deepcopy(dataset_doc)
    mutate(d)
    with pytest.raises(ValueError) as e:
        schema.validate(d, "dataset")
    assert str(e.value) == message


def test_integral_floats_count_as_integers_and_booleans_do_not(dataset_doc):
    d = copy.deepcopy(dataset_doc)
    d["observations"][2]["direction"]["X"] = -1.0  # what numpy writes
    schema.validate(d, "dataset")
    s = spec_doc()
    s["seed"] = 7.0
    schema.validate(s, "spec")
    s["seed"] = 2 ** 64
    with pytest.raises(ValueError, match=r"^spec\.seed: must be <= 18446744073709551615"):
        schema.validate(s, "spec")
    d["observations"][2]["direction"]["X"] = True
    with pytest.raises(ValueError, match=r"direction\.X: expected an integer, got a boolean"):
        schema.validate(d, "dataset")


def test_sigma_and_id_are_observation_keys(dataset_doc):
    d = copy.deepcopy(dataset_doc)
    d["observations"][0].update({"id": "touch-1", "sigma": 0.0006})
    d["observations"][41].update({"id": "r1", "sigma": [0.001, 0.001, 0.002]})
    schema.validate(d, "dataset")


def test_s_and_its_alias_c1_are_not_both_given(dataset_doc):
    d = copy.deepcopy(dataset_doc)
    d["observations"][0]["axes"]["C1"] = 0.0
    with pytest.raises(ValueError, match=r"^dataset\.observations\[0\]\.axes: duplicate axis 'S': both 'S' and its alias 'C1'"):
        schema.validate(d, "dataset")
    m = machine_doc()
    m["axes"]["C1"] = m["axes"]["S"]
    with pytest.raises(ValueError, match=r"^machine\.axes: duplicate axis 'S': both 'S' and its alias 'C1'"):
        schema.validate(m, "machine")


def test_files_may_name_their_schema():
    m = machine_doc()
    m["$schema"] = "https://fivecal.invalid/schemas/machine.schema.json"
    schema.validate(m, "machine")


def test_machine_priors_are_positive_numbers():
    m = machine_doc()
    m["priors"] = {"EX0C": 0.05, "class:location_angle": 1e-4}
    schema.validate(m, "machine")
    m["priors"]["EX0C"] = 0
    with pytest.raises(ValueError, match=r"^machine\.priors\.EX0C: must be > 0"):
        schema.validate(m, "machine")


def test_a_spec_names_its_machine_by_path_or_inline():
    s = spec_doc()
    schema.validate(s, "spec")
    s["machine"] = "../machines/hu40t.json"
    schema.validate(s, "spec")
    s["machine"] = 3
    with pytest.raises(ValueError, match=r"^spec\.machine: expected an object, got a number"):
        schema.validate(s, "spec")


def test_result_file_or_plain_error_values(result_doc):
    schema.validate({"EX0C": 0.01, "EB0C": 2e-5}, "errors")
    with pytest.raises(ValueError, match=r"^result\.EX0C: expected a number, got a string"):
        schema.validate({"EX0C": "0.01"}, "errors")
    r = copy.deepcopy(result_doc)
    r["parameters"]["EX0C"]["value"] = None
    with pytest.raises(ValueError, match=r"^result\.parameters\.EX0C\.value: expected a number, got null"):
        schema.validate(r, "errors")


# ---- big files -------------------------------------------------------------------
def _big_text(doc, n):
    d = copy.deepcopy(doc)
    obs = d["observations"][:40]
    d["observations"] = [obs[i % len(obs)] for i in range(n)]
    return json.dumps(d)


def test_big_dataset_text_is_checked_without_parsing_every_observation(dataset_doc, monkeypatch):
    monkeypatch.setattr(schema, "BIG_TEXT", 10_000)
    monkeypatch.setattr(schema, "BIG_TEXT_SAMPLE", 50)
    text = _big_text(dataset_doc, 400)
    assert len(text) > schema.BIG_TEXT
    assert schema.check_text(text, "dataset") is None  # the fast path: observations left to the C++ loader
    # fivecal writes `probe` after `observations`: the members after the array are checked too
    assert text.index('"observations"') < text.index('"probe"')
    for old, new, message in [
            ('"tip_radius"', '"tip_radus"', "dataset.probe.tip_radus: unknown key; did you mean 'tip_radius'?"),
            ('"artefact"', '"artifact"', "dataset.artifact: unknown key; did you mean 'artefact'?"),
            ('"topology"', '"topolgy"', "dataset.machine.topolgy: unknown key; did you mean 'topology'?")]:
        with pytest.raises(ValueError) as e:
            schema.check_text(text.replace(old, new, 1), "dataset", "big.json")
        assert str(e.value) == "big.json: " + message
    # the first BIG_TEXT_SAMPLE observations are checked by the schema
    d = json.loads(text)
    d["observations"][7]["dirction"] = d["observations"][7].pop("direction")
    with pytest.raises(ValueError, match=r"^dataset\.observations\[7\]\.dirction: unknown key"):
        schema.check_text(json.dumps(d), "dataset")
    # an extra member after the observations
    with pytest.raises(ValueError, match=r"^dataset\.extra: unknown key"):
        schema.check_text(text[:-1] + ', "extra": {"a": [1]}}', "dataset")
    # a syntax error anywhere takes the ordinary parse, which names the line
    with pytest.raises(ValueError, match=r"not valid JSON"):
        schema.check_text(text[:-1], "dataset")


def test_big_in_memory_documents_are_checked_by_shape(dataset_doc, monkeypatch):
    monkeypatch.setattr(schema, "FULL_CHECK_LIMIT", 10)
    d = json.loads(_big_text(dataset_doc, 300))
    schema.validate(d, "dataset")
    d["observations"][250]["dirction"] = d["observations"][250].pop("direction")
    with pytest.raises(ValueError, match=r"^dataset\.observations\[250\]\.dirction: unknown key"):
        schema.validate(d, "dataset")
    s = spec_doc()
    s["plan"][150]["nomral"] = 1
    with pytest.raises(ValueError, match=r"^spec\.plan\[150\]\.nomral: unknown key; did you mean 'normal'\?"):
        schema.validate(s, "spec")


def test_schema_check_of_a_big_dataset_text_takes_a_fraction_of_a_second(dataset_doc):
    text = _big_text(dataset_doc, 100_000)
    assert len(text) > schema.BIG_TEXT
    t = time.perf_counter()
    schema.check_text(text, "dataset")
    assert time.perf_counter() - t < 2.0  # ~0.05 s unloaded; a full jsonschema pass takes minutes


def test_deep_nesting_and_bad_json_are_one_line_errors():
    with pytest.raises(ValueError, match=r"^x: not a fivecal file \(JSON nested too deeply\)"):
        schema.check_text("[" * 100_000, "dataset", "x")
    with pytest.raises(ValueError, match=r"^x: not valid JSON \(Expecting property name enclosed in double quotes at line 1, column 2\)"):
        schema.check_text("{,}", "machine", "x")
