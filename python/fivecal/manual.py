"""The user documentation shipped with the package: ``fivecal docs [NAME]``.

The wheel installs the project's ``README.md`` into ``site-packages/fivecal/docs``
and ``docs/*.md`` into ``site-packages/fivecal/docs/docs`` (CMakeLists.txt): the
tree's layout, so the pages' relative links resolve, so a message can send an
installed user to a page they have: "see `fivecal docs dbb`", never to a
``docs/…`` path of a source tree they never saw. Run from a source tree
(``PYTHONPATH=python``) the tree's own ``docs/`` and ``README.md`` are found.
"""
from __future__ import annotations

import difflib
import os
from typing import Dict, Optional

__all__ = ["docs_dir", "doc_names", "doc_path"]

_HERE = os.path.dirname(os.path.abspath(__file__))
#: where the wheel puts them, then the source tree (python/fivecal/../../docs)
_PLACES = (os.path.join(_HERE, "docs", "docs"), os.path.join(_HERE, os.pardir, os.pardir, "docs"))


def docs_dir() -> Optional[str]:
    """The folder holding the user documentation, or None when it is missing
    (a package installed without its data files)."""
    for d in _PLACES:
        if os.path.isfile(os.path.join(d, "formats.md")):
            return os.path.normpath(d)
    return None


def _files() -> Dict[str, str]:
    """name -> path of every document: ``formats`` for formats.md, ``readme``."""
    d = docs_dir()
    if d is None:
        return {}
    out = {os.path.splitext(f)[0].lower(): os.path.join(d, f)
           for f in sorted(os.listdir(d)) if f.endswith(".md")}
    if "readme" not in out:  # the README sits beside docs/, installed or in a tree
        readme = os.path.join(os.path.dirname(d), "README.md")
        if os.path.isfile(readme):
            out["readme"] = readme
    return out


def doc_names() -> list:
    """The names ``fivecal docs NAME`` accepts, sorted."""
    return sorted(_files())


def doc_path(name: str) -> str:
    """The path of document ``name`` (``dbb``, ``dbb.md``, ``README``); a
    ValueError names the documents there are, or says they are not installed."""
    files = _files()
    if not files:
        raise ValueError("the documentation is not installed with this copy of fivecal (it is in the "
                         "docs/ folder of the source distribution)")
    key = os.path.splitext(os.path.basename(str(name).strip()))[0].lower()
    if key in files:
        return files[key]
    close = difflib.get_close_matches(key, list(files), n=1)
    raise ValueError(f"no document {name!r}" + (f"; did you mean '{close[0]}'?" if close else "")
                     + f" (documents: {', '.join(sorted(files))})")

