"""The notebook views of fivecal's objects (:mod:`fivecal.views`): what
``_repr_html_`` and ``plot()`` show of a :class:`~fivecal.Result`, a
:class:`~fivecal.Dataset`, a :class:`~fivecal.Machine` and the procedures'
results. Everything is made of the report's own pieces (the verdict banner,
the parameter table, the machine and data tables, the plots), in short form:
the verdict, then the machine errors the data determined."""
from __future__ import annotations

import re
from typing import List

from .. import guards, views
from ..dataset import Dataset
from ..identification import Result
from ..machine import Machine
from ..procedures.dbb import CircularResult, FourStepResult, WangIdentification
from ..procedures.machining import MachiningResult
from ..procedures.rtest import RTestResult
from ..procedures.sphere_check import SphereCheck
from . import plots, polar
from .document import (_CSS, _data_section, _kinds, _machine_section, _parameter_rows, _verdict_banner,
                       determined_machine_errors)
from .markup import _e

__all__ = ["result_html", "result_figures"]


def _scoped_css() -> str:
    # The report's style sheet, each rule limited to the view's <div>: a
    # notebook page must keep its own body, headings and links.
    rules = []
    for rule in re.sub(r"\s*\n\s*", " ", _CSS).split("}"):
        if "{" not in rule:
            continue
        selector, body = rule.split("{", 1)
        parts = [p.strip() for p in selector.split(",")]
        if any(p.split(" ")[0] in ("body", "main", "h1", "h2", "nav") for p in parts):
            continue
        rules.append(",".join(f".fivecal-view {p}" for p in parts) + "{" + body.strip() + "}")
    return "<style>" + "".join(rules) + "</style>"


_STYLE = _scoped_css()


def _view(title: str, *parts: str) -> str:
    return f"<div class='fivecal-view'>{_STYLE}<div class='sub'><b>{_e(title)}</b></div>{''.join(parts)}</div>"


def _fit_parts(result: Result) -> List[str]:
    """The verdict banner and the machine errors the data determined, as in
    the report; what it did not determine is counted, not listed."""
    fd = guards.findings(result)
    machine = result.dataset.machine
    mach_rows, other_rows, und_rows = _parameter_rows(result, machine, None)
    n_mach, n_other, n_und = (r.count("<tr") - 1 for r in (mach_rows, other_rows, und_rows))
    parts = [_verdict_banner(result, fd, anchor=False),
             f"<table>{mach_rows}</table>" if n_mach else
             "<p>No machine error determined by this data: no values to show.</p>"]
    tail = []
    if n_other:
        tail.append(f"{n_other} setup parameters")
    if n_und:
        tail.append(f"{n_und} parameters the data did not determine (never compensated)")
    parts.append("<p class='muted'>Values in µm, µrad, µm/m; u: one-sigma uncertainty, U = 2u."
                 + (f" Not shown: {_e('; '.join(tail))}." if tail else "")
                 + " The full report: <code>fivecal.write_report(result, folder)</code>.</p>")
    return parts


@views.html.register(Result)
def result_html(result: Result) -> str:
    m = result.dataset.machine
    return _view(f"Identification of {m.name}: {len(result.dataset)} observations, {result.n_parameters} "
                 f"parameters estimated, residual rms {result.rms * 1e3:.3f} µm", *_fit_parts(result))


#: beyond this many observations a dataset's view counts them per kind only:
#: the report's data table reads every observation (minutes for 10^6)
LARGE_DATASET = 20000


@views.html.register(Dataset)
def dataset_html(ds: Dataset) -> str:
    m = ds.machine
    title = f"Dataset: {len(ds)} observations on {m.name} ({m.topology})"
    if len(ds) <= LARGE_DATASET:
        return _view(title, _data_section(ds, None))
    counts: dict = {}
    for t in ds.observation_types:
        counts[t] = counts.get(t, 0) + 1
    return _view(title, f"<p>{_e(', '.join(f'{n} {t}' for t, n in counts.items()))}. Setups, indexations and "
                        "targets: the data table of <code>fivecal.write_report</code> (it reads every "
                        "observation).</p>")


@views.html.register(Machine)
def machine_html(m: Machine) -> str:
    return _view(f"Machine {m.name}: {len(m.parameter_names())} error parameters", _machine_section(m))


def _fit_of(obj):
    """The identification a procedure's result holds (its ``result`` or,
    for the four-step test, the general engine's fit), or None."""
    for name in ("result", "engine"):
        r = getattr(obj, name, None)
        if isinstance(r, Result):
            return r
    return None


_PROCEDURES = {SphereCheck: "Sphere check", RTestResult: "R-test", CircularResult: "Circular test",
               FourStepResult: "Four-step ball bar test", WangIdentification: "Wang ball bar path",
               MachiningResult: "Machining test"}


def procedure_html(obj) -> str:
    """The fit's verdict and machine errors (when the procedure fits any),
    then the procedure's own report, folded."""
    fit = _fit_of(obj)
    parts = _fit_parts(fit) if fit is not None else [
        "<div class='box'>No identification (<code>fivecal.identify</code>) in this result: its verdict "
        "and machine errors come with one; the procedure's own values are below.</div>"]
    text = obj.report()
    parts.append(f"<details{'' if fit is not None else ' open'}><summary>{_e(_PROCEDURES[type(obj)])} "
                 f"report</summary><pre>{_e(text)}</pre></details>")
    return _view(_PROCEDURES[type(obj)], *parts)


for _cls in _PROCEDURES:
    views.html.register(_cls, procedure_html)


# ---------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------

@views.figures.register(Result)
def result_figures(result: Result) -> list:
    """The report's figures of a fit, as Figures: the ones its kinds of data
    call for (residual vectors of touches, 3D components, ball bar polar
    panels), the residual histogram and the machine errors the data
    determined with ±2σ bars (one Figure per page of the report)."""
    types = set(result.dataset.observation_types)
    out = []
    if types & set(plots.PROBING):
        out.append(plots.residual_vectors_figure(result, title="Unexplained residual vectors (touch probing)",
                                                 kinds=plots.PROBING))
    for kind, r in _kinds().items():
        if r["components"] and kind in types:
            out.append(plots.component_figure(result, kind))
        elif r["figures"] == "polar" and kind in types:
            out += [polar.dbb_figure(result), polar.dbb_residual_figure(result)]
    out.append(plots.residual_histogram_figure(result))
    pages = plots.parameter_pages(determined_machine_errors(result, guards.findings(result)))
    for k, page in enumerate(pages):
        of = f" ({k + 1} of {len(pages)})" if len(pages) > 1 else ""
        out.append(plots.parameters_figure(result, names=page,
                                           title=f"Machine errors the data determined (error bars ±2σ){of}"))
    return [f for f in out if f is not None]


@views.figures.register(CircularResult)
def circular_figures(res: CircularResult) -> list:
    """The circular test's polar plot with its ISO 230-4 values."""
    return [polar.circular_test_figure(res)]


def procedure_figures(obj) -> list:
    fit = _fit_of(obj)
    if fit is None:
        raise ValueError(f"{_PROCEDURES[type(obj)]}: no fit to draw (the result holds no identification; "
                         "its values are in its report)")
    return result_figures(fit)


for _cls in _PROCEDURES:
    if _cls is not CircularResult:
        views.figures.register(_cls, procedure_figures)


@views.figures.register(Dataset)
def dataset_figures(ds: Dataset) -> list:
    """Each axis' command at every observation, one panel per axis, one
    colour per kind: where the test moved the machine."""
    return [plots.axes_figure(ds)]


@views.figures.register(Machine)
def machine_figures(m: Machine) -> list:
    """The axes at the zero pose: rotary axis lines through their points,
    linear axis directions, the tool tip."""
    return [plots.machine_figure(m)]
