"""The hybrid state of a run and the one event policy of both integrators: configurations
(:mod:`.state`), detection and decisions (:mod:`.policy`), load zones, the consistent start
(:mod:`.start`) and the equilibrium start.

Layer ``cmm_dae.hybrid``: may import core, description, equations; never a layer above it
(the contract is checked by tests/test_layers.py)."""

# the names of the module this package replaces (cmm_dae.hybrid, before 0.3)
from .state import (  # noqa: F401
    ZENO_DT,
    HybridState,
    Locked,
    LockUpError,
    Policy,
    SegmentTrace,
    Transition,
    Trigger,
)
