"""A configuration's exact event values: the lock forces of a KKT solve, for both IDA paths.

Near a lock force's threshold (or with the multipliers out of IDA's error test) the event
functions read the lock forces from a KKT solve at IDA's (t, q, q') instead of IDA's own
multipliers. Both paths evaluate one graph built here: the KKT system and the event values
as SX functions, the solve between them in MX (a QR: an LU's pivoting order would be fixed
by the values the graph first meets). The compiled segment lifts the two SX parts
(:mod:`~cmm_dae.equations.lifting`) and generates C of the composition; the Python path
calls the composition itself. The two solve the same system by the same algorithm, so the
event instants the paths locate agree to round-off, and their step sequences with them
(a numpy solve on one path and a QR on the other had put the two paths' release instants
5e-15 s apart, and their later steps 1e-8 s).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca

from ..equations import kkt
from ..equations.model import Model
from ..hybrid import policy as ev

__all__ = ["ExactParts", "exact_parts"]


@dataclass(frozen=True)
class ExactParts:
    """The two SX parts of the exact event values and their composition.

    Attributes
    ----------
    system : casadi.Function
        ``(t, y, p) -> (A, b)``: the configuration's KKT system at IDA's unknowns ``y``.
    values : casadi.Function
        ``(y, lam, p) -> g``: the event values with the multipliers ``lam`` (N).
    unpack : callable
        The multipliers from a solution of the system (symbolic).
    """

    system: ca.Function
    values: ca.Function
    unpack: Callable

    def compose(self, system: ca.Function | None = None, values: ca.Function | None = None,
                name: str = "cmm_evx") -> ca.Function:
        """``(t, y, p) -> [1, g]``: the system solved between the two parts (by default
        these, or their lifted forms, whose ``p`` inputs are prefixes of one ``p``)."""
        system = self.system if system is None else system
        values = self.values if values is None else values
        n = max(system.nnz_in(2), values.nnz_in(2))
        t, y, p = ca.MX.sym("t"), ca.MX.sym("y", system.nnz_in(1)), ca.MX.sym("p", n)
        A, b = system(t, y, p[:system.nnz_in(2)])
        lam = self.unpack(kkt.solve_symbolic(A, b))[1]
        return ca.Function(name, [t, y, p], [ca.vertcat(1.0, values(y, lam,
                                                                    p[:values.nnz_in(2)]))])


def exact_parts(model: Model, hs: ev.HybridState, triggers: list[ev.Trigger]) -> ExactParts:
    """The exact event values' parts for the configuration ``hs`` and its ``triggers``
    (in the order of :func:`~cmm_dae.hybrid.policy.event_list`); the KKT system is the
    linear one (friction from the reaction, whose system is not, is solved in Python)."""
    t, y, p = ca.SX.sym("t"), ca.SX.sym("y", model.ida.N), ca.SX.sym("p", model.n_params)
    q, v, _ = model.ida.symbolic(y)
    system = kkt.symbolic(model, q, v, t, p)
    lam = ca.SX.sym("lam", model.m)
    c, cd = model.cvel_fn(q, v, p)
    vals: list = [None] * len(triggers)
    ev.event_values(hs, c, cd, lam, triggers, vals, where=ca.if_else)
    return ExactParts(ca.Function("cmm_kkt", [t, y, p], [system.A, system.b]),
                      ca.Function("cmm_evl", [y, lam, p], [ca.vertcat(*vals)]),
                      system.unpack)
