"""The paper's fixed-step iterative algorithm (section 3, Fig. 10) on the same equations.

At each step ``t_n -> t_n + dt``:

1. the differential variables (the free joint coordinates of the current configuration)
   advance with the previous step's rates: ``c_j += c_j' dt``, ``c_j' += c_j'' dt``;
2. the dependent coordinates follow from the position equations (Newton);
3. the velocities from the velocity equations;
4. accelerations, driving efforts and constraint forces from the KKT system.

Limits crossed within a step and lock forces that change sign are triggers at the step's
end, handed to the same event policy as IDA's (:mod:`cmm_dae.hybrid.policy`: clamp onto the stop,
impact map, lock, release, Zeno rule with the step as the time resolution). The run driver
(:func:`cmm_dae.simulate`) makes the same Result of it as of an IDA run.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..core.errors import SolverError, Status
from ..core.records import Stats
from ..equations import kkt
from ..equations.codegen import Buffered
from ..equations.model import Model
from ..hybrid import policy as ev
from . import cbuild, coordinates, cstep
from .contract import Integrator, Recorder, RunOptions, SegmentEnd


class _Stepper:
    """Kinematic solves of one configuration with fixed differential variables."""

    def __init__(self, model: Model, hs: ev.HybridState, coords: list[str]):
        self.model, self.hs, self.coords = model, hs, coords
        self.kidx = [coordinates.index(model, n) for n in coords]
        self.wrap = coordinates.turning(model, self.kidx)
        self.natural = coordinates.natural(coords)
        self.act = model.active_rows(hs.p)
        #: natural coordinates: their system's condition number where chosen, and whether
        #: it has grown a hundredfold since (they are chosen anew before they stop
        #: spanning the motion: near that, Newton can land on another branch)
        self.cond0, self.worn = np.inf, False

    def positions(self, q0: np.ndarray, t: float, targets: np.ndarray) -> np.ndarray:
        model, p = self.model, self.hs.p
        q = q0.copy()
        for _ in range(25):
            con, c, c_q = coordinates.kinematics(model, q, t, p, self.natural)
            r = np.concatenate([con.phi[self.act],
                                coordinates.residual(c[self.kidx], targets, self.wrap)])
            if np.max(np.abs(r), initial=0.0) < 1e-13:
                return q
            J = np.vstack([con.Phi_q[self.act], c_q[self.kidx]])
            q = q - np.linalg.solve(J, r)
        con, c, _ = coordinates.kinematics(model, q, t, p, self.natural)
        r = np.concatenate([con.phi[self.act],
                            coordinates.residual(c[self.kidx], targets, self.wrap)])
        if np.max(np.abs(r), initial=0.0) > 1e-9:
            labels, ratio = ev.dependent_rows(model, q0, t, p, tol=1.0)
            raise SolverError(f"dead point near t = {t:.6g} s: the position equations do not "
                              f"converge (residual {np.max(np.abs(r)):.3g}); the constraints "
                              f"of {', '.join(labels)} are nearly dependent at the last "
                              f"position (singular-value ratio {ratio:.1e}): the mechanism "
                              "cannot follow its driver here", status=Status.DEAD_POINT)
        return q

    def velocities(self, q: np.ndarray, t: float, rates: np.ndarray) -> np.ndarray:
        model, p = self.model, self.hs.p
        con, _, c_q = coordinates.kinematics(model, q, t, p, self.natural)
        J = np.vstack([con.Phi_q[self.act], c_q[self.kidx]])
        rhs = np.concatenate([-con.Phi_t[self.act], rates])
        if self.natural:  # how well they still span the motion
            cond = float(np.linalg.cond(J))
            self.cond0 = min(self.cond0, cond)
            self.worn = not cond < 100.0 * self.cond0
        return np.linalg.solve(J, rhs)


class _CompiledStep:
    """One whole step of a configuration (steps 1-4 above, and the event functions at its
    end) as one CasADi function: the same equations, Newton iteration and tolerances as
    :class:`_Stepper`, evaluated in one call instead of a dozen (the Python stepper stays
    for Python load laws, which CasADi cannot call, and for the dead-point message)."""

    def __init__(self, model: Model, hs: ev.HybridState, coords: list[str],
                 triggers: list[ev.Trigger]):
        nq, m, npar = model.nq, model.m, model.n_params
        kidx = [coordinates.index(model, n) for n in coords]
        act = [int(i) for i in model.active_rows(hs.p)]
        nk = len(kidx)
        schur = bool(np.all(model.mass > 0.0) and m > 0)

        def rows(x, idx):  # x[idx] (rows), with an empty selection an empty column
            return x[idx, :] if idx else type(x)(0, x.shape[1])

        # Everything but the Newton iteration and the two linear solves is SX, in four
        # functions: MX evaluates node by node, and the step costs a third as much so.
        S = ca.SX.sym
        q, v, a, t, tn, p = S("q", nq), S("v", nq), S("a", nq), S("t"), S("tn"), S("p", npar)
        h = tn - t
        c, cd, cdd, _ = model.post_fn(q, v, a, t, p)
        pre = ca.Function("pre", [q, v, a, t, tn, p], [
            q + v * h, rows(c, kidx) + rows(cd, kidx) * h,  # the previous instant's rates
            rows(cd, kidx) + rows(cdd, kidx) * h])
        tar = S("tar", nk)
        phi, Phi_q, Phi_t, cz, c_q = model.kin_fn(q, tn, p)
        G = ca.Function("g", [q, tn, p, tar], [ca.vertcat(rows(phi, act), coordinates.residual(
            rows(cz, kidx), tar, coordinates.turning(model, kidx)))])
        rates = S("rates", nk)
        vel = ca.Function("vel", [q, tn, p, tar, rates], [
            ca.mmax(ca.fabs(G(q, tn, p, tar))), ca.vertcat(rows(Phi_q, act), rows(c_q, kidx)),
            ca.vertcat(-rows(Phi_t, act), rates)])
        # the Schur complement on the diagonal mass matrix (as the outputs) or, with point
        # masses, the whole KKT matrix
        system = kkt.symbolic(model, q, v, tn, p, schur=schur)
        kkt_fn = ca.Function("kkt", [q, v, tn, p], [system.A, system.b])
        sol = S("sol", system.b.numel())
        acc, lam = system.unpack(sol)
        c1, cd1 = model.cvel_fn(q, v, p)
        vals: list = [None] * len(triggers)
        ev.event_values(hs, c1, cd1, lam, triggers, vals, where=ca.if_else)
        fin = ca.Function("fin", [q, v, tn, p, sol], [acc, ca.vertcat(0.0, *vals)])

        # Newton to max |r| < 1e-13 in at most 25 iterations, as _Stepper.positions
        newton = ca.rootfinder("pos", "newton", G, {
            "abstol": 1e-13, "abstolStep": 0.0, "max_iter": 25, "error_on_fail": False,
            "linear_solver": "lapacklu"})  # LU with partial pivoting, as numpy.linalg.solve
        M = ca.MX.sym
        q, v, a, t, tn, p = M("q", nq), M("v", nq), M("a", nq), M("t"), M("tn"), M("p", npar)
        q0, targets, rates = pre(q, v, a, t, tn, p)
        q1 = newton(q0, tn, p, targets)
        r, J, rhs = vel(q1, tn, p, targets, rates)
        v1 = kkt.solve_symbolic(J, rhs)
        A, b = kkt_fn(q1, v1, tn, p)
        acc, values = fin(q1, v1, tn, p, kkt.solve_symbolic(A, b))
        self.fn = Buffered(ca.Function("step", [q, v, a, t, tn, p], [q1, v1, acc, r, values]))

    def __call__(self, q, v, a, t, tn, p):
        """(q, v, a) at ``tn``, the position residual and the event values."""
        try:
            q1, v1, a1, r, vals = self.fn(q, v, a, t, tn, p)
        except RuntimeError:  # a singular matrix inside (a dead point): the Python stepper
            return q, v, a, math.inf, None  # takes the step and says what happened
        return q1, v1, a1, float(r[0]), vals[1:]


class IterativeIntegrator(Integrator):
    """The paper's fixed-step algorithm, step ``dt``, output every ``output_every`` steps."""

    method = "iterative"

    @staticmethod
    def time_resolution(opts: RunOptions) -> float:
        # crossings are seen at step ends only: bounces closer than a step cannot be told
        # apart, and the policy's Zeno rule ends them there
        return opts.dt

    def __init__(self, model: Model, hs: ev.HybridState, opts: RunOptions, stats: Stats):
        super().__init__(model, hs, opts, stats)
        mech = model.mech
        self.prefer = [k for k in mech.initial.joints if k not in mech.drivers]
        self.n_steps = steps_needed(opts.t_end, opts.dt)
        self.n = 0  # steps taken so far: the grid is n * dt, never accumulated
        self.coords: list[str] = []
        self.key: tuple | None = None
        self.st: _Stepper | None = None
        self._steps: dict[tuple, _CompiledStep | cstep.CStep] = {}
        self.triggers: list[ev.Trigger] | None = None  # this configuration's (None: ask)
        #: a compiled step the run used (a Result's meta "compiled"), else None
        self.c: cstep.CStep | None = None

    def output_times(self, t0: float, t1: float) -> np.ndarray:
        return self._grid_inside(self.opts.dt * self.opts.output_every, t0,
                                 min(t1, self.opts.t_end))

    def after_singular(self, t: float) -> None:
        # go on from the grid point before t: the next step ends on the grid again
        self.n = max(self.n, int(np.floor(t / self.opts.dt + 1e-9)))

    def advance(self, t0: float, q: np.ndarray, v: np.ndarray, rec: Recorder) -> SegmentEnd:
        model, hs = self.model, self.hs
        key = tuple(sorted(hs.locked.items()))
        if key != self.key or self.st is None:  # a new configuration: choose its coordinates
            self.coords = coordinates.free(model, hs, q, t0, self.coords + self.prefer)
            self.st = _Stepper(model, hs, self.coords)
            self.key = key
        fast = self._compiled_step()
        t, p = t0, hs.p
        a, _, _ = model.kkt(q, v, t, p)
        kept: list[tuple[int, np.ndarray, np.ndarray]] = []
        try:
            return self._steps_from(t, q, v, a, rec, fast, kept)
        finally:  # the Python step's KKT solves at the samples: post-processing reuses them
            _keep_kkt(rec, kept)

    def _steps_from(self, t: float, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                    rec: Recorder, fast: _CompiledStep | None,
                    kept: list[tuple[int, np.ndarray, np.ndarray]]) -> SegmentEnd:
        """The fixed steps of one configuration from (t, q, v, a) to its end or first
        crossing; ``kept`` receives (sample index, a, lambda) of the samples whose
        accelerations and multipliers the Python step solved."""
        model, hs, opts, st = self.model, self.hs, self.opts, self.st
        k, cfg, p = st.kidx, hs.current(), hs.p
        again = False  # (natural coordinates chosen anew once for this step)
        while self.n < self.n_steps:
            if isinstance(fast, cstep.CStep):  # in C up to a step the loop below must see
                n0 = self.n
                flag, q, v, a, t, self.n, (T, Q, V) = fast.run(
                    q, v, a, t, self.n, p, opts.dt, opts.t_end, self.n_steps,
                    opts.output_every, 1e-9)
                self.stats.steps += self.n - n0
                rec.add_block(T, Q, V, cfg)
                if opts.progress is not None and self.n > n0:
                    opts.progress.update(t)
                if self.n >= self.n_steps or (flag == 0 and self.n > n0):
                    continue
            self.n += 1
            t_new = min(self.n * opts.dt, opts.t_end)
            h = t_new - t
            values = None
            if fast is not None:
                q_new, v_new, a_new, resid, values = fast(q, v, a, t, t_new, p)
            if fast is None or not resid < 1e-9:
                c, cd = model.joint_rates(q, v)
                c, cd, cdd = coordinates.extend(
                    (c, cd, model.joint_accelerations(q, v, a, t)), (q, v, a), st.natural)
                targets = c[k] + cd[k] * h  # the paper's step: rates of the previous instant
                rates = cd[k] + cdd[k] * h
                try:  # (also where the compiled Newton failed: the dead-point report)
                    q_new = st.positions(q + v * h, t_new, targets)
                except SolverError as e:
                    if e.status is not Status.DEAD_POINT:
                        raise
                    self.n -= 1  # the step is not taken
                    if st.natural:
                        if again:  # chosen anew, and still no position: not a singular one
                            raise SolverError(
                                f"the fixed-step algorithm cannot go on at t = {t:.6g} s: "
                                "its positions do not converge from its explicit step, "
                                "with its natural coordinates chosen anew too (its step "
                                f"moves a body's axes by up to {np.max(np.abs(v)) * h:.3g}"
                                "): a smaller dt, or IDA", status=Status.INTEGRATOR) from e
                        # natural coordinates that no longer span the motion (a ball
                        # joint's rotation turned away from them): chosen anew, here
                        self.coords = coordinates.free(model, hs, q, t, [])
                        st = self.st = _Stepper(model, hs, self.coords)
                        k, again = st.kidx, True
                        continue
                    return SegmentEnd(t, q, v, (), "singular")  # the policy crosses
                v_new, a_new, values = st.velocities(q_new, t_new, rates), None, None
            q, v = q_new, v_new
            t, again = t_new, False
            self.stats.steps += 1
            if st.worn:  # natural coordinates losing their span: chosen anew here
                self.coords = coordinates.free(model, hs, q, t, [])
                st = self.st = _Stepper(model, hs, self.coords)
                k = st.kidx
            if opts.progress is not None:
                opts.progress.update(t)
            # the Python step solves the KKT system at the new state once: for the event
            # functions (friction), the next step and post-processing (it was solved twice
            # a step, a third of a fixed-step run of a pin with reaction friction)
            sol = _solved(model, q, v, t, p) if a_new is None else None
            try:
                crossed = ev.crossings(hs, q, v, t, values, self.triggers,
                                       lam=None if sol is None else sol[1])
            except np.linalg.LinAlgError:
                # the forces cannot be solved with the slip directions in force (friction
                # from the reaction would lock a joint against its own load): a slipping
                # joint reversed within the step, which its rate event tells without them
                crossed = ev.crossings(hs, q, v, t, None,
                                       [tr for tr in self.triggers if tr.kind == "rate"])
                if not crossed:
                    raise
            if crossed:
                rec.add(t, q, v, cfg)  # the sample before the switch
                return SegmentEnd(t, q, v, tuple(crossed), "event")
            a = a_new if a_new is not None else (
                sol[0] if sol is not None else model.kkt(q, v, t, p)[0])
            if self.n % opts.output_every == 0 or self.n == self.n_steps:
                rec.add(t, q, v, cfg)
                if sol is not None:
                    kept.append((len(rec) - 1, sol[0], sol[1]))
        return SegmentEnd(t, q, v, (), "end")


    def _compiled_step(self) -> _CompiledStep | cstep.CStep | None:
        """The configuration's step in one call (cached): in C (:mod:`.cstep`) where the
        option ``compiled`` asks for it (``True``; ``"auto"``: where it is built, or where
        builds are allowed, :func:`~.cbuild.auto_builds`), else on CasADi's virtual
        machine; None with Python load laws or friction from the reaction (the Python
        step's KKT solves include it)."""
        model, hs = self.model, self.hs
        if coordinates.natural(self.coords):  # chosen anew where they stop spanning the
            if self.opts.compiled is True:  # motion, which the Python step sees
                cbuild._warn_once("compiled fixed step not used (natural coordinates of a "
                                  "spatial body among its coordinates): running the Python "
                                  "step")
            return None
        why = cbuild._unsupported(model)
        if why is not None:
            if self.opts.compiled is True:  # said as IDA's compiled segment says it
                cbuild._warn_once(f"compiled fixed step not used ({why}): running the "
                                  "Python step")
            return None
        triggers = self.triggers = ev.event_list(model, hs.locked)
        key = (tuple(self.coords), tuple(triggers), hs.mode())
        got = self._steps.get(key)
        if got is None:
            mode = self.opts.compiled
            got = "" if mode is False else cstep.build(
                model, hs, self.coords, triggers, mode, mode is True or cbuild.auto_builds())
            if isinstance(got, str):
                if mode is True:
                    cbuild._warn_once(f"compiled fixed step not used ({got}): running its "
                                      "step on CasADi's virtual machine")
                got = _CompiledStep(model, hs, self.coords, triggers)
            self._steps[key] = got
        if isinstance(got, cstep.CStep):
            self.c = got
        return got


def _solved(model: Model, q: np.ndarray, v: np.ndarray, t: float, p: np.ndarray
            ) -> tuple | None:
    """The KKT solve at a step's end; None where it is singular (the event functions, or
    the next step, ask for it again and say so, as where it was solved there alone: a
    crossing found without the multipliers still ends the step)."""
    try:
        return model.kkt(q, v, t, p)
    except np.linalg.LinAlgError:
        return None


def _keep_kkt(rec: Recorder, kept: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
    """Hand the recorder the kept (index, a, lambda) of samples, one block per run of
    consecutive indices (the compiled step's samples, solved in C without multipliers,
    leave gaps that post-processing fills)."""
    if not kept:
        return
    idx = np.array([i for i, _, _ in kept])
    cuts = np.flatnonzero(np.diff(idx) != 1) + 1
    for lo, hi in zip([0, *cuts], [*cuts, idx.size], strict=True):
        rec.keep_kkt(int(idx[lo]), np.array([x[1] for x in kept[lo:hi]]),
                     np.array([x[2] for x in kept[lo:hi]]))


def steps_needed(t_end: float, dt: float) -> int:
    """Number of fixed steps to reach t_end (the last one shortened to land on it)."""
    n = int(round(t_end / dt))
    if abs(n * dt - t_end) > 1e-9 * t_end:
        n = int(np.ceil(t_end / dt))
    return max(n, 1)
