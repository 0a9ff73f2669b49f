"""Initial pose of a fixed instrument (laser tracker, camera, CMM) in the machine frame.

A tracker reports points in its own frame, set wherever it stood. A fit of
``point`` observations started from a pose far from the truth (the identity,
when the tracker's frame is turned by 90° to the machine's) may not
converge, so the nominal pose is first found by a rigid alignment: the
rotation R and translation o that best map the measured points m_i onto the
points the nominal machine predicts, p_i ≈ R m_i + o (Kabsch / Umeyama, by
SVD, without scale). That is the pose of the ``point`` residual
``R_Iᵀ (P_F − o_I) − measured`` with R_I = R, o_I = o, and the fit then
estimates only the small corrections ``instrument.<id>.x|y|z|a|b|c``.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

#: below this ratio of the second to the first singular value of the centred
#: points, the points are taken as lying on a line: the rotation about it is
#: then decided by noise, not by geometry
COLLINEAR_RATIO = 1e-3


def _points(x, what: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{what}: expected an (N, 3) array of points, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what}: points must be finite")
    return a


def _check_spread(c: np.ndarray, what: str) -> None:
    s = np.linalg.svd(c, compute_uv=False)
    if s[0] == 0.0:
        raise ValueError(f"{what}: all points coincide; a rigid alignment needs at least 3 points "
                         "that are not on one line")
    if s[1] < COLLINEAR_RATIO * s[0]:
        raise ValueError(f"{what}: the points lie on a line (spread off the line {s[1] / s[0]:.2g} of the "
                         "spread along it); the rotation about that line cannot be found. Measure points "
                         "off the line (move a rotary axis or a second linear axis) or give the "
                         "instrument's pose (instrument_origin, instrument_angles)")


def rigid_align(measured: Sequence, nominal: Sequence):
    """(R, o, rms): the rotation R (3x3, det +1) and translation o (mm) that
    minimise Σ |R m_i + o − p_i|², m = ``measured``, p = ``nominal`` (both
    (N, 3)), and the rms distance left. Refuses fewer than 3 points and
    points on a line (or in a single point) in either set."""
    m = _points(measured, "measured points")
    p = _points(nominal, "nominal points")
    if m.shape != p.shape:
        raise ValueError(f"rigid alignment: {m.shape[0]} measured points but {p.shape[0]} nominal ones")
    if m.shape[0] < 3:
        raise ValueError(f"rigid alignment: {m.shape[0]} points; at least 3 not on one line are needed")
    mc, pc = m.mean(axis=0), p.mean(axis=0)
    _check_spread(m - mc, "rigid alignment of the measured points")
    _check_spread(p - pc, "rigid alignment of the nominal points")
    h = (m - mc).T @ (p - pc)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    o = pc - r @ mc
    rms = float(np.sqrt(np.mean(np.sum((m @ r.T + o - p) ** 2, axis=1))))
    return r, o, rms


def rotation_zyx(a: float, b: float, c: float) -> np.ndarray:
    """Rz(c)·Ry(b)·Rx(a), angles in rad (the ``instrument_angles`` convention)."""
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return rz @ ry @ rx


def angles_zyx(r: np.ndarray):
    """(a, b, c) in rad with Rz(c)·Ry(b)·Rx(a) = r."""
    b = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(r[2, 0]) < 1.0 - 1e-12:
        a = math.atan2(r[2, 1], r[2, 2])
        c = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: only a − c (or a + c) is defined; put it all in a
        c = 0.0
        a = math.atan2(-r[1, 2], r[1, 1])
    return a, b, c


def instrument_pose(measured: Sequence, nominal: Sequence):
    """The nominal instrument pose that maps ``measured`` (instrument frame)
    onto ``nominal`` (machine frame): (origin [mm], angles [deg] a b c, rms mm),
    as the ``instrument_origin`` / ``instrument_angles`` of point observations."""
    r, o, rms = rigid_align(measured, nominal)
    return [float(x) for x in o], [math.degrees(x) for x in angles_zyx(r)], rms
