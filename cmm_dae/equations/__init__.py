"""The equations of a mechanism: the CasADi model (:mod:`.model`), load and driver laws, code
generation and compiled evaluation (:mod:`.codegen`), the KKT solves (:mod:`.kkt`; a large
mechanism's banded Schur complement: :mod:`.banded`),
kinematics and the rank of the active constraints (:mod:`.kinematics`), IDA's reduced
unknowns (:mod:`.unknowns`).

Layer ``cmm_dae.equations.model``: may import core, description; never a layer above it (the
contract is checked by tests/test_layers.py)."""
