"""cmm_dae: constrained metamorphic mechanisms as index-reduced DAEs on SUNDIALS IDA.

Public API::

    mech = cmm_dae.load("models/slider_crank.toml")
    res = cmm_dae.simulate(mech, 10.0, method="ida", rtol=1e-8, output_dt=0.01)
    res = cmm_dae.run_dae(mech, 10.0)            # the same, IDA
    ref = cmm_dae.run_iterative(mech, 10.0, dt=0.01)  # the paper's fixed-step algorithm
    res.driver("A").effort, res.joint("B").force, res.events, res.stats, res.status
"""

from .core import moved as _moved
from .core.errors import (
    STATUS_MESSAGES,
    AssemblyError,
    CmmError,
    ModelError,
    Problem,
    SolverError,
    Status,
)
from .core.records import Configuration, Event, EventKind, Side, Stats
from .description.library import example, examples
from .description.loader import from_dict, load
from .description.mechanism import (
    Body,
    Curve,
    Damper,
    Driver,
    Element,
    Friction,
    Gear,
    Initial,
    Joint,
    Law,
    Limits,
    Load,
    Mechanism,
    Spring,
    Zone,
)
from .description.params import with_params
from .description.structure import Group, Structure, labeller
from .equations.model import Model
from .report.compare import Comparison, compare
from .results.result import Result
from .results.storage import load_result
from .sensitivity.run import Sensitivities, sensitivities
from .simulation.runner import METHODS, run_dae, run_iterative, simulate
from .simulation.structure import structure
from .studies.design import Design, DesignError, Target, design
from .studies.precision import Convergence, WorkPrecision, convergence, work_precision
from .studies.sweep import SweepTable, sweep

__all__ = [
    "METHODS", "STATUS_MESSAGES", "AssemblyError", "Body", "CmmError", "compare", "Comparison",
    "Configuration", "Convergence", "Curve", "convergence", "Damper", "Design", "DesignError",
    "design",
    "Driver", "Element", "Event", "EventKind",
    "example", "examples",
    "Friction", "from_dict", "Gear", "Group", "Initial", "Joint", "labeller", "Law", "Limits",
    "load", "Load",
    "load_result", "Mechanism", "Model", "ModelError", "Problem", "Result", "run_dae",
    "run_iterative", "Sensitivities", "sensitivities", "Side", "simulate", "SolverError", "Spring",
    "Stats", "Status", "Structure",
    "structure", "sweep", "Target", "SweepTable", "with_params", "work_precision", "WorkPrecision",
    "Zone",
]
__version__ = "0.3.0"

_moved.install()  # the module paths before 0.3 still import, with a DeprecationWarning


def __getattr__(name: str):
    """``cmm_dae.<old module>`` as an attribute (``cmm_dae.params`` before 0.3): the module
    that holds its code now, with a DeprecationWarning (see :mod:`cmm_dae.core.moved`)."""
    if name in _moved.MOVED:
        import importlib

        return importlib.import_module(f"cmm_dae.{name}")
    raise AttributeError(f"module 'cmm_dae' has no attribute {name!r}")
