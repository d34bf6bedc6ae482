"""The CasADi functions of the sensitivity pass (:mod:`cmm_dae.sensitivity`): the
augmented residual (state and sensitivities), the KKT system and the impact map as implicit
functions with their derivatives, the constraints, the joint coordinates, the Result's
joint and driver series, and the policy's event functions with the parameters symbolic."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..equations import outputs, reaction
from ..equations.kkt import blocks as kkt_blocks
from ..equations.model import Buffered, Model
from ..hybrid import policy as ev
from ..hybrid.state import HybridState, SegmentTrace

__all__ = ["Equations"]


class _Mat(Buffered):
    """A :class:`Buffered` function whose outputs are always 2-D, shaped as CasADi's
    (a column stays a column, a row a row, whatever the number of parameters)."""

    def __call__(self, *args) -> list[np.ndarray]:
        return [np.reshape(o, s) for o, s in zip(super().__call__(*args), self.shapes,
                                                  strict=True)]


class Equations:
    """The CasADi functions of the sensitivity pass, built once per model."""

    def __init__(self, model: Model):
        self.model = model
        sy = model.sym
        q, v, t, p, th = sy["q"], sy["v"], sy["t"], sy["p"], sy["theta"]
        y, yp, F = sy["y"], sy["yp"], sy["F"]
        nq, m, N, P = model.nq, model.m, model.N, model.theta.numel()
        self.P = P
        npar = model.n_params
        # --- augmented residual: [F; F_y S + F_y' S' + F_p dP + F_theta]
        S = ca.SX.sym("S", N, P)
        Sp = ca.SX.sym("Sp", N, P)
        dP = ca.SX.sym("dP", npar, P)
        Fs = (ca.jacobian(F, y) @ S + ca.jacobian(F, yp) @ Sp + ca.jacobian(F, p) @ dP
              + ca.jacobian(F, th))
        Y = ca.vertcat(y, ca.vec(S))
        Yp = ca.vertcat(yp, ca.vec(Sp))
        Fa = ca.vertcat(F, ca.vec(Fs))
        cj = ca.SX.sym("cj")
        J = ca.jacobian(Fa, Y) + cj * ca.jacobian(Fa, Yp)
        self.res = ca.Function("sres", [t, Y, Yp, p, ca.vec(dP), th], [Fa])
        self.jac = ca.Function("sjac", [t, Y, Yp, cj, p, ca.vec(dP), th], [ca.densify(J.T)])
        # --- KKT system K z = r, z = [a; lambda], and its derivatives
        z = ca.SX.sym("z", nq + m)
        K = kkt_blocks(sy["mass"], sy["Phi_q"], sy["free"])
        # friction from the reaction: its forces are those of the multipliers z[nq:]
        # (the system is nonlinear, dR/dz is K plus their derivative)
        Qr = ca.substitute(sy["Qr"], sy["lam"], z[nq:])
        R = K @ z - ca.vertcat(sy["Qf"] + Qr, sy["gamma"])
        dn = ca.densify
        self.kkt = _Mat(ca.Function("skkt", [q, v, t, p, th, z], [dn(ca.jacobian(R, z))] + [
            dn(ca.jacobian(R, x)) for x in (q, v, t, p, th)]))
        # --- impact map: K [v+; Lambda] = [M v-; b], b the velocity targets
        vm = ca.SX.sym("vm", nq)
        erow = ca.SX.sym("erow", m)
        tgt = ca.SX.sym("tgt")
        b = -sy["Phi_t"] * (1 - sy["free"]) * (1 - erow) + erow * tgt
        Ri = K @ z - ca.vertcat(sy["mass"] * vm, b)
        self.imp = _Mat(ca.Function("simp", [q, vm, t, p, th, erow, tgt, z], [dn(K)] + [
            dn(ca.jacobian(Ri, x)) for x in (q, vm, t, p, th, tgt)]))
        # the rebound target -e c'_k of a joint (onehot over joints)
        onehot = ca.SX.sym("oh", len(model.jidx))  # (joints, then slides)
        e = ca.vertcat(*[model.sjoints[n].restitution for n in model.jidx])
        target = -ca.dot(onehot, e) * ca.dot(onehot, sy["cdot"])
        self.tgt = _Mat(ca.Function("stgt", [q, v, th, onehot], [target] + [
            dn(ca.jacobian(target, x)) for x in (q, v, th)]))
        # --- constraints (positions, velocities) and their derivatives
        phi, h = sy["phi"], sy["h"]
        self.pos = _Mat(ca.Function("spos", [q, t, p, th], [dn(x) for x in (
            phi, sy["Phi_q"], sy["Phi_t"], ca.jacobian(phi, p), ca.jacobian(phi, th))]))
        self.vel = _Mat(ca.Function("svel", [q, v, t, p, th], [dn(x) for x in (
            h, ca.jacobian(h, q), sy["Phi_q"], ca.jacobian(h, p), ca.jacobian(h, th))]))
        # --- joint coordinates and rates
        c, cd = sy["c"], sy["cdot"]
        self.coords = _Mat(ca.Function("scoord", [q, v, th], [dn(x) for x in (
            c, cd, sy["c_q"], ca.jacobian(cd, q), ca.jacobian(c, th), ca.jacobian(cd, th))]))
        # --- outputs: c, c', c'', joint forces, torques, efforts
        a = sy["a"]
        lam = ca.SX.sym("lamo", m)
        out = self._outputs(lam)
        self.n_out = out.numel()
        self.out = _Mat(ca.Function("sout", [q, v, a, p, th, lam], [dn(out)] + [
            dn(ca.jacobian(out, x)) for x in (q, v, a, th, lam)]))
        self._events: dict[tuple, Buffered] = {}
        self._singular: _Mat | None = None

    def _outputs(self, lam) -> ca.SX:
        """The Result's joint and driver series as one vector, as post-processing gives
        them (:mod:`cmm_dae.equations.outputs`): c, c', c'', joint forces and moments,
        driver efforts, tooth forces."""
        sy = self.model.sym
        lam_all = ca.DM(outputs.kept_to_all(self.model)) @ lam
        force, torque, teeth, effort = outputs.expressions(self.model, lam_all)
        return ca.vertcat(sy["c"], sy["cdot"], sy["cddot"], force, torque, effort, teeth)

    def singular_function(self) -> _Mat:
        """``g = w . (Phi_q n)`` for a left and right null vector ``w``, ``n`` of the
        constraint Jacobian at a singular position, held fixed: it changes sign where the
        motion passes the position (the collapsing singular value, signed), so the
        instant's derivative follows from it as from an event function.
        (q, t, p, theta, w, n) -> (g, g_q, g_t, g_p, g_theta)."""
        if self._singular is None:
            model = self.model
            sy = model.sym
            w, n = ca.SX.sym("w", model.m), ca.SX.sym("n", model.nq)
            g = ca.dot(w, sy["Phi_q"] @ n)
            self._singular = _Mat(ca.Function("ssing", [sy["q"], sy["t"], sy["p"],
                                                        sy["theta"], w, n], [g] + [
                ca.densify(ca.jacobian(g, sy[x])) for x in ("q", "t", "p", "theta")]))
        return self._singular

    def event_function(self, seg: SegmentTrace, trig: ev.Trigger) -> Buffered:
        """The event function of ``trig`` in segment ``seg``'s configuration, as the
        policy defines it, with the parameters symbolic: (g, g_q, g_v, g_theta, g_lam)."""
        key = (trig, tuple(sorted(seg.locked.items())), seg.zones,
               tuple(sorted(seg.slip.items())))
        fn = self._events.get(key)
        if fn is None:
            model = self.model
            sy = model.sym
            lam = ca.SX.sym("lamg", model.m)
            hs = _SymbolicState(model, locked=dict(seg.locked), zones=seg.zones,
                                slip=dict(seg.slip), stick_at=dict(seg.stick_at))
            out = [None]
            ev.event_values(hs, sy["c"], sy["cdot"], lam, [trig], out, where=ca.if_else)
            g = ca.SX(out[0])
            fn = self._events[key] = _Mat(ca.Function(
                "sev", [sy["q"], sy["v"], sy["theta"], lam],
                [g] + [ca.densify(ca.jacobian(g, x)) for x in (sy["q"], sy["v"], sy["theta"],
                                                              lam)]))
        return fn


@dataclass
class _SymbolicState(HybridState):
    """The policy's state with the mechanism's thresholds (stop positions, static
    friction) read from the model's symbolic parameters: the event functions of
    :func:`~cmm_dae.hybrid.policy.event_values` as functions of them."""

    def limit_value(self, joint: str, side: str):
        if side == "stick":
            return self.stick_at[joint]
        lim = self.model.sjoints[joint].stops
        return lim.lower if side == "lower" else lim.upper

    def static(self, joint: str, lam=None):
        f = self.model.sjoints[joint].friction
        if f is None:
            return 0.0
        if lam is not None and self.model.joints[joint].friction.from_reaction:
            return reaction.level(self.model, joint, lam, "static", friction=f)
        return f.static

