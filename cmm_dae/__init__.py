"""cmm_dae: constrained metamorphic mechanisms as index-reduced DAEs on SUNDIALS IDA.

Public API::

    mech = cmm_dae.load("models/slider_crank.toml")
    res = cmm_dae.run_dae(mech, t_end=10.0, rtol=1e-8, atol=1e-10, output_dt=0.01)
    res.driver("A").effort, res.joint("B").force, res.events, res.stats
"""

from .dae import run_dae
from .equations import Model
from .errors import AssemblyError, CmmError, ModelError, Problem, SolverError
from .iterative import run_iterative
from .loader import from_dict, load
from .mechanism import Body, Damper, Driver, Initial, Joint, Limits, Mechanism, Spring
from .report import Comparison, compare
from .result import Configuration, Event, Result, Stats, load_result
from .structure import Group, Structure, labeller, structure
from .studies import convergence, work_precision
from .sweep import SweepTable, sweep, with_params

__all__ = [
    "AssemblyError", "Body", "CmmError", "Comparison", "Configuration", "compare",
    "convergence", "work_precision", "sweep", "SweepTable", "with_params", "Damper", "Driver",
    "Event",
    "Initial", "Joint", "Limits", "Mechanism", "Model", "ModelError", "Problem", "Result",
    "SolverError", "Spring", "Stats", "Group", "Structure", "from_dict", "labeller", "load",
    "load_result", "run_dae", "run_iterative", "structure",
]
__version__ = "0.1.0"
