"""Studies made of many runs: convergence and work-precision (:mod:`.precision`), sweeps,
design optimisation and its study files and targets, benchmarks.

Layer ``cmm_dae.studies``: may import every layer below (core .. sensitivity); never a layer
above it (the contract is checked by tests/test_layers.py)."""

# the names of the module this package replaces (cmm_dae.studies, before 0.3)
from .precision import Convergence, WorkPrecision, WorkPrecisionRow, convergence, work_precision  # noqa: F401
