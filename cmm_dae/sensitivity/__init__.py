"""Forward sensitivities through the hybrid run: the API (:mod:`.run`), the differentiated
equations (:mod:`.model`), the replay of the run's segments and events (:mod:`.replay`) and
of its crossings (:mod:`.crossing`).

Layer ``cmm_dae.sensitivity``: may import every layer below (core .. simulation); never a
layer above it (the contract is checked by tests/test_layers.py)."""

# the names of the module this package replaces (cmm_dae.sensitivity, before 0.3)
from .run import Sensitivities, sensitivities  # noqa: F401
