"""What a user looks at: the comparison report (:mod:`.compare`), the figures (:mod:`.plots`)
and the animation.

Layer ``cmm_dae.report``: may import every layer below (core .. studies); never a layer
above it (the contract is checked by tests/test_layers.py)."""

# the names of the module this package replaces (cmm_dae.report, before 0.3)
from .compare import Comparison, EventMatch, SeriesDiff, compare, match_events  # noqa: F401
