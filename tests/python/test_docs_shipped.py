"""The user documentation ships with the package, and every message that
points to a page points to one an installed user has: `fivecal docs NAME`
(the wheel installs README.md into site-packages/fivecal/docs and docs/*.md
into fivecal/docs/docs, the tree's layout;
run from a tree with PYTHONPATH=python, the tree's docs/ is found)."""
import ast
import os
import re
import subprocess
import sys

import pytest

import fivecal
from fivecal import manual

PACKAGE = os.path.dirname(os.path.abspath(fivecal.__file__))
#: a page by the path of a source tree, or a C++ header: neither is installed
TREE_PATH = re.compile(r"docs/[A-Za-z_]+\.md|\b[a-z_]+\.h\b")
POINTER = re.compile(r"fivecal docs ([A-Za-z_.]+)")


def _message_strings():
    """(file, line, text) of every string constant of the installed package
    that is not a docstring: help texts, messages, report and table text."""
    for folder, _, files in os.walk(PACKAGE):
        for f in files:
            if not f.endswith(".py"):
                continue
            path = os.path.join(folder, f)
            with open(path, encoding="utf-8") as fh:
                tree = ast.parse(fh.read())
            docstrings = set()
            for node in ast.walk(tree):
                if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
                    first = node.body[0]
                    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                        docstrings.add(id(first.value))
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
                    yield os.path.relpath(path, PACKAGE), node.lineno, node.value


def test_the_documentation_is_found():
    d = manual.docs_dir()
    assert d is not None and os.path.isfile(os.path.join(d, "dbb.md"))
    for name in ("dbb", "linuxcnc", "formats", "readme"):
        assert os.path.isfile(manual.doc_path(name)), name
    tree_docs = os.path.normpath(os.path.join(PACKAGE, os.pardir, os.pardir, "docs"))
    if not os.path.isdir(tree_docs):  # the installed package: its own copy, not a source tree's
        assert d == os.path.join(PACKAGE, "docs", "docs")


LINK = re.compile(r"\]\(([^)#\s]+)(#[^)\s]*)?\)")


def test_every_relative_link_of_a_page_resolves_where_it_is_read():
    # before: the wheel flattened README and docs/ into one folder, so the
    # README's docs/dbb.md and formats.md's ../README.md led nowhere
    pages = [manual.doc_path(n) for n in manual.doc_names()]
    broken = []
    for page in pages:
        with open(page, encoding="utf-8") as fh:
            for target, _ in LINK.findall(fh.read()):
                if re.match(r"[a-z]+:", target):
                    continue  # https:, mailto:
                if not os.path.exists(os.path.join(os.path.dirname(page), target)):
                    broken.append(f"{os.path.basename(page)}: {target}")
    tree = os.path.isdir(os.path.normpath(os.path.join(PACKAGE, os.pardir, os.pardir, "docs")))
    # the README's links to examples/ resolve in a tree only; the wheel ships examples/machines alone
    allowed = () if tree else ("examples/",)
    assert not [b for b in broken if not b.split(": ", 1)[1].startswith(allowed)], broken


def test_no_message_points_into_a_source_tree():
    bad = [f"{f}:{line}: {TREE_PATH.findall(text)}" for f, line, text in _message_strings()
           if TREE_PATH.search(text)]
    assert not bad, "messages naming files an installed user does not have:\n" + "\n".join(bad)


def test_every_page_a_message_names_is_installed():
    named = {}
    for f, line, text in _message_strings():
        for name in POINTER.findall(text):
            if name not in ("NAME",):
                named.setdefault(name.rstrip("."), f"{f}:{line}")
    assert {"dbb", "linuxcnc", "formats"} <= set(named)
    docs = manual.docs_dir()
    for name, where in named.items():
        path = manual.doc_path(name)  # raises for a page that is not there
        assert os.path.isfile(path), where
        assert os.path.dirname(path) in (docs, os.path.dirname(docs)), where


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "fivecal", *args], capture_output=True, text=True, timeout=60)


def test_fivecal_docs_lists_the_pages_and_prints_a_path():
    r = _cli("docs")
    assert r.returncode == 0, r.stderr
    for name in ("dbb", "linuxcnc", "formats", "readme"):
        assert re.search(rf"^\s+{name}\s", r.stdout, re.M), r.stdout
    r = _cli("docs", "dbb")
    assert r.returncode == 0 and os.path.isfile(r.stdout.strip())
    assert r.stdout.strip().endswith("dbb.md")


@pytest.mark.parametrize("name", ["dbc", "nothing"])
def test_fivecal_docs_refuses_an_unknown_page(name):
    r = _cli("docs", name)
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1
    assert f"no document '{name}'" in r.stderr and "dbb" in r.stderr
