"""The same computations written the way a strong Python user would with JAX:
the model of bench/baseline_numpy.py in double precision, jit-compiled, with
exact Jacobians (``jax.jacfwd``), a Levenberg-Marquardt solve inside
``lax.while_loop`` and ``vmap`` over Monte Carlo trials.

It is the second yardstick of bench/run.py (the first is the numpy/SciPy
baseline): run in the same process on the same data, its answers are checked
against fivecal's before any time is reported. JAX is a bench-only dependency
(the ``bench`` extra); the package never imports it.

Every solver here is built once per problem shape by ``jax.jit``: the first
call pays the compilation (reported apart as ``jax_compile_s``), later calls
on arrays of the same shapes reuse it.
"""
from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax import lax  # noqa: E402

import baseline_numpy as base  # noqa: E402  (dataset parsing: the same rows as the numpy baseline)

COMP = "XYZABC"


def rotzyx(a, b, c):
    """Rz(c) Ry(b) Rx(a) for broadcastable angles -> (..., 3, 3)."""
    a, b, c = jnp.broadcast_arrays(jnp.asarray(a), jnp.asarray(b), jnp.asarray(c))
    ca, sa, cb, sb, cc, sc = jnp.cos(a), jnp.sin(a), jnp.cos(b), jnp.sin(b), jnp.cos(c), jnp.sin(c)
    rows = [[cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa],
            [sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa],
            [-sb, cb * sa, cb * ca]]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def axis_angle(u, q):
    """Rotation by q (N,) about the constant unit u -> (N, 3, 3) (Rodrigues)."""
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]], dtype=float)
    s, c = jnp.sin(q)[:, None, None], jnp.cos(q)[:, None, None]
    return jnp.eye(3) + s * K + (1 - c) * (K @ K)


def mm(A, B):
    """Batched 3x3 products (einsum: on XLA's CPU backend it beat both the
    broadcast multiply-add and the unrolled nine-entry forms)."""
    return jnp.einsum("...ij,...jk->...ik", A, B)


def mv(A, v):
    """Batched 3x3 matrix times vector."""
    return jnp.einsum("...ij,...j->...i", A, v)


class JaxMachine:
    """The kinematic model of baseline_numpy.NumpyMachine in jax.numpy.

    ``theta`` is a dict name -> scalar (a Python float or a traced value);
    absent names are zero. The dict is read while tracing, so a jitted
    function fixes which names exist and takes their values as arrays."""

    def __init__(self, machine):
        self.names = machine.axis_names
        self.axes = {a["name"]: a for a in machine.axes}
        self.workpiece = machine.workpiece_chain
        self.tool = machine.tool_chain
        self.tip = np.asarray(machine.tip, dtype=float)

    def _chain(self, chain, q, dirs, th):
        n = q.shape[0]
        R = jnp.broadcast_to(jnp.eye(3), (n, 3, 3))
        t = jnp.zeros((n, 3))
        p_parent = np.zeros(3)
        for a in chain:
            ax = self.axes[a]
            k = self.names.index(a)
            u = np.asarray(ax["direction"], float)
            p = np.asarray(ax["point"], float)
            loc = [th.get(f"E{c}0{a}", 0.0) for c in COMP]
            t = t + mv(R, (p - p_parent) + jnp.stack(jnp.broadcast_arrays(*loc[:3])))
            R = mm(R, rotzyx(loc[3], loc[4], loc[5]))
            qk = q[:, k]
            qm = qk + th.get(f"E{a}{a}b", 0.0) * dirs[:, k]
            if ax["type"] == "rotary":
                R = mm(R, axis_angle(u, qm))
            else:
                t = t + mv(R, u) * qm[:, None]
            e = [sum(th.get(f"E{c}{a}{d}", 0.0) * qk ** d for d in (1, 2, 3)) for c in COMP]
            e = [jnp.broadcast_to(x, qk.shape) for x in e]
            t = t + mv(R, jnp.stack(e[:3], axis=1))
            R = mm(R, rotzyx(e[3], e[4], e[5]))
            p_parent = p
        return R, t, p_parent

    def tool_points(self, q, th, dirs=None, tip=None):
        """q: (N, num_axes) in mm / rad; th: dict name -> value; -> (N, 3)."""
        dirs = jnp.zeros_like(q) if dirs is None else dirs
        if tip is None:
            tip = self.tip + jnp.stack([jnp.asarray(th.get(f"tip.{c}", 0.0), float) for c in "xyz"])
        tip = jnp.broadcast_to(tip, (q.shape[0], 3))
        Rt, tt, pt = self._chain(self.tool, q, dirs, th)
        Rw, tw, pw = self._chain(self.workpiece, q, dirs, th)
        Pf = mv(Rt, tip - pt) + tt
        O = tw - mv(Rw, pw)
        return mv(jnp.swapaxes(Rw, -1, -2), Pf - O)


def forward_kinematics(machine, names):
    """A jitted (q (N, num_axes) in mm/rad, values (len(names),)) -> (N, 3)."""
    model, names = JaxMachine(machine), list(names)
    return jax.jit(lambda q, x: model.tool_points(q, dict(zip(names, x))))


# ---- Levenberg-Marquardt -----------------------------------------------------

def lm(fun, x0, max_iterations=100, ftol=1e-12, xtol=1e-12):
    """Levenberg-Marquardt on fun: x -> residual vector, inside lax.while_loop
    (so it jits and vmaps). Each pass is one forward-mode evaluation giving the
    residuals and their exact Jacobian (jacfwd) at the trial point x + dx; the
    step solves (J^T J + lam diag(J^T J)) dx = -J^T r in column-scaled form
    (the Marquardt scaling, as SciPy's x_scale="jac"). A step is taken when it
    lowers the cost; the solve stops when the cost falls by less than ftol
    relatively (or its linear model predicts so: near the optimum a step can
    lose to rounding, and raising lam then would only spin) or the scaled step
    is below xtol relatively. The first pass evaluates x0 itself, so the
    Jacobian is traced and compiled once.

    Returns (x, Jacobian evaluations, cost, converged)."""
    jac = jax.jacfwd(lambda x: (fun(x), fun(x)), has_aux=True)
    p = x0.shape[0]
    m = jax.eval_shape(fun, x0).shape[0]

    def step(r, J, lam):
        d = jnp.sum(J * J, axis=0)
        s = 1.0 / jnp.sqrt(jnp.where(d > 0, d, 1.0))
        Js = J * s
        return -s * jnp.linalg.solve(Js.T @ Js + lam * jnp.eye(p), Js.T @ r), s

    def body(state):
        x, r, J, c, lam, dx, s, it, _, _ = state
        J1, r1 = jac(x + dx)
        c1 = r1 @ r1
        first = it == 0
        accept = first | (c1 < c)
        lin = r + J @ dx
        small = jnp.linalg.norm(dx / s) <= xtol * (xtol + jnp.linalg.norm(x / s))
        conv = ~first & ((accept & (c - c1 <= ftol * c)) | (c - lin @ lin <= ftol * c) | small)
        x = jnp.where(accept, x + dx, x)
        r = jnp.where(accept, r1, r)
        J = jnp.where(accept, J1, J)
        c = jnp.where(accept, c1, c)
        lam = jnp.where(first, lam, jnp.where(accept, jnp.maximum(lam * 0.1, 1e-12), lam * 10.0))
        dx, s = step(r, J, lam)
        it = it + 1
        return x, r, J, c, lam, dx, s, it, conv | (it >= max_iterations) | (lam > 1e16), conv

    zero = jnp.zeros(p)
    state = (x0, jnp.zeros(m), jnp.zeros((m, p)), jnp.asarray(jnp.inf), jnp.asarray(1e-3), zero, zero + 1.0,
             jnp.asarray(0), jnp.asarray(False), jnp.asarray(False))
    x, _, _, c, _, _, _, it, _, ok = lax.while_loop(lambda st: ~st[8], body, state)
    return x, it, 0.5 * c, ok


# ---- the fits of bench/run.py ---------------------------------------------------

class JaxProblem:
    """The DESIGN.md residuals of a fivecal dataset (the rows and weights of
    baseline_numpy.NumpyProblem, which parses the dataset) in jax.numpy.

    ``weighted_residuals(x, noise)`` takes the values of ``names`` as a
    vector and an optional noise vector (in sigma units, added to the
    weighted rows: a Monte Carlo trial)."""

    def __init__(self, dataset, names):
        self.np = p = base.NumpyProblem(dataset)
        self.names = list(names)
        self.model = JaxMachine(dataset.machine)
        self.sigma = np.asarray(p.sigma, float)
        self.n_rows = self.sigma.size
        # Setup values enter by gathers from [x, 0] (index len(names): not
        # estimated, zero): one gather per kind of row, not one op per row.
        col = {n: i for i, n in enumerate(self.names)}

        def ix(keys):
            return np.array([col.get(k, len(self.names)) for k in keys], int)

        self.f_off = ix(f"facet.{i}" for i in p.f_ids)
        self.s_dc = ix(f"sphere.{i}.{c}" for i in p.s_ids for c in "xyz").reshape(-1, 3)
        self.s_dr = ix(f"sphere.{i}.r" for i in p.s_ids)
        self.bar_c = np.array([[b[3][s]["center"] for s in b[:2]] for b in p.bars], float).reshape(-1, 2, 3)
        self.bar_dc = ix(f"sphere.{s}.{c}" for b in p.bars for s in b[:2] for c in "xyz").reshape(-1, 2, 3)
        self.bar_len = np.array([b[2] for b in p.bars], float)
        pre = [("dbb" if o["type"] == "dbb" else "ball3d") + (f".{o['setup']}" if o.get("setup") else "")
               for o in p.balls]
        self.b_tool_d = ix(f"{q}.tool.{c}" for q in pre for c in "xyz").reshape(-1, 3)
        self.b_table_d = ix(f"{q}.table.{c}" for q in pre for c in "xyz").reshape(-1, 3)
        self.b_len_d = ix(f"{q}.length" for q in pre)
        self.b_tool = np.array([o["tool_ball"] for o in p.balls], float).reshape(-1, 3)
        self.b_table = np.array([o["table_ball"] for o in p.balls], float).reshape(-1, 3)
        self.b_meas = np.array([o.get("measured", [0, 0, 0]) for o in p.balls], float).reshape(-1, 3)
        self.b_dbb = np.array([o.get("length", 0.0) + o.get("reading", 0.0) for o in p.balls], float)
        # Ball rows in observation order (one per DBB reading, three per ball3d
        # sample) as one gather from [the ball3d rows, the DBB rows].
        nb, order = len(p.balls), []
        for k, o in enumerate(p.balls):
            order += [3 * nb + k] if o["type"] == "dbb" else [3 * k, 3 * k + 1, 3 * k + 2]
        self.b_order = np.array(order, int)

    def residuals(self, x):
        p = self.np
        v = dict(zip(self.names, x))
        xz = jnp.concatenate([x, jnp.zeros(1)])
        out = []
        if p.f_idx.size:
            P = self.model.tool_points(p.q[p.f_idx], v, p.dirs[p.f_idx])
            out.append(((P - p.f_a) * p.f_n).sum(1) - p.r_tip - xz[self.f_off])
        if p.s_idx.size:
            P = self.model.tool_points(p.q[p.s_idx], v, p.dirs[p.s_idx])
            out.append(jnp.linalg.norm(P - p.s_c - xz[self.s_dc], axis=1) - (p.s_r + p.r_tip + xz[self.s_dr]))
        if p.b_idx.size:
            tip = self.b_tool + xz[self.b_tool_d]
            tb = self.b_table + xz[self.b_table_d]
            P = self.model.tool_points(p.q[p.b_idx], v, p.dirs[p.b_idx], tip=tip)
            d3 = (P - tb - self.b_meas).ravel()
            dbb = jnp.linalg.norm(P - tb, axis=1) - (self.b_dbb + xz[self.b_len_d])
            out.append(jnp.concatenate([d3, dbb])[self.b_order])
        if self.bar_len.size:
            c = self.bar_c + xz[self.bar_dc]
            out.append(jnp.linalg.norm(c[:, 0] - c[:, 1], axis=1) - self.bar_len)
        return jnp.concatenate(out)

    def weighted_residuals(self, x, noise=None):
        w = self.residuals(x) / self.sigma
        return w if noise is None else w + noise

    def fit_function(self):
        """A jitted () -> (x, iterations, cost, converged) from zero."""
        x0 = jnp.zeros(len(self.names))
        return jax.jit(lambda: lm(self.weighted_residuals, x0))

    def monte_carlo_function(self, batch=64):
        """A jitted (x_start, key, trials) -> fitted values (trials, p):
        trial t re-fits the weighted rows plus N(0, 1) noise (on every row,
        the scale bars' included) from x_start
        (the reference fit), vmapped over trials ``batch`` at a time (lax.map:
        all trials at once would hold trials x rows x unknowns x 9 doubles of
        tangents per rotation)."""

        def one(x_start, noise):
            return lm(lambda x: self.weighted_residuals(x, noise), x_start)[0]

        # Every row, the scale bars' too: fivecal's Monte Carlo re-draws a
        # bar's calibrated length with the sigma its row is weighted by.
        def run(x_start, key, trials):
            noise = jax.random.normal(key, (trials, self.n_rows))
            return lax.map(lambda e: one(x_start, e), noise, batch_size=batch)

        return jax.jit(run, static_argnums=2)


# ---- estimate "auto": hierarchical prior, evidence loop, variance components ----
#
# baseline_numpy.identify_auto (fivecal's AdaptHyperparameters: class scales
# by the evidence fixed point, optional variance components, then one more
# MAP fit and the covariance) with one jitted round: the Levenberg-Marquardt
# MAP fit (``lm``) on JaxProblem's weighted rows plus the prior rows
# u / lambda, u = theta / documented sigma, warm-started from the previous
# round, then the evidence and variance steps on the exact Jacobian (jacfwd)
# at the MAP point. The rounds are a Python loop around it (the stopping
# rule needs one scalar per round); the final fit is one more round whose
# Jacobian gives the covariance. One round compiled, not two nested
# while_loops (the fit's compile dominated the whole loop's). The priors,
# classes and noise groups come from baseline_numpy.AutoSetup (the same
# parsing as the numpy baseline).

class JaxAuto:
    """estimate="auto" over ``names`` (fivecal's Result.estimated). Call
    ``run()`` -> dict(values (p,), std (p,), class_scales (K,) in
    ``setup.classes`` order, variance_factors (G,) in ``setup.groups``
    order, rounds, converged, jacobian_evaluations)."""

    def __init__(self, dataset, names, variance_components=False, max_rounds=60):
        a = self.setup = base.AutoSetup(dataset, names)
        jp = JaxProblem(dataset, names)
        prior, sigma = a.prior, jp.sigma
        members, group_rows = a.members, a.group_rows
        K, G, p, m = len(a.classes), len(a.groups), len(a.names), a.n_rows
        cls_idx = np.where(a.cls_idx >= 0, a.cls_idx, K)        # K: "no class", scale 1
        row_group = np.where(a.row_group >= 0, a.row_group, G)  # G: a scale bar, factor 1
        has_group = (a.row_group >= 0).astype(float)
        self.vc, self.max_rounds = variance_components, max_rounds
        self.tol = 1e-3 if variance_components else 0.01
        self.K, self.G = K, G

        def data_rows(u, f_rows):
            return jp.residuals(u * prior) / (sigma * f_rows)

        jac_data = jax.jacfwd(data_rows)

        def one_round(u, lam, factor):
            lam_p = jnp.append(lam, 1.0)[cls_idx]
            f_rows = jnp.append(factor, 1.0)[row_group]
            u, evaluations, _, conv = lm(lambda x: jnp.concatenate([data_rows(x, f_rows), x / lam_p]), u)
            Jd = jac_data(u, f_rows)
            r = data_rows(u, f_rows)
            N = Jd.T @ Jd
            Ninv = jnp.linalg.inv(N + jnp.diag(1.0 / lam_p ** 2))
            gamma = jnp.clip(1.0 - jnp.diag(Ninv) / lam_p ** 2, 0.0, 1.0)
            m2, g = members @ (u * u), members @ gamma
            new = jnp.where(g > 1e-9, jnp.sqrt(m2 / jnp.where(g > 1e-9, g, 1.0)), base.MIN_CLASS_SCALE)
            new = jnp.clip(jnp.where(jnp.isfinite(new), new, 1.0), base.MIN_CLASS_SCALE, 1.0)
            change = jnp.max(jnp.abs(jnp.log(new / lam)), initial=0.0)
            f = factor
            if variance_components:
                rg = r * has_group
                h = jnp.einsum("ij,ij->i", Jd @ Ninv, Jd)
                red = group_rows @ jnp.clip(1.0 - h, 0.0, 1.0)
                f = factor * jnp.sqrt((group_rows @ (rg * rg)) / red)
                f = jnp.where((red >= base.MIN_REDUNDANCY) & jnp.isfinite(f) & (f > 0), f, factor)
                change = jnp.maximum(change, jnp.max(jnp.abs(jnp.log(f / factor)), initial=0.0))
            # fivecal's covariance: documented priors (unit in u), inflated by
            # max(1, chi2 / dof), dof from the hat matrix of this fit's priors.
            Cs = jnp.linalg.inv(N + jnp.eye(p))
            p_eff = p - jnp.trace(jnp.linalg.inv(lam_p[:, None] * N * lam_p[None, :] + jnp.eye(p)))
            dof = jnp.maximum(1.0, m - jnp.round(p_eff))
            std = prior * jnp.sqrt(jnp.maximum(jnp.maximum(1.0, (r @ r) / dof) * jnp.diag(Cs), 0.0))
            return u, new, f, change, conv, evaluations + 1, std

        self._round = jax.jit(one_round)
        self._p = p

    def run(self):
        u, lam, factor = jnp.zeros(self._p), jnp.ones(self.K), jnp.ones(self.G)
        ok, evaluations, rounds = True, 0, 0
        for rounds in range(1, self.max_rounds + 1):
            u, new_lam, new_f, change, conv, ev, _ = self._round(u, lam, factor)
            lam, factor = new_lam, new_f
            ok, evaluations = ok & bool(conv), evaluations + int(ev)
            if float(change) < self.tol:
                break
        u, _, _, _, conv, ev, std = self._round(u, lam, factor)   # the final fit at the final scales
        return {"values": u * self.setup.prior, "std": std, "class_scales": lam, "variance_factors": factor,
                "rounds": rounds, "converged": ok & bool(conv), "jacobian_evaluations": evaluations + int(ev)}


def ball3d_fit_function(machine, names):
    """A jitted (q (N, num_axes) mm/rad, tool_ball, table_ball, measured (N, 3))
    -> (x, iterations, cost, converged): the ball3d fit of one mounting
    (the scaling benchmark), unweighted like the numpy baseline's (one sigma
    for every row does not move the optimum)."""
    model, names = JaxMachine(machine), list(names)

    def resid(x, q, tool, table, meas):
        return (model.tool_points(q, dict(zip(names, x)), tip=tool) - table - meas).ravel()

    def solve(q, tool, table, meas):
        return lm(lambda x: resid(x, q, tool, table, meas), jnp.zeros(len(names)))

    return jax.jit(solve)


def block(out):
    """Wait for JAX's asynchronous dispatch (timings must include the work)."""
    return jax.block_until_ready(out)
