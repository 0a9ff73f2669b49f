"""Columnar (Parquet) datasets: JSON -> Parquet -> JSON gives the same
dataset for every observation kind, a fit on either gives the same numbers
bit for bit, the CLI reads and converts them, and bad files are refused with
the kind, row and column named (docs/formats.md, "Columnar datasets")."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.procedures import tango
from fivecal.units import looks_like_radians

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
from fivecal.io import columnar  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from shared_machines import TABLE_HEAD  # noqa: E402


def _poses(rng, n):
    return [{"X": float(rng.uniform(-200, 200)), "Y": float(rng.uniform(-200, 200)),
             "Z": float(rng.uniform(-100, 100)), "B": float(rng.uniform(-60, 60)),
             "C": float(rng.uniform(0, 360))} for _ in range(n)]


def _spheres():
    with open(os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json")) as f:
        spec = json.load(f)
    with open(os.path.join(ROOT, "examples", "machines", "hu40t.json")) as f:
        machine = json.load(f)
    return fivecal.simulate(machine, spec["plan"], errors=spec["errors"], setup=spec["setup"],
                            artefact=spec["artefact"], tip_radius=3.0, sigma=spec["sigma"], seed=7)


def _balls():
    """Ball-bar and 3D ball samples interleaved, two mountings, ids, backlash
    directions and every form of sigma (none, one number, one per row)."""
    m = tango.hu40t_machine()
    rng = np.random.default_rng(3)
    plan = []
    for i in range(40):
        axes = {"X": float(rng.uniform(-50, 50)), "Y": float(rng.uniform(-50, 50)), "Z": float(rng.uniform(-50, 0)),
                "B": float(rng.uniform(0, 90)), "C": float(rng.uniform(-180, 180)), "S": 0.0}
        # the nominal tool ball (= the tool tip) at these axes, workpiece frame
        p = m.tool_point({a: [v] for a, v in axes.items()})[0]
        if i % 3 == 0:
            plan.append({"type": "dbb", "setup": "A1", "axes": axes, "tool_ball": [0, 0, 100],
                         "length": float(np.linalg.norm(p - np.array([100.0, 0, 0]))),
                         "table_ball": [100, 0, 0], "direction": {"C": 1 if i % 2 else -1}})
        else:
            plan.append({"type": "ball3d", "setup": "R1" if i % 2 else "R2", "axes": axes, "tool_ball": [0, 0, 100],
                         "table_ball": [float(x) for x in p], "id": f"s{i}"})
    d = fivecal.simulate(m, plan, errors={"EX0C": 0.01, "EB0C": 2e-5}, sigma={"dbb": 0.001, "ball3d": 0.001},
                         seed=2).to_dict()
    for i, o in enumerate(d["observations"]):
        if o["type"] == "ball3d" and i % 4 == 1:
            o["sigma"] = [0.001, 0.002, 0.003]
        elif i % 5 == 0:
            o["sigma"] = 0.0015
        elif "sigma" in o and i % 2:
            del o["sigma"]
    return fivecal.Dataset.from_dict(d)


def _points():
    rng = np.random.default_rng(4)
    plan = [{"type": "point", "instrument": "T1", "target": t, "target_point": p, "axes": q,
             "instrument_origin": [2000.0, -500.0, 400.0], "instrument_angles": [0.5, -1.0, 155.0]}
            for q in _poses(rng, 25) for t, p in (("tool", [0, 0, 150]), ("work", [120, 40, 20]))]
    d = fivecal.simulate(TABLE_HEAD, plan, errors={"EX0C": 0.03}, setup={"instrument.T1.x": 0.3},
                         sigma={"point": 0.005}, seed=4).to_dict()
    d["instruments"] = {"T1": {"sigma": [0.004, 0.004, 0.02]}}
    for o in d["observations"]:
        o.pop("sigma", None)
    return fivecal.Dataset.from_dict(d)


def _poses_kind():
    rng = np.random.default_rng(5)
    plan = [{"type": "pose", "instrument": "T1", "target": t, "target_point": p, "target_rotation": r, "axes": q,
             "instrument_origin": [2000.0, -500.0, 400.0], "instrument_angles": [0.5, -1.0, 155.0]}
            for q in _poses(rng, 20)
            for t, p, r in (("tool", [0, 0, 150], [0.2, -0.1, 0.4]), ("work", [120, 40, 20], [0.0, 0.0, 0.0]))]
    return fivecal.simulate(TABLE_HEAD, plan, errors={"EA0C": 2e-5}, setup={"instrument.T1.c": 2e-3},
                            sigma={"pose": 0.01, "pose_angle": 5e-5}, seed=5)


def _distances():
    rng = np.random.default_rng(6)
    stations = {"L1": [900, -700, 150], "L2": [-800, -600, 650], "L3": [700, 800, 900], "L4": [-900, 700, 100]}
    plan = []
    for q in _poses(rng, 10):
        for t, p in (("tool", [0, 0, 150]), ("work", [120, 40, 20])):
            for s, pos in stations.items():
                e = {"type": "distance", "station": s, "target": t, "target_point": p, "axes": q,
                     "station_position": pos}
                if s != "L4":
                    e["dead_length"] = 200.0
                if s == "L3":
                    e["instrument"] = "LT2"
                plan.append(e)
    return fivecal.simulate(TABLE_HEAD, plan, errors={"EX0C": 0.03}, setup={"instrument.L1.length": 0.05},
                            sigma={"distance": 0.001}, seed=6)


def _machined():
    m = fivecal.Machine.load(os.path.join(ROOT, "examples", "machines", "c600u.json"))
    plan = []
    for c in (0.0, -90.0, -180.0):
        plan.append({"type": "machined", "part": "P1", "feature": "face", "axes": {"A": -45.0, "C": c},
                     "point": [0.0, 150.0, 60.0], "normal": [0.0, 0.0, 1.0]})
        plan.append({"type": "machined", "part": "P1", "feature": "step", "axes": {"A": -90.0, "C": c},
                     "point": [0.0, 150.0, 60.0], "normal": [0.0, 0.0, 1.0],
                     "reference_axes": {"A": -90.0, "C": 0.0}, "id": f"step{c:g}"})
    plan.append({"type": "machined", "part": "P2", "feature": "step", "axes": {"A": -30.0, "C": 45.0},
                 "point": [100.0, -40.0, 40.0], "normal": [1.0, 0.0, 0.0], "reference_axes": {"A": -30.0, "C": 0.0},
                 "reference_point": [90.0, -40.0, 40.0], "reference_normal": [0.0, 1.0, 0.0]})
    return fivecal.simulate(m, plan, errors={"EA0C": 3e-5}, sigma={"machined": 0.003}, seed=8)


DATASETS = {
    "facet": lambda: tango.hu40t_dataset(seed=1),
    "sphere": _spheres,
    "cylinder": lambda: tango.kx8_curved_dataset(seed=5),
    "dbb_ball3d": _balls,
    "point": _points,
    "pose": _poses_kind,
    "distance": _distances,
    "machined": _machined,
}


@pytest.fixture(scope="module", params=sorted(DATASETS))
def dataset(request):
    return DATASETS[request.param]()


def test_every_registered_kind_is_covered():
    kinds = set()
    for make in DATASETS.values():
        kinds |= set(make().observation_types)
    assert kinds == {k["name"] for k in fivecal._core.observation_kinds()}


def test_json_parquet_json_is_the_same_dataset(dataset, tmp_path):
    src = tmp_path / "ds.json"
    fivecal.save_dataset(dataset, src)
    assert main(["convert", str(src), str(tmp_path / "ds.parquet")]) == 0
    assert main(["convert", str(tmp_path / "ds.parquet"), str(tmp_path / "back.json")]) == 0
    assert json.loads(src.read_text()) == json.loads((tmp_path / "back.json").read_text())
    assert src.read_bytes() == (tmp_path / "back.json").read_bytes()
    # and through the Python functions
    columnar.write_parquet(dataset, tmp_path / "f.parquet")
    assert columnar.read_parquet(tmp_path / "f.parquet").to_dict() == dataset.to_dict()
    assert fivecal.load_dataset(tmp_path / "f.parquet").to_dict() == dataset.to_dict()


def test_file_layout_one_row_per_observation_with_the_head_in_the_metadata(tmp_path):
    # The column names are those of the CSV observation tables: a 3-row sigma
    # as a vector (sigma_x ...), a pose's six numbered (sigma_1 ... sigma_6).
    pose = columnar.dataset_columns(_poses_kind()).schema.names
    assert [c for c in pose if c.startswith("sigma")] == [f"sigma_{r}" for r in range(1, 7)]
    ds = _balls()
    columnar.write_parquet(ds, tmp_path / "b.parquet")
    t = pq.read_table(tmp_path / "b.parquet")
    assert t.num_rows == len(ds)
    assert t.column("type").to_pylist() == ds.observation_types
    assert t.schema.names[:2] == ["type", "id"]
    assert {"X", "Y", "Z", "B", "C", "S", "dir_C", "measured_x", "tool_ball_z", "reading", "length",
            "setup", "sigma", "sigma_x", "sigma_z"} <= set(t.schema.names)
    assert t.schema.field("X").type == pa.float64() and t.schema.field("dir_C").type == pa.int8()
    meta = {k.decode(): v.decode() for k, v in t.schema.metadata.items() if k.startswith(b"fivecal.")}
    assert json.loads(meta["fivecal.machine"]) == ds.to_dict()["machine"]
    assert json.loads(meta["fivecal.units"]) == {"length": "mm", "rotary_axis": "deg", "angle": "rad"}
    assert meta["fivecal.version"] == "1"
    assert t.column("id").to_pylist() == [o.get("id") for o in ds.observations]


def test_mixed_kinds_across_many_batches_keep_their_order(tmp_path, monkeypatch):
    # Batches of 7 rows: kinds interleave inside a batch and across batches.
    ds = _balls()
    columnar.write_parquet(ds, tmp_path / "b.parquet")
    monkeypatch.setattr(columnar, "_BATCH_ROWS", 7)
    assert columnar.read_parquet(tmp_path / "b.parquet").to_dict() == ds.to_dict()


@pytest.mark.parametrize("make", sorted(DATASETS))
def test_identify_on_json_and_parquet_is_bit_identical(make, tmp_path):
    """The columnar path (Parquet columns; a trace's column blocks) gives the
    fit of the per-observation path (JSON objects) on every kind, bit for bit."""
    ds = DATASETS[make]()
    fivecal.save_dataset(ds, tmp_path / "a.json")
    fivecal.save_dataset(ds, tmp_path / "a.parquet")
    a, b = fivecal.load_dataset(tmp_path / "a.json"), fivecal.load_dataset(tmp_path / "a.parquet")
    ra, rb = fivecal.identify(a), fivecal.identify(b)
    assert ra.values == rb.values
    assert ra.std == rb.std
    assert np.array_equal(ra.residuals, rb.residuals)


def test_cli_identify_reads_parquet_by_its_content(tmp_path, capsys):
    ds = _balls()
    fivecal.save_dataset(ds, tmp_path / "a.json")
    fivecal.save_dataset(ds, tmp_path / "trace.data")  # no .parquet: JSON by name ...
    columnar.write_parquet(ds, tmp_path / "trace.data")  # ... Parquet by content
    rc_json = main(["identify", str(tmp_path / "a.json"), "--estimate", "location", "--out", str(tmp_path / "a.out")])
    rc_pq = main(["identify", str(tmp_path / "trace.data"), "--estimate", "location", "--out",
                  str(tmp_path / "b.out")])
    assert rc_json == rc_pq
    assert json.loads((tmp_path / "a.out").read_text()) == json.loads((tmp_path / "b.out").read_text())


# ---------------------------------------------------------------------------
# Bad files: ValueError naming what is wrong; exit code 2 in the CLI
# ---------------------------------------------------------------------------

def _ball3d_table(n=6):
    m = tango.hu40t_machine()
    q = {a: np.linspace(-10, 10, n) for a in "XYZ"}
    q.update(B=np.zeros(n), C=np.linspace(0, 90, n), S=np.zeros(n))
    ds = fivecal.ball_dataset(m, "ball3d", q, [0, 0, 100], [50, 0, 0], measured=np.full((n, 3), 0.001), setup="R1")
    return columnar.dataset_columns(ds)


def _write(t, path, meta=None):
    if meta is not None:
        t = t.replace_schema_metadata(meta)
    pq.write_table(t, path)
    return str(path)


def _refused(path, *needles):
    with pytest.raises(ValueError) as e:
        fivecal.load_dataset(path)
    msg = str(e.value)
    assert msg.startswith(str(path)), msg
    for n in needles:
        assert n in msg, msg
    assert main(["identify", str(path)]) == 2
    return msg


def _set(t, name, arr):
    return t.set_column(t.schema.get_field_index(name), name, arr).replace_schema_metadata(t.schema.metadata)


def test_missing_column(tmp_path):
    t = _ball3d_table()
    _refused(_write(t.drop_columns(["measured_y"]), tmp_path / "a.parquet", t.schema.metadata),
             "missing column measured_y")
    _refused(_write(t.drop_columns(["Y"]), tmp_path / "b.parquet", t.schema.metadata), "missing column Y")
    _refused(_write(t.drop_columns(["measured_x", "measured_y", "measured_z"]), tmp_path / "c.parquet",
                    t.schema.metadata), "missing column measured")
    _refused(_write(t.drop_columns(["type"]), tmp_path / "d.parquet", t.schema.metadata), "column type missing")


def test_wrong_dtype(tmp_path):
    t = _ball3d_table()
    bad = _set(t, "X", pa.array([str(x) for x in t.column("X").to_pylist()]))
    _refused(_write(bad, tmp_path / "a.parquet"), "column X", "expected numbers")
    bad = _set(t, "setup", pa.array([1.0] * t.num_rows))
    _refused(_write(bad, tmp_path / "b.parquet"), "column setup", "string")
    bad = _set(t, "measured_x", pa.array([[1.0]] * t.num_rows))
    _refused(_write(bad, tmp_path / "c.parquet"), "column measured_x", "neither numbers nor text")


def test_nan_and_null_name_the_row_and_column(tmp_path):
    t = _ball3d_table()
    v = t.column("measured_y").to_numpy().copy()
    v[3] = np.nan
    _refused(_write(_set(t, "measured_y", pa.array(v)), tmp_path / "a.parquet"),
             "ball3d row 3, column measured_y: NaN")
    x = t.column("X").to_pylist()
    x[4] = None
    _refused(_write(_set(t, "X", pa.array(x, pa.float64())), tmp_path / "b.parquet"), "ball3d row 4, column X: null")
    d = t.column("dir_C").to_pylist() if "dir_C" in t.schema.names else None
    assert d is None  # the trace has no backlash directions; add a bad one
    bad = t.append_column("dir_C", pa.array([0, 0, 2, 0, 0, 0], pa.int8())).replace_schema_metadata(
        t.schema.metadata)
    _refused(_write(bad, tmp_path / "c.parquet"), "ball3d row 2, column dir_C: must be -1, 0 or +1")
    m = t.column("measured_z").to_pylist()
    m[5] = None
    _refused(_write(_set(t, "measured_z", pa.array(m, pa.float64())), tmp_path / "d.parquet"),
             "ball3d row 5, column measured_z: null while measured_x is given")


def test_unknown_kind_and_unknown_column(tmp_path):
    t = _ball3d_table()
    _refused(_write(_set(t, "type", pa.array(["ball4d"] * t.num_rows)), tmp_path / "a.parquet"),
             "row 0, column type: unknown observation type 'ball4d'", "did you mean 'ball3d'")
    bad = t.append_column("mesured_w", pa.array([0.0] * t.num_rows)).replace_schema_metadata(t.schema.metadata)
    _refused(_write(bad, tmp_path / "b.parquet"), "unknown column 'mesured_w'")
    # an axis the machine does not have
    bad = t.append_column("A", pa.array([0.0] * t.num_rows)).replace_schema_metadata(t.schema.metadata)
    _refused(_write(bad, tmp_path / "c.parquet"), "unknown column 'A'", "machine axes")


def test_a_column_name_given_twice_is_refused(tmp_path):
    # Arrow keeps both columns; a reader keyed by name would keep one of them
    # silently (the last X won)
    t = _ball3d_table()
    for name, other in (("X", "X"), ("measured_y", "measured_y"), ("type", "type"), ("id", "id")):
        if name not in t.schema.names:
            t = t.append_column(name, pa.array([f"r{i}" for i in range(t.num_rows)]))
        col = t.column(name)
        bad = t.append_column(pa.field(other, col.type), col).replace_schema_metadata(t.schema.metadata)
        _refused(_write(bad, tmp_path / f"{name}.parquet"), f"column '{name}'", "twice", f"{t.num_columns + 1}")
    with pytest.raises(ValueError, match=r"column 'X' .*twice"):
        list(columnar.iter_datasets(_write(t.append_column(pa.field("X", pa.float64()), t.column("X"))
                                           .replace_schema_metadata(t.schema.metadata), tmp_path / "i.parquet")))


def test_metadata_missing_or_wrong(tmp_path):
    t = _ball3d_table()
    meta = dict(t.schema.metadata)
    no_machine = {k: v for k, v in meta.items() if k != b"fivecal.machine"}
    _refused(_write(t, tmp_path / "a.parquet", no_machine), "metadata fivecal.machine missing")
    _refused(_write(t, tmp_path / "b.parquet", {}), "not a fivecal dataset")
    bad_units = {**meta, b"fivecal.units": json.dumps({"length": "um", "rotary_axis": "deg",
                                                       "angle": "rad"}).encode()}
    _refused(_write(t, tmp_path / "c.parquet", bad_units), "fivecal.units", "um")
    broken = {**meta, b"fivecal.machine": b"{not json"}
    _refused(_write(t, tmp_path / "d.parquet", broken), "fivecal.machine: not valid JSON")
    m = json.loads(meta[b"fivecal.machine"])
    m["axes"]["B"]["direction"] = [0, 1]
    _refused(_write(t, tmp_path / "e.parquet", {**meta, b"fivecal.machine": json.dumps(m).encode()}),
             "machine.axes.B.direction")


def test_a_truncated_parquet_file_is_bad_input(tmp_path):
    columnar.write_parquet(_balls(), tmp_path / "a.parquet")
    data = (tmp_path / "a.parquet").read_bytes()
    (tmp_path / "t.parquet").write_bytes(data[: len(data) // 2])
    _refused(tmp_path / "t.parquet", "not a readable Parquet file")


def test_without_pyarrow_parquet_says_how_to_get_it(tmp_path, monkeypatch):
    columnar.write_parquet(_balls(), tmp_path / "a.parquet")
    for mod in [m for m in sys.modules if m == "pyarrow" or m.startswith("pyarrow.")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    _refused(tmp_path / "a.parquet", "pip install 'fivecal[arrow]'")
    with pytest.raises(ValueError, match=r"fivecal\[arrow\]"):
        fivecal.save_dataset(_balls(), tmp_path / "b.parquet")


def test_the_core_install_does_not_import_pyarrow(tmp_path):
    fivecal.save_dataset(_balls(), tmp_path / "a.json")
    code = ("import sys, fivecal; fivecal.load_dataset(sys.argv[1]); import fivecal.cli; "
            "assert 'pyarrow' not in sys.modules, 'pyarrow imported'")
    env = dict(os.environ)
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "a.json")], check=True, env=env)


def test_float64_columns_reach_the_core_without_a_copy(tmp_path):
    t = _ball3d_table()
    arr = t.column("X").chunk(0)
    values, valid = columnar._number(pa, arr, "X", "ball3d")
    assert valid is None
    assert values.ctypes.data == arr.buffers()[1].address + arr.offset * 8


def test_pieces_of_a_long_file_add_up_to_the_whole_and_name_file_rows(tmp_path):
    ds = _balls()
    columnar.write_parquet(ds, tmp_path / "b.parquet")
    pieces = list(columnar.iter_datasets(tmp_path / "b.parquet", rows=7))
    assert [len(p) for p in pieces] == [7] * 5 + [5]
    assert sum((p.observations for p in pieces), []) == ds.observations
    assert all(p.to_dict()["machine"] == ds.to_dict()["machine"] for p in pieces)
    t = _ball3d_table(20)
    v = t.column("measured_x").to_numpy().copy()
    v[10] = np.nan
    path = _write(_set(t, "measured_x", pa.array(v)), tmp_path / "nan.parquet")
    with pytest.raises(ValueError, match="ball3d row 10, column measured_x: NaN"):
        list(columnar.iter_datasets(path, rows=7))


def test_a_piece_is_freed_before_the_next_one_is_built(tmp_path, monkeypatch):
    # Two pieces in memory at once would double the peak of a long trace.
    import weakref

    from fivecal import plausibility

    columnar.write_parquet(_balls(), tmp_path / "b.parquet")
    previous, alive = [], []
    check, load = plausibility.check_loaded, columnar._load_batch

    def checked(ds, **kw):
        previous.append(weakref.ref(ds))
        return check(ds, **kw)

    def loading(*a, **kw):
        alive.append(any(r() is not None for r in previous))
        return load(*a, **kw)

    monkeypatch.setattr(plausibility, "check_loaded", checked)
    monkeypatch.setattr(columnar, "_load_batch", loading)
    for piece in columnar.iter_datasets(tmp_path / "b.parquet", rows=10):
        del piece
    assert alive == [False] * 4


def test_text_and_number_columns_of_other_arrow_types_are_read(tmp_path):
    # What other writers produce: dictionary-encoded text, large strings,
    # float32 / integer numbers.
    ds = _balls()
    t = columnar.dataset_columns(ds)
    t = _set(t, "type", t.column("type").dictionary_encode())
    t = _set(t, "setup", t.column("setup").cast(pa.large_string()))
    t = _set(t, "dir_C", t.column("dir_C").cast(pa.int64()))
    t = _set(t, "S", t.column("S").cast(pa.float32()))
    assert columnar.read_parquet(_write(t, tmp_path / "d.parquet")).to_dict() == ds.to_dict()


def test_three_noise_rows_read_numbered_or_as_a_vector(tmp_path):
    ds = _balls()
    t = columnar.dataset_columns(ds)
    t = t.rename_columns([{"sigma_x": "sigma_1", "sigma_y": "sigma_2", "sigma_z": "sigma_3"}.get(c, c)
                          for c in t.schema.names]).replace_schema_metadata(t.schema.metadata)
    assert columnar.read_parquet(_write(t, tmp_path / "n.parquet")).to_dict() == ds.to_dict()


def test_the_streaming_fit_of_a_parquet_trace_prepares_no_row_per_sample(tmp_path):
    # A long R-test trace from a Parquet file: the normal-equation passes
    # run on the kind's column block (solve/long_kernel.h) and prepare no
    # row at all (as the core counts them), and the fit is still the dense
    # one, which holds a prepared row per sample.
    from fivecal import _core

    m = fivecal.Machine.load(os.path.join(ROOT, "examples", "machines", "c600u.json"))
    true = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
    table = [50.0, 0.0, 80.0]
    n = 40_000
    rng = np.random.default_rng(4)
    tilt, turn = np.radians(rng.uniform(0, 60, n)), np.radians(rng.uniform(0, 360, n))
    tool_axes = np.column_stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), np.cos(tilt)])
    axes = m.inverse(np.tile(table, (n, 1)), tool_axes)
    meas = m.tool_point(axes, true) - np.array(table) + rng.normal(0, 5e-4, (n, 3))
    path = tmp_path / "trace.parquet"
    fivecal.save_dataset(fivecal.ball_dataset(m, "ball3d", axes, m.tip, table, measured=meas, setup="R1"), path)
    ds = fivecal.load_dataset(path)

    before = _core.prepared_rows(reset_peak=True)
    s = fivecal.identify(ds, list(true), fit_path="normal_equations", num_threads=2)
    after = _core.prepared_rows()
    assert after["alive"] == before["alive"]
    assert after["peak"] == before["alive"]
    _core.prepared_rows(reset_peak=True)
    d = fivecal.identify(ds, list(true), fit_path="dense")
    assert _core.prepared_rows()["peak"] - before["alive"] >= n  # the count sees held rows
    assert (d.fit_path, s.fit_path) == ("dense", "normal_equations")
    assert s.verdict == d.verdict == "ok"
    for k in d.estimated:
        assert abs(d.values[k] - s.values[k]) < 1e-9 * d.std[k], k
        assert s.std[k] == pytest.approx(d.std[k], rel=1e-8), k
    np.testing.assert_allclose(s.residuals, d.residuals, atol=1e-9 * d.rms)


# ---- fivecal convert, piece by piece -------------------------------------------------------------

def _convert_both_ways(ds, tmp_path, rows):
    """(JSON, whole Parquet, streamed Parquet, whole JSON back, streamed JSON
    back) bytes; `rows` observations per piece and per row group."""
    src = tmp_path / "src.json"
    fivecal.save_dataset(ds, src)
    out = {}
    for mode, limit in (("whole", 1 << 40), ("piece", 0)):
        pq_path, js_path = tmp_path / f"{mode}.parquet", tmp_path / f"{mode}.json"
        assert columnar.convert(src, pq_path, rows=rows, stream_bytes=limit) == len(ds)
        assert columnar.convert(pq_path, js_path, rows=rows, stream_bytes=limit) == len(ds)
        out[mode] = (pq_path.read_bytes(), js_path.read_bytes())
    return src.read_bytes(), out


@pytest.mark.parametrize("rows", [1, 7, 1000])
def test_convert_in_pieces_writes_what_the_whole_writes(dataset, tmp_path, rows):
    # Every kind (ids, every form of sigma, backlash directions, mountings,
    # instruments): the streamed convert writes the bytes the whole one does,
    # which save_dataset writes, and JSON comes back byte for byte.
    text, out = _convert_both_ways(dataset, tmp_path, rows)
    assert out["piece"][0] == out["whole"][0]
    assert out["piece"][1] == out["whole"][1] == text
    assert columnar.read_parquet(tmp_path / "piece.parquet").to_dict() == dataset.to_dict()


def test_convert_in_pieces_of_the_default_size_is_save_dataset(tmp_path, monkeypatch):
    ds = _balls()
    fivecal.save_dataset(ds, tmp_path / "saved.parquet")
    fivecal.save_dataset(ds, tmp_path / "src.json")
    monkeypatch.setattr(columnar, "STREAM_BYTES", 0)
    assert main(["convert", str(tmp_path / "src.json"), str(tmp_path / "out.parquet")]) == 0
    assert (tmp_path / "out.parquet").read_bytes() == (tmp_path / "saved.parquet").read_bytes()
    assert main(["convert", str(tmp_path / "out.parquet"), str(tmp_path / "back.json")]) == 0
    assert (tmp_path / "back.json").read_bytes() == (tmp_path / "src.json").read_bytes()


def test_a_column_that_first_appears_in_a_later_piece_is_in_every_row_group(tmp_path, monkeypatch):
    # ids, sigmas and backlash directions only from observation 20 on: the
    # first pass finds the columns changed and a second pass writes the file
    # with the whole dataset's columns.
    d = _balls().to_dict()
    for o in d["observations"][:20]:
        for k in ("id", "sigma", "direction"):
            o.pop(k, None)
    ds = fivecal.Dataset.from_dict(d)
    written = []
    real = columnar._batches
    # the batches of a piece (the 5th argument), one call per piece and pass
    monkeypatch.setattr(columnar, "_batches", lambda *a: (len(a) > 4 and written.append(1)) or real(*a))
    _, out = _convert_both_ways(ds, tmp_path, 6)
    assert out["piece"][0] == out["whole"][0]
    # 7 pieces: the first pass wrote 3 before the piece of observation 20
    assert len(written) == 3 + 7
    names = pq.read_schema(tmp_path / "piece.parquet").names
    assert {"id", "sigma", "dir_C"} <= set(names)


def test_a_bad_observation_in_any_piece_is_named_by_its_row_and_nothing_is_written(tmp_path):
    ds = _balls()
    d = ds.to_dict()
    d["observations"][23]["axes"]["X"] = 2e5
    src = tmp_path / "bad.json"
    src.write_text(json.dumps(d))
    with pytest.raises(ValueError) as whole:
        fivecal.load_dataset(src)
    assert "observations[23].axes.X" in str(whole.value)
    for dst in ("out.parquet", "out.json"):
        with pytest.raises(ValueError) as piece:
            columnar.convert(src, tmp_path / dst, rows=5, stream_bytes=0)
        assert str(piece.value) == str(whole.value)
        assert not os.path.exists(tmp_path / dst)
        assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]
    assert main(["convert", str(src), str(tmp_path / "out.parquet")]) == 2


def test_a_file_that_does_not_stream_converts_whole(tmp_path):
    # The head after the observations, a string beyond ASCII: the whole load.
    ds = _balls()
    d = ds.to_dict()
    src = tmp_path / "tail.json"
    src.write_text(json.dumps({"observations": d["observations"], **{k: v for k, v in d.items() if k != "observations"}}))
    columnar.convert(src, tmp_path / "a.parquet", rows=4, stream_bytes=0)
    columnar.convert(src, tmp_path / "b.parquet", rows=4, stream_bytes=1 << 40)
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()
    d["observations"][30]["id"] = "ré"
    src.write_text(json.dumps(d))
    columnar.convert(src, tmp_path / "c.parquet", rows=4, stream_bytes=0)
    assert columnar.read_parquet(tmp_path / "c.parquet").observations[30]["id"] == "ré"


def _warnings_of_load_and_streamed_convert(tmp_path, name):
    """The warnings of loading <name>.json whole, and of converting it to
    Parquet in pieces of 10 rows."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fivecal.load_dataset(tmp_path / f"{name}.json")
        whole = [str(x.message) for x in caught]
        caught.clear()
        columnar.convert(tmp_path / f"{name}.json", tmp_path / f"{name}.parquet", rows=10, stream_bytes=0)
        return whole, [str(x.message) for x in caught]


def test_the_plausibility_checks_see_the_whole_file_not_a_piece(tmp_path):
    # A slow rotary sweep: its first samples alone (B within 2 pi, spanning
    # more than 1, not round) look like radians, the whole sweep does not:
    # the streamed convert warns as the whole load does (not at all).
    m = tango.hu40t_machine()
    n = 400
    b = np.linspace(0.123, 89.9, n)
    axes = {"X": np.zeros(n), "Y": np.zeros(n), "Z": np.full(n, -20.0), "B": b, "C": np.zeros(n), "S": np.zeros(n)}
    ds = fivecal.ball_dataset(m, "ball3d", axes, [0, 0, 100], [100, 0, 0], measured=np.zeros((n, 3)), setup="R1")
    fivecal.save_dataset(ds, tmp_path / "sweep.json")
    assert looks_like_radians(b[:10]) and not looks_like_radians(b)  # a piece would mislead
    whole, piece = _warnings_of_load_and_streamed_convert(tmp_path, "sweep")
    assert piece == whole == []
    # and a trace in radians is warned about once, as by the whole load
    axes["B"] = np.radians(b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = fivecal.ball_dataset(m, "ball3d", axes, [0, 0, 100], [100, 0, 0], measured=np.zeros((n, 3)),
                                  setup="R1")
        fivecal.save_dataset(ds, tmp_path / "rad.json")
    whole, piece = _warnings_of_load_and_streamed_convert(tmp_path, "rad")
    assert len(whole) == 1 and piece == whole
