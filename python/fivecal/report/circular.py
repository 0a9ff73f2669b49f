"""The HTML report of a planar circular (ball bar) test, like identify's:
the verdict first, then the polar plot at its stated scale, the diagnosis
ranked by contribution to circularity, the ISO 230-4 values and what was
left out (docs/dbb.md, "The circular test report"); and of a volumetric
test, the planes' reports under one page that states the combined values.

Only formatting: every number comes from :class:`fivecal.procedures.dbb.
CircularResult` (the C++ core's analysis) or from the grade it made.
"""
from __future__ import annotations

import datetime
import os
from typing import Mapping, Optional, Sequence, Union

from .._version import __version__
from ..files import make_dirs, write_text
from .document import _CSS
from .markup import _e, _img_tag, table_html
from .polar import plot_circular_test, plot_volumetric

_VERDICT_CSS = """
.verdict{border-radius:6px;padding:12px 16px;margin:14px 0;font-size:1.1em}
.verdict.pass{background:#e6f4ea;border:2px solid #2e7d32}
.verdict.fail{background:#fdecea;border:2px solid #c62828}
.verdict.neutral{background:#eef3fa;border:2px solid #4c78a8}
.verdict b{font-size:1.25em}
main img{max-width:100%;height:auto}
"""


def _um(v: float) -> str:
    return f"{v * 1e3:.2f}"


def verdict(result, grade: Optional[Mapping] = None, usable: bool = True, reason: str = "") -> dict:
    """The one line a reader needs first: NOT USABLE, FAIL, PASS or (no
    tolerance given) the circularity alone, with the class of its box."""
    if not usable:
        return {"word": "NOT USABLE", "cls": "fail", "text": reason or "the analysis is not usable"}
    c = f"circularity {_um(result.circularity)} µm"
    if grade is None:
        return {"word": "NOT GRADED", "cls": "neutral", "text": f"{c}; no tolerance given (--tolerance)"}
    failed = [i for i in grade["items"] if i["grade"] != "PASS"]
    if grade["grade"] == "PASS":
        return {"word": "PASS", "cls": "pass", "text": f"{c}; every toleranced value within its tolerance"}
    names = ", ".join(f"{i['label']} ({i['grade'].lower()})" for i in failed[:6])
    return {"word": grade["grade"], "cls": "fail", "text": f"{c}; {names}"}


def _thermal_html(t: Optional[Mapping]) -> str:
    if not t:
        return "<p>No thermal compensation: the readings are as recorded.</p>"
    return ("<p>Thermal compensation: readings referred to 20 °C with the bar's expansion "
            f"{t['bar_expansion'] * 1e6:g} µm/m/K at {t['bar_temperature']:g} °C and the machine's "
            f"{t['machine_expansion'] * 1e6:g} µm/m/K at {t['machine_temperature']:g} °C "
            "(`fivecal docs dbb`, thermal compensation).</p>")


def _diagnosis_rows(result) -> list:
    rows = []
    for i, (n, c) in enumerate(result.ranking):
        if n in result.diagnosis:
            v, s = result.diagnosis[n], result.diagnosis_std[n]
            f, unit = _unit(n)
            value = f"{v * f:+.2f} ± {s * f:.2f} {unit}"
        else:
            amp = result.cyclic_amplitude(int(n[-1]))
            value = f"{amp[0] * 1e3:.2f} ± {amp[1] * 1e3:.2f} µm (amplitude)" if amp else ""
        rows.append((i + 1, result.label(n, short=True), f"{result.ranking_percent[n]:.0f}", _um(c), value))
    return rows


def _unit(name: str):
    if name == "squareness":
        return 1e6, "µrad"
    if name == "scale_mismatch":
        return 1e6, "µm/m"
    return 1e3, "µm"


def write_circular_report(result, out_dir: Union[str, os.PathLike], *, grade: Optional[Mapping] = None,
                          usable: bool = True, reason: str = "", scale: Optional[float] = None,
                          sources: Sequence[str] = (), embed_images: bool = True,
                          title: Optional[str] = None) -> str:
    """Write ``out_dir/report.html`` and its polar plot ``circular.png`` for
    a :class:`~fivecal.procedures.dbb.CircularResult`; returns the HTML path.
    ``grade``: the result of ``result.grade`` (PASS / FAIL per toleranced
    value); ``usable`` / ``reason``: the command's verdict on the numbers;
    ``scale``: ring spacing of the polar plot in µm (default automatic; the
    plot states it either way); ``sources``: the input files, listed."""
    out_dir = os.fspath(out_dir)
    make_dirs(out_dir)
    png = os.path.join(out_dir, "circular.png")
    plot_circular_test(result, png, scale=scale)
    v = verdict(result, grade, usable, reason)
    a1, a2 = result.plane[0], result.plane[1]
    title = title or f"fivecal circular test report — {result.plane} plane"
    if v["word"] in ("FAIL", "NOT USABLE", "NOT DETERMINED"):
        title += f" — {v['word']}"
    now = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    body = [f"<h1>{_e(title)}</h1>",
            f"<div class='sub'>fivecal {__version__} · {now} · {_e(result.header_line())}</div>",
            f"<div class='verdict {v['cls']}'><b>{_e(v['word'])}</b> — {_e(v['text'])}</div>"]
    if grade is not None:
        body.append(table_html(["toleranced value", "run", "value", "tolerance", "grade"],
                               [(i["label"], i["run"], i["shown"], i["tolerance_shown"], i["grade"])
                                for i in grade["items"]], [False, False, True, True, False]))
    body += ["<h2 id='plot'>Polar plot</h2>",
             f"<p>Radial deviation of each run from the nominal radius {result.nominal_radius:g} mm, angles from "
             f"+{a1} towards +{a2}. The scale (µm per ring) and the magnification are printed on the plot.</p>",
             _img_tag(png, out_dir, embed_images, "polar plot of the circular test"),
             "<h2 id='diagnosis'>Diagnosis, ranked by contribution to circularity</h2>",
             f"<p>Each diagnosis' contribution is the circular deviation of its fitted term alone, in % of the "
             f"circularity {_um(result.circularity)} µm (the largest G of the runs); ranges of separate terms do "
             "not add up to 100 %. Values ± one standard uncertainty.</p>",
             table_html(["rank", "diagnosis", "% of circularity", "contribution (µm)", "value"],
                        _diagnosis_rows(result), [True, False, True, True, True])]
    notes = [f"not fitted: {n}" for n in result.not_fitted]
    if result.not_significant:
        notes.append("not significant (below 3 standard uncertainties), left out: "
                     + ", ".join(result.not_significant))
    if notes:
        body.append("<ul>" + "".join(f"<li>{_e(n)}</li>" for n in notes) + "</ul>")
    other = [(result.label(n), f"{result.diagnosis[n] * _unit(n)[0]:+.3f} ± "
              f"{result.diagnosis_std[n] * _unit(n)[0]:.3f} {_unit(n)[1]}")
             for n in result.diagnosis if not any(n == r for r, _ in result.ranking)]
    body += ["<h2 id='iso'>ISO 230-4 values</h2>",
             table_html(["run", "circular deviation G (µm)", "radial deviation F max (µm)",
                         "F min (µm)", "LSC centre (µm)", "mean radius (mm)"],
                        [("CCW" if r.direction > 0 else "CW", _um(r.circular_deviation),
                          f"{r.radial_deviation_max * 1e3:+.2f}", f"{r.radial_deviation_min * 1e3:+.2f}",
                          f"({r.centre[0] * 1e3:+.2f}, {r.centre[1] * 1e3:+.2f})", f"{r.mean_radius:.5f}")
                         for r in result.runs], [False, True, True, True, False, True])]
    if result.hysteresis is not None:
        body.append(f"<p>Circular hysteresis H {_um(result.hysteresis)} µm.</p>")
    body.append(_thermal_html(result.thermal))
    body += ["<h2 id='other'>Set-up and derived values</h2>",
             table_html(["quantity", "value"], other, [False, True]),
             f"<p>Residual rms after the diagnosis {result.diagnosis_rms * 1e3:.3f} µm.</p>"]
    if sources:
        body += ["<h2 id='files'>Input</h2>", "<ul>" + "".join(f"<li><code>{_e(s)}</code></li>"
                                                                 for s in sources) + "</ul>"]
    page = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>{_e(title)}</title><style>{_CSS}{_VERDICT_CSS}</style></head><body><main>\n"
            + "\n".join(body) + "\n</main></body></html>\n")
    path = os.path.join(out_dir, "report.html")
    write_text(path, page)
    return path


def volumetric_verdict(vol, grades: Optional[Mapping] = None, usable: bool = True, reason: str = "") -> dict:
    """The volumetric page's one line: NOT USABLE, FAIL when any plane fails
    a tolerance, PASS when every plane was graded and passed, else the
    combined values alone."""
    if not usable:
        return {"word": "NOT USABLE", "cls": "fail", "text": reason or "the analysis is not usable"}
    c = f"combined circularity {_um(vol.circularity)} µm, volumetric {_um(vol.volumetric)} µm"
    if not grades:
        return {"word": "NOT GRADED", "cls": "neutral", "text": f"{c}; no tolerance given (--tolerance)"}
    bad = [f"{p} {i['label']} ({i['grade'].lower()})" for p, g in grades.items() for i in g["items"]
           if i["grade"] != "PASS"]
    if not bad:
        return {"word": "PASS", "cls": "pass", "text": f"{c}; every toleranced value of every plane within its "
                                                       "tolerance"}
    word = "FAIL" if any(g["grade"] == "FAIL" for g in grades.values()) else "NOT DETERMINED"
    return {"word": word, "cls": "fail", "text": f"{c}; " + ", ".join(bad[:6])}


def write_volumetric_report(vol, out_dir: Union[str, os.PathLike], *, grades: Optional[Mapping] = None,
                            usable: bool = True, reason: str = "", scale: Optional[float] = None,
                            sources: Optional[Mapping[str, Sequence[str]]] = None,
                            embed_images: bool = True) -> str:
    """Write ``out_dir/report.html`` for a
    :class:`~fivecal.procedures.dbb.VolumetricResult`: the verdict over every
    plane, the planes side by side (``volumetric.png``, one ring spacing),
    the combined values, and each plane's own circular test report in
    ``out_dir/<plane>/report.html`` (graded by ``grades[plane]``, the planes'
    :meth:`grade` results). ``sources``: the input files per plane."""
    out_dir = os.fspath(out_dir)
    make_dirs(out_dir)
    grades = dict(grades or {})
    sources = dict(sources or {})
    links = {}
    for p, r in vol.planes.items():
        sub = os.path.join(out_dir, p)
        write_circular_report(r, sub, grade=grades.get(p), usable=usable, reason=reason, scale=scale,
                              sources=sources.get(p, ()), embed_images=embed_images,
                              title=f"fivecal circular test report — {p} plane of a volumetric test")
        links[p] = f"{p}/report.html"
    png = os.path.join(out_dir, "volumetric.png")
    plot_volumetric(vol, png)
    v = volumetric_verdict(vol, grades, usable, reason)
    title = "fivecal volumetric circular test report"
    if v["word"] in ("FAIL", "NOT USABLE", "NOT DETERMINED"):
        title += f" — {v['word']}"
    now = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    rows = []
    for row in vol.plane_rows():
        p = row["plane"]
        r = vol.planes[p]
        top = r.label(row["top"][0], short=True) + f" {_um(row['top'][1])} µm" if row["top"] else "-"
        g = grades.get(p)
        rows.append((p, _um(row["circularity"]), _um(row["hysteresis"]) if row["hysteresis"] is not None else "-",
                     top, g["grade"] if g else "not graded", row["samples"]))
    body = [f"<h1>{_e(title)}</h1>",
            f"<div class='sub'>fivecal {__version__} · {now} · {_e(vol.header_line())}</div>",
            f"<div class='verdict {v['cls']}'><b>{_e(v['word'])}</b> — {_e(v['text'])}</div>",
            "<h2 id='planes'>Planes</h2>",
            table_html(["plane", "circularity G (µm)", "hysteresis H (µm)", "largest contribution", "grade",
                        "samples"], rows, [False, True, True, False, False, True]),
            "<p>Each plane's full report (polar plot, ranked diagnosis, ISO 230-4 values): "
            + ", ".join(f"<a href='{_e(u)}'>{_e(p)}</a>" for p, u in links.items()) + ".</p>",
            "<h2 id='plot'>Polar plots</h2>",
            "<p>The planes at one ring spacing, so that they compare at a glance; the scale is printed on the "
            "plot.</p>",
            _img_tag(png, out_dir, embed_images, "polar plots of the planes"),
            "<h2 id='combined'>Combined values</h2>"]
    combined = [("combined circularity (largest G of any plane)", f"{_um(vol.circularity)} µm"),
                ("volumetric (shell about each plane's centre holding every trace)", f"{_um(vol.volumetric)} µm")]
    c = vol.scale_closure()
    if c is not None:
        combined.append(("scale mismatch closure (X-Y)+(Y-Z)+(Z-X), 0 when consistent", f"{c * 1e6:.2f} µm/m"))
    for ax, vals in sorted(vol.axis_values().items()):
        combined.append((f"backlash {ax}", ", ".join(f"{x * 1e3:+.2f} ± {s * 1e3:.2f} µm ({p})"
                                                     for p, x, s in vals)))
    body.append(table_html(["quantity", "value"], combined, [False, True]))
    # one bar and one machine: every plane was corrected alike
    body.append(_thermal_html(next((r.thermal for r in vol.planes.values() if r.thermal), None)))
    files = [(p, f) for p, fs in sources.items() for f in fs]
    if files:
        body += ["<h2 id='files'>Input</h2>", "<ul>" + "".join(f"<li>{_e(p)}: <code>{_e(f)}</code></li>"
                                                                 for p, f in files) + "</ul>"]
    page = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>{_e(title)}</title><style>{_CSS}{_VERDICT_CSS}</style></head><body><main>\n"
            + "\n".join(body) + "\n</main></body></html>\n")
    path = os.path.join(out_dir, "report.html")
    write_text(path, page)
    return path
