"""What a mechanism is: the description records and their validation (:mod:`.mechanism`,
:mod:`.checks`), the model-file schema, loader and writer, dotted-path parameters, the
shipped examples, the structure analysis (active parts and Assur groups) and the IFToMM
benchmark mechanisms.

Layer ``cmm_dae.description``: may import core; never a layer above it (the contract is
checked by tests/test_layers.py)."""
