"""The README is kept true (issue 6, item 6): every code block in it runs as
written, against real files, the way a new user would paste it into a shell
at the root of a clone after the two commands at the top.
"""
import os
import re
import stat
import subprocess
import sys

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
README = os.path.join(ROOT, "README.md")

TOP_COMMANDS = [
    "bash scripts/install.sh && fivecal demo",
    "bash scripts/install.sh && bash scripts/test.sh",
]


def blocks():
    text = open(README, encoding="utf-8").read()
    return [(m.group(1), m.group(2)) for m in re.finditer(r"```(\w*)\n(.*?)```", text, re.S)]


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    """A working folder that looks like the root of a clone (examples/ and
    scripts/ linked) with `fivecal` on PATH running this interpreter."""
    d = tmp_path_factory.mktemp("readme")
    for name in ("examples", "scripts"):
        os.symlink(os.path.join(ROOT, name), d / name)
    bindir = d / "_bin"
    bindir.mkdir()
    shim = bindir / "fivecal"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m fivecal "$@"\n')
    shim.chmod(shim.stat().st_mode | stat.S_IEXEC)
    env = dict(os.environ)
    env["PATH"] = f"{bindir}{os.pathsep}{env.get('PATH', '')}"
    env.pop("FIVECAL_DEBUG", None)
    return d, env


def run(cmd, cwd, env, timeout=600):
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def test_readme_blocks_are_python_or_bash():
    langs = [lang for lang, _ in blocks()]
    assert langs and set(langs) <= {"python", "bash"}, langs


def test_the_two_commands_at_the_top_are_unchanged():
    lang, code = blocks()[0]
    assert lang == "bash"
    cmds = [line.split("#")[0].strip() for line in code.strip().splitlines()]
    assert cmds == TOP_COMMANDS


def test_readme_python_and_cli_snippets_run(clone):
    d, env = clone
    # the README's first command, after the install (the test suite runs installed)
    proc = run(["fivecal", "demo"], d, env)
    assert proc.returncode == 0, proc.stderr
    assert "report: " in proc.stdout and (d / "fivecal_demo" / "report.html").is_file()
    n_python = n_bash = 0
    for i, (lang, code) in enumerate(blocks()):
        if i == 0:
            continue  # the install commands, checked above
        if lang == "python":
            path = d / f"readme_block_{i}.py"
            path.write_text(code)
            proc = run([sys.executable, str(path)], d, env)
            assert proc.returncode == 0, f"README python block {i} failed:\n{proc.stderr[-3000:]}"
            n_python += 1
        elif lang == "bash":
            proc = run(["bash", "-euo", "pipefail", "-c", code], d, env)
            assert proc.returncode == 0, f"README bash block {i} failed:\n{code}\n{proc.stderr[-3000:]}"
            n_bash += 1
    assert n_python >= 1 and n_bash >= 1
    # what the snippets promise to write is there
    for name in ("my_report/report.html", "errors.csv", "part_comp.nc", "spheres.json", "result.json",
                 "report/report.html"):
        assert (d / name).is_file(), name
    assert (d / "part_comp.nc").read_bytes() != open(os.path.join(ROOT, "examples", "gcode",
                                                                  "hu40t_5axis.nc"), "rb").read()


# ---------------------------------------------------------------------------
# the newcomer's map ("Where the code is"): one table, folder by folder
# ---------------------------------------------------------------------------

#: folders whose every subfolder the map names (and the top level itself)
MAPPED = ("", "cpp/src", "cpp/include/fivecal", "python/fivecal")
#: never part of the map: build outputs, caches, the demo's output
_NOT_TREE = {"build", "__pycache__", "fivecal_demo", "dist"}


def map_rows(text=None):
    """(folder, stage, holds, layer) of each row of the map table (the one
    whose header starts ``| folder |``)."""
    text = text if text is not None else open(README, encoding="utf-8").read()
    lines = text.split("## Where the code is", 1)[1].split("\n## ", 1)[0].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| folder |"))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        folders = re.findall(r"`([^`]+/)`", cells[0])
        assert folders and re.fullmatch(r"(`[^`]+/`[ ,]*)+", cells[0]), \
            f"map row whose first cell is not `folder/`, `folder/` ...: {line}"
        rows += [(f, *cells[1:]) for f in folders]
    return rows


def tree_folders() -> set:
    """The folders the map must name: every tracked folder at the top level
    and directly under the folders of MAPPED (git's list, so a build or a
    cache in the working tree does not count; the walk when not a clone)."""
    try:
        listed = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True,
                                timeout=60).stdout.splitlines()
        dirs = {os.path.dirname(p) for p in listed} - {""}
        for d in list(dirs):
            while d:
                dirs.add(d)
                d = os.path.dirname(d)
    except (OSError, subprocess.SubprocessError):
        dirs = set()
        for folder, names, _ in os.walk(ROOT):
            names[:] = [n for n in names if n not in _NOT_TREE and not (n.startswith(".") and n != ".ci")]
            rel = os.path.relpath(folder, ROOT)
            if rel != ".":
                dirs.add(rel.replace(os.sep, "/"))
    return {d + "/" for d in dirs if os.path.dirname(d) in MAPPED and os.path.isdir(os.path.join(ROOT, d))}


def test_every_folder_of_the_tree_is_in_the_map():
    named = {r[0] for r in map_rows()}
    missing = sorted(tree_folders() - named)
    assert not missing, f"folders missing from the README map (Where the code is): {missing}"


def test_every_folder_of_the_map_exists():
    gone = [r[0] for r in map_rows() if not os.path.isdir(os.path.join(ROOT, r[0]))]
    assert not gone, f"the README map names folders that do not exist: {gone}"


def test_every_python_module_is_in_the_map_in_its_layer():
    """Each top-level module of python/fivecal is named in a row of the
    map, every module a row names exists, and a row's layer is the one
    tests/python/test_architecture.py holds the module or package to."""
    sys.path.insert(0, os.path.dirname(__file__))
    try:
        from test_architecture import _layer
    finally:
        sys.path.pop(0)
    pkg = os.path.join(ROOT, "python", "fivecal")
    modules = {n for n in os.listdir(pkg) if n.endswith(".py")}
    named, bad = set(), []
    for folder, _, holds, layer in map_rows():
        if not folder.startswith("python/fivecal/"):
            continue
        want = None if layer == "none" else (int(layer.split()[0]) if layer else "no layer")
        sub = folder[len("python/fivecal/"):].strip("/")
        mods = re.findall(r"`([\w.]+)\.py`", holds)
        if sub:
            if want != "no layer" and _layer("fivecal." + sub) != want:
                bad.append(f"{folder}: README layer {layer!r}, test_architecture {_layer('fivecal.' + sub)}")
            if not os.path.isfile(os.path.join(pkg, sub, "__init__.py")):
                continue  # data folders (schemas/) hold no modules
            where = os.path.join(pkg, sub)
            bad += [f"{folder}: names {m}.py, not there" for m in mods
                    if not os.path.isfile(os.path.join(where, m + ".py")) and m + ".py" not in modules]
            named |= {m + ".py" for m in mods if m + ".py" in modules and not os.path.isfile(
                os.path.join(where, m + ".py"))}
            continue
        for m in mods:
            if m + ".py" not in modules:
                bad.append(f"{folder}: names {m}.py, not there")
                continue
            named.add(m + ".py")
            got = _layer("fivecal" if m == "__init__" else "fivecal." + m)
            if got != want:
                bad.append(f"{m}.py: README layer {layer!r}, test_architecture {got}")
    bad += [f"{m}: not in the README map" for m in sorted(modules - named)]
    assert not bad, "README map (Where the code is) against the package:\n" + "\n".join(bad)


def test_the_map_checks_can_fail():
    """The table reader sees a folder that is missing and one that is made up."""
    text = ("## Where the code is\n\n| folder | stage | what it holds | Python layer |\n|---|---|---|---|\n"
            "| `cpp/src/model/`, `cpp/include/fivecal/model/` | machine | x | |\n| `nowhere/` | all | y | |\n\n"
            "## Next\n")
    rows = map_rows(text)
    assert [r[0] for r in rows] == ["cpp/src/model/", "cpp/include/fivecal/model/", "nowhere/"]
    assert not os.path.isdir(os.path.join(ROOT, rows[2][0]))
    assert "cpp/src/solve/" in tree_folders() - {r[0] for r in rows}
