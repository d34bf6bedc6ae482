"""Singular positions: the crossing's Gauss-Legendre steps (:mod:`.gauss`), the step over a
singular position on the branch of the motion (:mod:`.step`), the branches and the singular
instant.

Layer ``cmm_dae.singular``: may import core, description, equations, hybrid; never a layer
above it (the contract is checked by tests/test_layers.py)."""

# the names of the module this package replaces (cmm_dae.singular, before 0.3)
from .step import Crossing, leaves_singular, step_over  # noqa: F401
