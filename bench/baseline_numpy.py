"""The same computations written with numpy and SciPy. The bench's fits and
forward kinematics use what a strong numpy user writes (``FusedProblem``,
``ball3d_fused``, ``lm``, ``fused_tool_points``: bench/fused_model.py's
expressions specialised to the estimated parameters, exact Jacobians by
dual numbers, fivecal's Levenberg-Marquardt rule); ``NumpyMachine`` and
``NumpyProblem`` (einsum transforms, every parameter by name) stay as the
plain reference the tests compare with and as the parser of the datasets,
and ``fit`` (``scipy.optimize.least_squares``, finite differences) serves
the "auto" loop.

It is the yardstick of bench/run.py: every figure there is a ratio measured
side by side in the same process on the same data. tests/python/test_bench_baseline.py
checks that it computes the same thing as fivecal.
"""
from __future__ import annotations

import functools

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
        # fivecal weights each row by 1 / its declared sigma (mm): the observation's
        # "sigma" (one number or one per row), else its kind's default; a scale bar
        # row has its own default. These defaults mirror the C++ DefaultSigma and
        # kScaleBarSigma, so the baseline solves the same weighted problem.
        default = {"facet": 0.001, "sphere": 0.001, "dbb": 0.0005, "ball3d": 0.001}

        def sig(i):
            o, n = obs[i], 3 if obs[i]["type"] == "ball3d" else 1
            s = o.get("sigma", default[o["type"]])
            return np.broadcast_to(np.asarray(s, float), (n,))

        parts = [sig(i) for i in list(self.f_idx) + list(self.s_idx) + list(self.b_idx)]
        parts += [np.array([0.001])] * len(self.bars)
        self.sigma = np.concatenate(parts) if parts else np.zeros(0)

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

    def weighted_residuals(self, values):
        """residuals(values) / declared sigma: the rows fivecal's fit minimises."""
        return self.residuals(values) / self.sigma

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


# ---- the fits of bench/run.py, written the way a strong numpy user would ------
#
# fused_model.Model (one expression per matrix entry, specialised to the
# estimated parameters) evaluated on numpy arrays, with exact derivatives by
# forward-mode dual numbers (value and the derivatives by every estimated
# parameter, carried through the same element-wise expressions), and the
# Levenberg-Marquardt of fivecal (bench/baseline_jax.py: lm, the same start,
# step, acceptance and stopping rule) as a Python loop. SciPy's
# least_squares has no way to cost a candidate without its Jacobian nor
# fivecal's stopping rule; ``fit`` above (least_squares, trf, finite
# differences) stays for the design search and the "auto" loop.

import fused_model as fm  # noqa: E402


class Dual:
    """A value (scalar or (N,)) and its derivatives by the p estimated
    parameters ((p, 1) or (p, N))."""

    __slots__ = ("v", "d")
    __array_ufunc__ = None      # array (op) Dual: numpy defers to Dual's reflected operators

    def __init__(self, v, d):
        self.v, self.d = v, d

    def __add__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v + o.v, self.d + o.d)
        return Dual(self.v + o, self.d)

    __radd__ = __add__

    def __sub__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v - o.v, self.d - o.d)
        return Dual(self.v - o, self.d)

    def __rsub__(self, o):
        return Dual(o - self.v, -self.d)

    def __neg__(self):
        return Dual(-self.v, -self.d)

    def __mul__(self, o):
        if isinstance(o, Dual):
            return Dual(self.v * o.v, self.d * o.v + o.d * self.v)
        return Dual(self.v * o, self.d * o)

    __rmul__ = __mul__

    def __getitem__(self, i):
        return Dual(self.v[i], self.d[:, i])


class DualOps:
    @staticmethod
    def sin(x):
        return Dual(np.sin(x.v), x.d * np.cos(x.v)) if isinstance(x, Dual) else np.sin(x)

    @staticmethod
    def cos(x):
        return Dual(np.cos(x.v), -x.d * np.sin(x.v)) if isinstance(x, Dual) else np.cos(x)

    @staticmethod
    def sqrt(x):
        s = np.sqrt(x.v)
        return Dual(s, x.d * (0.5 / s))


def _sqrt(x):
    return DualOps.sqrt(x) if isinstance(x, Dual) else np.sqrt(x)


def _parameters(x, with_jacobian):
    """The estimated values as model inputs: floats, or duals seeded by the identity."""
    if not with_jacobian:
        return [float(v) for v in x]
    eye = np.eye(len(x))
    return [Dual(float(v), eye[:, i:i + 1]) for i, v in enumerate(x)]


def _rows(parts):
    """Concatenated residual rows -> (r (m,), J (m, p) or None)."""
    if not isinstance(parts[0], Dual):
        return np.concatenate([np.broadcast_to(np.asarray(v, float), np.shape(v)) for v in parts]), None
    v = np.concatenate([np.asarray(d.v, float) for d in parts])
    J = np.concatenate([np.broadcast_to(d.d, (d.d.shape[0], np.size(d.v))) for d in parts], axis=1)
    return v, J.T


class FusedProblem:
    """NumpyProblem's weighted probing rows (facets, spheres, scale bars; the
    TANGO fits) over ``names`` with fused_model and dual numbers.
    ``evaluate(x, jacobian)`` -> (weighted rows, their Jacobian or None);
    ``noise`` (sigma units) is added to the weighted rows (a Monte Carlo trial);
    ``prob``: the dataset's NumpyProblem when the caller has parsed it already."""

    def __init__(self, dataset, names, prob=None):
        self.np = p = NumpyProblem(dataset) if prob is None else prob
        if p.b_idx.size:
            raise ValueError("FusedProblem: probing datasets only")
        self.names = list(names)
        self.model = fm.Model(dataset.machine, DualOps)
        rows = np.concatenate([p.f_idx, p.s_idx]).astype(int)
        self.nf = p.f_idx.size
        self.q, self.dirs = fm.axis_columns(dataset.machine, p.q[rows], p.dirs[rows])
        self.n_rows = p.sigma.size
        self.noise = None
        col = {n: i for i, n in enumerate(self.names)}
        self.col = col

    def evaluate(self, x, jacobian=True):
        p, col = self.np, self.col
        th = _parameters(x, jacobian)
        v = dict(zip(self.names, th))
        P = self.model.tool_points(self.q, v, self.dirs)
        nf = self.nf
        parts = []

        def setup(key):
            return th[col[key]] if key in col else 0.0

        if nf:
            d = sum(fm.mul(P[i][:nf] if not fm.const(P[i]) else P[i], p.f_n[:, i]) for i in range(3))
            off = [setup(f"facet.{t}") for t in p.f_ids]
            dot = fm.sub(d, (p.f_a * p.f_n).sum(1) + p.r_tip)
            parts.append(self._minus_each(dot, off))
        if p.s_idx.size:
            dc = [[setup(f"sphere.{t}.{c}") for t in p.s_ids] for c in "xyz"]
            d = [self._minus_each(P[i][nf:] - p.s_c[:, i], dc[i]) for i in range(3)]
            rr = [setup(f"sphere.{t}.r") for t in p.s_ids]
            parts.append(self._minus_each(_sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - (p.s_r + p.r_tip), rr))
        for s1, s2, L, spheres in p.bars:
            c = [[fm.add(spheres[s]["center"][k], setup(f"sphere.{s}.{'xyz'[k]}")) for k in range(3)]
                 for s in (s1, s2)]
            dd = [fm.sub(c[0][k], c[1][k]) for k in range(3)]
            sq = fm.add(fm.add(fm.mul(dd[0], dd[0]), fm.mul(dd[1], dd[1])), fm.mul(dd[2], dd[2]))
            bar = _sqrt(sq) - L
            parts.append(Dual(np.atleast_1d(bar.v), bar.d) if isinstance(bar, Dual) else np.atleast_1d(bar))
        if jacobian:
            parts = [q if isinstance(q, Dual) else Dual(np.asarray(q, float), np.zeros((len(x), 1))) for q in parts]
        r, J = _rows(parts)
        w = 1.0 / p.sigma
        r = r * w
        if self.noise is not None:
            r = r + self.noise
        return r, (None if J is None else J * w[:, None])

    @staticmethod
    def _minus_each(a, values):
        """a (N,) minus a per-row setup value (floats or duals, mostly 0)."""
        idx = [i for i, v in enumerate(values) if not fm.zero(v)]
        if not idx:
            return a
        if isinstance(values[idx[0]], Dual):
            a = a if isinstance(a, Dual) else Dual(np.asarray(a, float), np.zeros((values[idx[0]].d.shape[0], 1)))
            n = np.size(a.v)
            v = np.zeros(n)
            d = np.zeros((a.d.shape[0], n))
            for i in idx:
                v[i] = values[i].v
                d[:, i] = values[i].d[:, 0]
            return a - Dual(v, d)
        v = np.zeros(np.size(a.v if isinstance(a, Dual) else a))
        for i in idx:
            v[i] = values[i]
        return a - v


def fused_tool_points(machine, q, theta):
    """Forward kinematics with fused_model on numpy (values as constants: the
    zero ones cost nothing). q (N, num_axes) in mm / rad -> (N, 3)."""
    qd, _ = fm.axis_columns(machine, q)
    P = fm.Model(machine, np).tool_points(qd, {k: float(v) for k, v in theta.items()})
    return np.stack([np.broadcast_to(v, (q.shape[0],)) for v in P], axis=1)


def ball3d_fused(machine, names, q, tool_ball, table_ball, measured):
    """The ball3d rows of one mounting (the scaling benchmark) as
    ``evaluate(x, jacobian)`` -> (rows (3N,), Jacobian or None), unweighted."""
    model = fm.Model(machine, DualOps)
    qd, _ = fm.axis_columns(machine, q)
    tool = [float(v) for v in tool_ball]
    const_part = [np.asarray(table_ball, float)[i] + measured[:, i] for i in range(3)]
    n = q.shape[0]

    def evaluate(x, jacobian=True):
        th = _parameters(x, jacobian)
        P = model.tool_points(qd, dict(zip(names, th)), None, tool)
        cols = [fm.sub(P[i], const_part[i]) for i in range(3)]
        if not jacobian:
            return np.stack([np.broadcast_to(c, (n,)) for c in cols], axis=1).ravel(), None
        r = np.stack([c.v for c in cols], axis=1).ravel()
        J = np.stack([np.broadcast_to(c.d, (len(x), n)) for c in cols], axis=2).reshape(len(x), 3 * n).T
        return r, J

    return evaluate


def lm(evaluate, x0, max_iterations=100):
    """fivecal's Levenberg-Marquardt (baseline_jax.lm's rule) on
    ``evaluate(x, jacobian)`` as a Python loop. Returns a dict: x, cost,
    converged, iterations (steps solved), jacobian_evaluations,
    residual_evaluations, JtJ (at x)."""
    FTOL, XTOL, GTOL = 1e-10, 1e-12, 1e-16
    x = np.asarray(x0, float).copy()
    r, J = evaluate(x, True)
    nj, nr, it = 1, 0, 0
    c = 0.5 * r @ r
    radius, df = 1e12, 2.0
    converged = False
    while it < max_iterations:
        g = J.T @ r
        N = J.T @ J
        if np.max(np.abs(g)) <= GTOL:
            converged = True
            break
        A = N + np.diag(np.clip(np.diagonal(N), 1e-6, 1e32) / radius)
        dx = -np.linalg.solve(A, g)
        if np.linalg.norm(dx) <= XTOL * (np.linalg.norm(x) + XTOL):
            converged = True
            break
        it += 1
        model = -(g @ dx + 0.5 * dx @ (N @ dx))
        last = model <= 10 * FTOL * c
        cand = x + dx
        r1, J1 = evaluate(cand, not last)
        nj, nr = nj + (not last), nr + last
        c1 = 0.5 * r1 @ r1
        if abs(c - c1) <= FTOL * c:
            converged = True
            break
        rho = (c - c1) / model if model > 0 else -1.0
        if np.isfinite(c1) and rho > 1e-3:
            if last:
                r1, J1 = evaluate(cand, True)
                nj += 1
            x, r, J, c = cand, r1, J1, c1
            radius = min(1e16, radius / max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3))
            df = 2.0
        else:
            radius /= df
            df *= 2.0
            if radius < 1e-32:
                break
    return {"x": x, "cost": c, "converged": bool(converged), "iterations": int(it),
            "jacobian_evaluations": int(nj), "residual_evaluations": int(nr), "JtJ": J.T @ J, "r": r, "J": J}


# ---- estimate "auto": hierarchical prior, evidence loop, variance components ----
#
# fivecal's identify(ds, "auto") (cpp/src/solve/identify.cc, AdaptHyperparameters)
# written with numpy: every candidate under a Gaussian prior (mean 0,
# the documented sigma of its class), the class scales lambda_k in [1e-3, 1]
# on those sigmas by MacKay's evidence fixed point
#     lambda_k^2 = sum_j (theta_j / s_j)^2 / sum_j gamma_j,
#     gamma_j = 1 - posterior var_j / (lambda_k s_j)^2,
# at the MAP point of the current scales (one warm-started MAP fit per
# round), optionally with Helmert/REML variance components of the noise
# groups, f_g^2 <- f_g^2 sum_g (e_i / s_i)^2 / sum_g (1 - H_ii); stop when no
# scale or factor moves by more than 1 % (1e-3 with variance components) in
# log, at most 60 rounds; then one more MAP fit at the final scales and the
# posterior covariance under the documented (unscaled) priors, inflated by
# max(1, chi2 / dof). Setup parameters and the stylus tip keep their prior.

MIN_CLASS_SCALE = 1e-3
MIN_REDUNDANCY = 5.0
# A probe touch of any kind is one instrument (fivecal's noise class "probe");
# the ball instruments are each their own.
NOISE_GROUP = {"facet": "probe", "sphere": "probe", "dbb": "dbb", "ball3d": "ball3d"}


def prior_class(machine: fivecal.Machine, name: str) -> str:
    """The documented prior class of a parameter (the rules of
    cpp/src/solve/priors.cc PriorClassOf for the probing setup)."""
    if name.startswith("tip."):
        return "tip"
    if name.startswith("facet."):
        return "facet"
    if name.startswith("sphere."):
        return "sphere_radius" if name.endswith(".r") else "sphere_center"
    if not name.startswith("E") or len(name) != 4:
        raise ValueError(f"prior_class: no class for '{name}' in the numpy baseline")
    comp, axis, last = name[1], name[2:3], name[3]
    if axis == "0":          # location E<c>0<axis>
        return "location_angle" if comp in "ABC" else "location_offset"
    ax = {a["name"]: a for a in machine.axes}[axis]
    rotary = ax["type"] == "rotary"
    if last == "b":
        return "backlash_rotary" if rotary else "backlash_linear"
    d, angular = int(last), comp in "ABC"
    if rotary:
        return f"rotary_{'tilt' if angular else 'motion'}_{d}"
    if d == 1 and not angular and abs(ax["direction"]["XYZ".index(comp)]) > 0.5:
        return "scale_gain"    # the axis's own translational component of degree 1
    return f"linear_{'tilt' if angular else 'motion'}_{d}"


def prior_sigmas(dataset: fivecal.Dataset, names):
    """(documented prior sigma per name, class per name): the class's sigma,
    overridden by the machine file's "priors" (class:<name>, then the name)."""
    from fivecal.identification import prior_classes

    sigma = {c["name"]: c["sigma"] for c in prior_classes()}
    machine_priors = dataset.to_dict()["machine"].get("priors") or {}
    cls = [prior_class(dataset.machine, n) for n in names]
    s = []
    for n, c in zip(names, cls):
        v = machine_priors.get(f"class:{c}", sigma[c])
        s.append(machine_priors.get(n, v))
    return np.array(s, float), cls


class AutoSetup:
    """What both baselines need for "auto": documented priors of ``names``,
    the hierarchical classes (machine errors but the tip: setup parameters
    keep their prior) as a one-hot (classes x names) matrix, and the noise
    group of every residual row of NumpyProblem (scale bars: none, -1)."""

    def __init__(self, dataset, names, prob=None):
        self.dataset = dataset
        self.prob = NumpyProblem(dataset) if prob is None else prob
        self.names = list(names)
        self.prior, cls = prior_sigmas(dataset, self.names)
        machine_names = set(dataset.machine.parameter_names())
        scaled = [c if (n in machine_names and c != "tip") else None for n, c in zip(self.names, cls)]
        self.classes = sorted({c for c in scaled if c})
        self.cls_idx = np.array([self.classes.index(c) if c else -1 for c in scaled], int)
        self.members = np.array([self.cls_idx == k for k in range(len(self.classes))], float).reshape(
            len(self.classes), len(self.names))
        p = self.prob
        kinds = ([p.types[i] for i in p.f_idx] + [p.types[i] for i in p.s_idx]
                 + [t for i in p.b_idx for t in [p.types[i]] * (3 if p.types[i] == "ball3d" else 1)])
        self.groups = sorted({NOISE_GROUP[k] for k in kinds})
        self.row_group = np.array([self.groups.index(NOISE_GROUP[k]) for k in kinds] + [-1] * len(p.bars), int)
        self.group_rows = np.array([self.row_group == g for g in range(len(self.groups))], float).reshape(
            len(self.groups), self.row_group.size)
        self.n_rows = self.row_group.size

    @functools.cached_property
    def fused(self):
        """The numpy baseline's problem over these names (built once per
        setup, like the JAX baseline's trace; probing datasets only)."""
        return FusedProblem(self.dataset, self.names, prob=self.prob)

    def lam_per_name(self, lam):
        return np.where(self.cls_idx >= 0, np.append(lam, 1.0)[self.cls_idx], 1.0)

    def factor_per_row(self, factor):
        return np.where(self.row_group >= 0, np.append(factor, 1.0)[self.row_group], 1.0)


def evidence_update(members, u, Jd, lam_p):
    """One evidence step. u: values in units of the documented priors; Jd:
    weighted data rows' Jacobian in those units; lam_p: the class scale of
    each column (1 for unscaled ones). Returns (new class scales, Ninv in u
    units)."""
    N = Jd.T @ Jd
    N[np.diag_indices_from(N)] += 1.0 / lam_p ** 2
    Ninv = np.linalg.inv(N)
    gamma = np.clip(1.0 - np.diag(Ninv) / lam_p ** 2, 0.0, 1.0)
    m2, g = members @ (u * u), members @ gamma
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(g > 1e-9, np.sqrt(m2 / np.where(g > 1e-9, g, 1.0)), MIN_CLASS_SCALE)
    lam = np.clip(np.where(np.isfinite(lam), lam, 1.0), MIN_CLASS_SCALE, 1.0)
    return lam, Ninv


def variance_update(group_rows, factor, r_w, Jd, Ninv):
    """Helmert / REML step: r_w the weighted data rows at the current noise."""
    h = np.einsum("ij,ij->i", Jd @ Ninv, Jd)
    red = group_rows @ np.clip(1.0 - h, 0.0, 1.0)
    chi2 = group_rows @ (r_w * r_w)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = factor * np.sqrt(chi2 / red)
    ok = (red >= MIN_REDUNDANCY) & np.isfinite(f) & (f > 0)
    return np.where(ok, f, factor), red


def auto_covariance(Jd, lam_p, chi2, n_rows):
    """fivecal's MAP covariance in prior units: (Jd^T Jd + I)^-1 under the
    documented priors, times max(1, chi2 / dof), dof = rows - round(trace of
    the hat matrix of the fit that ran, at the scaled priors)."""
    p = Jd.shape[1]
    N = Jd.T @ Jd
    Cs = np.linalg.inv(N + np.eye(p))
    Nu = (lam_p[:, None] * N * lam_p[None, :]) + np.eye(p)
    p_eff = p - np.trace(np.linalg.inv(Nu))
    dof = max(1, n_rows - int(round(p_eff)))
    return max(1.0, chi2 / dof) * Cs


def identify_auto(dataset, names, variance_components=False, setup=None, max_rounds=60):
    """estimate="auto" with numpy over ``names`` (fivecal's candidates,
    ``Result.estimated``), as a strong numpy user writes it: each MAP fit is
    ``lm`` (fivecal's Levenberg-Marquardt rule, warm-started from the last
    round) on FusedProblem's weighted rows, with their exact dual-number
    Jacobian, augmented by the prior rows u / lambda, in u = theta /
    documented sigma; the evidence and variance updates use the Jacobian
    ``lm`` ends on (no extra evaluation). Returns a dict: values, std (dicts
    by name), class_scales, variance_factors, rounds, function_evaluations
    (costed without derivatives) and jacobian_evaluations."""
    a = AutoSetup(dataset, names) if setup is None else setup
    fused = a.fused
    prior, n, m = a.prior, len(a.names), a.n_rows
    lam = np.ones(len(a.classes))
    factor = np.ones(len(a.groups))
    tol = 1e-3 if variance_components else 0.01
    u = np.zeros(n)
    counts = {"residual": 0, "jacobian": 0}

    def map_fit(u0, lam_p, f_rows):
        prior_rows = np.diag(1.0 / lam_p)

        def evaluate(x, jacobian=True):
            r, J = fused.evaluate(x * prior, jacobian)
            r = np.concatenate([r / f_rows, x / lam_p])
            if J is None:
                return r, None
            return r, np.vstack([J * prior[None, :] / f_rows[:, None], prior_rows])

        sol = lm(evaluate, u0)
        counts["residual"] += sol["residual_evaluations"]
        counts["jacobian"] += sol["jacobian_evaluations"]
        return sol

    rounds = 0
    for rounds in range(1, max_rounds + 1):
        lam_p = a.lam_per_name(lam)
        sol = map_fit(u, lam_p, a.factor_per_row(factor))
        u = sol["x"]
        Jd = sol["J"][:m]
        new_lam, Ninv = evidence_update(a.members, u, Jd, lam_p)
        change = float(np.max(np.abs(np.log(new_lam / lam)), initial=0.0))
        lam = new_lam
        if variance_components:
            new_f, _ = variance_update(a.group_rows, factor, sol["r"][:m] * (a.row_group >= 0), Jd, Ninv)
            change = max(change, float(np.max(np.abs(np.log(new_f / factor)), initial=0.0)))
            factor = new_f
        if change < tol:
            break
    lam_p = a.lam_per_name(lam)
    sol = map_fit(u, lam_p, a.factor_per_row(factor))
    Jd, r_w = sol["J"][:m], sol["r"][:m]
    Cs = auto_covariance(Jd, lam_p, float(r_w @ r_w), m)
    std = prior * np.sqrt(np.maximum(np.diag(Cs), 0.0))
    return {"values": dict(zip(a.names, sol["x"] * prior)), "std": dict(zip(a.names, std)),
            "class_scales": dict(zip(a.classes, lam)),
            "variance_factors": dict(zip(a.groups, factor)) if variance_components else {},
            "rounds": rounds, "function_evaluations": int(counts["residual"]),
            "jacobian_evaluations": int(counts["jacobian"])}


# ---- test design: greedy + exchange D-optimal search ----------------------------

def fd_jacobian(fun, names, h=1e-6):
    """Central finite-difference Jacobian of fun(dict) at 0 over ``names``."""
    cols = []
    for n in names:
        cols.append((fun({n: h}) - fun({n: -h})) / (2 * h))
    return np.stack(cols, axis=1)


class NumpyDesign:
    """The search of fivecal.design.design_plan (criterion "d", method
    "exchange"), written with numpy: the Jacobian of the DESIGN.md residuals
    at the nominal machine by central finite differences of NumpyProblem,
    per-indexation information matrices J_g^T J_g, and batched numpy linear
    algebra (one ``eigvalsh`` over the stack of all candidate selections of a
    step). Same rules as the C++ search: a setup column (facet offset, sphere
    centre) counts only once a chosen touch uses it, the scale bar's row once
    both of its balls are touched; rank first (fewest null directions, then
    the largest sum of log non-null eigenvalues), then the Ds-criterion
    (1/p_m) log det of the Schur complement on the machine columns in
    characteristic units.

    ``names``: the estimated columns, machine parameters first (``n_machine``
    of them); ``scale``: their characteristic scales (mm per unit).
    """

    def __init__(self, dataset, names, n_machine, scale, groups, tol=1e-7):
        prob = NumpyProblem(dataset)
        self.names, self.p, self.pm = list(names), len(names), int(n_machine)
        self.tol = tol
        J = fd_jacobian(prob.residuals, self.names)
        n_obs = len(prob.types)
        row_obs = np.concatenate([prob.f_idx, prob.s_idx, prob.b_idx]).astype(int)
        if prob.b_idx.size:
            raise ValueError("NumpyDesign: probing datasets only (facets, spheres, scale bars)")
        n_touch_rows = row_obs.size
        self.groups = np.asarray(groups, dtype=int)
        self.G = int(self.groups.max()) + 1
        col = {n: i for i, n in enumerate(self.names)}
        # per-indexation information and activation counts
        g_row = self.groups[row_obs]
        order = np.argsort(g_row, kind="stable")
        cuts = np.searchsorted(g_row[order], np.arange(self.G + 1))
        Jt = J[:n_touch_rows][order]
        self.info = np.empty((self.G, self.p, self.p))
        for g in range(self.G):
            Jg = Jt[cuts[g]:cuts[g + 1]]
            self.info[g] = Jg.T @ Jg
        obs = dataset.to_dict()["observations"]
        sphere_ids = sorted({o["target"] for o in obs if o["type"] == "sphere"})
        sph = {s: i for i, s in enumerate(sphere_ids)}
        self.cnt = np.zeros((self.G, self.p), dtype=int)
        self.sph = np.zeros((self.G, max(1, len(sphere_ids))), dtype=int)
        for i in range(n_obs):
            o, g = obs[i], self.groups[i]
            if o["type"] == "facet":
                c = col.get(f"facet.{o['target']}")
                if c is not None:
                    self.cnt[g, c] += 1
            else:
                self.sph[g, sph[o["target"]]] += 1
                for a in "xyz":
                    c = col.get(f"sphere.{o['target']}.{a}")
                    if c is not None:
                        self.cnt[g, c] += 1
        self.core = np.arange(self.p) < self.pm            # machine columns: always estimated
        self.bars = []
        for b, (s1, s2, _, _) in enumerate(prob.bars):
            r = J[n_touch_rows + b]
            self.bars.append((sph[s1], sph[s2], np.outer(r, r)))
        self.log_scale2 = 2.0 * np.log(np.asarray(scale, float)[: self.pm])
        self.evaluations = 0

    # -- scoring a stack of selections ------------------------------------------
    def _with_bars(self, M, sph):
        """M: (B, p, p) touches only; sph: (B, n_spheres) touch counts."""
        for s1, s2, Mb in self.bars:
            on = (sph[:, s1] > 0) & (sph[:, s2] > 0)
            if on.any():
                M = M + on[:, None, None] * Mb
        return M

    def score(self, M, cnt, sph):
        """Deficiency, log-eigenvalue sum (rank-deficient ranking) and
        Ds-criterion of each selection of the stack."""
        self.evaluations += M.shape[0]
        A = self._with_bars(M, sph)
        active = self.core[None, :] | (cnt > 0)
        d = np.diagonal(A, axis1=1, axis2=2)
        live = active & (d > 0)
        s = np.where(live, 1.0 / np.sqrt(np.where(live, d, 1.0)), 0.0)
        Ms = A * s[:, :, None] * s[:, None, :]
        i = np.arange(self.p)
        Ms[:, i, i] = np.where(live, Ms[:, i, i], 1.0)     # unused columns: decoupled unit eigenvalues
        lam = np.linalg.eigvalsh(Ms)
        cut = self.tol ** 2 * lam[:, -1:]
        pos = lam > cut
        deficiency = (active.sum(1) - live.sum(1)) + (~pos).sum(1)
        logsum = np.where(pos, np.log(np.where(pos, lam, 1.0)), 0.0).sum(1)
        nonnull = logsum / active.sum(1)
        dcrit = np.full(M.shape[0], -np.inf)
        ok = deficiency == 0
        if ok.any():
            Ss = Ms[ok][:, self.pm:, self.pm:]
            sign, logdet_ss = np.linalg.slogdet(Ss) if Ss.shape[1] else (np.ones(ok.sum()), np.zeros(ok.sum()))
            shift = (np.log(d[ok][:, : self.pm]) + self.log_scale2).sum(1)
            dcrit[ok] = np.where(sign > 0, (logsum[ok] - logdet_ss + shift) / self.pm, -np.inf)
        return deficiency, nonnull, dcrit

    @staticmethod
    def _best(deficiency, nonnull, dcrit):
        m = deficiency.min()
        key = -nonnull if m > 0 else -dcrit
        return int(np.argmin(np.where(deficiency == m, key, np.inf)))

    @staticmethod
    def _better(a, b):
        """fivecal's strict ordering of two (deficiency, nonnull, dcrit)."""
        if a[0] != b[0]:
            return a[0] < b[0]
        if a[0] > 0:
            return a[1] > b[1] + 1e-12
        return -a[2] < -b[2] - 1e-9 * max(1.0, abs(b[2]))

    def search(self, k, max_passes=50):
        """Greedy forward selection of k indexations, then best-swap exchange
        passes while a swap improves. Returns (groups, history)."""
        chosen = np.zeros(self.G, dtype=bool)
        M = np.zeros((self.p, self.p))
        cnt = np.zeros(self.p, dtype=int)
        sph = np.zeros(self.sph.shape[1], dtype=int)
        history = []
        best = None
        for _ in range(k):
            h = np.where(~chosen)[0]
            sc = self.score(M + self.info[h], cnt + self.cnt[h], sph + self.sph[h])
            j = self._best(*sc)
            g = h[j]
            chosen[g] = True
            M, cnt, sph = M + self.info[g], cnt + self.cnt[g], sph + self.sph[g]
            best = tuple(x[j] for x in sc)
            history.append(best[2] if best[0] == 0 else -np.inf)
        for _ in range(max_passes):
            swap, swap_score = None, best
            h = np.where(~chosen)[0]
            if h.size == 0:
                break
            for g in np.where(chosen)[0]:
                Mw, cw, sw = M - self.info[g], cnt - self.cnt[g], sph - self.sph[g]
                sc = self.score(Mw + self.info[h], cw + self.cnt[h], sw + self.sph[h])
                j = self._best(*sc)
                cand = tuple(x[j] for x in sc)
                if self._better(cand, swap_score):
                    swap, swap_score = (g, h[j]), cand
            if swap is None:
                break
            g, hh = swap
            chosen[g], chosen[hh] = False, True
            M = M - self.info[g] + self.info[hh]
            cnt = cnt - self.cnt[g] + self.cnt[hh]
            sph = sph - self.sph[g] + self.sph[hh]
            best = swap_score
            history.append(best[2] if best[0] == 0 else -np.inf)
        return [int(g) for g in np.where(chosen)[0]], history


def design_search(dataset, names, n_machine, scale, groups, k, max_passes=50):
    """Everything the numpy way, from the candidate dataset: Jacobian, per-
    indexation information, greedy + exchange. Returns (groups, observation
    indices, history, evaluations)."""
    nd = NumpyDesign(dataset, names, n_machine, scale, groups)
    chosen, history = nd.search(k, max_passes)
    obs = np.where(np.isin(nd.groups, chosen))[0]
    return chosen, [int(i) for i in obs], history, nd.evaluations
