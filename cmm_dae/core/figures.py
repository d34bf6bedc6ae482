"""The one way the package draws figures: matplotlib's pyplot on the Agg backend (files,
no window), imported when a figure is first drawn, not with the package (at module level
it took 0.5 s of every ``import cmm_dae``, and so of every command-line call)."""

from __future__ import annotations

__all__ = ["pyplot"]


def pyplot():
    """matplotlib.pyplot, the Agg backend chosen first."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
