"""The Result of a run (:mod:`.result`), how it is built from the samples (:mod:`.post`), its
energy audit, export and storage.

Layer ``cmm_dae.results``: may import core, description, equations; never a layer above it
(the contract is checked by tests/test_layers.py)."""
