"""Renishaw ballbar ``.b5r`` files: the header and the diagnostics
Renishaw's software wrote, read as documented (docs/dbb.md, "Renishaw .b5r
files").

A ``.b5r`` file is XML. Its layout is not published by Renishaw; what is read
here is what two independent public parsers agree on: the root
``TEST_DOCUMENT``; ``TEST_SPEC@NAME``; ``INSTRUMENT@MANUFACTURER|MODEL``;
``NOMINAL_LENGTH`` (mm), ``PROGRAMMED_FEEDRATE`` (mm/min), ``PLANE@TEST_PLANE``
with ``A_AXIS_NAME`` / ``B_AXIS_NAME``; ``OPERATOR``, ``DATE_STARTED``,
``DATE_COMPLETED``, ``MACHINE_TESTED@NAME``; per run ``RUN_RESULTS/
BALLBAR_RUN`` with ``RUN_DIRECTION`` and ``FEATURE`` elements; and
``ANALYSIS NAME="RENISHAW_DIAGNOSTICS"`` with ``FEATURE NAME=... DT=...``
values, ``DT`` naming the unit. A feature whose name or unit is not among
those documented is not read: it is listed, by element, as not read, and a
documented feature with an undocumented unit or a value that is not a number
is refused naming the element. The raw trace is not read: its layout is not
public.
"""
from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Optional, Union

from .. import _core, files

#: DT -> (factor to fivecal's unit, fivecal's unit): lengths mm, angles rad, times s.
UNITS = {"UT_LENGTH_MM": (1.0, "mm"), "UT_LENGTH_UM": (1e-3, "mm"), "UT_LENGTH_M": (1e3, "mm"),
         "UT_FEEDRATE": (1.0, "mm/min"), "UT_SQUARENESS": (1e-6, "rad"), "UT_SERVO_MISMATCH": (1e-3, "s"),
         "UT_PERCENT": (1.0, "%"), "UT_ANGLE": (1.0, "deg")}

#: The diagnostics the public parsers name (A, B: the plane's first and second
#: axis; POS / NEG: Renishaw's + and -), with the DT they carry and the name
#: ballbar users know. fivecal's own diagnosis names are not assigned to them:
#: Renishaw's definitions (peak-to-valley or amplitude, signs) are not public.
DIAGNOSTICS = {
    "AF_CIRCULARITY": ("length", "circularity"),
    "AF_SCALE_MISMATCH": ("length", "scale mismatch {a}-{b}"),
    "AF_SQUARENESS": ("squareness", "squareness {a}{b}"),
    "AF_SERVO_MISMATCH": ("servo", "servo mismatch"),
    "AF_STRAIGHTNESS_A": ("length", "straightness {a}"), "AF_STRAIGHTNESS_B": ("length", "straightness {b}"),
    "AF_CYCLIC_ERROR_A_FWD": ("length", "cyclic error {a}"), "AF_CYCLIC_ERROR_B_FWD": ("length", "cyclic error {b}"),
}
for _ax in ("A", "B"):
    for _end, _sign in (("POS", "+"), ("NEG", "-")):
        for _kind, _word in (("BACKLASH", "backlash"), ("LATERAL_PLAY", "lateral play"),
                             ("REVERSAL_SPIKES", "reversal spikes")):
            DIAGNOSTICS[f"AF_{_kind}_{_ax}_{_end}"] = ("length", f"{_word} {{{_ax.lower()}}}{_sign}")
#: What each kind of diagnostic may carry as DT.
_KIND_UNITS = {"length": ("UT_LENGTH_MM", "UT_LENGTH_UM", "UT_LENGTH_M"), "squareness": ("UT_SQUARENESS",),
               "servo": ("UT_SERVO_MISMATCH",)}
_RUN_FEATURES = {"AF_CIRCULARITY": ("UT_LENGTH_MM", "UT_LENGTH_UM", "UT_LENGTH_M"),
                 "AF_CALCULATED_FEEDRATE": ("UT_FEEDRATE",)}


@dataclass
class B5rDiagnostic:
    element: str          # the FEATURE's NAME
    label: str            # the name ballbar users know, with the plane's axes
    value: float          # fivecal's unit: mm, rad or s
    unit: str
    contribution: Optional[float] = None  # mm, to the circularity (None: cannot be ranked)
    percent: Optional[float] = None


@dataclass
class B5rTest:
    path: str
    header: dict
    runs: list            # [{"direction": "CW"|"CCW", "circularity": mm, "feedrate": mm/min}]
    diagnostics: list     # B5rDiagnostic, ranked by contribution (unranked last)
    not_read: list = field(default_factory=list)  # "FEATURE AF_X (why)"
    circularity: Optional[float] = None

    def report(self) -> str:
        h = self.header
        L = [f"Renishaw ballbar file {os.path.basename(self.path)} (diagnostics as Renishaw's software wrote them; "
             "the raw trace is not read: its layout is not public)",
             f"  test {h.get('test') or 'not given'}  ·  machine {h.get('machine') or 'not given'}  ·  "
             f"plane {h.get('plane') or 'not given'}  ·  radius {h.get('nominal_length', 'not given')} mm  ·  "
             f"feed {h.get('feedrate', 'not given')} mm/min  ·  started {h.get('date_started') or 'not given'}"]
        for r in self.runs:
            c = f"{r['circularity'] * 1e3:.2f} µm" if r.get("circularity") is not None else "not given"
            L.append(f"  run {r['direction'] or '?'}: circularity {c}")
        if self.circularity is not None:
            L.append(f"  circularity (diagnostics) {self.circularity * 1e3:.2f} µm")
        L += ["", "  diagnostics ranked by contribution to circularity (the length as the file gives it; squareness "
              "and servo mismatch as the circular deviation they cause on this radius):"]
        for i, d in enumerate(self.diagnostics):
            shown = _shown(d)
            if d.contribution is None:
                L.append(f"     -  {d.label:<24}{shown:>16}   not ranked (needs the nominal length"
                         f"{' and the feed' if d.unit == 's' else ''})")
            else:
                pct = f"{d.percent:5.0f} %" if d.percent is not None else "    - "
                L.append(f"    {i + 1:2d}. {d.label:<24}{shown:>16}   {pct} {d.contribution * 1e3:8.2f} µm")
        for n in self.not_read:
            L.append(f"  not read: {n}")
        return "\n".join(L)

    def to_dict(self) -> dict:
        return {"path": os.path.basename(self.path), "header": self.header, "runs": self.runs,
                "circularity": self.circularity, "not_read": self.not_read,
                "diagnostics": [vars(d) for d in self.diagnostics]}


def _shown(d: B5rDiagnostic) -> str:
    if d.unit == "rad":
        return f"{d.value * 1e6:+.2f} µm/m"
    if d.unit == "s":
        return f"{d.value * 1e3:+.3f} ms"
    return f"{d.value * 1e3:+.2f} µm"


def _number(text, where: str) -> float:
    try:
        v = float(str(text).strip())
    except (TypeError, ValueError):
        raise ValueError(f"{where}: '{str(text).strip()[:40]}' is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{where}: not a finite number")
    return v


def _first(root, tag: str):
    return next(root.iter(tag), None)


def read_b5r(path: Union[str, os.PathLike], nominal_radius: Optional[float] = None) -> B5rTest:
    """Read a ``.b5r`` file's header and diagnostics (module docstring).
    ``nominal_radius`` (mm) overrides / supplies ``NOMINAL_LENGTH``; a
    mismatch with the file's is refused. ValueError naming the file and
    element on bad input."""
    path = os.fspath(path)
    text = files.read_text(path, ".b5r file")
    # Entities expand to anything: a ballbar file has none, so one is refused.
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise ValueError(f"{path}: has a DOCTYPE / ENTITY declaration; a .b5r file has none (refused)")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise ValueError(f"{path}: not well-formed XML ({e})") from None
    if root.tag != "TEST_DOCUMENT":
        raise ValueError(f"{path}: root element <{root.tag}>; a .b5r file's root is <TEST_DOCUMENT>")
    header: dict = {}
    spec = _first(root, "TEST_SPEC")
    header["test"] = spec.get("NAME") if spec is not None else None
    inst = _first(root, "INSTRUMENT")
    if inst is not None:
        header["instrument"] = " ".join(x for x in (inst.get("MANUFACTURER"), inst.get("MODEL")) if x) or None
    for tag, key in (("OPERATOR", "operator"), ("DATE_STARTED", "date_started"), ("DATE_COMPLETED", "date_completed")):
        e = _first(root, tag)
        header[key] = e.text.strip() if e is not None and e.text else None
    m = _first(root, "MACHINE_TESTED")
    header["machine"] = m.get("NAME") if m is not None else None
    plane = _first(root, "PLANE")
    axes = ("A", "B")
    if plane is not None:
        header["plane"] = (plane.get("TEST_PLANE") or "").strip().upper() or None
        names = []
        for tag in ("A_AXIS_NAME", "B_AXIS_NAME"):
            e = plane.find(tag)
            names.append(e.text.strip().upper() if e is not None and e.text else None)
        if all(names):
            axes = tuple(names)
        elif header["plane"] and len(header["plane"]) == 2:
            axes = tuple(header["plane"])
    for tag, key in (("NOMINAL_LENGTH", "nominal_length"), ("PROGRAMMED_FEEDRATE", "feedrate")):
        e = _first(root, tag)
        if e is not None and e.text and e.text.strip():
            header[key] = _number(e.text, f"{path}: <{tag}>")
            if header[key] <= 0:
                raise ValueError(f"{path}: <{tag}> {header[key]:g}: must be > 0")
    R = header.get("nominal_length")
    if nominal_radius is not None:
        if R is not None and abs(R - nominal_radius) > 1e-6 * R:
            raise ValueError(f"--radius {nominal_radius:g}: the file's <NOMINAL_LENGTH> is {R:g} mm")
        R = header["nominal_length"] = float(nominal_radius)
    not_read = []
    runs = []
    for run in root.iter("BALLBAR_RUN"):
        d = run.find("RUN_DIRECTION")
        entry = {"direction": d.text.strip().upper() if d is not None and d.text else None}
        for f in run.iter("FEATURE"):
            name, dt = f.get("NAME", ""), f.get("DT", "")
            where = f"{path}: BALLBAR_RUN FEATURE {name}"
            if name not in _RUN_FEATURES:
                not_read.append(f"BALLBAR_RUN FEATURE {name or '(no NAME)'} (not documented)")
                continue
            if dt not in _RUN_FEATURES[name]:
                raise ValueError(f"{where}: DT '{dt}' is not a documented unit for it "
                                 f"({', '.join(_RUN_FEATURES[name])})")
            v = _number(f.text, where) * UNITS[dt][0]
            entry["circularity" if name == "AF_CIRCULARITY" else "feedrate"] = v
        runs.append(entry)
    analyses = [a for a in root.iter("ANALYSIS") if a.get("NAME") == "RENISHAW_DIAGNOSTICS"]
    for a in root.iter("ANALYSIS"):
        if a.get("NAME") != "RENISHAW_DIAGNOSTICS":
            not_read.append(f"ANALYSIS NAME=\"{a.get('NAME')}\" (not documented)")
    if len(analyses) > 1:
        raise ValueError(f"{path}: {len(analyses)} ANALYSIS NAME=\"RENISHAW_DIAGNOSTICS\" elements; expected one")
    diags, circ = [], None
    a_name, b_name = axes
    feed = header.get("feedrate")
    for f in (analyses[0].iter("FEATURE") if analyses else ()):
        name, dt = f.get("NAME", ""), f.get("DT", "")
        where = f"{path}: ANALYSIS RENISHAW_DIAGNOSTICS FEATURE {name}"
        if name not in DIAGNOSTICS:
            not_read.append(f"FEATURE {name or '(no NAME)'} (DT {dt or 'none'}: not documented)")
            continue
        kind, label = DIAGNOSTICS[name]
        if dt not in _KIND_UNITS[kind]:
            raise ValueError(f"{where}: DT '{dt}' is not a documented unit for it ({', '.join(_KIND_UNITS[kind])})")
        factor, unit = UNITS[dt]
        v = _number(f.text, where) * factor
        if name == "AF_CIRCULARITY":
            circ = v
            continue
        contribution = None
        if kind == "length":
            contribution = abs(v)
        elif kind == "squareness" and R:
            contribution = _core.diagnosis_contribution("squareness", v, R)
        elif kind == "servo" and R and feed:
            # the lag difference times the feed is fivecal's servo mismatch (mm)
            contribution = _core.diagnosis_contribution("servo_mismatch", v * feed / 60.0, R)
        diags.append(B5rDiagnostic(name, label.format(a=a_name, b=b_name), v, unit, contribution))
    if circ is None:
        runs_c = [r["circularity"] for r in runs if r.get("circularity") is not None]
        circ = max(runs_c) if runs_c else None
    for d in diags:
        if d.contribution is not None and circ:
            d.percent = 100.0 * d.contribution / circ
    diags.sort(key=lambda d: (d.contribution is None, -(d.contribution or 0.0)))
    if not diags and circ is None:
        raise ValueError(f"{path}: no ANALYSIS NAME=\"RENISHAW_DIAGNOSTICS\" features and no run circularity: "
                         "nothing documented to read")
    return B5rTest(path, header, runs, diags, not_read, circ)
