"""DESIGN.md's kinematic model as a strong user writes it for a fit: one
scalar expression per matrix entry, specialised at trace time to the
parameters that are estimated.

Both baselines run this code: bench/baseline_jax.py with ``jax.numpy`` (jit
fuses the element-wise expressions; ``jacfwd`` differentiates them) and
bench/baseline_numpy.py with forward-mode dual numbers over numpy arrays
(exact derivatives of the same expressions). A matrix is nested lists of
3 x 3 entries; an entry is either a Python float, known while the model is
built (the nominal geometry, an absent error: 0.0), or an array / traced
value. ``mul`` and ``add`` fold the constants, so an error that is not
estimated costs nothing (no ``0.0 * q**d`` over every sample, no sines of
zero arrays) and an axis-aligned rotation is the four entries it changes.
"""
from __future__ import annotations

import math

COMP = "XYZABC"


def const(x):
    return isinstance(x, (int, float))


def zero(x):
    return const(x) and x == 0


def add(a, b):
    if const(a) and a == 0:
        return b
    if const(b) and b == 0:
        return a
    return a + b


def sub(a, b):
    if const(b) and b == 0:
        return a
    if const(a) and a == 0:
        return -b
    return a - b


def mul(a, b):
    if const(a):
        if a == 0:
            return 0.0
        if a == 1:
            return b
        if a == -1 and not const(b):
            return -b
    if const(b):
        if b == 0:
            return 0.0
        if b == 1:
            return a
        if b == -1:
            return -a
    return a * b


def dot3(a, b):
    return add(add(mul(a[0], b[0]), mul(a[1], b[1])), mul(a[2], b[2]))


def matmul(A, B):
    return [[dot3(A[i], [B[0][j], B[1][j], B[2][j]]) for j in range(3)] for i in range(3)]


def matvec(A, v):
    return [dot3(A[i], v) for i in range(3)]


def tmatvec(A, v):
    """A^T v."""
    return [dot3([A[0][i], A[1][i], A[2][i]], v) for i in range(3)]


IDENTITY = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


class Model:
    """The machine of a fivecal.Machine for one fit. ``ops`` supplies sin and
    cos of non-constant values (jax.numpy, or the dual numbers of
    baseline_numpy)."""

    def __init__(self, machine, ops):
        self.names = machine.axis_names
        self.axes = {a["name"]: a for a in machine.axes}
        self.workpiece = machine.workpiece_chain
        self.tool = machine.tool_chain
        self.tip = [float(v) for v in machine.tip]
        self.ops = ops

    def sin(self, x):
        return math.sin(x) if const(x) else self.ops.sin(x)

    def cos(self, x):
        return math.cos(x) if const(x) else self.ops.cos(x)

    def rotzyx(self, a, b, c):
        """Rz(c) Ry(b) Rx(a), entry by entry."""
        ca, sa, cb, sb, cc, sc = self.cos(a), self.sin(a), self.cos(b), self.sin(b), self.cos(c), self.sin(c)
        return [[mul(cc, cb), sub(mul(mul(cc, sb), sa), mul(sc, ca)), add(mul(mul(cc, sb), ca), mul(sc, sa))],
                [mul(sc, cb), add(mul(mul(sc, sb), sa), mul(cc, ca)), sub(mul(mul(sc, sb), ca), mul(cc, sa))],
                [mul(-1.0, sb), mul(cb, sa), mul(cb, ca)]]

    def axis_angle(self, u, q):
        """Rotation by q about the constant unit u (Rodrigues:
        c I + s [u]x + (1 - c) u u^T)."""
        s, c = self.sin(q), self.cos(q)
        omc = sub(1.0, c)
        K = [[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]]
        out = [[None] * 3 for _ in range(3)]
        for i in range(3):
            for j in range(3):
                uu = u[i] * u[j]
                if i == j and uu == 1.0:     # the axis itself: exactly 1
                    out[i][j] = 1.0
                    continue
                out[i][j] = add(add(c if i == j else 0.0, mul(s, K[i][j])), mul(omc, uu))
        return out

    def chain(self, chain, q, dirs, th):
        """(R, t, last axis point) of a chain. q, dirs: per axis name, the
        axis values (rad / mm) and last-move directions (None: none);
        th: dict name -> value of the estimated parameters (absent: 0)."""
        R, t, p_parent = IDENTITY, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        for a in chain:
            ax = self.axes[a]
            u = [float(v) for v in ax["direction"]]
            p = [float(v) for v in ax["point"]]
            loc = [th.get(f"E{c}0{a}", 0.0) for c in COMP]
            t = [add(t[i], v) for i, v in enumerate(matvec(R, [add(p[k] - p_parent[k], loc[k]) for k in range(3)]))]
            if any(not zero(x) for x in loc[3:]):
                R = matmul(R, self.rotzyx(*loc[3:]))
            qk = q[a]
            qm = qk
            if dirs is not None and dirs.get(a) is not None and f"E{a}{a}b" in th:
                qm = add(qk, mul(th[f"E{a}{a}b"], dirs[a]))
            if ax["type"] == "rotary":
                R = matmul(R, self.axis_angle(u, qm))
            else:
                t = [add(t[i], mul(v, qm)) for i, v in enumerate(matvec(R, u))]
            e = []
            for c in COMP:
                s = 0.0
                for d in (1, 2, 3):
                    v = th.get(f"E{c}{a}{d}")
                    if v is not None:
                        s = add(s, mul(v, qk ** d))
                e.append(s)
            if any(not zero(x) for x in e[:3]):
                t = [add(t[i], v) for i, v in enumerate(matvec(R, e[:3]))]
            if any(not zero(x) for x in e[3:]):
                R = matmul(R, self.rotzyx(*e[3:]))
            p_parent = p
            R, t = self.barrier(R, t)
        return R, t, p_parent

    def barrier(self, R, t):
        """The frame after an axis, written out when ``ops`` has a
        ``barrier`` (bench/baseline_jax.py). Without it XLA:CPU's loop
        fusion evaluates every entry again in each entry that uses it, down
        the whole chain."""
        fn = getattr(self.ops, "barrier", None)
        if fn is None:
            return R, t
        flat = [R[i][j] for i in range(3) for j in range(3)] + list(t)
        live = [k for k, v in enumerate(flat) if not const(v)]
        if not live:
            return R, t
        out = fn([flat[k] for k in live])
        for k, v in zip(live, out):
            flat[k] = v
        return [flat[0:3], flat[3:6], flat[6:9]], flat[9:12]

    def tool_points(self, q, th, dirs=None, tip=None):
        """The tool point in workpiece coordinates, as three per-sample
        expressions. q: axis name -> values; tip: 3 values (default: the
        machine's tip plus the estimated tip.x/y/z)."""
        if tip is None:
            tip = [add(self.tip[i], th.get(f"tip.{c}", 0.0)) for i, c in enumerate("xyz")]
        Rt, tt, pt = self.chain(self.tool, q, dirs, th)
        Rw, tw, pw = self.chain(self.workpiece, q, dirs, th)
        Pf = [add(v, tt[i]) for i, v in enumerate(matvec(Rt, [sub(tip[k], pt[k]) for k in range(3)]))]
        O = [sub(tw[i], v) for i, v in enumerate(matvec(Rw, pw))]
        return tmatvec(Rw, [sub(Pf[k], O[k]) for k in range(3)])


def axis_columns(machine, q, dirs=None):
    """(q, dirs) as dicts axis name -> column, for Model; q (N, num_axes)
    already in rad / mm. A direction column that is all zero is left out
    (its backlash term is then zero for every sample)."""
    import numpy as np

    names = machine.axis_names
    qd = {a: q[:, k] for k, a in enumerate(names)}
    if dirs is None:
        return qd, None
    dd = {a: dirs[:, k] for k, a in enumerate(names) if np.any(np.asarray(dirs[:, k]) != 0)}
    return qd, dd
