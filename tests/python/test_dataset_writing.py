"""Writing datasets (issue 30, "save_dataset and convert stream"): the core
writes the JSON file piece by piece and the Parquet file block by block
through files.atomic_output. Saved and loaded back, every kind's dataset is
the same (set-ups, noise, ids, instruments, set-up uncertainty), in both
formats and whatever the piece size; a write that fails midway leaves the
target as it was and no temporary file; bad input is refused naming the
observation or row, before anything is written."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

import fivecal
from fivecal import _core, files
from fivecal.cli import main

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
from fivecal.io import columnar  # noqa: E402
from test_columnar import DATASETS  # noqa: E402  (one dataset per registered kind)


@pytest.fixture(scope="module", params=sorted(DATASETS))
def dataset(request):
    return DATASETS[request.param]()


@pytest.mark.parametrize("fmt", ["json", "parquet"])
def test_save_then_load_is_the_same_dataset_for_every_kind(dataset, fmt, tmp_path):
    # The core's own JSON of a dataset is canonical (sorted keys, every
    # number exact): equal text is the same machine, artefact, observations,
    # set-ups, noise and ids, to the last bit.
    path = tmp_path / f"ds.{fmt}"
    fivecal.save_dataset(dataset, path)
    back = fivecal.load_dataset(path)
    assert back._core.to_json() == dataset._core.to_json()
    assert back.to_dict() == dataset.to_dict()


def test_small_pieces_and_row_groups_give_the_same_files(tmp_path):
    ds = DATASETS["dbb_ball3d"]()
    pieces = []
    ds._core.write_json(pieces.append, chunk_bytes=500)
    whole = []
    ds._core.write_json(whole.append)
    assert len(pieces) > 10 and len(whole) == 1      # written as it goes, not at the end
    assert b"".join(pieces) == whole[0]
    assert max(len(p) for p in pieces[:-1]) < 500 + 1000   # a piece is cut after the line that fills it
    columnar.write_parquet(ds, tmp_path / "small.parquet", rows=7)
    assert pq.ParquetFile(tmp_path / "small.parquet").metadata.num_row_groups == math.ceil(len(ds) / 7)
    assert fivecal.load_dataset(tmp_path / "small.parquet")._core.to_json() == ds._core.to_json()
    columnar.write_parquet(ds, tmp_path / "one.parquet")
    assert pq.read_table(tmp_path / "small.parquet").equals(pq.read_table(tmp_path / "one.parquet"))


def test_set_up_uncertainty_and_instrument_noise_survive_both_formats(tmp_path):
    # Parquet used to drop the declared set-up uncertainty (it was not in the metadata).
    d = DATASETS["point"]().to_dict()
    d["setup_uncertainty"] = {"instrument.T1.x": 0.5, "class:instrument_angle": 0.01}
    ds = fivecal.Dataset.from_dict(d)
    for name in ("u.json", "u.parquet"):
        fivecal.save_dataset(ds, tmp_path / name)
        back = fivecal.load_dataset(tmp_path / name)
        assert back.to_dict()["setup_uncertainty"] == d["setup_uncertainty"]
        assert back.to_dict()["instruments"] == d["instruments"]
        assert back._core.to_json() == ds._core.to_json()


def test_json_file_is_the_head_then_one_observation_per_line(tmp_path):
    ds = DATASETS["dbb_ball3d"]()
    fivecal.save_dataset(ds, tmp_path / "b.json")
    text = (tmp_path / "b.json").read_text()
    lines = text.splitlines()
    first = lines.index(' "observations": [') + 1
    rows = lines[first:first + len(ds)]
    assert lines[first + len(ds):] == [" ]", "}"]
    for line, o in zip(rows, ds.observations):
        assert line.startswith('  {"type": ')
        assert json.loads(line.rstrip(",")) == o
    # axes as people write them: linear, rotary, spindle
    assert list(json.loads(rows[0].rstrip(","))["axes"]) == ["X", "Y", "Z", "B", "C", "S"]
    assert json.loads(text) == ds.to_dict()


def test_parquet_columns_are_the_ones_the_loader_reads(tmp_path):
    ds = DATASETS["dbb_ball3d"]()
    names = columnar.dataset_columns(ds).schema.names
    assert names[:8] == ["type", "id", "X", "Y", "Z", "B", "C", "S"]
    assert names[-4:] == ["sigma", "sigma_x", "sigma_y", "sigma_z"]
    w = _core.ColumnWriter(ds._core)
    blocks = w.write(0, w.rows)
    cols = dict(zip([n for n, _ in w.columns], blocks))
    # a ball3d row has no reading: null, not 0
    values, valid = cols["reading"]
    assert valid is not None and not valid[1] and math.isnan(values[1])
    assert dict(w.columns)["dir_C"] == "int8"
    with pytest.raises(ValueError, match="rows 5 to 3"):
        w.write(5, 3)


# ---------------------------------------------------------------------------
# interrupted writes
# ---------------------------------------------------------------------------

def _failing_after(monkeypatch, calls: int, exc):
    real = files._Output.write
    seen = []

    def write(self, data):
        seen.append(len(data))
        if len(seen) > calls:
            raise exc
        return real(self, data)

    monkeypatch.setattr(files._Output, "write", write)
    return seen


def _long_trace(n=60_000):
    m = fivecal.Machine.load(os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines",
                                          "hu40t.json"))
    t = np.arange(n) * 1e-3
    axes = {"X": 100 * np.cos(t), "Y": 100 * np.sin(t), "Z": -50 + 10 * np.sin(0.1 * t),
            "B": 30 + 30 * np.sin(0.1 * t), "C": np.degrees(t) % 360 - 180, "S": np.zeros(n)}
    return fivecal.ball_dataset(m, "ball3d", axes, [0, 0, 100], [100, 0, 0],
                                measured=np.random.default_rng(1).normal(0, 0.002, (n, 3)), setup="R1")


@pytest.mark.parametrize("name", ["trace.json", "trace.parquet"])
@pytest.mark.parametrize("exc", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_a_write_that_fails_midstream_leaves_the_target_untouched(name, exc, tmp_path, monkeypatch):
    ds = _long_trace()
    target = tmp_path / name
    target.write_bytes(b"the previous file")
    seen = _failing_after(monkeypatch, 2, exc)
    if name.endswith(".parquet"):
        monkeypatch.setattr(columnar, "_BATCH_ROWS", 10_000)
    with pytest.raises(ValueError if isinstance(exc, OSError) else KeyboardInterrupt) as e:
        fivecal.save_dataset(ds, target)
    assert len(seen) == 3                     # it failed midway, after two pieces were written
    if isinstance(exc, OSError):
        assert str(target) in str(e.value) and "No space left" in str(e.value)
    assert target.read_bytes() == b"the previous file"
    assert os.listdir(tmp_path) == [name]     # no temporary file left beside it
    monkeypatch.undo()
    fivecal.save_dataset(ds, target)          # and the same write, undisturbed, succeeds
    assert len(fivecal.load_dataset(target)) == len(ds)


def test_convert_that_fails_midstream_creates_nothing(tmp_path, monkeypatch, capsys):
    src = tmp_path / "t.json"
    fivecal.save_dataset(_long_trace(20_000), src)
    _failing_after(monkeypatch, 1, OSError(28, "No space left on device"))
    monkeypatch.setattr(columnar, "_BATCH_ROWS", 5_000)
    assert main(["convert", str(src), str(tmp_path / "t.parquet")]) == 2
    assert "No space left" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["t.json"]


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------

def test_save_dataset_refuses_a_bad_observation_by_index_and_writes_nothing(tmp_path):
    d = DATASETS["dbb_ball3d"]().to_dict()
    d["observations"][3]["axes"]["X"] = "12,5"
    for name in ("a.json", "a.parquet"):
        with pytest.raises(ValueError, match=r"observations\[3\]\.axes\.X"):
            fivecal.save_dataset(d, tmp_path / name)
    assert os.listdir(tmp_path) == []


def test_convert_names_the_bad_observation_of_a_json_input(tmp_path, capsys):
    d = DATASETS["dbb_ball3d"]().to_dict()
    d["observations"][5]["tool_ball"] = [0, 0]
    src = tmp_path / "bad.json"
    src.write_text(json.dumps(d))
    assert main(["convert", str(src), str(tmp_path / "out.parquet")]) == 2
    err = capsys.readouterr().err
    assert "observations[5]" in err and "tool_ball" in err
    assert sorted(os.listdir(tmp_path)) == ["bad.json"]


def test_convert_names_the_bad_row_of_a_parquet_input(tmp_path, capsys):
    ds = _long_trace(50)
    t = columnar.dataset_columns(ds)
    x = t.column("measured_y").to_numpy(zero_copy_only=False).copy()
    x[7] = np.nan
    t = t.set_column(t.schema.get_field_index("measured_y"), "measured_y", pa.array(x))
    src = tmp_path / "bad.parquet"
    pq.write_table(t.replace_schema_metadata(columnar.dataset_columns(ds).schema.metadata), src)
    out = tmp_path / "out.json"
    out.write_text("kept")
    assert main(["convert", str(src), str(out)]) == 2
    err = capsys.readouterr().err
    assert "row 7" in err and "measured_y" in err
    assert out.read_text() == "kept"


def test_convert_refuses_to_write_over_its_input(tmp_path, capsys):
    src = tmp_path / "a.parquet"
    fivecal.save_dataset(DATASETS["dbb_ball3d"](), src)
    before = src.read_bytes()
    assert main(["convert", str(src), str(src)]) == 2
    assert "input" in capsys.readouterr().err
    assert src.read_bytes() == before


def test_json_parquet_json_through_the_cli_is_identical(tmp_path):
    ds = _long_trace(5_000)
    fivecal.save_dataset(ds, tmp_path / "a.json")
    assert main(["convert", str(tmp_path / "a.json"), str(tmp_path / "a.parquet")]) == 0
    assert main(["convert", str(tmp_path / "a.parquet"), str(tmp_path / "b.json")]) == 0
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
