"""Long traces held as column blocks (dataset.h TraceBlock, docs/formats.md
"In memory: column blocks"): the same data as blocks and as one object per
sample give the same fit bit for bit, load and save keep the file's order,
ids and values, messages name the file row, and a Parquet trace is loaded
with no per-sample object."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

import fivecal
from fivecal import _core
from fivecal.dataset import Dataset

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TRUE = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
TABLE = [50.0, 0.0, 80.0]


def _axes(m, n, seed):
    rng = np.random.default_rng(seed)
    tilt, turn = np.radians(rng.uniform(0, 60, n)), np.radians(rng.uniform(0, 360, n))
    tool_axes = np.column_stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), np.cos(tilt)])
    return m.inverse(np.tile(TABLE, (n, 1)), tool_axes), rng


def _trace(m, kind, n, seed=3, directions=None, sigma=None):
    """A simulated R-test (ball3d) or ball-bar (dbb, the bar from the table
    ball along X) trace of the machine with errors TRUE, 0.5 um noise."""
    axes, rng = _axes(m, n, seed)
    p = m.tool_point(axes, TRUE)
    if kind == "ball3d":
        meas = p - np.array(TABLE) + rng.normal(0, 5e-4, (n, 3))
        return fivecal.ball_dataset(m, "ball3d", axes, m.tip, TABLE, measured=meas, setup="R1",
                                    directions=directions, sigma=sigma)
    centre = np.array(TABLE) - [100.0, 0.0, 0.0]
    reading = np.linalg.norm(p - centre, axis=1) - 100.0 + rng.normal(0, 5e-4, n)
    return fivecal.ball_dataset(m, "dbb", axes, m.tip, centre, length=100.0, readings=reading, setup="A1",
                                directions=directions, sigma=sigma)


def _objects(ds):
    """The same dataset with one object per sample (the blocks expanded)."""
    return Dataset(ds._core.expanded())


def _same_result(a, b):
    assert a.fit_path == b.fit_path and a.verdict == b.verdict and a.estimated == b.estimated
    for k in a.estimated:
        assert a.values[k] == b.values[k] and a.std[k] == b.std[k], k
    assert a.chi2 == b.chi2 and a.rms == b.rms
    assert a.residual_units == b.residual_units
    np.testing.assert_array_equal(a.residuals, b.residuals)
    ja, jb = json.loads(a.to_json()), json.loads(b.to_json())
    for j in (ja, jb):
        j.pop("timing", None)
        j.get("fit", {}).pop("seconds", None)
    assert ja == jb


@pytest.mark.parametrize("kind", ["ball3d", "dbb"])
@pytest.mark.parametrize("path", ["normal_equations", "dense"])
def test_blocks_and_objects_give_the_same_fit(c600u, kind, path):
    n = 6000
    ds = _trace(c600u, kind, n, directions={"C": np.where(np.arange(n) % 3, 1, -1)},
                sigma=np.where(np.arange(n) % 5, 5e-4, 7e-4))
    objects = _objects(ds)
    assert (ds._core.num_block_rows, objects._core.num_block_rows) == (n, 0)
    assert ds.to_dict() == objects.to_dict()
    est = list(TRUE) if kind == "ball3d" else ["EA0C", "EB0C"]
    a = fivecal.identify(ds, est, fit_path=path, num_threads=2)
    b = fivecal.identify(objects, est, fit_path=path, num_threads=2)
    assert a.fit_path == path
    _same_result(a, b)
    if kind == "ball3d":
        # a true answer, not only the same one
        assert a.verdict == "ok"
        for k in TRUE:
            assert abs(a.values[k] - TRUE[k]) < 4 * a.std[k], k


def test_a_long_trace_fits_on_its_blocks_and_recovers_the_truth(c600u):
    ds = _trace(c600u, "ball3d", 120_000, seed=11)
    assert ds._core.num_blocks == 1
    before = _core.prepared_rows(reset_peak=True)
    r = fivecal.identify(ds, list(TRUE), num_threads=2)
    assert _core.prepared_rows()["peak"] == before["alive"]
    assert r.fit_path == "normal_equations" and r.verdict == "ok"
    for k in TRUE:
        assert abs(r.values[k] - TRUE[k]) < 4 * r.std[k], k
    _same_result(r, fivecal.identify(_objects(ds), list(TRUE), num_threads=2))


def _mixed():
    """Facet touches with ball samples before, between and after them (a
    mounting changing every row before), with ids: the balls after the last
    touch are blocks, the others objects."""
    from fivecal.procedures import tango

    d = tango.hu40t_dataset(seed=1).to_dict()
    touches = d["observations"][:12]
    rng = np.random.default_rng(5)

    def balls(n, kind, tag):
        out = []
        for i in range(n):
            axes = {"X": float(rng.uniform(-50, 50)), "Y": float(rng.uniform(-50, 50)),
                    "Z": float(rng.uniform(-50, 0)), "B": float(rng.uniform(0, 90)),
                    "C": float(rng.uniform(-180, 180)), "S": 0.0}
            o = {"type": kind, "setup": "R1" if kind == "ball3d" else "A1", "axes": axes,
                 "tool_ball": [0.0, 0.0, 100.0], "table_ball": [100.0, 0.0, 0.0 if n > 10 else float(i % 2)]}
            if kind == "ball3d":
                o["measured"] = [float(x) for x in rng.normal(0, 0.01, 3)]
            else:
                o["reading"], o["length"] = float(rng.normal(0, 0.01)), 150.0
            if i % 3:
                o["id"] = f"{tag}{i}"
            if i % 4 == 1:
                o["sigma"] = 0.002
            if i % 5 == 2:
                o["direction"] = {"C": 1}
            out.append(o)
        return out

    d["observations"] = (balls(5, "ball3d", "a") + touches[:6] + balls(4, "dbb", "b") + touches[6:]
                         + balls(70, "ball3d", "c") + balls(80, "dbb", "d") + balls(75, "ball3d", "e"))
    return Dataset.from_dict(d), 225


def test_parquet_and_json_round_trips_keep_order_ids_and_bytes(c600u, tmp_path):
    from fivecal.io import columnar

    ds = _trace(c600u, "ball3d", 3000, directions={"C": np.where(np.arange(3000) % 2, 1, -1)})
    mixed, tail = _mixed()
    for name, d, blocks in (("trace", ds, 3000), ("mixed", mixed, 0)):
        objects = _objects(d)
        for ext in ("json", "parquet"):
            a, b = tmp_path / f"{name}_blocks.{ext}", tmp_path / f"{name}_objects.{ext}"
            fivecal.save_dataset(d, a)
            fivecal.save_dataset(objects, b)
            assert a.read_bytes() == b.read_bytes(), (name, ext)
            back = fivecal.load_dataset(a)
            assert back.to_dict() == objects.to_dict(), (name, ext)
            if ext == "parquet":
                # the trailing run of ball rows (after the last touch) is columns
                assert back._core.num_block_rows == (3000 if name == "trace" else tail)
                fivecal.save_dataset(back, tmp_path / f"{name}_again.{ext}")
                assert (tmp_path / f"{name}_again.{ext}").read_bytes() == a.read_bytes()
    # a JSON load packed into blocks afterwards keeps the order too
    m = Dataset.from_dict(mixed.to_dict())
    assert m._core.pack_traces() == tail and m._core.num_block_rows == tail
    assert m.to_dict() == mixed.to_dict()
    assert columnar.dataset_columns(m).equals(columnar.dataset_columns(mixed))


def _parquet(c600u, tmp_path, edit=None, n=400):
    ds = _trace(c600u, "ball3d", n, directions={"C": np.ones(n, int)})
    path = tmp_path / "t.parquet"
    fivecal.save_dataset(ds, path)
    if edit:
        t = pq.read_table(path)
        cols = {c: t.column(c).to_numpy(zero_copy_only=False).copy() for c in t.schema.names}
        edit(cols)
        t2 = pa.table({c: pa.array(v, type=t.schema.field(c).type) for c, v in cols.items()})
        pq.write_table(t2.replace_schema_metadata(t.schema.metadata), path)
    return path


@pytest.mark.parametrize("column,value,message", [
    ("measured_y", np.nan, r"ball3d row 17, column measured_y: NaN"),
    ("X", np.inf, r"ball3d row 17, column X: not a finite number"),
    ("dir_C", 2, r"ball3d row 17, column dir_C: must be -1, 0 or \+1"),
    ("measured_x", 2e5, r"ball3d row 17, column measured\[0\]: 200000 mm is implausible"),
])
def test_a_bad_value_in_a_parquet_block_names_row_and_column(c600u, tmp_path, column, value, message):
    def edit(cols):
        cols[column][17] = value

    with pytest.raises(ValueError, match=message):
        fivecal.load_dataset(_parquet(c600u, tmp_path, edit))


def test_readings_in_um_in_a_parquet_block_are_refused_naming_the_row(c600u, tmp_path):
    def edit(cols):
        cols["measured_x"][23] = 1200.0  # um written where mm are expected

    with pytest.raises(ValueError, match=r"observations\[23\]\.measured"):
        fivecal.load_dataset(_parquet(c600u, tmp_path, edit))


def test_a_parquet_trace_is_loaded_into_blocks_without_an_object_per_sample(c600u, tmp_path):
    path = _parquet(c600u, tmp_path, n=50_000)
    ds = fivecal.load_dataset(path)
    assert ds._core.num_observations == ds._core.num_block_rows == 50_000
    assert ds._core.num_blocks == 1


def test_a_mounting_changing_every_few_rows_stays_objects(tmp_path):
    # Blocks of a few rows would cost more than objects (and a search per
    # row): the loader keeps such rows as objects, in the same order.
    from test_columnar import _balls

    ds = _balls()
    fivecal.save_dataset(ds, tmp_path / "b.parquet")
    back = fivecal.load_dataset(tmp_path / "b.parquet")
    assert back._core.num_block_rows == 0
    assert back.to_dict() == ds.to_dict()


def test_subset_of_a_block_dataset(c600u):
    ds = _trace(c600u, "dbb", 200, directions={"C": np.where(np.arange(200) % 2, 1, -1)})
    objects = _objects(ds)
    for idx in ([5, 6, 7, 8], [9, 3, 150, 151, 152], [], list(range(200))):
        a, b = ds.subset(idx), objects.subset(idx)
        assert a.to_dict() == b.to_dict(), idx
        assert a._core.num_observations == len(idx)
    assert ds.subset([5, 6, 7, 8])._core.num_block_rows == 4
    with pytest.raises(ValueError, match="out of range"):
        ds.subset([200])


def test_a_bad_sample_of_a_block_is_named_by_its_index(c600u):
    sigma = np.full(300, 5e-4)
    sigma[7] = 0.0
    with pytest.raises(ValueError, match=r"observations\[7\]\.sigma"):
        _trace(c600u, "ball3d", 300, sigma=sigma)


def test_the_procedures_see_block_rows(c600u):
    # An R-test evaluation (a procedure on Observation objects, which
    # expands the blocks at its entry) of a trace held as blocks is that of
    # the same trace as objects.
    ds = _trace(c600u, "ball3d", 500)
    a = _core.rtest(ds._core, identify=False)
    b = _core.rtest(_objects(ds)._core, identify=False)
    assert [g.observations for g in a.tests] == [g.observations for g in b.tests]
    assert sum(len(g.observations) for g in a.tests) == 500
    for ga, gb in zip(a.tests, b.tests):
        np.testing.assert_array_equal(ga.deviations, gb.deviations)
