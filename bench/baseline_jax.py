"""The same computations written the way a strong Python user would with JAX:
the model of bench/fused_model.py (one scalar expression per matrix entry,
specialised at trace time to the estimated parameters: an absent error is
dropped, not multiplied by zero over every sample) in double precision,
jit-compiled, with exact Jacobians (``jax.jacfwd``), a Levenberg-Marquardt
solve with fivecal's start and stopping rule inside ``lax.while_loop``, and
``vmap`` over Monte Carlo trials.

It is the second yardstick of bench/run.py (the first is the numpy
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
import fused_model as fm  # noqa: E402

COMP = fm.COMP


def _materialise(values):
    """The values written out: a lax.cond (both branches the identity, on a
    predicate XLA cannot fold) is a fusion boundary that survives XLA:CPU's
    compilation (lax.optimization_barrier does not)."""
    v0 = jnp.ravel(values[0])[0]
    return lax.cond(v0 == v0, lambda v: v, lambda v: v, values)


class JaxOps:
    """What fused_model.Model needs from jax.numpy."""
    sin = staticmethod(jnp.sin)
    cos = staticmethod(jnp.cos)
    barrier = staticmethod(_materialise)


class JaxMachine:
    """fused_model.Model on jax.numpy with an (N, num_axes) interface.

    ``theta`` is a dict name -> scalar (a Python float or a traced value);
    absent names are zero and cost nothing. The dict is read while tracing,
    so a jitted function fixes which names exist and takes their values as
    arrays."""

    def __init__(self, machine):
        self.machine = machine
        self.model = fm.Model(machine, JaxOps)

    def columns(self, q, th, dirs=None, tip=None):
        """The tool point as three (N,) expressions (for residuals that
        combine them element-wise: faster under jacfwd than tool_points)."""
        qd, dd = fm.axis_columns(self.machine, q, dirs)
        if tip is not None:
            tip = [tip[:, i] if getattr(tip, "ndim", 1) == 2 else tip[i] for i in range(3)]
        P = self.model.tool_points(qd, th, dd, tip)
        n = q.shape[0]
        return [jnp.broadcast_to(jnp.asarray(v, float), (n,)) for v in P]

    def tool_points(self, q, th, dirs=None, tip=None):
        """q: (N, num_axes) in mm / rad; th: dict name -> value; -> (N, 3).

        Stacked as (3, N) and transposed: XLA:CPU then writes the three
        expressions out once. Stacked along the last axis (or on axis 0 and
        used as such), its loop fusion evaluated the whole chain again for
        every output entry: 2,000 poses of the forward kinematics took
        0.17 s instead of 4 ms. (lax.optimization_barrier between axes does
        not survive XLA:CPU's compilation.)"""
        return jnp.stack(self.columns(q, th, dirs, tip), axis=0).T


def forward_kinematics(machine, names):
    """A jitted (q (N, num_axes) in mm/rad, values (len(names),)) -> (N, 3)."""
    model, names = JaxMachine(machine), list(names)
    return jax.jit(lambda q, x: model.tool_points(q, dict(zip(names, x))))


# ---- Levenberg-Marquardt -----------------------------------------------------

# fivecal's solver (cpp/src/solve/refit.cc DenseRefit, normal_equations.cc
# FitNormalEquations; tolerances of Problem::SolverOptions): a trust region
# so large (1e12) that the first steps are Gauss-Newton steps, the step
# (J^T J + diag(J^T J) clamped to [1e-6, 1e32] / radius) dx = -J^T r, a
# candidate accepted when its cost falls by more than 1e-3 of the linear
# model's prediction, the radius grown by 1 / max(1/3, 1 - (2 rho - 1)^3)
# after an accepted step and halved, quartered, ... after a rejected one; stop
# on a relative cost change <= 1e-10 (the candidate not taken), a step
# <= 1e-12 (|x| + 1e-12) or a gradient <= 1e-16. A candidate whose predicted
# decrease is within 10 x the function tolerance nearly always ends the fit,
# so it is costed without derivatives (DenseRefit's rule); every other one in
# one pass with its Jacobian.
FTOL, XTOL, GTOL, MIN_RELATIVE_DECREASE = 1e-10, 1e-12, 1e-16, 1e-3


def lm(fun, x0, max_iterations=100, with_rows=False):
    """Levenberg-Marquardt on fun: x -> residual vector with fivecal's start
    and stopping rule, in one lax.while_loop (it jits and vmaps). Each pass
    of the loop evaluates one point: the start or a refresh (residuals and
    exact Jacobian from one forward-mode pass, jacfwd with has_aux), or a
    candidate (the same pass, or residuals only for the last candidate of a
    converging fit; lax.cond: only the branch taken runs, unless vmapped),
    then computes the next step. The Jacobian is traced once.

    Returns (x, Jacobian evaluations, cost, converged, iterations (steps
    solved, as fivecal's Result.iterations), residual-only evaluations,
    J^T J at x) and, ``with_rows``, the residuals and Jacobian at x (what
    the evidence loop reuses instead of evaluating them again)."""
    jac = jax.jacfwd(lambda x: (lambda f: (f, f))(fun(x)), has_aux=True)
    p = x0.shape[0]
    m = jax.eval_shape(fun, x0).shape[0]

    def body(s):
        x, r, J, c, radius, df, it, nj, nr, _, _, y, mode, model = s
        # mode 0: y is x to (re)evaluate with its Jacobian; 1: a candidate
        # with its Jacobian; 2: a candidate costed without derivatives.
        r1, J1 = lax.cond(mode == 2, lambda: (fun(y), J), lambda: jac(y)[::-1])
        nj = nj + (mode != 2)
        nr = nr + (mode == 2)
        c1 = 0.5 * r1 @ r1
        cand = mode != 0
        ftol_stop = cand & (jnp.abs(c - c1) <= FTOL * c)
        rho = jnp.where(model > 0, (c - c1) / model, -1.0)
        accept = cand & ~ftol_stop & jnp.isfinite(c1) & (rho > MIN_RELATIVE_DECREASE)
        take = (mode == 0) | accept
        x = jnp.where(take, y, x)
        r = jnp.where(take, r1, r)
        J = jnp.where(take, J1, J)
        c = jnp.where(take, c1, c)
        grown = jnp.minimum(1e16, radius / jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3))
        radius = jnp.where(accept, grown, jnp.where(cand, radius / df, radius))
        df = jnp.where(accept, 2.0, jnp.where(cand, 2.0 * df, df))
        # An accepted candidate costed without derivatives: its Jacobian next.
        refresh = accept & (mode == 2)
        g = J.T @ r
        N = J.T @ J
        grad_stop = ~refresh & (jnp.max(jnp.abs(g)) <= GTOL)
        A = N + jnp.diag(jnp.clip(jnp.diagonal(N), 1e-6, 1e32) / radius)
        dx = -jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(A), True), g)
        small = ~refresh & ~grad_stop & (jnp.linalg.norm(dx) <= XTOL * (jnp.linalg.norm(x) + XTOL))
        new_model = -(g @ dx + 0.5 * dx @ (N @ dx))
        step = ~refresh & ~grad_stop & ~ftol_stop & ~small
        it = it + step
        y = jnp.where(refresh, x, x + dx)
        mode = jnp.where(refresh, 0, jnp.where(new_model <= 10 * FTOL * c, 2, 1))
        stop = ftol_stop | grad_stop | small
        done = stop | ((it >= max_iterations) & step) | (radius < 1e-32)
        return x, r, J, c, radius, df, it, nj, nr, done, stop, y, mode, new_model

    i0 = jnp.asarray(0)
    state = (x0, jnp.zeros(m), jnp.zeros((m, p)), jnp.asarray(0.0), jnp.asarray(1e12), jnp.asarray(2.0), i0, i0,
             i0, jnp.asarray(False), jnp.asarray(False), x0, i0, jnp.asarray(0.0))
    x, r, J, c, _, _, it, nj, nr, _, ok, _, _, _ = lax.while_loop(lambda s: ~s[9], body, state)
    return (x, nj, c, ok, it, nr, J.T @ J) + ((r, J) if with_rows else ())


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
        p, model = self.np, self.model
        v = dict(zip(self.names, x))
        xz = jnp.concatenate([x, jnp.zeros(1)])
        out = []
        nf = p.f_idx.size
        if nf + p.s_idx.size:
            # one model evaluation for every touch (facets, then spheres)
            rows = np.concatenate([p.f_idx, p.s_idx])
            P = model.columns(p.q[rows], v, p.dirs[rows])
        if nf:
            out.append(sum((P[i][:nf] - p.f_a[:, i]) * p.f_n[:, i] for i in range(3)) - p.r_tip - xz[self.f_off])
        if p.s_idx.size:
            d = [P[i][nf:] - p.s_c[:, i] - xz[self.s_dc[:, i]] for i in range(3)]
            out.append(jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - (p.s_r + p.r_tip + xz[self.s_dr]))
        if p.b_idx.size:
            tip = self.b_tool + xz[self.b_tool_d]
            tb = self.b_table + xz[self.b_table_d]
            P = jnp.stack(model.columns(p.q[p.b_idx], v, p.dirs[p.b_idx], tip=tip), axis=1)
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

    def fit_function(self, x0=None):
        """A jitted () -> lm's tuple (x, Jacobian evaluations, cost,
        converged, iterations, residual-only evaluations, J^T J) from x0
        (default zero)."""
        x0 = jnp.zeros(len(self.names)) if x0 is None else jnp.asarray(x0, float)
        return jax.jit(lambda: lm(self.weighted_residuals, x0))

    def monte_carlo_function(self, batch=None):
        """A jitted (x_start, key, trials) -> (fitted values (trials, p),
        Jacobian evaluations (trials,)):
        trial t re-fits the weighted rows plus N(0, 1) noise (on every row,
        the scale bars' included) from x_start
        (the reference fit), lax.map over the trials one at a time by
        default (``batch``: vmapped that many at a time; under vmap lax.cond
        runs both of its branches and the loop runs until the slowest trial
        of the batch stops: on TANGO S3, 128 trials took 19 ms a trial one
        at a time, 34 ms in batches of 16, 53 ms in batches of 64)."""

        def one(x_start, noise):
            out = lm(lambda x: self.weighted_residuals(x, noise), x_start)
            return out[0], out[1]

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

        def one_round(u, lam, factor):
            lam_p = jnp.append(lam, 1.0)[cls_idx]
            f_rows = jnp.append(factor, 1.0)[row_group]
            out = lm(lambda x: jnp.concatenate([data_rows(x, f_rows), x / lam_p]), u, with_rows=True)
            u, evaluations, conv = out[0], out[1], out[3]
            # the data rows and their Jacobian where lm stopped (a strong user
            # does not evaluate them again)
            r, Jd = out[7][:m], out[8][:m]
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
            return u, new, f, change, conv, evaluations, std

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
    -> lm's tuple: the ball3d fit of one mounting
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


# ---- test design: greedy + exchange D-optimal search ---------------------------
# (the search of baseline_numpy.NumpyDesign and of fivecal.design.design_plan,
# criterion "d", method "exchange", written the JAX way)

from functools import partial  # noqa: E402

def _design_scores(Mb, cb, sb, info, cnt, sph, bar_M, bar_s, core, log_scale2, tol, pm):
    """Scores of the selections base + one candidate, for every candidate.

    Mb (p, p), cb (p,), sb (n_spheres,): the base selection's touch information,
    column and sphere counts; info (G, p, p), cnt (G, p), sph (G, n_spheres):
    the candidates'. Returns (deficiency, nonnull, dcrit), each (G,): the
    ranking of fivecal's Evaluate (null directions counted against tol^2
    lambda_max of the column-scaled matrix; Ds-criterion on the Schur
    complement of the machine columns in characteristic units)."""
    p = Mb.shape[0]
    A = Mb + info
    S = sb + sph
    if bar_M.shape[0]:      # a scale bar's row counts once both of its balls are touched
        on = (S[:, bar_s[:, 0]] > 0) & (S[:, bar_s[:, 1]] > 0)
        A = A + jnp.einsum("gb,bij->gij", on.astype(A.dtype), bar_M)
    active = core | ((cb + cnt) > 0)

    def one(A, active):
        d = jnp.diagonal(A)
        live = active & (d > 0)
        s = jnp.where(live, 1.0 / jnp.sqrt(jnp.where(live, d, 1.0)), 0.0)
        # Unused columns: decoupled unit eigenvalues (log 1 = 0, never null).
        Ms = A * s[:, None] * s[None, :] + jnp.diag(jnp.where(live, 0.0, 1.0))
        lam = jnp.linalg.eigvalsh(Ms)
        # The Cholesky below must wait for eigvalsh (the zero times an
        # eigenvalue makes it wait; lax.optimization_barrier does not survive
        # XLA:CPU's compilation): XLA:CPU runs independent batched LAPACK calls
        # at once, each on a thread of its intra-op pool and each blocking its
        # thread until the pool has run its share of the batch; with two pool
        # threads (2 cores) both then wait for each other for ever (seen with
        # jaxlib 0.10: both pool threads parked in jax::ParallelBatchMap).
        Ss = Ms[pm:, pm:] + 0.0 * lam[-1]
        pos = lam > tol * tol * lam[-1]
        n_active = active.sum()
        deficiency = n_active - live.sum() + (~pos).sum()
        logsum = jnp.where(pos, jnp.log(jnp.where(pos, lam, 1.0)), 0.0).sum()
        if p > pm:
            L = jnp.linalg.cholesky(Ss)      # NaN when not positive definite
            logdet_ss = 2.0 * jnp.log(jnp.diagonal(L)).sum()
        else:
            logdet_ss = 0.0
        shift = (jnp.log(d[:pm]) + log_scale2).sum()
        dc = (logsum - logdet_ss + shift) / pm
        dcrit = jnp.where((deficiency == 0) & jnp.isfinite(dc), dc, -jnp.inf)
        return deficiency, logsum / n_active, dcrit

    return jax.vmap(one)(A, active)


@partial(jax.jit, static_argnames=("tol", "pm"))
def _design_add_scores(Mb, cb, sb, data, tol, pm):
    """Greedy step: the base plus each candidate indexation."""
    return _design_scores(Mb, cb, sb, *data, tol, pm)


@partial(jax.jit, static_argnames=("tol", "pm"))
def _design_swap_scores(Mbs, cbs, sbs, data, tol, pm):
    """Exchange pass: for each chosen indexation, the selection without it plus
    each candidate -> (k, G) scores; lax.map over the k bases keeps one (G, p, p)
    stack alive at a time."""
    return lax.map(lambda b: _design_scores(*b, *data, tol, pm), (Mbs, cbs, sbs))


class JaxDesign:
    """The D-optimal greedy + exchange search of fivecal.design.design_plan
    (criterion "d", method "exchange") in JAX: the Jacobian of JaxProblem's
    residuals at the nominal machine by ``jacfwd`` and the per-indexation
    information matrices in one jitted call, each step's candidate selections
    scored by one jitted, vmapped function (eigvalsh, Cholesky of the setup
    block); the discrete choices in Python around it. The rules are
    NumpyDesign's (a setup column counts once a chosen touch uses it, a scale
    bar's row once both of its balls are touched; rank first, then the
    Ds-criterion) and the choice among near-equal candidates is fivecal's:
    candidates in its scan order, a later one taken only when strictly better
    beyond its tolerance.

    Built once per pool (parsing, bookkeeping); ``search`` runs everything
    that computes, so its first call compiles."""

    def __init__(self, dataset, names, n_machine, scale, groups, tol=1e-7):
        self.prob = JaxProblem(dataset, names)
        p = self.prob.np
        if p.b_idx.size:
            raise ValueError("JaxDesign: probing datasets only (facets, spheres, scale bars)")
        self.names, self.p, self.pm, self.tol = list(names), len(names), int(n_machine), float(tol)
        self.groups = np.asarray(groups, dtype=int)
        self.G = int(self.groups.max()) + 1
        col = {n: i for i, n in enumerate(self.names)}
        # Touch rows (facets, then spheres: JaxProblem's order) gathered per
        # indexation into a zero-padded (G, rows, p) stack: row n_touch is zero.
        row_obs = np.concatenate([p.f_idx, p.s_idx]).astype(int)
        self.n_touch = row_obs.size
        g_row = self.groups[row_obs]
        order = np.argsort(g_row, kind="stable")
        size = np.bincount(g_row, minlength=self.G)
        start = np.concatenate([[0], np.cumsum(size)[:-1]])
        rank = np.arange(order.size) - start[g_row[order]]
        self.gather = np.full((self.G, int(size.max())), self.n_touch)
        self.gather[g_row[order], rank] = order
        # Activation: facet offsets and sphere centres by touch, sphere touches by sphere.
        sphere_ids = sorted(set(p.s_ids))
        sph = {s: i for i, s in enumerate(sphere_ids)}
        self.cnt = np.zeros((self.G, self.p), dtype=int)
        self.sph = np.zeros((self.G, max(1, len(sphere_ids))), dtype=int)
        for i, t in zip(p.f_idx, p.f_ids):
            if f"facet.{t}" in col:
                np.add.at(self.cnt, (self.groups[i], col[f"facet.{t}"]), 1)
        for i, t in zip(p.s_idx, p.s_ids):
            self.sph[self.groups[i], sph[t]] += 1
            for a in "xyz":
                if f"sphere.{t}.{a}" in col:
                    self.cnt[self.groups[i], col[f"sphere.{t}.{a}"]] += 1
        self.bar_s = np.array([[sph[b[0]], sph[b[1]]] for b in p.bars], dtype=int).reshape(-1, 2)
        self.core = np.arange(self.p) < self.pm
        self.log_scale2 = 2.0 * np.log(np.asarray(scale, float)[: self.pm])
        prob, gather, n_touch = self.prob, self.gather, self.n_touch

        def information(x):
            J = jax.jacfwd(prob.residuals)(x)
            Jt = jnp.concatenate([J[:n_touch], jnp.zeros((1, J.shape[1]))])[gather]
            Jb = J[n_touch:]
            return jnp.einsum("gri,grj->gij", Jt, Jt), jnp.einsum("bi,bj->bij", Jb, Jb)

        self._information = jax.jit(information)
        self.evaluations = 0

    def search(self, k, max_passes=50):
        """Jacobian, information, greedy forward selection of k indexations,
        then best-swap exchange passes while a swap improves. Returns
        (groups, history, evaluations); evaluations counts the candidate
        selections of the search (the unchosen ones of each step)."""
        info_d, bar_M = self._information(jnp.zeros(self.p))
        info = np.asarray(info_d)
        data = (info_d, self.cnt, self.sph, bar_M, self.bar_s, self.core, self.log_scale2)
        static = {"tol": self.tol, "pm": self.pm}
        chosen = np.zeros(self.G, dtype=bool)
        M = np.zeros((self.p, self.p))
        cnt = np.zeros(self.p, dtype=int)
        sph = np.zeros(self.sph.shape[1], dtype=int)
        history, best, evaluations = [], None, 0
        for _ in range(k):
            sc = [np.asarray(x) for x in _design_add_scores(M, cnt, sph, data, **static)]
            h = np.where(~chosen)[0]
            evaluations += h.size
            g = h[_pick(sc, h)]
            chosen[g] = True
            M, cnt, sph = M + info[g], cnt + self.cnt[g], sph + self.sph[g]
            best = tuple(x[g] for x in sc)
            history.append(float(best[2]) if best[0] == 0 else -np.inf)
        for _ in range(max_passes):
            out = np.where(chosen)[0]
            h = np.where(~chosen)[0]
            if h.size == 0:
                break
            sc = [np.asarray(x) for x in _design_swap_scores(M - info[out], cnt - self.cnt[out],
                                                             sph - self.sph[out], data, **static)]
            evaluations += out.size * h.size
            # fivecal's scan order: removed indexation ascending, then added.
            flat = (np.arange(out.size)[:, None] * self.G + h[None, :]).ravel()
            j = _pick([x.ravel() for x in sc], flat, best)
            if j is None:
                break
            g, hh = out[flat[j] // self.G], flat[j] % self.G
            chosen[g], chosen[hh] = False, True
            M = M - info[g] + info[hh]
            cnt = cnt - self.cnt[g] + self.cnt[hh]
            sph = sph - self.sph[g] + self.sph[hh]
            best = tuple(x.ravel()[flat[j]] for x in sc)
            history.append(float(best[2]) if best[0] == 0 else -np.inf)
        self.evaluations = evaluations
        return [int(g) for g in np.where(chosen)[0]], history, evaluations


_better = base.NumpyDesign._better     # fivecal's strict ordering of two scores, shared


def _pick(scores, candidates, start=None):
    """What fivecal's scan picks: over ``candidates`` (indices into the score
    arrays, in scan order) the current pick is replaced only by a strictly
    better one (_better), starting from ``start`` (a score; None: the first
    candidate). Returns the position in ``candidates`` or None when nothing
    beats ``start``. Only candidates near the best can end as the pick (one
    far from it is replaced by any near one and never replaces one), so the
    scan runs over those few."""
    defi, nonnull, dcrit = (x[candidates] for x in scores)
    m = defi.min()
    key = -nonnull if m > 0 else -dcrit
    kmin = key[defi == m].min()
    near = np.where((defi == m) & (key <= kmin + 1e-6 * max(1.0, abs(kmin))))[0] if np.isfinite(kmin) \
        else np.where((defi == m) & (key == kmin))[0]
    pick, pick_score = None, start
    for j in near:
        s = (defi[j], nonnull[j], dcrit[j])
        if pick_score is None or _better(s, pick_score):
            pick, pick_score = j, s
    return pick


def design_search_function(dataset, names, n_machine, scale, groups, k, max_passes=50):
    """A () -> (groups, observation indices, history, evaluations) running the
    whole JAX search on the candidate dataset (as baseline_numpy.design_search
    returns); the pool is parsed once here, the first call compiles."""
    jd = JaxDesign(dataset, names, n_machine, scale, groups)

    def run():
        chosen, history, evaluations = jd.search(k, max_passes)
        obs = np.where(np.isin(jd.groups, chosen))[0]
        return chosen, [int(i) for i in obs], history, evaluations

    return run
