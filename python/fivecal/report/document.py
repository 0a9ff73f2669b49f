"""The HTML report of an identification: one self-contained HTML file (the
plots embedded as base64 PNG) written next to the same plots as PNG files and
the result JSON.

Contents: machine and data summary (with the setups of each kind of data),
fit quality, identifiability (confounded groups, strongly correlated pairs),
the parameter table in µm / µrad / µm/m with one-sigma uncertainties, and
the plots the kinds of data present call for: residual vectors in the table
frame for touch probing (thesis Figure 4-7 style), per-component deviations
against the rotary angle for R-test / 3D ball data, polar plots per setup,
plane and bar length for double ball bar data; then the residual histogram,
parameter bars with ±2σ error bars and the correlation matrix.

    from fivecal.report import write_report
    path = write_report(result, "report_dir")        # -> report_dir/report.html

Ball bar plots come from ``fivecal.report.polar.report_figures(result, out_dir)``,
called when the dataset has ``dbb`` observations; it returns a list of PNG
paths or ``(path, caption)`` pairs written inside ``out_dir``. A failure
there (or in the R-test plots) is shown in the report, not raised.
"""
from __future__ import annotations

import datetime
import json
import os
from typing import List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _core, guards
from .._version import __version__
from ..files import make_dirs, write_text
from ..guards import NEAR_SINGULAR_R as _NEAR_R, PARTLY_INFORMED as _PARTLY
from ..identification import MICRO_UNITS, noise_lines, verdict_lines
from ..procedures.dbb import trace_from_dataset
from ..units import display_scale, format_value
from . import plots, polar
from .history import sections_and_standing as _history_sections
from .markup import _e, _img_tag, table_html

__all__ = ["write_report", "Section"]

Section = Tuple[str, str]  # (title, HTML body)

Figure = Tuple[str, str]   # (png path, caption)

_CSS = """
body{font-family:-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;margin:0;color:#222;background:#fafafa}
main{max-width:1180px;margin:0 auto;padding:18px 28px 60px;background:#fff}
h1{font-size:1.6em;margin:0.2em 0 0.1em}h2{font-size:1.25em;border-bottom:2px solid #4c78a8;
padding-bottom:3px;margin-top:1.8em}h3{font-size:1.05em;margin-bottom:0.3em}
.sub{color:#666;margin-bottom:1em}
table{border-collapse:collapse;margin:0.5em 0 1em;font-size:0.92em}
th,td{border:1px solid #ddd;padding:3px 9px;text-align:left;vertical-align:top}
th{background:#eef2f7}td.num{text-align:right;font-family:Menlo,Consolas,monospace;white-space:nowrap}
tr.conf td{background:#fff4e5}tr.implausible td{background:#fdeeee}tr.fixed td{color:#777}
.kv td:first-child{color:#555;white-space:nowrap}
.box{border-left:4px solid #4c78a8;background:#f3f6fa;padding:8px 14px;margin:0.8em 0}
.warn{border-left-color:#e4a000;background:#fff8e6}.bad{border-left-color:#d62728;background:#fdeeee}
.ok{border-left-color:#2ca02c;background:#eff8ef}
figure{margin:1em 0 1.6em}figure img{max-width:100%;border:1px solid #e3e3e3}
figcaption{color:#555;font-size:0.9em;margin-top:4px}
nav a{margin-right:12px}small,.muted{color:#777}
details summary{cursor:pointer;color:#4c78a8}
ul.families{margin:2px 0 0;padding-left:1.2em}ul.families li{margin:1px 0}
table.findings td:first-child{white-space:normal;width:13em}
pre{background:#f6f6f6;padding:8px;overflow-x:auto;font-size:0.85em}
"""


def _fmt(v: float, digits: int = 3) -> str:
    if v is None or not np.isfinite(v):
        return "–"
    return f"{v:.{digits}f}"


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _kind(machine_names: set, machine, name: str) -> str:
    if name in machine_names:
        return machine.parameter_kind(name)
    return name.split(".", 1)[0] if "." in name else "setup"


def _negative_axes(machine) -> set:
    return {a["name"] for a in machine.axes if min(a["direction"]) < -0.5 and max(a["direction"]) < 0.5}


def _machine_section(machine) -> str:
    rows = []
    for a in machine.axes:
        d = ", ".join(f"{x:g}" for x in a["direction"])
        p = ", ".join(f"{x:g}" for x in a.get("point", [0, 0, 0])) if a["type"] == "rotary" else ""
        rows.append(f"<tr><td>{_e(a['name'])}</td><td>{_e(a['type'])}</td><td>[{d}]</td>"
                    f"<td>{('[' + p + ']') if p else ''}</td></tr>")
    tip = ", ".join(f"{x:g}" for x in machine.tip)
    return (f'<table class="kv"><tr><td>name</td><td>{_e(machine.name)}</td></tr>'
            f"<tr><td>topology</td><td><code>{_e(machine.topology)}</code> (workpiece to tool)</td></tr>"
            f"<tr><td>workpiece chain</td><td>{_e(' → '.join(machine.workpiece_chain) or '–')} "
            f"<small>(from the foundation outward)</small></td></tr>"
            f"<tr><td>tool chain</td><td>{_e(' → '.join(machine.tool_chain) or '–')}</td></tr>"
            f"<tr><td>tool tip</td><td>[{tip}] mm</td></tr></table>"
            "<table><tr><th>axis</th><th>type</th><th>direction (F, zero pose)</th>"
            "<th>point (mm)</th></tr>" + "".join(rows) + "</table>")


def _kinds() -> dict:
    """name -> what the report shows of the kind (``report`` of
    ``_core.observation_kinds()``): the report names no kind itself."""
    return {k["name"]: k["report"] for k in _core.observation_kinds()}


def _setup_counts(obs, kind: str, key: str = "setup") -> dict:
    counts: dict = {}
    for o in obs:
        if o.get("type") == kind:
            k = o.get(key, "") or f"(no {key} id)"
            counts[k] = counts.get(k, 0) + 1
    return counts


def _dbb_setup_text(dataset, kind: str) -> str:
    """Each DBB setup with its sample count, plane and bar length."""
    parts = []
    for setup, length, idx in polar.dbb_groups(dataset):
        plane = ""
        if len(idx) >= 3:
            try:
                t = trace_from_dataset(dataset, setup, idx)
                plane = (f", plane {t.plane}" if np.ptp(t.angles) >= polar.MIN_SWEEP else
                         f", no circle: the balls sweep {np.ptp(t.angles):.2g}°")
            except ValueError:
                plane = ""
        parts.append(f"{setup or '(no setup id)'} ({_count(len(idx), 'sample')}{plane}, bar {length:g} mm)")
    return ", ".join(parts)


def _data_section(dataset, result) -> str:
    obs = dataset.observations
    kinds = _kinds()
    types: dict = {}
    for o in obs:
        types[o["type"]] = types.get(o["type"], 0) + 1
    rot = [a for a in dataset.machine.axis_names if a in "ABCS"]
    # a ball bar sweeps the axes: its poses are no indexations
    indexed = {t for t in types if kinds.get(t, {}).get("indexed", True)}
    idx = {tuple(round(float(o["axes"].get(a, 0.0)), 1) for a in rot) for o in obs if o["type"] in indexed}
    art = dataset.artefact or {}
    tip_r = (dataset._view().get("probe") or {}).get("tip_radius")  # the shared view: no copy of 10^5 observations
    targets = sorted({o.get("target") for o in obs if o.get("target")}, key=str)
    rows = [("observations", ", ".join(f"{n} {t}" for t, n in types.items()) or "none")]
    if result is not None:  # a dataset alone (its notebook view) has no residuals yet
        rows.append(("residual rows", f"{len(result.residuals)} (observations plus scale bars)"))
    if indexed:
        rows.append(("rotary indexations", f"{len(idx)} distinct ({', '.join(rot)})" if rot else "–"))
    lists = [(r["target_list"], name) for name, r in kinds.items() if r["target_list"]]
    if any(kinds.get(t, {}).get("target_list") for t in types):
        rows += [("artefact", ", ".join(_count(len(art.get(k, [])), w) for k, w in
                                        lists + [("scale_bars", "scale bar")])),
                 ("targets touched", f"{len(targets)}" + (f": {', '.join(map(str, targets[:40]))}"
                                                           + (" …" if len(targets) > 40 else "") if targets else "")),
                 ("probe tip radius", f"{tip_r:g} mm" if tip_r is not None else "–")]
    # The observations by set-up id, one row per heading (kinds that share an
    # instrument's heading, a tracker's points and poses, share its row).
    headings: dict = {}
    for name, r in kinds.items():
        if name in types and r["setup_heading"]:
            headings.setdefault(r["setup_heading"], []).append(name)
    for heading, names in headings.items():
        if len(names) == 1 and kinds[names[0]]["figures"] == "polar":
            n = len(_setup_counts(obs, names[0]))
            rows.append((f"{heading} ({n})", _dbb_setup_text(dataset, names[0])))
            continue
        by: dict = {}
        for o in obs:
            if o["type"] in names:
                key = kinds[o["type"]]["setup_key"] or "setup"
                k = o.get(key, "") or f"(no {key} id)"
                by.setdefault(k, {}).setdefault(o["type"], 0)
                by[k][o["type"]] += 1
        if len(names) == 1:
            word = kinds[names[0]]["count_word"]
            text = ", ".join(f"{k} ({_count(sum(v.values()), word)})" for k, v in by.items())
        else:
            text = ", ".join(f"{k} ({', '.join(_count(n, t) for t, n in v.items())})" for k, v in by.items())
        rows.append((f"{heading} ({len(by)})", text))
    return '<table class="kv">' + "".join(f"<tr><td>{_e(k)}</td><td>{_e(v)}</td></tr>" for k, v in rows) \
        + "</table>"


def _verdict_banner(result, fd, standing=None, anchor: bool = True) -> str:
    """The verdict at the top of the report, with its grade in one word: red
    NOT USABLE when the fit is not usable (never green then), red FAIL when a
    usable calibration fails its tolerances (the history's pass / fail),
    amber UNDECIDED or ALARM (undecided against a tolerance; a change the
    history's CUSUM detected at this calibration) and amber OK WITH
    RESERVATIONS, green OK only for a usable fit with nothing left
    undetermined or inseparable and no left-out error carried into an
    estimate beyond its σ, that passes whatever it was graded against.
    ``anchor``: the report's one ``id='verdict'``; a notebook page shows many
    results, and an id must be unique in a page."""
    a = fd.assessment
    ident = " id='verdict'" if anchor else ""
    if not a.usable:
        return (f"<div class='box bad'{ident}><b>NOT USABLE — {_e(a.verdict.replace('_', ' '))}.</b> "
                f"{_e(a.reason[:1].upper() + a.reason[1:])}. Do not compensate a machine with these "
                "values: compensation, error tables and G-code refuse this result (force=True / "
                "<code>--force</code> only to inspect it). The values below are shown for diagnosis.</div>")
    cls = "warn" if (fd.undetermined or fd.inseparable or fd.implausible or fd.partly or fd.carried) else "ok"
    notes = []
    if fd.undetermined:
        notes.append(f"{len(fd.undetermined)} parameters not determined by this data (left out of "
                     "compensation)")
    if fd.partly:
        notes.append(f"{len(fd.partly)} informed only in part")
    if fd.implausible:
        notes.append(f"implausible values: {', '.join(fd.implausible)}")
    if fd.inseparable:
        notes.append(f"{len(fd.inseparable)} pairs with |r| ≥ {_NEAR_R:g}")
    if fd.carried:
        # their σ assumes the left-out error is 0: a plausible value moves them by more
        moved = list(dict.fromkeys(c.estimate for c in fd.carried))
        notes.append(f"{_count(len(moved), 'estimate')} ({guards.name_list(moved)}) would move by more than "
                     f"{guards.CARRIED_SIGMAS:g} σ under an error the preset left out")
    grade = "OK WITH RESERVATIONS" if cls == "warn" else "OK"
    head = []
    if standing is not None and standing.grade == "fail":
        cls, grade = "bad", "FAIL"
        head.append("out of tolerance: " + _e(guards.name_list(standing.failed) or "see Pass / fail")
                    + " (see <a href='#history-grade'>Pass / fail</a>)")
    elif standing is not None and standing.alarms:
        cls, grade = "warn", "ALARM"
        head.append("the calibration history detected a change at this calibration: "
                    + _e(guards.name_list(standing.alarms)) + " (see Calibration history)")
    elif standing is not None and standing.grade == "undecided":
        cls, grade = "warn", "UNDECIDED"
        head.append("within the uncertainty of a tolerance limit (see <a href='#history-grade'>Pass / fail</a>)")
    elif standing is not None and standing.grade == "pass":
        notes.insert(0, "within every tolerance")
    # the grade stands in bold before it: the fit's own words without "OK (usable)"
    text = "Usable: " + " ".join(verdict_lines(result, fd)).split(": ", 1)[-1]
    return (f"<div class='box {cls}'{ident}><b>{grade}.</b> "
            + "".join(f"<b>{h}.</b> " for h in head) + _e(text)
            + (f" {_e('; '.join(notes))}." if notes else "") + "</div>")


#: names a summary row lists before "and N more" (every one: the Parameters section)
_SHOWN_NAMES = 24
#: confounded groups the Identifiability section lists (every one: result.json)
_SHOWN_GROUPS = 10


def _not_determined_html(fd) -> str:
    """What the data could not tell, one line per family with the
    measurement that would tell it (identification.not_determined_lines)."""
    families = fd.assessment.not_determined
    if not families:
        return _e(_name_list(fd.undetermined)) if fd.undetermined else "none"
    items = []
    for f in families:
        n, of = len(f.get("names", [])), f.get("estimated")
        items.append(f"<li><b>{_e(f['family'])}</b> ({n}{f' of {of}' if of else ''}): {_e(f['why'])}</li>")
    return "<ul class='families'>" + "".join(items) + "</ul>"


def _name_list(names, limit: int = _SHOWN_NAMES) -> str:
    names = list(names)
    return ", ".join(names[:limit]) + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _findings_section(result, fd) -> str:
    """What was identified, what was informed only in part, what the data
    could not tell (one line per family, with what would tell it): the
    compact summary under the verdict, before the details."""
    machine_names = set(result.dataset.machine.parameter_names())

    def names(lst):
        # machine errors by name (the first few); the many setup values (probe tip, artefact) as a count
        mach = [n for n in lst if n in machine_names and not n.startswith("tip.")]
        setup = len(lst) - len(mach)
        text = ", ".join(f"<code>{_e(n)}</code>" for n in mach[:_SHOWN_NAMES])
        if len(mach) > _SHOWN_NAMES:
            text += f" and {len(mach) - _SHOWN_NAMES} more (see Parameters)"
        if setup:
            rest = _name_list([n for n in lst if n not in mach], 6)
            text += (" and " if text else "") + _count(setup, "setup parameter") + f" ({_e(rest)})"
        return text or "none"

    trusted = fd.assessment.verdict in ("ok", "undetermined")  # see identification.finding_lines
    types: dict = {}
    for t in result.dataset.observation_types:
        types[t] = types.get(t, 0) + 1
    chi2 = getattr(result, "chi2", None)
    fit = (f"{_count(len(result.dataset), 'observation')} ({', '.join(f'{n} {t}' for t, n in types.items())}); "
           f"{result.n_parameters} parameters estimated; residual rms {result.rms * 1e3:.3f} µm, "
           f"σ̂ {result.sigma * 1e3:.3f} µm"
           + (f"; χ² {chi2:.4g} for {getattr(result, 'dof', '?')} degrees of freedom" if chi2 is not None
              and np.isfinite(chi2) else ""))
    rows = [("Data and fit", _e(fit)),
            ("Identified", names(fd.identified) if trusted else
             f"none: the fit is not usable ({len(fd.identified)} parameters estimated without a "
             "trustworthy value)")]
    if fd.left_out:
        rows.append((f"Left out by the preset ({len(fd.left_out)})",
                     "<small>(not estimated; judged against the priors of the machine's kind)</small> "
                     + "; ".join(f"<code>{_e(n)}</code>: {_e(w)}" for n, w in list(fd.left_out.items())[:12])
                     + (f" and {len(fd.left_out) - 12} more" if len(fd.left_out) > 12 else "")))
    if fd.carried:
        rows.append((f"Carried from what was left out ({len(fd.carried)})",
                     f"<small>(an estimate's σ assumes the errors left out are 0; at its plausible size each of "
                     f"these would move the estimate by more than {guards.CARRIED_SIGMAS:g} σ)</small> "
                     + "; ".join(f"<code>{_e(c.name)}</code> ({_e(format_value(c.name, c.plausible))}) would move "
                                 f"<code>{_e(c.estimate)}</code> by {_e(format_value(c.estimate, c.shift))} = "
                                 f"{abs(c.sigmas):.3g} σ" for c in fd.carried[:12])
                     + (f" and {len(fd.carried) - 12} more" if len(fd.carried) > 12 else "")))
    if fd.informed or fd.partly:
        rows.append(("Informed only in part", f"<small>(the data narrowed the plausible range less than "
                     f"{1 / _PARTLY:g}-fold)</small> " + names(fd.partly)))
    rows.append((f"Not determined by this data ({len(fd.undetermined)})",
                 "<small>Values arbitrary, never compensated. Per family, why and what measurement "
                 "would determine them:</small>" + _not_determined_html(fd) if fd.undetermined else "none"))
    if fd.inseparable:
        sep = sorted({n for a, b, _ in fd.inseparable for n in (a, b)})
        rows.append(("Not separable from one another", f"<small>(|r| ≥ {_NEAR_R:g}; only combinations are "
                     "determined)</small> " + names(sep)))
    if fd.absent:
        rows.append(("Error classes the data show no sign of", "<small>(held near 0 in the point "
                     "estimate)</small> " + _e(", ".join(c.replace("_", " ") for c in fd.absent))
                     + (f"; determined there, so held near 0: {names(fd.held)}" if fd.held else "")))
    if fd.implausible:
        rows.append(("Implausible", "<small>(far outside the plausible size: check units, setup, the "
                     "nominal)</small> " + names(fd.implausible)))
    return ('<table class="kv findings">' + "".join(f"<tr><td>{_e(k)}</td><td>{v}</td></tr>" for k, v in rows)
            + "</table>")


def _fit_section(result) -> str:
    fd = guards.findings(result)
    a = fd.assessment
    cls = "bad" if not a.usable else ("warn" if result.unidentifiable or fd.inseparable else "ok")
    chi2 = getattr(result, "chi2", None)
    rows = []
    for unit, u in (getattr(result, "residual_units", None)
                    or {"mm": {"rms": result.rms, "max_abs": result.max_abs, "sigma": result.sigma}}).items():
        f, shown = MICRO_UNITS.get(unit, (1.0, unit))
        of = "" if unit == "mm" else f" ({unit} rows: rotations)"
        rows += [(f"residual rms{of}", f"{u['rms'] * f:.3f} {shown}"),
                 (f"largest |residual|{of}", f"{u['max_abs'] * f:.3f} {shown}"),
                 (f"σ̂ (a posteriori){of}", f"{u['sigma'] * f:.3f} {shown}")]
    rows += [("parameters", f"{result.n_parameters} estimated, rank {result.rank}"),
            ("condition number", f"{result.condition_number:.4g} (of the scaled Jacobian)"),
            ("solver", f"{'converged' if result.converged else 'NOT converged'} in {result.iterations} "
                       "iterations")]
    for line in noise_lines(result):
        rows.append(("instrument noise", line))
    if chi2 is not None and np.isfinite(chi2):
        rows.append(("χ² against the " + ("estimated" if getattr(result, "variance_components", None)
                                           else "declared") + " noise",
                     f"{chi2:.4g} for {getattr(result, 'dof', '?')} degrees of freedom, p = "
                     f"{_fmt(getattr(result, 'chi2_p', float('nan')), 3)}: "
                     + ("adequate" if getattr(result, "adequate", True) else "INADEQUATE")
                     + (f" ({getattr(result, 'adequacy', '')})" if getattr(result, "adequacy", "") else "")))
    if result.outliers:
        ids = result.residual_table()
        rows.append(("robust loss", f"{len(result.outliers)} outlier rows flagged: " + ", ".join(
            f"{i} ({ids[i]['id']})" if 0 <= i < len(ids) and ids[i]["id"] else str(i)
            for i in result.outliers[:30])))
    verdict = ("The fit converged and every estimated parameter is identifiable from this data."
               if cls == "ok" else
               f"Not usable: {a.reason}." if cls == "bad" else
               "Some parameters cannot be separated with this data (see Identifiability).")
    return (f'<div class="box {cls}">{_e(verdict)}</div><table class="kv">'
            + "".join(f"<tr><td>{_e(k)}</td><td>{_e(v)}</td></tr>" for k, v in rows) + "</table>")


def _largest_residuals(result, n: int = 10) -> str:
    """The rows with the largest |residual|, named by observation id (all rows: residuals.csv)."""
    top = np.argsort(-np.abs(np.asarray(result.residuals)), kind="stable")[:n]
    rows = result.residual_table(top)
    if not rows:
        return ""
    return (f"<p>The {len(rows)} largest residuals (every row with its observation id: "
            "<a href='residuals.csv'>residuals.csv</a>):</p>"
            + table_html(["row", "id", "type", "target / setup", "component", "residual [µm]"],
                         [(r["row"], r["id"], r["type"], r["target"], r["component"],
                           f"{r['residual'] * 1e3:.3f}") for r in rows],
                         numeric=[True, False, False, False, False, True]))


def _strong_pairs(result, threshold: float = 0.9, limit: int = 20) -> List[Tuple[str, str, float]]:
    C = np.asarray(result.correlation)
    est = result.estimated
    pairs = []
    for i in range(len(est)):
        for j in range(i + 1, len(est)):
            if abs(C[i, j]) >= threshold:
                pairs.append((est[i], est[j], float(C[i, j])))
    pairs.sort(key=lambda p: -abs(p[2]))
    return pairs[:limit]


def _identifiability_section(result) -> str:
    parts = []
    real = [g for g in result.unidentifiable if len(g) > 1]
    if real:
        parts.append('<div class="box warn">These groups are <b>confounded</b>: the data cannot separate '
                     "their members; only combinations are determined. Fix all but one member of each "
                     "group, or add measurements that move them differently.</div><ul>")
        for g in real[:_SHOWN_GROUPS]:
            parts.append("<li>{" + ", ".join(f"<code>{_e(n)}</code>" for n in g[:_SHOWN_NAMES])
                         + (f" and {len(g) - _SHOWN_NAMES} more" if len(g) > _SHOWN_NAMES else "") + "}</li>")
        if len(real) > _SHOWN_GROUPS:
            parts.append(f"<li>and {len(real) - _SHOWN_GROUPS} more groups (every one: <code>unidentifiable</code> "
                         "in result.json)</li>")
        parts.append("</ul>")
    fd = guards.findings(result)
    group = {n: i for i, g in enumerate(result.unidentifiable) for n in g}
    # pairs inside one confounded group are already named above
    extra = [(a, b, r) for a, b, r in fd.inseparable if a not in group or group[a] != group.get(b)]
    if extra:
        names = sorted({n for a, b, _ in extra for n in (a, b)})
        parts.append(f'<div class="box bad">{_count(len(extra), "pair")} of estimates '
                     f"{'has' if len(extra) == 1 else 'have'} "
                     f"|r| ≥ {_NEAR_R:g}: the data cannot separate "
                     f"{_e(', '.join(names[:12]))}{' …' if len(names) > 12 else ''} in practice; "
                     "only their combinations are determined (condition number "
                     f"{result.condition_number:.3g}). Fix all but one of each pair or add "
                     "measurements that move them differently.</div>")
    if fd.undetermined and not real:
        parts.append(f'<div class="box warn">{_count(len(fd.undetermined), "parameter")} not determined by '
                     "this data (per family at the top, every one at the end); their values are arbitrary "
                     "and are never used for compensation.</div>")
    if not result.unidentifiable and not fd.inseparable and not fd.undetermined:
        if fd.assessment.usable:
            parts.append(f'<div class="box ok">No confounded groups: the {len(result.estimated)} estimated '
                         f"parameters are separable (rank {result.rank}, condition number "
                         f"{result.condition_number:.3g}).</div>")
        else:
            parts.append(f'<div class="box bad">No confounded group was found, but the fit is not usable '
                         f"({_e(fd.assessment.reason)}), so separability says nothing about these "
                         "values.</div>")
    # pairs of parameters the data determined (an undetermined one's value is the prior's)
    und = set(fd.undetermined)
    pairs = [p for p in _strong_pairs(result, limit=100000)
             if abs(p[2]) < _NEAR_R and p[0] not in und and p[1] not in und]
    machine_names = set(result.dataset.machine.parameter_names())  # includes tip.x|y|z
    both = [p for p in pairs if p[0] in machine_names and p[1] in machine_names][:20]
    mixed: dict = {}
    for a, b, r in pairs:
        if (a in machine_names) != (b in machine_names):
            m, o = (a, b) if a in machine_names else (b, a)
            mixed.setdefault(m, []).append((o, r))
    setup_only = [p for p in pairs if p[0] not in machine_names and p[1] not in machine_names]
    if pairs:
        parts.append(f"<h3>Strongly correlated pairs (0.9 ≤ |r| &lt; {_NEAR_R:g})</h3><p class='muted'>"
                     "Their uncertainties are inflated by the correlation.</p>")
    rows = [(a, b, f"{r:+.3f}") for a, b, r in both]
    for m, lst in list(mixed.items())[:20]:
        o, r = lst[0]
        more = f" and {len(lst) - 1} more setup parameters (|r| ≥ 0.9)" if len(lst) > 1 else ""
        rows.append((m, o + more, f"{r:+.3f}"))
    if rows:
        parts.append("<table><tr><th>parameter</th><th>correlated with</th><th>r</th></tr>")
        parts += [f"<tr><td>{_e(a)}</td><td>{_e(b)}</td><td class='num'>{r}</td></tr>" for a, b, r in rows]
        parts.append("</table>")
    if setup_only:
        names = sorted({n for a, b, _ in setup_only for n in (a, b)})
        parts.append(f"<p>{len(setup_only)} pair{'s' if len(setup_only) != 1 else ''} among setup "
                     f"parameters only ({_e(', '.join(names[:10]))}{' …' if len(names) > 10 else ''}), "
                     "typically artefact offsets against each other.</p>")
    return "".join(parts)


def _parameter_rows(result, machine, truth: Optional[Mapping[str, float]]) -> Tuple[str, str, str]:
    """Table rows: the machine errors and the setup parameters the data
    determined (and implausible ones), then every parameter it did not
    determine (for the collapsed list at the end of the report)."""
    machine_names = set(machine.parameter_names())
    confounded = {n: g for g in result.unidentifiable for n in g}
    negative = _negative_axes(machine)
    order = {n: i for i, n in enumerate(machine.parameter_names())}
    est = list(result.estimated)
    mach = sorted([n for n in est if n in machine_names and not n.startswith("tip.")], key=order.get)
    other = [n for n in est if n not in mach]

    fd = guards.findings(result)
    und, part, impl, held = set(fd.undetermined), set(fd.partly), set(fd.implausible), set(fd.held)
    prior = getattr(result, "prior_std", None) or {}

    def row(n: str) -> str:
        f, unit = display_scale(n)
        v, s = result.values[n], result.std.get(n, float("nan"))
        sig = abs(v) / s if s and np.isfinite(s) and s > 0 else float("nan")
        notes = []
        if n in und:
            notes.append("NOT DETERMINED by this data: value arbitrary, never compensated")
        elif n in held:
            notes.append("held near 0: its class shows no sign in the data")
        elif n in part:
            notes.append("informed only in part by the data")
        if n in impl:
            notes.append("IMPLAUSIBLE: far outside its plausible size")
        if n in confounded and len(confounded[n]) > 1:
            notes.append("confounded with " + _name_list([x for x in confounded[n] if x != n], 3))
        if len(n) == 4 and n[0] == "E" and n[1] == n[2] and n[3] == "1" and n[2] in negative:
            notes.append("axis moves along a negative basis vector: positive shortens the travel")
        if np.isfinite(sig) and sig < 2:
            notes.append("not significant (|value| < 2σ)")
        cells = [f"<td><code>{_e(n)}</code></td><td>{_e(_kind(machine_names, machine, n))}</td>",
                 f"<td class='num'>{_fmt(v * f)}</td><td class='num'>{_fmt(s * f)}</td>",
                 f"<td class='num'>{_fmt(2 * s * f)}</td><td>{_e(unit)}</td>",
                 f"<td class='num'>{_fmt(sig, 1)}</td>"]
        if prior:
            ps, inf = prior.get(n), fd.informed.get(n)
            cells.append(f"<td class='num'>{_fmt(ps * f) if ps is not None else '–'}</td>"
                         f"<td class='num'>{_fmt(inf, 2) if inf is not None else '–'}</td>")
        if truth is not None:
            t = truth.get(n)
            z = (v - t) / s if t is not None and s > 0 else float("nan")
            cells.append(f"<td class='num'>{_fmt(t * f) if t is not None else '–'}</td>"
                         f"<td class='num'>{_fmt(z, 2)}</td>")
        cells.append(f"<td>{_e('; '.join(notes))}</td>")
        cls = ' class="implausible"' if n in impl else ' class="conf"' if (n in confounded or n in und) else ""
        return f"<tr{cls}>" + "".join(cells) + "</tr>"

    head = ("<tr><th>parameter</th><th>kind</th><th>value</th><th>u (1σ)</th><th>U (2σ)</th>"
            "<th>unit</th><th>|value|/σ</th>"
            + ("<th>prior σ</th><th>informed (σ/prior σ)</th>" if prior else "")
            + ("<th>true</th><th>z</th>" if truth is not None else "")
            + "<th>notes</th></tr>")
    told = lambda n: (n not in und and n not in held) or n in impl  # noqa: E731
    return (head + "".join(row(n) for n in mach if told(n)), head + "".join(row(n) for n in other if told(n)),
            head + "".join(row(n) for n in mach + other if not told(n)))


def _parameter_section(result, machine, truth) -> Tuple[str, str]:
    """The Parameters section (what the data determined) and the collapsed
    list of every parameter it did not determine, for the end of the report."""
    mach_rows, other_rows, und_rows = _parameter_rows(result, machine, truth)
    fixed = {n: v for n, v in result.values.items() if n not in result.std}
    n_mach, n_other, n_und = (r.count("<tr") - 1 for r in (mach_rows, other_rows, und_rows))
    out = ["<p>Values in µm, µrad, µm/m (µm/m per mm of travel for linear error-motion slopes, "
           "µrad/rad for rotary ones); files keep mm and rad. u: one-sigma standard uncertainty; "
           "U: expanded uncertainty (k = 2). Sign conventions: see the notes at the end."
           + (f" The {_count(n_und, 'parameter')} the data did not determine (or held near 0) are listed at the "
              "end." if n_und else "") + "</p>",
           "<h3>Machine errors</h3>",
           f"<table>{mach_rows}</table>" if n_mach else
           "<p>None determined by this data: no values to show.</p>"]
    if n_other:
        out += [f"<details{' open' if n_other <= 12 else ''}><summary>Setup parameters (probe tip, "
                f"artefact, ball bar): {n_other}</summary><table>", other_rows, "</table></details>"]
    if fixed:
        out.append("<h3>Fixed at non-zero values (not estimated)</h3><table><tr><th>parameter</th>"
                   "<th>value</th><th>unit</th></tr>")
        for n, v in fixed.items():
            f, unit = display_scale(n)
            out.append(f"<tr class='fixed'><td>{_e(n)}</td><td class='num'>{_fmt(v * f)}</td>"
                       f"<td>{_e(unit)}</td></tr>")
        out.append("</table>")
    rest = ("" if not n_und else
            f"<details id='undetermined'><summary>Every parameter this data did not determine or held near 0 "
            f"({n_und})</summary><table>" + und_rows + "</table></details>")
    return "".join(out), rest


_CONVENTIONS = """
<ul>
<li>Units: files and APIs keep mm and rad; this report shows µm, µrad, µm/m. Rotary commands are in degrees.</li>
<li>Location errors <code>E{X,Y,Z}0k</code> / <code>E{A,B,C}0k</code>: offset along / rotation about the x, y, z
axes of the machine frame F (at the zero pose) of axis k relative to the next axis toward the foundation
(chain-relative: C relative to B on a B-C table). Positive = displaced in +x / rotated counter-clockwise
about +x (right-hand rule). On the workpiece side that moves the workpiece, so the tool seen from the part
moves the opposite way.</li>
<li>Error motions <code>E{D}{k}{1,2,3}</code>: coefficients of q, q², q³ (q in mm for linear axes, rad for rotary
axes) of the error motion of axis k along/about the axes of F. For an axis whose direction is a negative basis
vector a positive <code>Ekk1</code> shortens the travel.</li>
<li>Backlash <code>Ekkb</code>: added to the command in the direction the axis last moved.</li>
<li>Residuals (`fivecal docs formats`): for a facet touch n̂·(P − a) − r − facet offset, i.e. how far the identified
model puts the stylus ball from the facet at the moment the probe triggered (mm; 0 for a perfect model). Residual
vectors are these distances along the surface normal, drawn in the workpiece (table) frame.</li>
</ul>
"""


def _dbb_figures(result, out_dir: str) -> Tuple[List[Figure], Optional[str]]:
    """Polar plots from fivecal.report.polar when the data has DBB traces."""
    if not {n for n, r in _kinds().items() if r["figures"] == "polar"} & set(result.dataset.observation_types):
        return [], None
    try:
        out = []
        for f in list(polar.report_figures(result, out_dir) or []):
            path, cap = (f, "Double ball bar trace (polar plot)") if isinstance(f, (str, os.PathLike)) else f
            out.append((os.fspath(path), str(cap)))
        return out, None
    except Exception as e:  # a plotting problem must not lose the rest of the report
        return [], f"DBB polar plots could not be drawn: {_e(type(e).__name__)}: {_e(e)}"


def determined_machine_errors(result, fd) -> List[str]:
    """The estimated machine errors the data determined, the ones the
    parameter and correlation plots show: an undetermined value is the
    prior's, and a hundred of them made plots thousands of pixels wide with
    nothing to read."""
    machine_names = set(result.dataset.machine.parameter_names())
    und = set(fd.undetermined) | set(fd.held)
    return [n for n in result.estimated if n in machine_names and not n.startswith("tip.") and n not in und]


def _kind_figures(result, out_dir: str) -> Tuple[List[Figure], List[str]]:
    """The figures chosen by the kinds of data present: residual vectors for
    touch probing (facet, sphere), per-component deviations for ball3d
    (R-test), polar panels and residuals per setup for DBB. Returns
    (figures, notes on figures that could not be drawn)."""
    types = set(result.dataset.observation_types)
    first: List[Figure] = []
    notes: List[str] = []
    if types & set(plots.PROBING):
        p = os.path.join(out_dir, "residual_vectors.png")
        plots.plot_residual_vectors(result, p, title="Unexplained residual vectors (touch probing)",
                                    kinds=plots.PROBING)
        first.append((p, "Residual vectors at the touch points in the table (workpiece) frame, magnified, "
                         "one colour per rotary indexation (Rahman 2016, Figure 4-7 style). Systematic "
                         "patterns (arrows of one colour pointing the same way) mean unmodelled errors; "
                         "random directions mean probing noise."))
    captions = {name: r["component_caption"] for name, r in _kinds().items() if r["components"]}
    for kind, caption in captions.items():
        if kind not in types:
            continue
        p = os.path.join(out_dir, f"{kind}_components.png")
        try:
            plots.plot_components(result, p, kind)
            first.append((p, caption))
        except Exception as e:  # a plotting problem must not lose the rest of the report
            notes.append(f"{kind} plots could not be drawn: {_e(type(e).__name__)}: {_e(e)}")
    dbb_figs, dbb_note = _dbb_figures(result, out_dir)
    first += dbb_figs
    if dbb_note:
        notes.append(dbb_note)
    return first, notes


def write_report(result, out_dir: Union[str, os.PathLike], title: Optional[str] = None,
                 truth: Optional[Mapping[str, float]] = None,
                 sections: Sequence[Section] = (), figures: Sequence[Figure] = (),
                 embed_images: bool = True, write_result_json: bool = True,
                 summary: Optional[str] = None, history=None, machine_id: Optional[str] = None,
                 procedure: str = "identify", procedure_values: Optional[Mapping] = None) -> str:
    """Write ``out_dir/report.html`` (plus PNGs and ``result.json``) for an
    identification :class:`fivecal.Result`; returns the HTML path.

    ``truth``: known true values (simulations) to show beside the estimates,
    with z = (estimate - truth) / σ. ``sections``: extra (title, HTML) blocks
    placed after the parameter table (the demo adds its validation).
    ``figures``: extra (PNG path, caption) pairs shown after the standard
    plots. ``embed_images``: embed the plots as base64 so the HTML file stands
    alone (default); otherwise it references the PNG files next to it.
    ``summary``: a line of text shown under the title.
    ``history``: a calibration store (path or :class:`fivecal.history.Store`)
    or a :class:`fivecal.report.history.History` with tolerances; with
    ``machine_id`` it adds the machine's trend, the comparison with the
    previous calibration and pass / fail (docs/history.md).

    A result that is not usable (not converged, non-finite, inadequate against
    the declared noise, or with requested parameters the data did not
    determine) is still written, because the report is where one finds out
    why; it then opens with a red "NOT USABLE" banner giving the reason, the
    page title says so, and no box on the page is green.
    """
    out_dir = os.fspath(out_dir)
    make_dirs(out_dir)
    ds = result.dataset
    machine = ds.machine
    if write_result_json:
        result.save(os.path.join(out_dir, "result.json"), procedure, procedure_values)
    result.write_residuals(os.path.join(out_dir, "residuals.csv"))

    figs: List[Figure] = []
    kind_figs, notes = _kind_figures(result, out_dir)
    figs += kind_figs
    p = os.path.join(out_dir, "residual_histogram.png")
    plots.plot_residual_histogram(result, p)
    figs.append((p, "Distribution of the residuals with the normal density of the a-posteriori σ̂."))
    fd = guards.findings(result)
    mnames = determined_machine_errors(result, fd)
    pages = plots.parameter_pages(mnames)
    for k, page in enumerate(pages):
        p = os.path.join(out_dir, "parameters.png" if k == 0 else f"parameters_{k + 1}.png")
        of = f" ({k + 1} of {len(pages)})" if len(pages) > 1 else ""
        plots.plot_parameters(result, p, names=page, truth=truth,
                              title=f"Machine errors the data determined (error bars ±2σ){of}")
        figs.append((p, f"Machine errors the data determined{of}, with ±2σ error bars, one panel per unit"
                        + (", true values in red." if truth else ".")))
    cnames = mnames
    if len(cnames) >= 2:
        p = os.path.join(out_dir, "correlation.png")
        plots.plot_correlation(result, p, names=cnames, title="Correlation of the determined machine parameters")
        figs.append((p, "Correlation coefficients between the machine parameters the data determined (setup "
                        "parameters omitted; strongly correlated pairs are listed under Identifiability)"
                        + (f"; with {len(cnames)} parameters, the {plots.CORRELATION_PAIRS} pairs of largest |r|."
                           if len(cnames) > plots.CORRELATION_MATRIX_MAX else ".")))
    figs += list(figures)
    standing = None
    if history is not None:
        extra, standing = _history_sections(history, machine_id, out_dir, result, embed_images)
        sections = list(sections) + extra

    title = title or f"fivecal identification report — {machine.name}"
    if not fd.assessment.usable:
        title += " — NOT USABLE"
    elif standing is not None and standing.grade == "fail":
        title += " — FAIL"
    now = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    body = [f"<h1>{_e(title)}</h1>",
            f"<div class='sub'>fivecal {__version__} · {now} · {_e(machine.name)} "
            f"(<code>{_e(machine.topology)}</code>) · {len(ds)} observations · residual rms "
            f"{result.rms * 1e3:.3f} µm</div>"]
    # What a reader needs first (the verdict and a compact summary) fits on one
    # screen; the details follow in #details, the longest lists collapsed.
    body.append(_verdict_banner(result, fd, standing))
    if summary:
        body.append(f"<div class='box'>{_e(summary)}</div>")
    nav = ["findings", "machine", "data", "fit", "identifiability", "parameters"] + \
          [f"extra{i}" for i in range(len(sections))] + ["plots", "conventions", "files"]
    labels = ["What the data told", "Machine", "Data", "Fit", "Identifiability", "Parameters"] + \
             [t for t, _ in sections] + ["Plots", "Conventions", "Files"]
    params, undetermined = _parameter_section(result, machine, truth)
    body += ["<h2 id='findings'>What the data told</h2>", _findings_section(result, fd),
             "<nav>" + "".join(f"<a href='#{a}'>{_e(b)}</a>" for a, b in zip(nav, labels)) + "</nav>",
             "<div id='details'>",
             "<h2 id='machine'>Machine</h2>", _machine_section(machine),
             "<h2 id='data'>Data</h2>", _data_section(ds, result),
             "<h2 id='fit'>Fit</h2>", _fit_section(result), _largest_residuals(result),
             "<h2 id='identifiability'>Identifiability</h2>", _identifiability_section(result),
             "<h2 id='parameters'>Parameters</h2>", params]
    for i, (t, h) in enumerate(sections):
        body += [f"<h2 id='extra{i}'>{_e(t)}</h2>", h]
    body.append("<h2 id='plots'>Plots</h2>")
    for path, cap in figs:
        body.append(f"<figure>{_img_tag(path, out_dir, embed_images, cap)}<figcaption>{_e(cap)}"
                    f" <small>({_e(os.path.basename(path))})</small></figcaption></figure>")
    for note in notes:
        body.append(f"<div class='box warn'>{note}</div>")
    body += ["<h2 id='conventions'>Conventions</h2>", _CONVENTIONS,
             "<h2 id='files'>Files</h2><ul>",
             "<li><a href='result.json'>result.json</a> — the result (format: `fivecal docs formats`; values in mm and "
             "rad, one-sigma std)</li>" if write_result_json else "",
             "".join(f"<li><a href='{_e(os.path.basename(pth))}'>{_e(os.path.basename(pth))}</a></li>"
                     for pth, _ in figs if os.path.dirname(os.path.abspath(pth)) == os.path.abspath(out_dir)),
             "".join(f"<li><a href='{_e(f)}'>{_e(f)}</a></li>" for f in sorted(os.listdir(out_dir))
                     if f not in ("result.json", "report.html") and not f.startswith("_")
                     and os.path.splitext(f)[1] in (".json", ".txt", ".csv", ".nc")),
             "</ul>", undetermined, "</div>"]
    doc = ("<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
           "<meta name='viewport' content='width=device-width, initial-scale=1'>"
           f"<title>{_e(title)}</title><style>{_CSS}</style></head><body><main>\n"
           + "\n".join(body) + "\n</main></body></html>\n")
    path = os.path.join(out_dir, "report.html")
    write_text(path, doc)
    return path
