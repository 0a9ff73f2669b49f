"""Reading inputs and writing outputs safely.

Every file the package writes goes through :func:`write_text` /
:func:`write_bytes` (or :func:`save_figure`), or, for a file too large to
hold in memory whole, :func:`atomic_output` (piece by piece): the data goes
to a temporary file in the destination's folder, is flushed and fsynced, and
then replaces the destination with ``os.replace``.  An interrupted write
(Ctrl-C, SIGTERM, a full disk, an error midway through a stream) therefore
leaves either the complete old file or the complete new one, never an empty
or truncated file.

Inputs are read with :func:`read_text` / :func:`read_bytes`: regular files
(or pipes) up to :data:`MAX_INPUT_BYTES`; devices and directories are
refused, and text must be UTF-8 without NUL bytes.  Errors name the file.

Inside :func:`transaction` (the ``fivecal`` command runs each command in
one), every path read is remembered, a write over one of them is refused,
and when the command fails the files it created are removed and the files
it replaced get their previous content back.

One guard, :func:`guard_output`, stands before every write: a file read in
the running transaction, or a database opened with :func:`open_sqlite` (a
calibration store, read or written, in a transaction or not, while it is
open), is never overwritten. Writers that produce bytes another library
makes (Parquet through :func:`write_parquet_table` or, streamed,
:func:`write_parquet_batches`, figures through :func:`save_figure`) go
through :func:`atomic_output` like the rest, so no
module writes a file but through here (tests/python/test_files.py checks
the source for it).
"""
from __future__ import annotations

import contextlib
import io
import os
import shutil
import sqlite3
import stat
import tempfile
import threading
import weakref
from typing import List, Optional, Sequence, Tuple, Union

PathLike = Union[str, "os.PathLike[str]"]

#: Largest input file read (bytes).  Datasets of 10^6 observations are a few
#: hundred MB; the cap keeps a wrong path (a device, a huge log) from filling
#: memory before anything can be said about it.
MAX_INPUT_BYTES = 2 * 1024 ** 3

_CHUNK = 1 << 20


class _Transaction:
    def __init__(self):
        self.inputs: List[Tuple[str, Optional[os.stat_result]]] = []
        self.created: List[str] = []
        self.backups: List[Tuple[str, str]] = []  # (destination, hard link to its previous content)
        self.dirs: List[str] = []
        self.databases: List[Tuple[str, Optional[os.stat_result]]] = []  # opened with open_sqlite

    def note_input(self, path: str, database: bool = False) -> None:
        try:
            st = os.stat(path)
        except OSError:
            st = None
        self.inputs.append((path, st))
        if database:
            self.databases.append((path, st))


_active: List[_Transaction] = []


def _same(a: os.stat_result, b: os.stat_result) -> bool:
    return a.st_dev == b.st_dev and a.st_ino == b.st_ino


def _stat(path: str) -> Optional[os.stat_result]:
    try:
        return os.stat(path)
    except OSError:
        return None


class _HeldConnection(sqlite3.Connection):
    """A SQLite connection whose file (and its WAL and shared-memory files)
    is an input for as long as it is open."""
    _fivecal_inputs: List[Tuple[str, Optional[os.stat_result]]] = []

    def close(self) -> None:
        try:
            super().close()
        finally:
            with _held_lock:
                _held.discard(self)


#: open database connections (weak: one dropped without close() stops guarding)
_held: "weakref.WeakSet[_HeldConnection]" = weakref.WeakSet()
_held_lock = threading.Lock()


def _inputs() -> List[Tuple[str, Optional[os.stat_result]]]:
    out = list(_active[-1].inputs) if _active else []
    with _held_lock:
        for c in list(_held):
            out.extend(c._fivecal_inputs)
    return out


def _clash(dest: str, inputs) -> Optional[str]:
    st = _stat(dest)
    real = os.path.realpath(dest)
    for path, ist in inputs:
        if st is not None and ist is not None and _same(st, ist):
            return path
        if os.path.realpath(path) == real:
            return path
    return None


def _input_clash(dest: str) -> Optional[str]:
    """The input (read in the active transaction, or an open database) that
    ``dest`` is, by name, symbolic link or hard link."""
    return _clash(dest, _inputs())


def guard_output(path: PathLike, label: str = "") -> str:
    """The one output-is-not-an-input check: ValueError naming ``label`` (an
    option such as ``--plot``), the path and the input when ``path`` is a
    file read in the running transaction or an open database. Every write of
    the package passes here (through :func:`write_bytes` or directly, for a
    library that writes a folder itself)."""
    path = os.fspath(path)
    clash = _input_clash(path)
    if clash is not None:
        what = f"{label} {path}" if label else path
        raise ValueError(f"{what}: is the input {clash}; refusing to overwrite an input")
    return path


def write_folder(path: PathLike, contents: "dict[str, str]", label: str = "") -> str:
    """The folder ``path`` holding exactly ``contents`` (file name -> text),
    all or nothing: the files are written into a new folder beside it, which
    then takes its place (an existing folder is replaced whole, so stale
    files of an earlier write go). On any failure the old folder stays as it
    was and nothing is left beside it. ValueError names ``label``."""
    dest = os.path.realpath(guard_output(path, label))
    what = label or dest
    for name in contents:
        guard_output(os.path.join(dest, name), label)
    parent = os.path.dirname(dest)
    make_dirs(parent)
    try:
        tmp = tempfile.mkdtemp(dir=parent, prefix=f".{os.path.basename(dest)}.", suffix=".new")
    except OSError as e:
        raise ValueError(f"{what}: cannot create a folder beside it ({e.strerror})") from None
    try:
        mask = os.umask(0)
        os.umask(mask)
        # mkdtemp makes it private; the new folder keeps the old folder's mode
        os.chmod(tmp, stat.S_IMODE(os.stat(dest).st_mode) if os.path.isdir(dest) else 0o777 & ~mask)
        for name, text in contents.items():
            write_text(os.path.join(tmp, name), text)
        if os.path.isdir(dest):
            aside = tmp[:-len(".new")] + ".old"
            os.rename(dest, aside)
            try:
                os.rename(tmp, dest)
            except BaseException:
                os.rename(aside, dest)
                raise
            shutil.rmtree(aside, ignore_errors=True)
        else:
            os.rename(tmp, dest)
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(e, OSError):
            raise ValueError(f"{what}: cannot write ({e.strerror or e})") from None
        raise
    return dest


def note_input(path: PathLike) -> None:
    """Count ``path`` as an input of the running transaction (no-op outside
    one): a later write over it is refused."""
    if _active:
        _active[-1].note_input(os.fspath(path))


def open_sqlite(path: PathLike, label: str = "", **kwargs) -> sqlite3.Connection:
    """``sqlite3.connect(path, **kwargs)`` for a database that is both read
    and written (the calibration store): refused when it is an input of the
    running transaction under another name (a dataset given as the store),
    and, while the connection is open and for the rest of the transaction,
    an input itself, so no output of the command lands on it."""
    path = os.fspath(path)
    if _active:
        # a database opened before in this transaction is this one again, not a clash
        dbs = _active[-1].databases
        files_read = [i for i in _active[-1].inputs if _clash(i[0], dbs) is None]
        clash = _clash(path, files_read)
        if clash is not None:
            raise ValueError(f"{label + ' ' if label else ''}{path}: is the input {clash}; refusing to "
                             "open it as a database (it would be written)")
    db = sqlite3.connect(path, factory=_HeldConnection, **kwargs)
    # the WAL holds committed data not yet copied into the file: as precious
    parts = (path, path + "-wal", path + "-shm")
    db._fivecal_inputs = [(p, _stat(p)) for p in parts]
    with _held_lock:
        _held.add(db)
    if _active:
        for p in parts:
            _active[-1].note_input(p, database=True)
    return db


@contextlib.contextmanager
def transaction():
    """All-or-nothing outputs: inside the block writes over an input read in
    it are refused; if the block raises (or is interrupted), files it created
    are removed, files it replaced are restored and folders it created are
    removed when empty."""
    t = _Transaction()
    _active.append(t)
    ok = False
    try:
        yield t
        ok = True
    finally:
        _active.remove(t)
        if ok:
            for _, bak in t.backups:
                _unlink_quiet(bak)
        else:
            for dest, bak in reversed(t.backups):
                try:
                    os.replace(bak, dest)
                except OSError:
                    _unlink_quiet(bak)
            for p in reversed(t.created):
                _unlink_quiet(p)
            for d in reversed(t.dirs):
                with contextlib.suppress(OSError):
                    os.rmdir(d)


def _unlink_quiet(p: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(p)


# --------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------

def read_bytes(path: PathLike, what: str = "input", max_bytes: int = MAX_INPUT_BYTES) -> bytes:
    """The content of a regular file or a pipe, at most ``max_bytes``;
    ValueError naming the file for devices, folders, unreadable or too large
    files."""
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except OSError as e:
        raise ValueError(f"{path}: cannot read {what} ({e.strerror})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{path}: is a folder, expected a {what} file")
    if not (stat.S_ISREG(st.st_mode) or stat.S_ISFIFO(st.st_mode)):
        raise ValueError(f"{path}: not a regular file (a device or socket); expected a {what} file")
    if stat.S_ISREG(st.st_mode) and st.st_size > max_bytes:
        raise ValueError(f"{path}: {st.st_size} bytes; {what} files larger than {max_bytes} bytes are refused")
    if _active:
        _active[-1].note_input(path)
    try:
        with open(path, "rb") as f:
            parts, n = [], 0
            while True:
                b = f.read(min(_CHUNK, max_bytes + 1 - n))
                if not b:
                    break
                parts.append(b)
                n += len(b)
                if n > max_bytes:
                    raise ValueError(f"{path}: more than {max_bytes} bytes; {what} files this large are refused")
    except OSError as e:
        raise ValueError(f"{path}: cannot read {what} ({e.strerror})") from None
    return b"".join(parts)


def decode_text(data: bytes, path: str) -> str:
    """UTF-8 text (a leading BOM is dropped); ValueError naming the file and
    the byte offset (and line) for binary data or another encoding."""
    nul = data.find(b"\0")
    if nul >= 0:
        raise ValueError(f"{path}: binary data (a NUL byte at byte offset {nul}), expected UTF-8 text")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        b = data[e.start]
        line = data.count(b"\n", 0, e.start) + 1
        # the usual culprit: a degree or micro sign saved by a Windows tool
        latin = f", '{bytes([b]).decode('cp1252')}' in Latin-1 / Windows-1252" if b in (0xb0, 0xb5) else ""
        raise ValueError(f"{path}: not UTF-8 text (byte 0x{b:02x} at byte offset {e.start}) on line {line}"
                         f"{latin}; save the file as UTF-8") from None
    return text[1:] if text.startswith("\ufeff") else text


def read_text(path: PathLike, what: str = "input", max_bytes: int = MAX_INPUT_BYTES) -> str:
    """:func:`read_bytes` decoded as UTF-8 (see :func:`decode_text`)."""
    path = os.fspath(path)
    return decode_text(read_bytes(path, what, max_bytes), path)


def read_json(path: PathLike, what: str = "input"):
    """A JSON document from a file; ValueError naming the file, line and column."""
    import json

    path = os.fspath(path)
    text = read_text(path, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e.msg} at line {e.lineno}, column {e.colno})") from None
    except RecursionError:
        raise ValueError(f"{path}: JSON nested too deeply") from None


# --------------------------------------------------------------------------
# Checks before a command writes anything
# --------------------------------------------------------------------------

def check_outputs(inputs: Sequence[Tuple[str, PathLike]], outputs: Sequence[Tuple[str, PathLike]]) -> None:
    """Refuse (ValueError naming both) an output that is, or resolves through
    a symbolic or hard link to, one of the inputs or another output.
    ``inputs`` and ``outputs`` are ``(label, path)`` pairs; label is e.g.
    ``"--out"`` or ``"dataset"``."""
    def key(p):
        try:
            st = os.stat(p)
            return ("ino", st.st_dev, st.st_ino)
        except OSError:
            return ("path", os.path.realpath(p))

    seen = {}
    for label, p in inputs:
        if p is None:
            continue
        seen.setdefault(key(os.fspath(p)), (label, os.fspath(p), True))
    for label, p in outputs:
        if p is None:
            continue
        p = os.fspath(p)
        k = key(p)
        if k in seen:
            other_label, other, is_input = seen[k]
            if is_input:
                raise ValueError(f"{label} {p}: is the input {other_label} {other}; refusing to overwrite "
                                 "an input (choose another output file)")
            raise ValueError(f"{label} {p}: the same file as {other_label} {other}; give each output its own file")
        if os.path.isdir(p) and not label.endswith("DIR"):
            raise ValueError(f"{label} {p}: is a folder, expected a file name")
        seen[k] = (label, p, False)


# --------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------

def _new_file_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


#: Test hook: called with the open temporary file between the data and the
#: fsync (a test makes the write slow to interrupt it).
_before_replace = None


class _Output:
    """The temporary file :func:`atomic_output` writes to: bytes in, nothing
    else (no seeking back into what is written)."""

    def __init__(self, f):
        self._f = f

    def write(self, data) -> int:
        return self._f.write(data)

    def tell(self) -> int:
        return self._f.tell()

    def flush(self) -> None:
        self._f.flush()

    @property
    def closed(self) -> bool:
        return self._f.closed

    def writable(self) -> bool:
        return True

    def readable(self) -> bool:
        return False

    def seekable(self) -> bool:
        return False


@contextlib.contextmanager
def atomic_output(path: PathLike, label: str = "", durable: bool = True):
    """A file to write ``path`` through, piece by piece: the pieces go to a
    temporary file beside it, which replaces ``path`` (through a symbolic
    link: its target) when the block ends normally. When the block raises or
    is interrupted (an exception, Ctrl-C, SIGTERM) the temporary file is
    removed and ``path`` is left as it was, so a long streamed write never
    leaves a partial file. Yields an object with ``write(bytes)``.
    ValueError (naming ``label``) when ``path`` is an input
    (:func:`guard_output`) or cannot be written. ``durable=False`` skips the
    fsyncs (the replace stays atomic)."""
    path = guard_output(path, label)
    dest = os.path.realpath(path)
    folder = os.path.dirname(dest) or "."
    if os.path.isdir(dest):
        raise ValueError(f"{path}: is a folder, expected a file name")
    try:
        old = os.stat(dest)
    except OSError:
        old = None
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{os.path.basename(dest)}.", suffix=".tmp")
    except OSError as e:
        raise ValueError(f"{path}: cannot write ({e.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            yield _Output(f)
            if _before_replace is not None:
                _before_replace(f)
            f.flush()
            if durable:
                os.fsync(f.fileno())
        os.chmod(tmp, stat.S_IMODE(old.st_mode) if old is not None else _new_file_mode())
        backup = None
        if _active and old is not None:
            backup = tmp + ".old"
            try:
                os.link(dest, backup)
            except OSError:
                backup = None
        os.replace(tmp, dest)
    except BaseException as e:
        _unlink_quiet(tmp)
        if isinstance(e, OSError):
            raise ValueError(f"{path}: cannot write ({e.strerror or e})") from None
        raise
    if _active:
        if old is None:
            _active[-1].created.append(dest)
        elif backup is not None:
            _active[-1].backups.append((dest, backup))
    if not durable:
        return
    with contextlib.suppress(OSError):  # the rename itself durable
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def write_bytes(path: PathLike, data: bytes, label: str = "", durable: bool = True) -> str:
    """Atomically replace ``path`` (through a symbolic link: its target) with
    ``data``; returns ``path``.  ValueError (naming ``label``, the option
    that named the file) when ``path`` is an input (:func:`guard_output`).
    ``durable=False`` skips the fsyncs (the replace stays atomic): for
    thousands of generated files that can be made again."""
    with atomic_output(path, label=label, durable=durable) as out:
        out.write(data)
    return os.fspath(path)


def write_text(path: PathLike, text: str, encoding: str = "utf-8", label: str = "", durable: bool = True) -> str:
    """:func:`write_bytes` of ``text`` encoded (UTF-8 by default)."""
    return write_bytes(path, text.encode(encoding), label=label, durable=durable)


def write_json(path: PathLike, obj, indent: int = 1, **kw) -> str:
    """``obj`` as JSON text (and a final newline), written atomically."""
    import json

    return write_text(path, json.dumps(obj, indent=indent, **kw) + "\n")


def make_dirs(path: PathLike) -> str:
    """``os.makedirs(path, exist_ok=True)``; inside a :func:`transaction` the
    folders created are removed again (when empty) if the command fails."""
    path = os.fspath(path)
    missing = []
    p = os.path.abspath(path)
    while p and not os.path.exists(p):
        missing.append(p)
        parent = os.path.dirname(p)
        if parent == p:
            break
        p = parent
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise ValueError(f"{path}: cannot create the folder ({e.strerror})") from None
    if not os.path.isdir(path):
        raise ValueError(f"{path}: exists and is not a folder")
    if _active:
        _active[-1].dirs.extend(reversed(missing))
    return path


def save_figure(fig, path: PathLike, label: str = "", **kw) -> str:
    """Render a matplotlib Figure (PNG unless the name says otherwise) to
    memory, then write it atomically."""
    path = guard_output(path, label)     # before the rendering: say it at once
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    buf = io.BytesIO()
    fig.savefig(buf, format=kw.pop("format", None) or (ext if ext in ("png", "pdf", "svg", "eps", "ps", "jpg",
                                                                        "jpeg", "tif", "tiff", "webp")
                                                       else "png"), **kw)
    return write_bytes(path, buf.getvalue(), label=label)


def write_parquet_table(path: PathLike, table, label: str = "", **kw) -> str:
    """A pyarrow Table as a Parquet file (``pyarrow.parquet.write_table``
    options in ``kw``), rendered in memory, then written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = guard_output(path, label)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, **kw)
    return write_bytes(path, memoryview(sink.getvalue()), label=label)


def write_parquet_batches(path: PathLike, schema, batches, label: str = "", **kw) -> str:
    """A Parquet file of ``schema`` (a pyarrow Schema) from an iterable of
    record batches, each written as it comes (one row group or more per
    batch: the file is never whole in memory), through :func:`atomic_output`:
    a failure midway (in ``batches`` or the write) leaves ``path`` as it was.
    ``kw``: ``pyarrow.parquet.ParquetWriter`` options."""
    import pyarrow.parquet as pq

    with atomic_output(path, label=label) as out:
        with pq.ParquetWriter(out, schema, **kw) as w:
            for b in batches:
                w.write_batch(b)
    return os.fspath(path)
