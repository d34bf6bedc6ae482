"""The package's ground floor: every exception class and the status of a run (:mod:`.errors`),
the records the layers pass each other (:mod:`.records`: Configuration, Event, Stats), the
progress bar, values computed once per model (:mod:`.memo`).

Layer ``cmm_dae.core``: may import nothing else of cmm_dae; never a layer above it (the
contract is checked by tests/test_layers.py)."""
