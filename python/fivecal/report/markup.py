"""HTML pieces the report's sections share (report/document.py,
report/history.py)."""
from __future__ import annotations

import base64
import html
import os
from typing import Iterable, Sequence


def _e(x) -> str:
    return html.escape(str(x))


def _img_tag(path: str, out_dir: str, embed: bool, alt: str) -> str:
    if embed:
        with open(path, "rb") as f:
            data = base64.b64encode(f.read()).decode("ascii")
        src = f"data:image/png;base64,{data}"
    else:
        src = os.path.relpath(os.path.abspath(path), os.path.abspath(out_dir)).replace(os.sep, "/")
    return f'<img src="{_e(src)}" alt="{_e(alt)}">'


def table_html(header: Sequence[str], rows: Iterable[Sequence], numeric: Sequence[bool] = ()) -> str:
    """A small HTML table (for the ``sections`` of :func:`write_report`)."""
    num = list(numeric) + [False] * (len(header) - len(numeric))
    out = ["<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f"<td class='num'>{_e(c)}</td>" if num[i] else f"<td>{_e(c)}</td>"
                                    for i, c in enumerate(r)) + "</tr>")
    out.append("</table>")
    return "".join(out)
