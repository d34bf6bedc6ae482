"""Where a crossing of a passage IDA stepped over would start: the last sample before it
whose singular-value ratio reaches START_RATIO, found by galloping back and halving,
against the sample-by-sample walk it replaced (on ratios rising back from the passage,
as they do: they fall linearly to it)."""

from __future__ import annotations

import numpy as np
import pytest

from cmm_dae.simulation.passage import START_RATIO, _start_before


def _walk(a: int, ratios: np.ndarray) -> int:
    j = a
    while j > 0 and ratios[j] < START_RATIO:
        j -= 1
    return j


@pytest.mark.parametrize("seed", range(20))
def test_galloping_start_is_the_walks(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    # a ratio rising back from the passage at sample n - 1, reaching START_RATIO or not
    ratios = np.cumsum(rng.uniform(0.0, 3.0 * START_RATIO / n, n))[::-1]
    asked: list[int] = []

    def r(i: int) -> float:
        asked.append(i)
        return float(ratios[i])

    a = n - 1
    assert _start_before(a, r) == _walk(a, ratios)
    assert len(asked) <= 2 * max(n, 2).bit_length() + 1  # not one per sample


def test_no_sample_reaches_the_start_ratio():
    ratios = np.full(129, 0.5 * START_RATIO)
    asked: list[int] = []
    assert _start_before(128, lambda i: asked.append(i) or float(ratios[i])) == 0
    assert len(asked) == 9  # 128, then 127, 126, 124, 120, 112, 96, 64, 0
