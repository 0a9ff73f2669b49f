"""Columnar datasets: a dataset as one Parquet file (docs/formats.md,
"Columnar datasets (Parquet)").

One row per observation, in the dataset's order, with a ``type`` column and
the columns of every kind the file holds (null where a row's kind has no such
key); axes by axis letter (``X``, ``B``, ...), backlash directions as
``dir_X``, 3-vectors as ``<key>_x|y|z``, noise as ``sigma`` (or ``sigma_1``
... one per residual row): the column names of fivecal's observation tables. The machine, probe, artefact,
instruments and units are the file's key-value metadata (``fivecal.*``, JSON
strings). Loading hands Arrow's buffers to the C++ core (no Python per row);
writing takes the core's column buffers (ColumnWriter) block by block, one
row group each.

Needs pyarrow (``pip install 'fivecal[arrow]'``); the rest of fivecal does not.
"""
from __future__ import annotations

import json
import os
import stat
from typing import Iterable, Union

import numpy as np

from .. import _core, files, plausibility
from ..dataset import Dataset, load_dataset, register_format, write_json
from .. import schema

__all__ = ["FORMAT_VERSION", "UNITS", "is_parquet", "read_parquet", "iter_datasets", "write_parquet",
           "json_to_parquet", "parquet_to_json", "convert", "dataset_columns", "STREAM_BYTES"]

FORMAT_VERSION = "1"
# What the numbers of a fivecal file are in (docs/formats.md, "Units"): a file
# declaring anything else is refused rather than misread.
UNITS = {"length": "mm", "rotary_axis": "deg", "angle": "rad"}
_MAGIC = b"PAR1"
# What the file's metadata holds besides the format, version and units (the
# writer writes every key of the core's head; the reader reads these).
_HEAD_KEYS = ("machine", "probe", "artefact", "instruments", "setup_uncertainty")
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

def _bitmap(pa, valid):
    # Arrow's validity is a bit per row, least significant bit first.
    return None if valid is None else pa.py_buffer(np.packbits(valid, bitorder="little"))


def _arrow_schema(pa, writer, ds) -> "pyarrow.Schema":
    types = {"string": pa.string(), "float64": pa.float64(), "int8": pa.int8()}
    meta = {"fivecal.format": "dataset", "fivecal.version": FORMAT_VERSION,
            "fivecal.units": json.dumps(UNITS)}
    for k, v in ds._core.head().items():
        meta[f"fivecal.{k}"] = v
    return pa.schema([pa.field(name, types[t]) for name, t in writer.columns],
                     metadata={k.encode(): v.encode() for k, v in meta.items()})


def _batches(pa, writer, schema, rows: int, piece=None):
    """The dataset's rows (or, with ``piece``, that piece's rows, for a writer
    that has scanned it) as record batches of at most ``rows``, each built
    from the core's column buffers (no Python object per row)."""
    n = writer.rows if piece is None else len(piece)
    extra = () if piece is None else (piece._core,)
    for start in range(0, n, rows):
        stop = min(n, start + rows)
        arrays = []
        for field, col in zip(schema, writer.write(start, stop, *extra)):
            if pa.types.is_string(field.type):
                offsets, data, valid = col
                arrays.append(pa.StringArray.from_buffers(stop - start, pa.py_buffer(offsets), pa.py_buffer(data),
                                                          _bitmap(pa, valid)))
            else:
                values, valid = col
                arrays.append(pa.Array.from_buffers(field.type, stop - start,
                                                    [_bitmap(pa, valid), pa.py_buffer(values)]))
        yield pa.RecordBatch.from_arrays(arrays, schema=schema)


def dataset_columns(ds) -> "pyarrow.Table":
    """The dataset (a Dataset or a dict in the dataset format) as an Arrow
    table with the fivecal metadata (what :func:`write_parquet` writes),
    whole in memory: for a long trace, :func:`write_parquet` streams."""
    pa = _pyarrow()
    ds = Dataset.from_dict(ds)
    writer = _core.ColumnWriter(ds._core)
    schema = _arrow_schema(pa, writer, ds)
    return pa.Table.from_batches(list(_batches(pa, writer, schema, max(writer.rows, 1))), schema=schema)


def write_parquet(ds, path: Union[str, os.PathLike], compression: str = "zstd", rows: int = _BATCH_ROWS) -> None:
    """Write a dataset (a Dataset or a dict in the dataset format, validated
    first) as a Parquet file (docs/formats.md, "Columnar datasets"): one row
    group per ``rows`` observations, each built by the core from the dataset
    and written before the next (10^6 observations in seconds; no copy of
    the whole in memory). Atomic: a failure midway leaves ``path`` as it was."""
    pa = _pyarrow()
    if rows < 1:
        raise ValueError(f"rows: expected a positive number of observations per row group, got {rows}")
    ds = Dataset.from_dict(ds)
    writer = _core.ColumnWriter(ds._core)
    schema = _arrow_schema(pa, writer, ds)
    files.write_parquet_batches(path, schema, _batches(pa, writer, schema, int(rows)), compression=compression)


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


def iter_datasets(path: Union[str, os.PathLike], rows: int = 1_000_000, check: bool = True) -> Iterable:
    """The Parquet dataset in consecutive pieces of at most ``rows``
    observations, each a :class:`fivecal.Dataset` with the file's machine,
    artefact and instruments: a trace too long to hold whole (10^7 samples
    are about 6 GB loaded) read piece by piece. Messages name the row of the
    file. ``check``: run the plausibility checks (units) on each piece."""
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
        if check:
            plausibility.check_loaded(ds, where=path)
        yield ds
        del ds


# --------------------------------------------------------------------------
# Conversion
# --------------------------------------------------------------------------

def json_to_parquet(src: Union[str, os.PathLike], dst: Union[str, os.PathLike]) -> None:
    """A JSON dataset file as a Parquet one (lossless: :func:`parquet_to_json`
    gives the same dataset back), piece by piece (:func:`convert`)."""
    convert(src, dst, to_parquet=True)


def parquet_to_json(src: Union[str, os.PathLike], dst: Union[str, os.PathLike]) -> None:
    """A Parquet dataset file as a JSON one, piece by piece (:func:`convert`)."""
    if not is_parquet(src):
        read_parquet(src)  # says what the file is not
    convert(src, dst, to_parquet=False)


#: Files up to this size convert whole (they fit in memory; JSON text then
#: goes through the schema as :func:`fivecal.load_dataset` checks it).
STREAM_BYTES = schema.BIG_TEXT


class _Whole(Exception):
    """The input is of a layout the piece readers leave to the whole load
    (a JSON head after its observations, a string beyond ASCII, ...)."""


class _Restart(Exception):
    """A later piece has columns the first pieces lacked."""


def convert(src: Union[str, os.PathLike], dst: Union[str, os.PathLike], rows: int = _BATCH_ROWS,
            to_parquet: Union[bool, None] = None, stream_bytes: Union[int, None] = None) -> int:
    """Write dataset file ``src`` (JSON or Parquet, recognised by its
    content) as ``dst``: Parquet when ``to_parquet`` (by default: when its
    name ends in .parquet or .pq), else JSON; returns the number of
    observations. JSON to Parquet and Parquet to JSON go piece by piece
    (``rows`` observations, one row group, at a time: memory holds a piece,
    whatever the file's length) and write what :func:`fivecal.save_dataset`
    of the whole dataset writes, byte for byte; the checks are those of
    :func:`fivecal.load_dataset`, and a message is the whole load's (a
    failure converts the whole file again, which says what is wrong).
    Atomic: a failure leaves ``dst`` as it was. Files up to ``stream_bytes``
    (default :data:`STREAM_BYTES`), and a layout the piece readers do not
    take, convert whole."""
    src = os.fspath(src)
    if to_parquet is None:
        to_parquet = os.fspath(dst).lower().endswith((".parquet", ".pq"))
    if rows < 1:
        raise ValueError(f"rows: expected a positive number of observations per piece, got {rows}")
    from_parquet = is_parquet(src)
    limit = STREAM_BYTES if stream_bytes is None else stream_bytes
    try:
        st = os.stat(src)
        streams = stat.S_ISREG(st.st_mode) and st.st_size > limit and from_parquet != to_parquet
    except OSError:
        streams = False  # the whole load names the problem
    if streams:
        files.note_input(src)
        try:
            if to_parquet:
                return _stream_to_parquet(src, dst, rows)
            return _stream_to_json(src, dst, rows, from_parquet)
        except (_Whole, ValueError):
            # The whole convert decides: a file of another layout, and the
            # messages of a bad one (the schema's first, then the rows of the
            # file, then the output's), or a piece that failed for want of a
            # member the file gives after its observations.
            pass
    ds = load_dataset(src)
    if to_parquet:
        write_parquet(ds, dst, rows=rows)
    else:
        write_json(ds, dst)
    return len(ds)


def _pieces(src: str, rows: int, from_parquet: bool, checks: list):
    """The file's pieces of ``rows`` observations; appends what the
    plausibility checks read of each to ``checks`` (run on the whole at the
    end, as load_dataset runs them)."""
    offset = 0
    if from_parquet:
        source = iter_datasets(src, rows, check=False)
    else:
        reader = _core.DatasetFileReader(src)
        if not reader.streamable:
            raise _Whole
        head = json.loads(reader.head)
        schema.validate(dict(head, observations=[]), "dataset", src)

        def read():
            while True:
                try:
                    core = reader.next(rows)
                except ValueError as e:
                    raise ValueError(f"{src}: {e}") from None
                if core is None:
                    if not reader.streamable:
                        raise _Whole
                    return
                yield Dataset(core)
                del core
        source = read()
    for ds in source:
        checks.append(plausibility.loaded_columns(ds, offset))
        offset += len(ds)
        yield ds
        del ds


def _stream_to_json(src: str, dst, rows: int, from_parquet: bool) -> int:
    checks, n, head = [], 0, None
    with files.atomic_output(dst) as out:
        writer = None
        for piece in _pieces(src, rows, from_parquet, checks):
            if writer is None:
                writer, head = _core.DatasetJsonWriter(piece._core, out.write), piece.subset([])
            writer.add(piece._core)
            n += len(piece)
            del piece
        if writer is None:
            raise _Whole  # no observations: the whole load says so
        plausibility.check_loaded_pieces(head, checks, where=src)
        writer.finish()
    return n


def _stream_to_parquet(src: str, dst, rows: int) -> int:
    pa = _pyarrow()
    writer = _core.ColumnWriter()
    # A first pass writes with the columns of the pieces read so far; when a
    # later piece brings a column (an id, a direction, a kind's key), it reads
    # on only to find the columns of the whole, and a second pass writes.
    for scanning in (True, False):
        checks = []
        pieces = _pieces(src, rows, False, checks)
        first = next(pieces, None)
        if first is None:
            raise _Whole  # no observations: the whole load says so
        if scanning:
            writer.scan(first._core)
        schema_ = _arrow_schema(pa, writer, first)
        head = first.subset([])
        held = [first]
        del first
        count = [0]

        def batches():
            piece = held.pop()
            while piece is not None:
                if scanning and count[0] and writer.scan(piece._core, count[0]):
                    count[0] += len(piece)
                    raise _Restart
                yield from _batches(pa, writer, schema_, rows, piece)
                count[0] += len(piece)
                piece = None  # gone before the next is read
                piece = next(pieces, None)
            plausibility.check_loaded_pieces(head, checks, where=src)

        try:
            files.write_parquet_batches(dst, schema_, batches(), compression="zstd")
            return count[0]
        except _Restart:
            for piece in pieces:
                writer.scan(piece._core, count[0])
                count[0] += len(piece)
                del piece
    raise AssertionError("unreachable: the second pass has every column")


# load_dataset and save_dataset read and write Parquet through this
register_format(is_parquet, read_parquet, (".parquet", ".pq"), write_parquet)
