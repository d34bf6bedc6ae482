"""The integrators behind one contract (:mod:`.contract`): SUNDIALS IDA (:mod:`.ida`, its
compiled segment :mod:`.csegment` and ``segment.c``, its tolerances) and the paper's fixed-
step algorithm (:mod:`.iterative`).

Layer ``cmm_dae.integrators``: may import core, description, equations, hybrid, singular;
never a layer above it (the contract is checked by tests/test_layers.py)."""
