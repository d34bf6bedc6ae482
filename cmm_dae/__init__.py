"""cmm_dae: constrained metamorphic mechanisms as index-reduced DAEs on SUNDIALS IDA.

Public API::

    mech = cmm_dae.load("models/slider_crank.toml")
    res = cmm_dae.simulate(mech, 10.0, method="ida", rtol=1e-8, output_dt=0.01)
    res = cmm_dae.run_dae(mech, 10.0)            # the same, IDA
    ref = cmm_dae.run_iterative(mech, 10.0, dt=0.01)  # the paper's fixed-step algorithm
    res.driver("A").effort, res.joint("B").force, res.events, res.stats, res.status
"""

from .design import Design, DesignError, Target, design
from .equations import Model
from .errors import (
    STATUS_MESSAGES,
    AssemblyError,
    CmmError,
    ModelError,
    Problem,
    SolverError,
    Status,
)
from .library import example, examples
from .loader import from_dict, load
from .mechanism import (
    Body,
    Damper,
    Driver,
    Element,
    Friction,
    Initial,
    Joint,
    Law,
    Limits,
    Load,
    Mechanism,
    Spring,
    Zone,
)
from .params import with_params
from .report import Comparison, compare
from .result import Configuration, Event, Result, Stats
from .runner import METHODS, run_dae, run_iterative, simulate
from .sensitivity import Sensitivities, sensitivities
from .storage import load_result
from .structure import Group, Structure, labeller, structure
from .studies import Convergence, WorkPrecision, convergence, work_precision
from .sweep import SweepTable, sweep

__all__ = [
    "METHODS", "STATUS_MESSAGES", "AssemblyError", "Body", "CmmError", "compare", "Comparison",
    "Configuration", "Convergence", "convergence", "Damper", "Design", "DesignError", "design",
    "Driver", "Element", "Event",
    "example", "examples",
    "Friction", "from_dict", "Group", "Initial", "Joint", "labeller", "Law", "Limits", "load",
    "Load",
    "load_result", "Mechanism", "Model", "ModelError", "Problem", "Result", "run_dae",
    "run_iterative", "Sensitivities", "sensitivities", "simulate", "SolverError", "Spring",
    "Stats", "Status", "Structure",
    "structure", "sweep", "Target", "SweepTable", "with_params", "work_precision", "WorkPrecision",
    "Zone",
]
__version__ = "0.2.0"
