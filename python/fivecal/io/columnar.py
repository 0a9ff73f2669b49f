"""Columnar datasets: a dataset as one Parquet file (docs/formats.md,
"Columnar datasets (Parquet)").

One row per observation, in the dataset's order, with a ``type`` column and
the columns of every kind the file holds (null where a row's kind has no such
key); axes by axis letter (``X``, ``B``, ...), backlash directions as
``dir_X``, 3-vectors as ``<key>_x|y|z``, noise as ``sigma`` (or ``sigma_1``
... one per residual row): the column names of fivecal's observation tables. The machine, probe, artefact,
instruments and units are the file's key-value metadata (``fivecal.*``, JSON
strings). Loading hands Arrow's buffers to the C++ core (no Python per row);
writing goes through the dataset's dicts.

Needs pyarrow (``pip install 'fivecal[arrow]'``); the rest of fivecal does not.
"""
from __future__ import annotations

import json
import os
from typing import Iterable, Mapping, Union

import numpy as np

from .. import _core, files, plausibility
from ..dataset import Dataset, load_dataset, register_format
from .. import schema

__all__ = ["FORMAT_VERSION", "UNITS", "is_parquet", "read_parquet", "iter_datasets", "write_parquet",
           "json_to_parquet", "parquet_to_json", "dataset_columns"]

FORMAT_VERSION = "1"
# What the numbers of a fivecal file are in (docs/formats.md, "Units"): a file
# declaring anything else is refused rather than misread.
UNITS = {"length": "mm", "rotary_axis": "deg", "angle": "rad"}
_MAGIC = b"PAR1"
_HEAD_KEYS = ("machine", "probe", "artefact", "instruments")
# Rows per batch handed to the core: bounds the Arrow memory held at once.
_BATCH_ROWS = 1 << 18


def _pyarrow():
    try:
        import pyarrow
        import pyarrow.compute  # noqa: F401
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        raise ValueError("Parquet datasets need pyarrow, which is not installed: "
                         "pip install 'fivecal[arrow]'") from None
    return pyarrow


def is_parquet(path: Union[str, os.PathLike]) -> bool:
    """Whether the file starts with Parquet's magic bytes (whatever its name)."""
    try:
        with open(path, "rb") as f:
            return f.read(4) == _MAGIC
    except OSError:
        return False


# --------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------

def _flatten(o: Mapping, axis_letters: str, numbered=frozenset()) -> dict:
    """One observation dict as {column: value}: the names of columns.h, which
    are those of fivecal's observation tables (``fivecal import fivecal``)."""
    out = {}
    for key, v in o.items():
        if key == "axes":
            out.update(v)
        elif key == "direction":
            out.update({f"dir_{a}": d for a, d in v.items()})
        elif key == "sigma" and not isinstance(v, list):
            out["sigma"] = v
        elif isinstance(v, list):
            # As the CSV tables name them: three values as a vector, a key
            # with lists of another length in any row numbered from 1.
            if len(v) != 3 and key != "sigma":
                raise ValueError(f"{key}: a list of {len(v)} values has no column form (3-vectors only)")
            if key in numbered:
                out.update({f"{key}_{r + 1}": x for r, x in enumerate(v)})
            else:
                out.update({f"{key}_{c}": x for c, x in zip("xyz", v)})
        elif isinstance(v, dict):
            if not key.endswith("_axes"):
                raise ValueError(f"{key}: only a set of axis commands (<name>_axes) has a column form")
            for a, x in v.items():
                if a not in axis_letters:
                    raise ValueError(f"{key}.{a}: not an axis letter of the machine")
                out[f"{key[:-len('_axes')]}_{a}"] = x
        elif isinstance(v, bool):
            raise ValueError(f"{key}: true/false has no column form")
        else:
            out[key] = v
    return out


def dataset_columns(ds) -> "pyarrow.Table":
    """The dataset (a Dataset or a dict in the dataset format) as an Arrow
    table with the fivecal metadata (what :func:`write_parquet` writes)."""
    pa = _pyarrow()
    d = Dataset.from_dict(ds).to_dict()
    # Linear axes, then rotary, then the spindle: the order people write them in.
    axis_letters = sorted(d["machine"]["axes"], key=lambda a: ("XYZABCS".find(a) % 8, a))
    letters = "".join(axis_letters)
    numbered = frozenset(k for o in d["observations"] for k, v in o.items() if isinstance(v, list) and len(v) != 3)
    rows = [_flatten(o, letters, numbered) for o in d["observations"]]
    n = len(rows)
    # Column order: type, id, the axes in machine order, the directions, then
    # each kind's keys as they first appear, the noise last.
    names = {}
    for r in rows:
        for k in r:
            names.setdefault(k, None)
    first = ["type"] + (["id"] if "id" in names else [])
    axes = [a for a in axis_letters if a in names]
    dirs = [f"dir_{a}" for a in axis_letters if f"dir_{a}" in names]
    sig = sorted(k for k in names if k == "sigma" or k.startswith("sigma_"))
    rest = [k for k in names if k not in set(first) | set(axes) | set(dirs) | set(sig)]
    arrays, fields = [], []
    for name in first + axes + dirs + rest + sig:
        vals = [r.get(name) for r in rows]
        kinds = {type(v) for v in vals if v is not None}
        if name.startswith("dir_"):
            # Absent = 0 (no backlash term), as the loader reads it.
            arr = pa.array([0 if v is None else v for v in vals], pa.int8())
        elif kinds <= {str}:
            arr = pa.array(vals, pa.string())
        elif kinds <= {int, float}:
            arr = pa.array([None if v is None else float(v) for v in vals], pa.float64())
        else:
            raise ValueError(f"column {name}: both text and numbers")
        arrays.append(arr)
        fields.append(pa.field(name, arr.type))
    meta = {"fivecal.format": "dataset", "fivecal.version": FORMAT_VERSION,
            "fivecal.units": json.dumps(UNITS)}
    for k in _HEAD_KEYS:
        if k in d:
            meta[f"fivecal.{k}"] = json.dumps(d[k])
    schema = pa.schema(fields, metadata={k.encode(): v.encode() for k, v in meta.items()})
    return pa.Table.from_arrays(arrays, schema=schema) if n else schema.empty_table()


def write_parquet(ds, path: Union[str, os.PathLike], compression: str = "zstd") -> None:
    """Write a dataset (a Dataset or a dict in the dataset format, validated
    first) as a Parquet file (docs/formats.md, "Columnar datasets")."""
    _pyarrow()
    # Written whole and renamed into place, as every fivecal output.
    files.write_parquet_table(path, dataset_columns(ds), compression=compression)


# --------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------

def _metadata(pf, path: str) -> dict:
    raw = pf.schema_arrow.metadata or {}
    meta = {k.decode("utf-8", "replace"): v for k, v in raw.items()}
    if not any(k.startswith("fivecal.") for k in meta):
        raise ValueError(f"{path}: a Parquet file without fivecal metadata (fivecal.machine, ...): "
                         "not a fivecal dataset (write one with fivecal convert or fivecal.io.columnar.write_parquet)")
    if meta.get("fivecal.format", b"dataset") not in (b"dataset",):
        raise ValueError(f"{path}: metadata fivecal.format: {meta['fivecal.format'].decode(errors='replace')!r} "
                         "is not a dataset")
    if meta.get("fivecal.version", FORMAT_VERSION.encode()) != FORMAT_VERSION.encode():
        raise ValueError(f"{path}: metadata fivecal.version: "
                         f"{meta['fivecal.version'].decode(errors='replace')!r}: this fivecal reads version "
                         f"{FORMAT_VERSION}")
    head = {}
    for k in ("units",) + _HEAD_KEYS:
        v = meta.get(f"fivecal.{k}")
        if v is None:
            continue
        try:
            head[k] = json.loads(v)
        except (ValueError, UnicodeDecodeError) as e:
            raise ValueError(f"{path}: metadata fivecal.{k}: not valid JSON ({e})") from None
    if "machine" not in head:
        raise ValueError(f"{path}: metadata fivecal.machine missing (the machine the data was taken on, "
                         "as JSON)")
    units = head.pop("units", None)
    if units is not None and units != UNITS:
        raise ValueError(f"{path}: metadata fivecal.units: {json.dumps(units)}; fivecal files are in "
                         f"{json.dumps(UNITS)} (convert the columns first)")
    return head


def _number(pa, arr, name: str, kind: str):
    t = arr.type
    if not (pa.types.is_floating(t) or pa.types.is_integer(t)):
        return None
    valid = None
    if arr.null_count:
        valid = arr.is_valid().to_numpy(zero_copy_only=False)
    if pa.types.is_float64(t) and not arr.null_count:
        values = arr.to_numpy(zero_copy_only=True)  # Arrow's own buffer
    else:
        values = arr.cast(pa.float64()).to_numpy(zero_copy_only=False)
    return values, valid


def _is_text(pa, t) -> bool:
    # string_view exists from pyarrow 16 on; fivecal[arrow] asks for >= 14
    view = getattr(pa.types, "is_string_view", lambda _: False)
    return pa.types.is_string(t) or pa.types.is_large_string(t) or view(t)


def _text(pa, arr):
    t = arr.type
    if pa.types.is_dictionary(t):
        arr = arr.dictionary_decode()
        t = arr.type
    if not _is_text(pa, t):
        return None
    if not pa.types.is_large_string(t):
        arr = arr.cast(pa.large_string())
    bufs = arr.buffers()
    n = len(arr)
    offsets = np.frombuffer(bufs[1], dtype=np.int64)[arr.offset:arr.offset + n + 1]
    data = np.frombuffer(bufs[2], dtype=np.uint8) if bufs[2] is not None else np.zeros(0, np.uint8)
    valid = arr.is_valid().to_numpy(zero_copy_only=False) if arr.null_count else None
    return offsets, data, valid


def _add(loader, pa, batch, kind: str, positions, mixed: bool, path: str) -> None:
    numbers, strings = {}, {}
    for name, arr in zip(batch.schema.names, batch.columns):
        if name == "type":
            continue
        # In a file of several kinds, a column no row of this kind fills
        # belongs to another kind.
        if mixed and arr.null_count == len(arr):
            continue
        num = _number(pa, arr, name, kind)
        if num is not None:
            numbers[name] = num
            continue
        txt = _text(pa, arr)
        if txt is not None:
            strings[name] = txt
            continue
        raise ValueError(f"{path}: {kind}: column {name}: type {arr.type} is neither numbers nor text")
    loader.add(kind, batch.num_rows, numbers, strings, positions)


def _open(path: str):
    """The file, its head as a core Dataset, its kinds and whether it mixes them."""
    pa = _pyarrow()
    import pyarrow.compute as pc
    import pyarrow.parquet as pq


    try:
        pf = pq.ParquetFile(path)
    except (pa.ArrowException, OSError) as e:
        if isinstance(e, FileNotFoundError):
            raise ValueError(f"{path}: cannot read dataset (no such file)") from None
        raise ValueError(f"{path}: not a readable Parquet file ({e})") from None
    names = pf.schema_arrow.names
    first = {}
    for i, name in enumerate(names):
        if name in first:
            # Arrow keeps both; every lookup by name below would see only one
            raise ValueError(f"{path}: column '{name}' appears twice (columns {first[name] + 1} and {i + 1}); "
                             "each column name once")
        first[name] = i
    head = _metadata(pf, path)
    schema.validate(dict(head, observations=[]), "dataset", path)
    try:
        core_head = _core.Dataset.from_json(json.dumps(dict(head, observations=[])), require_observations=False)
    except ValueError as e:
        raise ValueError(f"{path}: metadata: {e}") from None
    if "type" not in pf.schema_arrow.names:
        raise ValueError(f"{path}: column type missing (the observation kind of each row: "
                         f"{', '.join(k['name'] for k in _core.observation_kinds())})")
    try:
        types = pf.read(columns=["type"]).column("type")
    except pa.ArrowException as e:
        raise ValueError(f"{path}: not a readable Parquet file ({e})") from None
    if not (_is_text(pa, types.type) or pa.types.is_dictionary(types.type)):
        raise ValueError(f"{path}: column type: expected text (the observation kind), got {types.type}")
    if types.null_count:
        row = int(np.flatnonzero(types.is_null().to_numpy(zero_copy_only=False))[0])
        raise ValueError(f"{path}: row {row}, column type: null (every row names its observation kind)")
    kinds = pc.unique(types).to_pylist()
    known = [k["name"] for k in _core.observation_kinds()]
    for k in kinds:
        if k not in known:
            import difflib

            row = int(np.flatnonzero(pc.equal(types, k).to_numpy(zero_copy_only=False))[0])
            near = difflib.get_close_matches(k, known, n=1)
            raise ValueError(f"{path}: row {row}, column type: unknown observation type {k!r} "
                             f"({', '.join(known)})" + (f" (did you mean {near[0]!r}?)" if near else ""))
    return pf, core_head, kinds


def _load_batch(loader, pa, batch, kinds, offset: int, path: str) -> None:
    """Hands one record batch to the loader; `offset`: the loader position of
    its first row."""
    import pyarrow.compute as pc

    if batch.num_rows == 0:
        return
    if len(kinds) == 1:
        _add(loader, pa, batch, kinds[0], None, False, path)
        return
    t = batch.column("type")
    for kind in pc.unique(t).to_pylist():
        idx = np.flatnonzero(pc.equal(t, kind).to_numpy(zero_copy_only=False))
        sub = batch if len(idx) == batch.num_rows else batch.take(pa.array(idx))
        _add(loader, pa, sub, kind, np.ascontiguousarray(idx + offset, dtype=np.int64), True, path)


def read_parquet(path: Union[str, os.PathLike], check: bool = True):
    """Load a Parquet dataset (docs/formats.md, "Columnar datasets"): the
    observations go from Arrow's buffers into the C++ core, which checks them
    as it checks a JSON file. ValueError names the file, and the kind, row and
    column at fault. ``check``: run the plausibility checks (units) as
    :func:`fivecal.load_dataset` does."""
    path = os.fspath(path)
    try:
        pa = _pyarrow()
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    pf, core_head, kinds = _open(path)
    loader = _core.ColumnLoader(core_head, pf.metadata.num_rows)
    start = 0
    try:
        for batch in pf.iter_batches(batch_size=_BATCH_ROWS):
            _load_batch(loader, pa, batch, kinds, start, path)
            start += batch.num_rows
        core = loader.finish()
    except pa.ArrowException as e:
        raise ValueError(f"{path}: not a readable Parquet file ({e})") from None
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    ds = Dataset(core)
    if check:
        plausibility.check_loaded(ds, where=path)
    return ds


def iter_datasets(path: Union[str, os.PathLike], rows: int = 1_000_000) -> Iterable:
    """The Parquet dataset in consecutive pieces of at most ``rows``
    observations, each a :class:`fivecal.Dataset` with the file's machine,
    artefact and instruments: a trace too long to hold whole (10^7 samples
    are about 6 GB loaded) read piece by piece. Messages name the row of the
    file."""
    path = os.fspath(path)
    try:
        pa = _pyarrow()
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    if rows < 1:
        raise ValueError(f"rows: expected a positive number of observations per piece, got {rows}")
    pf, core_head, kinds = _open(path)
    start = 0
    batches = pf.iter_batches(batch_size=int(rows))
    while True:
        try:
            batch = next(batches)
        except StopIteration:
            return
        except pa.ArrowException as e:
            raise ValueError(f"{path}: not a readable Parquet file ({e})") from None
        loader = _core.ColumnLoader(core_head, batch.num_rows, start)
        try:
            _load_batch(loader, pa, batch, kinds, 0, path)
            core = loader.finish(whole=False)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
        start += batch.num_rows
        # Nothing of this piece may stay referenced here while the next one is
        # read: two pieces in memory at once would double the peak.
        del loader, batch
        ds = Dataset(core)
        del core
        plausibility.check_loaded(ds, where=path)
        yield ds
        del ds


# --------------------------------------------------------------------------
# Conversion
# --------------------------------------------------------------------------

def json_to_parquet(src: Union[str, os.PathLike], dst: Union[str, os.PathLike]) -> None:
    """A JSON dataset file as a Parquet one (lossless: :func:`parquet_to_json`
    gives the same dataset back)."""
    write_parquet(load_dataset(src), dst)


def parquet_to_json(src: Union[str, os.PathLike], dst: Union[str, os.PathLike]) -> None:
    """A Parquet dataset file as a JSON one."""
    files.write_json(dst, read_parquet(src).to_dict())


# load_dataset and save_dataset read and write Parquet through this
register_format(is_parquet, read_parquet, (".parquet", ".pq"), write_parquet)
