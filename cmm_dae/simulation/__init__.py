"""The one run driver (:mod:`.runner`: options, start, the hybrid loop, failure wrapping) and
its singular-position glue (:mod:`.crossing`, :mod:`.passage`).

Layer ``cmm_dae.simulation``: may import core, description, equations, hybrid, singular,
integrators, results; never a layer above it (the contract is checked by
tests/test_layers.py)."""
