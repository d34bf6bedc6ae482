"""The one exception family of cmm_dae.

Every error a user can provoke with a model file or a run option is one of these;
nothing from CasADi or SUNDIALS leaks out of the package unwrapped.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from .result import Event, Result


class CmmError(Exception):
    """Base class of every error raised by cmm_dae."""


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
        head = f"model file '{source}'" if source else "mechanism"
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
    result : Result
        Everything computed up to the failure (``result.t[-1]`` is the last
        time reached).
    configuration : Any
        The configuration in force at the failure.
    last_event : Event or None
        The last event before the failure.
    """

    def __init__(self, message: str, *, result: Result | None = None,
                 configuration: Any = None, last_event: Event | None = None):
        self.result = result
        self.configuration = configuration
        self.last_event = last_event
        super().__init__(message)
