"""The one exception family of cmm_dae.

Every error a user can provoke with a model file or a run option is one of these;
nothing from CasADi or SUNDIALS leaks out of the package unwrapped.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any


class CmmError(Exception):
    """Base class of every error raised by cmm_dae."""


class CompileNotice(UserWarning):
    """Said once per process when ``compiled="auto"`` builds a mechanism's compiled
    segment in the background (filter it by this class to keep a script quiet)."""


class Status(StrEnum):
    """How a run ended. The value is a short tag (``Result.status``); the full sentence of
    the run is ``Result.message``; :data:`STATUS_MESSAGES` explains each code."""

    SUCCESS = "success"
    DEAD_POINT = "dead point"
    LOCK_UP = "lock-up"
    JAM = "friction jam"
    STALLED = "stalled"
    MAX_EVENTS = "max_events"
    INTERRUPTED = "interrupted"
    INTEGRATOR = "integrator failure"
    NUMERICAL = "numerical failure"


#: What each status means, for reports and ``cmm-dae`` messages.
STATUS_MESSAGES: dict[Status, str] = {
    Status.SUCCESS: "the run reached its end time",
    Status.DEAD_POINT: "the drivers cannot carry the mechanism through a position where its "
                       "constraints become dependent",
    Status.LOCK_UP: "a new lock leaves the drivers no freedom: a stop would have to stop a "
                    "driver",
    Status.JAM: "a joint comes to rest where neither sticking nor slipping is consistent: "
                "friction from the reactions would lock the mechanism against its own loads",
    Status.STALLED: "the run-wide step budget (max_steps) was spent: a fast motion over a "
                    "long run, or tiny steps at a grazing contact, a near-singular position or "
                    "forces too stiff for the tolerances",
    Status.MAX_EVENTS: "more events than max_events",
    Status.INTERRUPTED: "interrupted by the user (Ctrl-C)",
    Status.INTEGRATOR: "the integrator could not continue (tolerances too tight or forces "
                       "too stiff)",
    Status.NUMERICAL: "a numerical failure inside the run (a singular linear system, an "
                      "overflow or a non-finite value)",
}


@dataclass(frozen=True)
class Problem:
    """One problem found in a mechanism description.

    Attributes
    ----------
    table : str
        Dotted table path, e.g. ``"joints.A"`` or ``"bodies.crank"``.
    key : str
        Key inside that table (``""`` for the table as a whole).
    message : str
        What is wrong and what was expected.
    """

    table: str
    key: str
    message: str

    def __str__(self) -> str:
        where = f"[{self.table}]" if self.table else "[top level]"
        if self.key:
            where += f" {self.key}"
        return f"{where}: {self.message}"


class ModelError(CmmError, ValueError):
    """Bad input: a mechanism description with one or more problems.

    All problems of one description come in one exception, each naming the
    file, the table and the key.
    """

    def __init__(self, problems: list[Problem] | Problem | str, source: str | None = None):
        if isinstance(problems, str):
            problems = [Problem("", "", problems)]
        elif isinstance(problems, Problem):
            problems = [problems]
        self.problems: list[Problem] = list(problems)
        self.source = source
        if source:
            head = f"model file '{source}'"
        elif self.problems and all(p.table == "run" for p in self.problems):
            head = "run options"
        else:
            head = "mechanism"
        n = len(self.problems)
        lines = [f"{head}: {n} problem{'s' if n != 1 else ''}:"]
        lines += [f"  - {p}" for p in self.problems]
        super().__init__("\n".join(lines))


class AssemblyError(CmmError):
    """The mechanism cannot be put together: a loop that does not close, or
    a constraint set that is redundant or singular."""

    def __init__(self, message: str, *, joints: list[str] | None = None,
                 residual: float | None = None):
        self.joints = list(joints or [])
        self.residual = residual
        super().__init__(message)


class SolverError(CmmError):
    """A run failed part-way.

    Attributes
    ----------
    status : Status
        What kind of failure (see :data:`STATUS_MESSAGES`).
    result : Result
        Everything computed up to the failure (``result.t[-1]`` is the last
        time reached).
    configuration : Any
        The configuration in force at the failure.
    last_event : Event or None
        The last event before the failure.
    """

    def __init__(self, message: str, *, status: Status = Status.INTEGRATOR,
                 result: Any = None, configuration: Any = None, last_event: Any = None):
        # result: cmm_dae.Result, last_event: cmm_dae.Event (not imported: result.py
        # imports this module)
        self.status = Status(status)
        self.result = result
        self.configuration = configuration
        self.last_event = last_event
        super().__init__(message)
