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
