"""The same computations written the way a researcher would with numpy and
SciPy: vectorised homogeneous transforms for the forward kinematics of
DESIGN.md's machine model, the DESIGN.md residuals, and
``scipy.optimize.least_squares`` with a finite-difference Jacobian.

It is the yardstick of bench/run.py: every figure there is a ratio measured
side by side in the same process on the same data. tests/python/test_bench_baseline.py
checks that it computes the same thing as fivecal.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

import fivecal

COMP = "XYZABC"


def rotzyx(a, b, c):
    """Rz(c) Ry(b) Rx(a) for arrays of angles -> (N, 3, 3)."""
    a, b, c = np.broadcast_arrays(np.atleast_1d(a), np.atleast_1d(b), np.atleast_1d(c))
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    R = np.empty(a.shape + (3, 3))
    R[..., 0, 0] = cc * cb
    R[..., 0, 1] = cc * sb * sa - sc * ca
    R[..., 0, 2] = cc * sb * ca + sc * sa
    R[..., 1, 0] = sc * cb
    R[..., 1, 1] = sc * sb * sa + cc * ca
    R[..., 1, 2] = sc * sb * ca - cc * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def axis_angle(u, q):
    """Rotation by q (N,) about unit u -> (N, 3, 3) (Rodrigues)."""
    q = np.atleast_1d(q)
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    s, c = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


class NumpyMachine:
    """DESIGN.md's kinematic model, vectorised over poses with numpy."""

    def __init__(self, machine: fivecal.Machine):
        self.names = machine.axis_names
        self.axes = {a["name"]: a for a in machine.axes}
        self.workpiece = machine.workpiece_chain
        self.tool = machine.tool_chain
        self.tip = np.asarray(machine.tip, dtype=float)
        self.tool_axis = np.asarray(machine._core.tool_axis, dtype=float)

    def _chain(self, chain, q, dirs, th):
        n = q.shape[0]
        R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        t = np.zeros((n, 3))
        p_parent = np.zeros(3)
        for a in chain:
            ax = self.axes[a]
            k = self.names.index(a)
            u = np.asarray(ax["direction"])
            p = np.asarray(ax["point"])
            loc = [th.get(f"E{c}0{a}", 0.0) for c in COMP]
            t = t + np.einsum("nij,j->ni", R, p - p_parent + np.array(loc[:3]))
            R = R @ rotzyx(loc[3], loc[4], loc[5])[0]
            qk = q[:, k]
            qm = qk + th.get(f"E{a}{a}b", 0.0) * dirs[:, k]
            if ax["type"] == "rotary":
                R = np.einsum("nij,njk->nik", R, axis_angle(u, qm))
            else:
                t = t + np.einsum("nij,j->ni", R, u) * qm[:, None]
            e = [sum(th.get(f"E{c}{a}{d}", 0.0) * qk ** d for d in (1, 2, 3)) for c in COMP]
            e = [np.broadcast_to(x, qk.shape) for x in e]
            t = t + np.einsum("nij,nj->ni", R, np.stack(e[:3], axis=1))
            R = np.einsum("nij,njk->nik", R, rotzyx(e[3], e[4], e[5]))
            p_parent = p
        return R, t, p_parent

    def tool_points(self, q, theta, dirs=None, tip=None):
        """q: (N, num_axes) in mm / rad; theta: dict name -> value; -> (N, 3)."""
        dirs = np.zeros_like(q) if dirs is None else dirs
        if tip is None:
            tip = self.tip + np.array([theta.get(f"tip.{c}", 0.0) for c in "xyz"])
        tip = np.broadcast_to(tip, (q.shape[0], 3))
        Rt, tt, pt = self._chain(self.tool, q, dirs, theta)
        Rw, tw, pw = self._chain(self.workpiece, q, dirs, theta)
        Pf = np.einsum("nij,nj->ni", Rt, tip - pt) + tt
        O = tw - np.einsum("nij,j->ni", Rw, pw)
        return np.einsum("nji,nj->ni", Rw, Pf - O)


class NumpyProblem:
    """The DESIGN.md residuals of a fivecal dataset, evaluated with NumpyMachine."""

    def __init__(self, dataset: fivecal.Dataset):
        d = dataset.to_dict()
        m = dataset.machine
        self.model = NumpyMachine(m)
        rot = np.array([m.is_rotary(a) for a in m.axis_names])
        obs = d["observations"]
        q = np.array([[o["axes"].get(a, 0.0) for a in m.axis_names] for o in obs], dtype=float)
        q[:, rot] = np.deg2rad(q[:, rot])
        self.q = q
        self.dirs = np.array([[o.get("direction", {}).get(a, 0) for a in m.axis_names] for o in obs],
                             dtype=float)
        self.types = np.array([o["type"] for o in obs])
        self.r_tip = d["probe"]["tip_radius"]
        facets = {f["id"]: f for f in d["artefact"]["facets"]}
        spheres = {s["id"]: s for s in d["artefact"]["spheres"]}
        self.f_idx = np.where(self.types == "facet")[0]
        self.f_ids = [obs[i]["target"] for i in self.f_idx]
        self.f_a = np.array([facets[i]["point"] for i in self.f_ids]).reshape(-1, 3)
        self.f_n = np.array([facets[i]["normal"] for i in self.f_ids]).reshape(-1, 3)
        self.s_idx = np.where(self.types == "sphere")[0]
        self.s_ids = [obs[i]["target"] for i in self.s_idx]
        self.s_c = np.array([spheres[i]["center"] for i in self.s_ids]).reshape(-1, 3)
        self.s_r = np.array([spheres[i]["radius"] for i in self.s_ids])
        probed = set(self.s_ids)
        self.bars = [(b["spheres"][0], b["spheres"][1], b["length"], spheres)
                     for b in d["artefact"]["scale_bars"] if set(b["spheres"]) <= probed]
        self.b_idx = np.where(np.isin(self.types, ["dbb", "ball3d"]))[0]
        self.balls = [obs[i] for i in self.b_idx]

    def residuals(self, values):
        """values: dict name -> value (machine and setup) -> residual vector (mm)."""
        out = []
        if self.f_idx.size:
            P = self.model.tool_points(self.q[self.f_idx], values, self.dirs[self.f_idx])
            off = np.array([values.get(f"facet.{i}", 0.0) for i in self.f_ids])
            out.append(np.einsum("ni,ni->n", self.f_n, P - self.f_a) - self.r_tip - off)
        if self.s_idx.size:
            P = self.model.tool_points(self.q[self.s_idx], values, self.dirs[self.s_idx])
            dc = np.array([[values.get(f"sphere.{i}.{c}", 0.0) for c in "xyz"] for i in self.s_ids])
            dr = np.array([values.get(f"sphere.{i}.r", 0.0) for i in self.s_ids])
            out.append(np.linalg.norm(P - self.s_c - dc, axis=1) - (self.s_r + self.r_tip + dr))
        if self.b_idx.size:
            out.append(self._ball_residuals(values))
        for s1, s2, L, spheres in self.bars:
            c1 = np.array(spheres[s1]["center"]) + [values.get(f"sphere.{s1}.{c}", 0.0) for c in "xyz"]
            c2 = np.array(spheres[s2]["center"]) + [values.get(f"sphere.{s2}.{c}", 0.0) for c in "xyz"]
            out.append(np.array([np.linalg.norm(c1 - c2) - L]))
        return np.concatenate(out)

    def _ball_residuals(self, values):
        rows = []
        for i, o in zip(self.b_idx, self.balls):
            pre = ("dbb" if o["type"] == "dbb" else "ball3d") + (f".{o['setup']}" if o.get("setup") else "")
            tip = np.array(o["tool_ball"]) + [values.get(f"{pre}.tool.{c}", 0.0) for c in "xyz"]
            tb = np.array(o["table_ball"]) + [values.get(f"{pre}.table.{c}", 0.0) for c in "xyz"]
            P = self.model.tool_points(self.q[i:i + 1], values, self.dirs[i:i + 1], tip=tip)[0]
            if o["type"] == "dbb":
                rows.append([np.linalg.norm(P - tb) - (o["length"] + values.get(f"{pre}.length", 0.0) + o["reading"])])
            else:
                rows.append(P - tb - np.array(o["measured"]))
        return np.concatenate(rows)


def ball3d_residuals(model: NumpyMachine, q, tool_ball, table_ball, measured, values):
    """Vectorised ball3d residuals of one mounting (the scaling benchmark)."""
    P = model.tool_points(q, values, tip=np.asarray(tool_ball, float))
    return (P - np.asarray(table_ball, float) - measured).ravel()


def fit(fun, names, x0=None):
    """scipy least_squares with a 2-point finite-difference Jacobian."""
    x0 = np.zeros(len(names)) if x0 is None else x0
    return least_squares(lambda x: fun(dict(zip(names, x))), x0, jac="2-point", method="trf",
                         x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12)
