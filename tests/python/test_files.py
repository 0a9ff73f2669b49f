"""Safe files (issue 12, "Crash and data loss" and hygiene): atomic writes
that survive SIGTERM and Ctrl-C, outputs that resolve to an input refused,
a failed command leaves no outputs, capped UTF-8 reads that name the file,
deep JSON without RecursionError, no bare writes outside files.py, and plots
that leave the caller's matplotlib backend alone."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import fivecal
from fivecal import files

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
PKG = os.path.dirname(os.path.abspath(fivecal.__file__))
SPEC = os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json")


def _env():
    e = dict(os.environ)
    e.pop("FIVECAL_DEBUG", None)
    # the fivecal this test imported (a source tree on PYTHONPATH or the installed one)
    e["PYTHONPATH"] = os.path.dirname(os.path.dirname(os.path.abspath(fivecal.__file__))) + os.pathsep + \
        e.get("PYTHONPATH", "")
    return e


# ---------------------------------------------------------------------------
# atomic writes
# ---------------------------------------------------------------------------
def test_write_replaces_atomically_and_keeps_the_mode(tmp_path):
    p = tmp_path / "a.txt"
    files.write_text(p, "one\n")
    os.chmod(p, 0o640)
    files.write_text(p, "two\n")
    assert p.read_text() == "two\n"
    assert (os.stat(p).st_mode & 0o777) == 0o640
    assert sorted(os.listdir(tmp_path)) == ["a.txt"]  # no temporary left


def test_write_through_a_symlink_replaces_the_target_not_the_link(tmp_path):
    (tmp_path / "real.json").write_text("old")
    os.symlink("real.json", tmp_path / "link.json")
    files.write_text(tmp_path / "link.json", "new")
    assert os.path.islink(tmp_path / "link.json")
    assert (tmp_path / "real.json").read_text() == "new"


def test_a_write_that_raises_midway_keeps_the_old_file(tmp_path, monkeypatch):
    p = tmp_path / "out.json"
    p.write_text("previous content")

    def boom(f):
        raise KeyboardInterrupt

    monkeypatch.setattr(files, "_before_replace", boom)
    with pytest.raises(KeyboardInterrupt):
        files.write_text(p, "x" * 100000)
    assert p.read_text() == "previous content"
    assert os.listdir(tmp_path) == ["out.json"]


_SLOW_SIMULATE = textwrap.dedent("""
    import signal, sys, time
    from fivecal import cli, files

    # A user's Ctrl-C: the child of a runner that ignores SIGINT (pytest-xdist
    # workers, a shell's background job) inherits SIG_IGN, and Python then
    # installs no KeyboardInterrupt handler at all.
    signal.signal(signal.SIGINT, signal.default_int_handler)

    def slow(f):
        f.flush()
        open(sys.argv[3], "w").close()  # tell the test the data is half written
        time.sleep(60)

    files._before_replace = slow
    sys.exit(cli.main(["simulate", sys.argv[1], "--out", sys.argv[2]]))
""")


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_simulate_killed_while_writing_leaves_the_previous_file_intact(tmp_path, sig, code):
    out = tmp_path / "dataset.json"
    out.write_text('{"previous": "dataset"}\n')
    marker = tmp_path / "writing"
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_SIMULATE, SPEC, str(out), str(marker)],
                            env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while not marker.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.time() - t0 < 120
        time.sleep(0.05)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert out.read_text() == '{"previous": "dataset"}\n'
    assert sorted(os.listdir(tmp_path)) == ["dataset.json", "writing"]  # the temporary is gone
    assert "Traceback" not in err


def test_a_failed_command_leaves_no_outputs_and_restores_replaced_ones(tmp_path):
    ds = tmp_path / "ds.json"
    r = subprocess.run([sys.executable, "-m", "fivecal", "simulate", SPEC, "--out", ds], env=_env(),
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    not_a_folder = tmp_path / "report"
    not_a_folder.write_text("a file where the report folder should go")
    # --out is written first, then the report folder cannot be made: the command fails
    r = subprocess.run([sys.executable, "-m", "fivecal", "identify", ds, "--estimate", "S1", "--out",
                        tmp_path / "new.json", "--report", not_a_folder], env=_env(), capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert "report" in r.stderr
    assert not (tmp_path / "new.json").exists()
    (tmp_path / "old.json").write_text("older result")
    r = subprocess.run([sys.executable, "-m", "fivecal", "identify", ds, "--estimate", "S1", "--out",
                        tmp_path / "old.json", "--report", not_a_folder], env=_env(), capture_output=True, text=True)
    assert r.returncode == 2
    assert (tmp_path / "old.json").read_text() == "older result"
    assert sorted(os.listdir(tmp_path)) == ["ds.json", "old.json", "report"]


def test_transaction_rolls_back_files_and_folders(tmp_path):
    (tmp_path / "kept.txt").write_text("v1")
    with pytest.raises(RuntimeError):
        with files.transaction():
            files.write_text(tmp_path / "kept.txt", "v2")
            files.write_text(tmp_path / "kept.txt", "v3")
            files.make_dirs(tmp_path / "a" / "b")
            files.write_text(tmp_path / "a" / "b" / "new.txt", "x")
            raise RuntimeError("the command failed")
    assert (tmp_path / "kept.txt").read_text() == "v1"
    assert sorted(os.listdir(tmp_path)) == ["kept.txt"]
    with files.transaction():
        files.write_text(tmp_path / "kept.txt", "v2")
    assert (tmp_path / "kept.txt").read_text() == "v2"
    assert sorted(os.listdir(tmp_path)) == ["kept.txt"]  # backups removed on success


def test_transaction_refuses_to_write_over_an_input_read_in_it(tmp_path):
    p = tmp_path / "in.json"
    p.write_text("{}")
    os.link(p, tmp_path / "hard.json")
    with files.transaction():
        files.read_text(p)
        for out in (p, tmp_path / "hard.json"):
            with pytest.raises(ValueError, match="in.json"):
                files.write_text(out, "lost?")
    assert p.read_text() == "{}"


def test_check_outputs_names_both_files(tmp_path):
    a = tmp_path / "a.json"
    a.write_text("{}")
    os.symlink(a, tmp_path / "s.json")
    os.link(a, tmp_path / "h.json")
    for out in (a, tmp_path / "s.json", tmp_path / "h.json", tmp_path / "sub" / ".." / "a.json"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(ValueError) as e:
            files.check_outputs([("dataset", a)], [("--out", out)])
        assert "--out" in str(e.value) and "dataset" in str(e.value) and "a.json" in str(e.value)
    with pytest.raises(ValueError, match="--plot .*--out"):
        files.check_outputs([], [("--out", tmp_path / "x"), ("--plot", tmp_path / "x")])
    files.check_outputs([("dataset", a)], [("--out", tmp_path / "b.json")])


# ---------------------------------------------------------------------------
# capped, named reads
# ---------------------------------------------------------------------------
def test_devices_and_folders_are_refused_at_once(tmp_path):
    t0 = time.time()
    with pytest.raises(ValueError, match="/dev/zero: not a regular file"):
        fivecal.load_dataset("/dev/zero")
    assert time.time() - t0 < 1
    with pytest.raises(ValueError, match="is a folder"):
        fivecal.load_dataset(tmp_path)


def test_binary_and_non_utf8_files_are_named_with_the_byte_offset(tmp_path):
    b = tmp_path / "data.bin"
    b.write_bytes(b'{"a": 1}\x00\x01\x02')
    with pytest.raises(ValueError, match=r"data.bin: binary data \(a NUL byte at byte offset 8\)"):
        fivecal.load_dataset(b)
    lat = tmp_path / "latin1.json"
    lat.write_bytes('{"name": "Fräse"}'.encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin1.json: not UTF-8 text \(byte 0xe4 at byte offset 12\)"):
        fivecal.Machine.load(lat)
    bom = tmp_path / "bom.json"
    bom.write_bytes(b"\xef\xbb\xbf{}")
    assert files.read_json(bom) == {}


def test_reads_are_capped(tmp_path):
    p = tmp_path / "big.json"
    p.write_text("[" + "0," * 1000 + "0]")
    with pytest.raises(ValueError, match="big.json: .*larger than 100 bytes"):
        files.read_text(p, "dataset", max_bytes=100)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    writer = subprocess.Popen(["sh", "-c", f"head -c 5000 /dev/zero > {fifo}"])
    with pytest.raises(ValueError, match="more than 1000 bytes"):
        files.read_bytes(fifo, max_bytes=1000)
    writer.kill()
    writer.wait()
    assert files.MAX_INPUT_BYTES == 2 * 1024 ** 3


def test_deep_json_is_a_named_error_not_a_recursion_error(tmp_path):
    deep = current = {}
    for _ in range(5000):
        current["k"] = {}
        current = current["k"]
    with pytest.raises(ValueError, match=r"setup\.k\.k.*nested deeper than"):
        fivecal.simulate(fivecal.Machine.load(os.path.join(ROOT, "examples", "machines", "hu40t.json")),
                         [], setup=deep)
    p = tmp_path / "deep.json"
    p.write_text('{"a": ' * 5000 + "1" + "}" * 5000)
    with pytest.raises(ValueError, match="deep.json: JSON nested too deeply"):
        files.read_json(p)


# ---------------------------------------------------------------------------
# hygiene
# ---------------------------------------------------------------------------
_WRITE_MODE = re.compile(r"[wax+]")
#: calls that write a file whatever their receiver (matplotlib, numpy, pandas, json to a file object)
_WRITING_METHODS = {"savefig", "tofile", "to_csv", "to_parquet", "to_feather", "to_hdf", "to_pickle"}
#: functions of a module that write files: (module, function)
_WRITING_FUNCTIONS = {("os", "replace"), ("os", "rename"), ("os", "renames"), ("os", "link"), ("os", "symlink"),
                      ("os", "truncate"), ("shutil", "copy"), ("shutil", "copy2"), ("shutil", "copyfile"),
                      ("shutil", "copytree"), ("shutil", "move"), ("sqlite3", "connect"), ("json", "dump"),
                      ("np", "save"), ("np", "savez"), ("np", "savez_compressed"), ("np", "savetxt"),
                      ("numpy", "save"), ("numpy", "savetxt"), ("pickle", "dump")}
#: pyarrow's writers (through any alias of a pyarrow module)
_PYARROW_WRITERS = {"write_table", "write_dataset", "write_to_dataset", "ParquetWriter", "write_feather",
                    "write_csv", "CSVWriter", "new_file", "new_stream", "OSFile"}


def _bare_writes(source: str, where: str) -> list:
    """Every place in ``source`` that writes a file other than through
    fivecal.files: open(..., "w"/"a"/"x"/"+") (or a mode that is not a
    literal), os.open for writing, os.replace / shutil copies, sqlite3.connect,
    pyarrow / numpy / pandas / matplotlib writers, pathlib write_text /
    write_bytes. The one guard against overwriting an input is in files.py."""
    import ast

    tree = ast.parse(source, where)
    pyarrow = set()             # names bound to a pyarrow module in this source
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "pyarrow":
                    pyarrow.add(a.asname or a.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in ("pyarrow", "sqlite3"):
            for a in node.names:
                if a.name in _PYARROW_WRITERS or a.name == "connect":
                    bad.append(f"{where}:{node.lineno}: from {node.module} import {a.name}")
                pyarrow.add(a.asname or a.name)
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        mode = [k.value for k in node.keywords if k.arg in ("mode", "flags")]
        line = f"{where}:{node.lineno}: {ast.unparse(node)[:90]}"
        if isinstance(f, ast.Name) and f.id == "open":
            m = mode or node.args[1:2]
            if m and not (isinstance(m[0], ast.Constant) and isinstance(m[0].value, str)
                          and not _WRITE_MODE.search(m[0].value)):
                bad.append(line)
        elif isinstance(f, ast.Attribute):
            recv = f.value.id if isinstance(f.value, ast.Name) else ""
            if f.attr == "open" and recv == "os":
                devnull = bool(node.args) and ast.unparse(node.args[0]) == "os.devnull"
                flags = ast.unparse(node.args[1]) if len(node.args) > 1 else ""
                if not devnull and re.search(r"O_(WRONLY|RDWR|CREAT|TRUNC|APPEND)", flags):
                    bad.append(line)
            elif f.attr == "open":          # io / gzip / tarfile / pathlib open with a write mode
                lits = [a for a in list(node.args) + mode if isinstance(a, ast.Constant) and isinstance(a.value, str)]
                if any(_WRITE_MODE.search(a.value) and len(a.value) <= 3 for a in lits):
                    bad.append(line)
            elif f.attr in _WRITING_METHODS or (recv, f.attr) in _WRITING_FUNCTIONS:
                bad.append(line)
            elif f.attr in _PYARROW_WRITERS and (recv in pyarrow or (isinstance(f.value, ast.Attribute)
                                                                     and ast.unparse(f.value).startswith("pa"))):
                bad.append(line)
            elif f.attr in ("write_text", "write_bytes") and recv != "files":
                bad.append(line)
    return bad


def test_the_write_checker_finds_every_kind_of_bare_write():
    src = textwrap.dedent("""
        import os, shutil, sqlite3, json
        import numpy as np
        import pyarrow.parquet as pq
        import pyarrow.dataset as pds
        from pathlib import Path
        open(p, "w"); open(p, mode="ab"); open(p, m); open(p, "r+")
        Path(p).open("w"); Path(p).write_text("x")
        os.open(p, os.O_WRONLY | os.O_CREAT); os.replace(a, b); shutil.copyfile(a, b)
        sqlite3.connect(p); json.dump(d, f); np.save(p, x); fig.savefig(p); df.to_csv(p)
        pq.write_table(t, p); pds.write_dataset(t, p)
        """)
    assert len(_bare_writes(src, "x.py")) == 16
    ok = textwrap.dedent("""
        import os
        from . import files
        open(p); open(p, "rb"); open(p, encoding="utf-8"); os.open(os.devnull, os.O_WRONLY)
        files.write_text(p, "x"); files.save_figure(fig, p); tables.write_dataset(a, b); fig.savefig_x
        """)
    assert _bare_writes(ok, "ok.py") == []


def test_no_module_writes_a_file_but_through_files_py():
    """Every writer of the package, in every subpackage, goes through
    fivecal.files: atomic writes, and the one output-is-not-an-input guard
    (files.guard_output), which also holds the calibration stores opened
    through files.open_sqlite. A new writer that bypasses it fails here."""
    bad = []
    for folder, _, names in os.walk(PKG):
        for name in sorted(names):
            path = os.path.join(folder, name)
            rel = os.path.relpath(path, PKG)
            if name.endswith(".py") and rel != "files.py":
                with open(path, encoding="utf-8") as f:
                    bad += _bare_writes(f.read(), rel)
    assert not bad, "\n".join(bad)


def test_plots_leave_the_matplotlib_backend_alone(tmp_path):
    code = textwrap.dedent(f"""
        import matplotlib
        matplotlib.use("svg")
        import sys
        import numpy as np
        from fivecal.procedures import dbb
        from fivecal.report import polar, plots
        t = dbb.Trace(np.arange(0.0, 360.0, 5.0), 0.001 * np.sin(np.radians(np.arange(0.0, 360.0, 5.0))),
                      label="CCW")
        polar.plot_polar([t], {str(tmp_path / 'p.png')!r}, 100.0, "trace")
        assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
        assert "matplotlib.pyplot" not in sys.modules or not __import__("matplotlib.pyplot").pyplot.get_fignums()
        print("ok")
    """)
    r = subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True, text=True)
    assert r.returncode == 0 and "ok" in r.stdout, r.stderr
    with open(tmp_path / "p.png", "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_toml_machine_without_tomllib(tmp_path, monkeypatch):
    """Python < 3.11 has no tomllib: the tomli package is the fallback."""
    import builtins
    import types

    import tomllib

    m = tmp_path / "m.toml"
    m.write_text('name = "t"\ntopology = "wXYZft"\n'
                 '[axes.X]\ntype = "linear"\ndirection = [1, 0, 0]\n'
                 '[axes.Y]\ntype = "linear"\ndirection = [0, 1, 0]\n'
                 '[axes.Z]\ntype = "linear"\ndirection = [0, 0, 1]\n', encoding="utf-8")
    fake = types.ModuleType("tomli")
    fake.loads, fake.TOMLDecodeError = tomllib.loads, tomllib.TOMLDecodeError
    monkeypatch.setitem(sys.modules, "tomli", fake)
    real_import = builtins.__import__

    def no_tomllib(name, *a, **k):
        if name == "tomllib":
            raise ImportError("No module named 'tomllib'")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_tomllib)
    assert fivecal.Machine.load(m).name == "t"


def test_pyproject_dependencies():
    import tomllib

    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        proj = tomllib.load(f)["project"]
    deps = proj["dependencies"]
    assert not any(d.startswith("scipy") for d in deps)  # never imported by the package
    assert 'tomli>=1.1; python_version < "3.11"' in deps
    assert any(d.startswith("scipy") for d in proj["optional-dependencies"]["test"])  # bench baseline test
    assert any(d.startswith("hypothesis") for d in proj["optional-dependencies"]["test"])
    for name in os.listdir(PKG):
        if name.endswith(".py"):
            with open(os.path.join(PKG, name), encoding="utf-8") as f:
                assert not re.search(r"^\s*(import|from)\s+scipy", f.read(), re.M), name
