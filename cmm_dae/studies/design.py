"""Design of a metamorphic mechanism by gradient-based optimisation on exact sensitivities.

:func:`design` minimises a scalar of a run (by default the peak |driving effort|) over
bounded model parameters, subject to targets on event times (a lock at 2.5 s) and on
series values at given times, with :func:`scipy.optimize.minimize` (SLSQP or
trust-constr) fed the exact gradients of :func:`cmm_dae.sensitivities`. Parameters are
scaled to [0, 1] over their bounds for the optimiser.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import CmmError, ModelError, Problem
from ..core.figures import pyplot
from ..core.scipy_late import minimize
from ..description.mechanism import Mechanism
from ..description.params import param_value, with_params
from ..description.writer import write_model
from ..results.result import Result
from ..sensitivity.run import Sensitivities, check_params, sensitivities
from .targets import Target, parse_target

__all__ = ["Design", "DesignError", "Target", "design", "peak_effort"]


#: The files a design report writes into its folder (checked for overwriting up front).
REPORT_FILES = ("summary.md", "effort.png", "history.png", "optimised.toml")


class DesignError(CmmError):
    """A design the optimiser tried could not be run (a dead point, a changed event
    sequence); ``history`` holds the designs evaluated before it."""

    history: list[dict]

def peak_effort(driver: str | None = None) -> Callable[[Result, Sensitivities],
                                                       tuple[float, np.ndarray]]:
    """The objective "peak |effort| of a driver" (the first one by default), N m or N, and
    its gradient: the derivative at the peak sample (the peak's own shift in time adds
    nothing to first order)."""

    def objective(res: Result, s: Sensitivities) -> tuple[float, np.ndarray]:
        name = driver if driver is not None else res.layout.drivers[0]
        eff = res.driver(name).effort
        i = int(np.argmax(np.abs(eff)))
        return float(abs(eff[i])), np.sign(eff[i]) * s.driver(name).effort[i]

    objective.label = (f"peak absolute effort of driver {driver}" if driver  # type: ignore
                       else "peak absolute effort of the first driver")
    return objective


@dataclass
class Design:
    """The outcome of :func:`design`.

    Attributes
    ----------
    mechanism : Mechanism
        The optimised mechanism (:meth:`write_toml` writes it as a model file).
    params : tuple[str, ...]
        The design parameters; ``start`` and ``optimum`` their values.
    objective_start, objective_end : float
        The objective before and after.
    targets : list[Target]
        The constraints; ``targets_start`` and ``targets_end`` their measured values.
    history : list[dict]
        One entry per evaluated design: parameter values, objective, target values.
    before, after : Sensitivities
        The runs (with their sensitivities) at the start and at the optimum.
    """

    mechanism: Mechanism
    params: tuple[str, ...]
    bounds: list[tuple[float, float]]
    start: np.ndarray
    optimum: np.ndarray
    objective_label: str
    objective_start: float
    objective_end: float
    targets: list[Target]
    targets_start: list[float]
    targets_end: list[float]
    history: list[dict] = field(repr=False)
    before: Sensitivities = field(repr=False)
    after: Sensitivities = field(repr=False)
    success: bool = False
    message: str = ""
    wall_time: float = 0.0
    iterations: int = 0

    def summary(self) -> str:
        """The study as Markdown: parameters, objective, targets, before and after."""
        lines = ["| parameter | bounds | start | optimum |", "|---|---|---|---|"]
        for p, (lo, hi), a, b in zip(self.params, self.bounds, self.start, self.optimum,
                                     strict=True):
            lines.append(f"| `{p}` | [{lo:.6g}, {hi:.6g}] | {a:.9g} | {b:.9g} |")
        lines += ["", "| quantity | start | optimum |", "|---|---|---|",
                  f"| {self.objective_label} | {self.objective_start:.9g} | "
                  f"{self.objective_end:.9g} |"]
        for t, a, b in zip(self.targets, self.targets_start, self.targets_end, strict=True):
            lines.append(f"| {t.label} | {a:.9g} | {b:.9g} |")
        lines += ["", f"Optimiser: {'converged' if self.success else 'NOT converged'} "
                  f"({self.message}); {self.iterations} iterations, {len(self.history)} "
                  f"runs with sensitivities, {self.wall_time:.1f} s."]
        return "\n".join(lines)

    def write_toml(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """Write the optimised mechanism as a model file (the original file's tables with
        the optimised values; comments are not kept). Refuses to overwrite an existing
        file unless ``overwrite``."""

        return write_model(self.mechanism, path, dict(zip(self.params, self.optimum,
                                                          strict=True)),
                           overwrite=overwrite)

    def report(self, out_dir: str | Path, *, overwrite: bool = False) -> Path:
        """Write summary.md (tables before and after, event tables, the optimiser's
        history), effort.png (driving effort before and after), history.png and the
        optimised model file into ``out_dir``; returns the summary's path."""
        plt = pyplot()
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        files = [out / n for n in REPORT_FILES]
        if not overwrite:
            there = [str(f) for f in files if f.exists()]
            if there:
                raise CmmError(f"would overwrite {', '.join(there)}; pass overwrite=True "
                               "(--force) or choose another directory")
        fig, ax = plt.subplots(figsize=(8, 4))
        for s, lab in ((self.before, "start"), (self.after, "optimum")):
            r = s.result
            for d in r.layout.drivers:
                ax.plot(r.t, r.driver(d).effort, label=f"{lab}: driver {d}")
            for e in r.events:
                ax.axvline(e.t, color="0.7", lw=0.6)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("driving effort (N m or N)")
        ax.legend()
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(files[1], dpi=120)
        plt.close(fig)
        fig, axs = plt.subplots(1, 2, figsize=(9, 3.5))
        axs[0].plot([h["objective"] for h in self.history], "o-")
        axs[0].set_xlabel("evaluation")
        axs[0].set_ylabel(self.objective_label)
        for j, t in enumerate(self.targets):
            ref = t.value if t.value is not None else (t.min if t.min is not None else t.max)
            axs[1].semilogy([max(abs(h["targets"][j] - ref), 1e-16) for h in self.history],
                            "o-", label=t.label)
        axs[1].set_xlabel("evaluation")
        axs[1].set_ylabel("|target - value|")
        if self.targets:
            axs[1].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(files[2], dpi=120)
        plt.close(fig)
        self.write_toml(files[3], overwrite=True)
        hist = ["| # | " + " | ".join(f"`{p}`" for p in self.params) + " | objective | "
                + " | ".join(t.label for t in self.targets) + " |",
                "|---" * (len(self.params) + len(self.targets) + 2) + "|"]
        for i, h in enumerate(self.history):
            hist.append(f"| {i} | " + " | ".join(f"{x:.9g}" for x in h["x"])
                        + f" | {h['objective']:.9g} | "
                        + " | ".join(f"{x:.9g}" for x in h["targets"]) + " |")
        text = ["# Design study", "", self.summary(), "", "![effort](effort.png)", "",
                "![history](history.png)", "", "## Events at the start", "", "```",
                self.before.result.event_table(), "```", "", "## Events at the optimum", "",
                "```", self.after.result.event_table(), "```", "",
                "## Event-time sensitivities at the optimum", "", "```",
                self.after.event_table(), "```", "", "## Optimiser history", ""] + hist
        files[0].write_text("\n".join(text) + "\n")
        return files[0]


def design(mech: Mechanism, params: Sequence[str], bounds: Sequence[tuple[float, float]],
           objective: str | Callable[[Result, Sensitivities], tuple[float, np.ndarray]]
           = "peak_effort", constraints: Sequence[Mapping | Target] = (),
           t_end: float = 10.0, *, driver: str | None = None, method: str = "SLSQP",
           max_iter: int = 50, tol: float = 1e-10, feas_tol: float = 1e-7,
           **run_options) -> Design:
    """Minimise an objective of a run over bounded model parameters, subject to targets,
    with exact gradients.

    Parameters
    ----------
    mech : Mechanism
        The mechanism at the start of the study.
    params : list of str
        Dotted model paths (as for :func:`cmm_dae.sensitivities`).
    bounds : list of (float, float)
        Lower and upper bound of each parameter (its units); the start must lie within.
    objective : "peak_effort" or callable
        ``"peak_effort"``: the peak |effort| of ``driver`` (the first driver by default),
        N m or N. A callable ``f(result, sensitivities) -> (value, gradient (P,))``.
    constraints : list of dict or Target
        Targets: ``{"event": "limit E", "time"...}`` see :class:`Target` (keys ``event``,
        ``occurrence``, ``series``, ``t``, ``value``, ``min``, ``max``).
    t_end : float
        End time of each run, s.
    method : {"SLSQP", "trust-constr"}
        The scipy optimiser.
    max_iter : int
        Most optimiser iterations.
    tol : float
        The optimiser's tolerance (on the scaled parameters).
    feas_tol : float
        How near a target counts as met (its units) when the optimiser is stopped by a
        design it cannot run and the best design so far is chosen.
    **run_options
        For each run (``rtol``, ``atol``, ``output_dt``, ...; :func:`cmm_dae.run_dae`).

    Returns
    -------
    Design

    Raises
    ------
    ModelError
        A bad parameter, bound, objective, target or method, named.
    CmmError
        The event sequence a target names disappeared at some design.
    """
    wall0 = time.perf_counter()
    paths = check_params(mech, params)
    x0, lo, hi = _checked(mech, paths, bounds, objective, driver, method)
    targets = [parse_target(c, i, mech) for i, c in enumerate(constraints)]
    fobj = peak_effort(driver or next(iter(mech.drivers))) if isinstance(objective, str) \
        else objective
    label = getattr(fobj, "label", getattr(fobj, "__name__", "objective"))
    span = hi - lo
    cache: dict[bytes, tuple] = {}
    history: list[dict] = []

    def evaluate(z: np.ndarray) -> tuple:
        z = np.clip(np.asarray(z, float), 0.0, 1.0)
        key = z.tobytes()
        if key not in cache:
            x = lo + z * span
            m = with_params(mech, dict(zip(paths, x.tolist(), strict=True)))
            try:
                s = sensitivities(m, paths, t_end, **run_options)
                f, g = fobj(s.result, s)
                meas = [t.measure(s) for t in targets]
            except CmmError as e:  # the design the optimiser tried, named
                at = ", ".join(f"{p} = {float(v)!r}" for p, v in zip(paths, x, strict=True))
                err = DesignError(f"at the design {at} (evaluation {len(history) + 1}): "
                                  f"{e}")
                err.history = history
                raise err from e
            cache[key] = (f, np.asarray(g, float) * span, meas, s)
            history.append({"x": x.tolist(), "objective": f,
                            "targets": [v for v, _ in meas], "z": z})
        return cache[key]

    cons = _scipy_constraints(targets, evaluate, span)
    z0 = (x0 - lo) / span
    first = evaluate(z0)
    z_opt, success, message, nit = _optimise(evaluate, z0, cons, method, tol, max_iter,
                                             history, targets, feas_tol)
    best = evaluate(z_opt)
    x_opt = lo + np.clip(z_opt, 0.0, 1.0) * span
    return Design(with_params(mech, dict(zip(paths, x_opt.tolist(), strict=True))), paths,
                  list(zip(lo.tolist(), hi.tolist(), strict=True)), x0, x_opt, label,
                  first[0], best[0], targets, [v for v, _ in first[2]],
                  [v for v, _ in best[2]], history, first[3], best[3], success, message,
                  time.perf_counter() - wall0, nit)


def _checked(mech: Mechanism, paths: list[str], bounds, objective, driver: str | None,
             method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The start values and the bounds of the parameters (x0, lower, upper), every
    problem with the study's arguments reported at once (a ModelError)."""
    bad: list[Problem] = []
    if method not in ("SLSQP", "trust-constr"):
        bad.append(Problem("design", "method", f"expected 'SLSQP' or 'trust-constr', got "
                           f"{method!r}"))
    if not isinstance(bounds, Sequence) or len(bounds) != len(paths):
        raise ModelError(Problem("design", "bounds", f"expected {len(paths)} (lower, upper) "
                                 f"pairs, one per parameter, got {bounds!r}"), mech.source)
    x0 = np.array([param_value(mech, p) for p in paths])
    lo, hi = np.zeros(len(paths)), np.zeros(len(paths))
    for i, (p, b) in enumerate(zip(paths, bounds, strict=True)):
        ok = (isinstance(b, Sequence) and len(b) == 2 and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in b) and b[0] < b[1])
        if not ok:
            bad.append(Problem("design", f"bounds of {p}", f"expected (lower, upper) with "
                               f"lower < upper, got {b!r}"))
            continue
        lo[i], hi[i] = b
        if not lo[i] <= x0[i] <= hi[i]:
            bad.append(Problem("design", f"bounds of {p}", f"[{b[0]:g}, {b[1]:g}] excludes "
                               f"the start value {x0[i]:.9g}"))
    if isinstance(objective, str):
        if objective != "peak_effort":
            bad.append(Problem("design", "objective", f"expected 'peak_effort' or a "
                               f"callable, got {objective!r}"))
        elif not mech.drivers:
            bad.append(Problem("design", "objective", "'peak_effort' needs a driver; the "
                               "mechanism has none"))
        elif driver is not None and driver not in mech.drivers:
            bad.append(Problem("design", "driver", f"no driver at joint {driver!r} "
                               f"(drivers: {', '.join(mech.drivers)})"))
    elif not callable(objective):
        bad.append(Problem("design", "objective", f"expected 'peak_effort' or a callable, "
                           f"got {objective!r}"))
    if bad:
        raise ModelError(bad, mech.source)
    return x0, lo, hi


def _scipy_constraints(targets: list[Target], evaluate: Callable, span: np.ndarray
                       ) -> list[dict]:
    """The targets as scipy's constraints on the scaled parameters z (value, min, max),
    their values and gradients from ``evaluate(z)``."""
    cons = []
    for j, t in enumerate(targets):
        def val(z, j=j):
            return evaluate(z)[2][j][0]

        def grad(z, j=j):
            return evaluate(z)[2][j][1] * span

        if t.value is not None:
            cons.append({"type": "eq", "fun": lambda z, j=j, v=t.value: val(z, j) - v,
                         "jac": grad})
        if t.min is not None:
            cons.append({"type": "ineq", "fun": lambda z, j=j, v=t.min: val(z, j) - v,
                         "jac": grad})
        if t.max is not None:
            cons.append({"type": "ineq", "fun": lambda z, j=j, v=t.max: v - val(z, j),
                         "jac": lambda z, j=j: -grad(z, j)})
    return cons


def _best_so_far(history: list[dict], targets: list[Target], feas_tol: float) -> dict:
    """The design evaluated so far that meets the targets best (within ``feas_tol``),
    then has the smallest objective."""
    def badness(h: dict) -> tuple[float, float]:
        worst = 0.0
        for t, v in zip(targets, h["targets"], strict=True):
            if t.value is not None:
                worst = max(worst, abs(v - t.value))
            worst = max(worst, (t.min - v) if t.min is not None else 0.0,
                        (v - t.max) if t.max is not None else 0.0)
        return (max(worst, feas_tol), h["objective"])

    return min(history, key=badness)


def _optimise(evaluate: Callable, z0: np.ndarray, cons: list[dict], method: str, tol: float,
              max_iter: int, history: list[dict], targets: list[Target], feas_tol: float
              ) -> tuple[np.ndarray, bool, str, int]:
    """scipy's optimiser on the scaled parameters: (z, success, message, iterations); where
    a trial design could not be run, the best design evaluated so far, and why it
    stopped."""
    try:
        opt = minimize(lambda z: evaluate(z)[0], z0, jac=lambda z: evaluate(z)[1],
                       bounds=[(0.0, 1.0)] * z0.size, constraints=cons, method=method,
                       tol=tol, options={"maxiter": max_iter})
        return opt.x, bool(opt.success), str(opt.message), int(getattr(opt, "nit", 0))
    except DesignError as e:
        z_opt = _best_so_far(history, targets, feas_tol)["z"]
        return (z_opt, False, f"stopped: {e}; the best design evaluated before it is "
                "returned", len(history))
