"""The instant a banded Jacobian loses rank, by Newton's method on the signed smallest
singular value (:mod:`cmm_dae.singular.tip`): against a closed form where several
singular values collapse at once with different slopes, and against the ratio's
parabolic search it replaces on A02's logged passages."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cmm_dae.equations import banded
from cmm_dae.singular.tip import TIP_RATIO, newton_tip

X_STAR = 0.3712345678901234
BLOCKS = 10  # 4 x 4 blocks, one more (zero) column: 40 rows, 41 columns, banded


def _blocks(x: float, miss: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """J(x) = blockdiag(G(x) D_j(x)): each block a rotation (turning with x) of a diagonal
    whose last entry is c_j (x - X_STAR), sqrt of that squared plus ``miss`` squared for
    a near miss; the rest bounded away from zero. Its smallest singular value is
    min_j |c_j| |x - X_STAR| (BLOCKS of them collapse there at once)."""
    rows, cols, vals = [], [], []
    for j in range(BLOCKS):
        c = 0.5 + 0.17 * j
        last = c * (x - X_STAR) if miss == 0.0 else math.hypot(c * (x - X_STAR), miss)
        d = np.array([1.0 + 0.1 * j, 2.0, 0.7, last])
        th = 0.3 + 2.0 * x + 0.05 * j
        g = np.eye(4)
        g[np.ix_([1, 3], [1, 3])] = [[math.cos(th), -math.sin(th)],
                                     [math.sin(th), math.cos(th)]]
        b = g @ np.diag(d)
        for r in range(4):
            for k in range(4):
                rows.append(4 * j + r)
                cols.append(4 * j + k)
                vals.append(b[r, k])
    return np.array(rows), np.array(cols), np.array(vals)


def test_newton_finds_where_ten_singular_values_collapse_at_once():
    rows, cols, _ = _blocks(0.0)
    band = banded.structure(rows, cols, 4 * BLOCKS)
    assert band is not None
    calls = []

    def values_at(x: float) -> np.ndarray:
        calls.append(x)
        return _blocks(x)[2]

    got = newton_tip(values_at, band, 4 * BLOCKS + 1, 0.3, 0.45, 0.33)
    assert got is not None
    x, sigma = got
    assert abs(x - X_STAR) <= 1e-13  # measured 0 to 1.4e-15 from six starts
    assert sigma <= 1e-14  # |J^T w| there: an upper bound on the smallest singular value
    assert len(calls) <= 22  # measured 5 (two J evaluations a step; round-off at 3)
    # a near miss (smallest singular value 1e-7 at best): the least value's place
    rows, cols, _ = _blocks(0.0, 1e-7)
    got = newton_tip(lambda x: _blocks(x, 1e-7)[2], band, 4 * BLOCKS + 1, 0.3, 0.45, 0.44)
    assert got is None or abs(got[0] - X_STAR) <= 1e-6  # measured 9.0e-9
    assert got is None or got[1] >= 0.5 * 1e-7  # the bound is no less than the least value


def test_newton_gives_up_outside_its_bracket():
    rows, cols, _ = _blocks(0.0)
    band = banded.structure(rows, cols, 4 * BLOCKS)
    # the instant lies outside [0.4, 0.45]: the first step leaves it
    assert newton_tip(lambda x: _blocks(x)[2], band, 4 * BLOCKS + 1, 0.4, 0.45, 0.41) is None


def _a02_passages(loops: int, counted: tuple, variants: dict) -> tuple[np.ndarray, dict]:
    """A02's logged passages (2 s, rtol 1e-3) searched in its samples once per variant
    (``{name: (module, attribute, replacement)}``, the replacement in place during the
    search), counting the calls of ``counted`` (module, attribute): the samples' times
    and ``{name: (passages, calls)}``."""
    import cmm_dae as cd
    from cmm_dae.description import iftomm
    from cmm_dae.simulation import passage

    mech = iftomm.a02_four_bar(loops)
    model = cd.Model(mech)
    res = cd.run_dae(mech, 2.0, rtol=1e-3, model=model)
    p, t, q, v = model.params(), res.t, res.data["q"], res.data["v"]
    calls: list[int] = []
    inner = getattr(*counted)

    def counting(*args):
        calls.append(1)
        return inner(*args)

    runs = {}
    for name, (module, attr, fn) in variants.items():
        calls.clear()
        kept = getattr(module, attr)
        setattr(*counted, counting)
        setattr(module, attr, fn if fn is not None else kept)
        try:
            runs[name] = (passage.passages(model, p, t, q, v, start=False), len(calls))
        finally:
            setattr(module, attr, kept)
            setattr(*counted, inner)
    return t, runs


@pytest.mark.parametrize("loops", [1, 8, 32])
def test_a02_passages_by_newton_are_the_ratios_minimum(loops):
    """A02's two logged passages (rtol 1e-3): the instants the parabolic search on the
    exact ratio finds (to 1e-9 of the interval), the ratio there bounded at round-off
    without an exact ratio (twelve for the two by the parabolas)."""
    from cmm_dae.simulation import passage
    from cmm_dae.singular import tip

    t, runs = _a02_passages(loops, (passage, "singular_ratio"), {
        "newton": (tip, "newton_tip", None), "parabola": (tip, "newton_tip", lambda *a: None)})
    (by_newton, n_newton), (by_parabola, n_parabola) = runs["newton"], runs["parabola"]
    assert len(by_newton) == len(by_parabola) == 2
    for a, b in zip(by_newton, by_parabola, strict=True):
        assert a.interval == b.interval
        h = t[a.interval + 1] - t[a.interval]
        if loops == 1 and b.ratio > 1e-11:
            # one loop's second passage is a near miss (the interpolant passes 1.4e-10
            # from the position): Newton stops where a step no longer lowers the smallest
            # singular value, 2.7e-9 of the interval from the ratio's minimum, the ratio
            # there 1.2 times it (measured)
            assert abs(a.t - b.t) <= 1e-8 * h and b.ratio <= a.ratio <= 1.5 * b.ratio
            continue
        assert abs(a.t - b.t) <= 1e-9 * h  # measured 4.3e-12 to 1.9e-11 of the interval
        # the bound at Newton's instant (measured 4.9e-15 to 5.5e-13), the exact ratio at
        # the parabolas' (within 1e-9 of the interval of the instant: the ratio falls
        # 7e-3 over it with 32 loops; measured 9.3e-15 to 6.7e-14)
        assert a.ratio <= 1e-11 < TIP_RATIO and b.ratio <= 1e-10
    assert n_parabola - n_newton >= 12  # six exact ratios fewer for each passage


@pytest.mark.parametrize("loops", [1, 8, 32])
def test_newton_from_the_dip_sample_is_newton_from_the_grid(loops):
    """Newton's method started at the dipping sample itself, across the intervals on
    both sides (:func:`~cmm_dae.singular.tip.sample_instant`), against Newton started
    from the coarse grid's lowest point in the interval (the path it replaces where it
    succeeds): the same interval, the instant to 1e-10 of the interval (measured
    2.2e-14 to 1.1e-11: Newton stops at round-off, 4096 units of it at most), the ratio
    bounded at round-off, and no grid evaluated."""
    from cmm_dae.simulation import passage

    t, runs = _a02_passages(loops, (passage, "_on_grids"), {
        "sample": (passage, "sample_instant", None),
        "grid": (passage, "sample_instant", lambda *a: None)})
    (by_sample, n_sample), (by_grid, n_grid) = runs["sample"], runs["grid"]
    assert len(by_sample) == len(by_grid) == 2
    for a, b in zip(by_sample, by_grid, strict=True):
        assert a.interval == b.interval
        h = t[a.interval + 1] - t[a.interval]
        if loops == 1 and b.ratio > 1e-11:  # the near miss (above): 2.6e-9 measured
            assert abs(a.t - b.t) <= 1e-8 * h and a.ratio < TIP_RATIO
            continue
        assert abs(a.t - b.t) <= 1e-10 * h
        assert a.ratio <= 1e-11 < TIP_RATIO
    assert n_sample == 0 < n_grid


def test_tip_ratio_bounds_before_it_asks_the_exact_ratio():
    """At Newton's instant the ratio is sigma over a lower bound on the largest singular
    value: J's largest row norm (1.9939 here; the largest singular value is 2), else the
    power iterations' (within 3.2e-3 of it), else the exact ratio, asked only where
    neither bound shows it below TIP_RATIO."""
    from cmm_dae.singular.tip import tip_ratio

    rows, cols, vals = _blocks(X_STAR)
    band = banded.structure(rows, cols, 4 * BLOCKS)
    J = np.zeros((4 * BLOCKS, 4 * BLOCKS + 1))
    J[rows, cols] = vals
    row, top = np.linalg.norm(J, axis=1).max(), np.linalg.svd(J, compute_uv=False)[0]
    asked: list[int] = []

    def exact() -> float:
        asked.append(1)
        return 0.5

    r = tip_ratio(vals, 1e-14, band, 4 * BLOCKS + 1, exact)
    assert abs(r - 1e-14 / row) <= 1e-12 * r and not asked
    sigma = TIP_RATIO * 0.5 * (row + top)  # not shown by the rows, by the power iterations
    r = tip_ratio(vals, sigma, band, 4 * BLOCKS + 1, exact)
    assert not asked and sigma / top <= r <= (1.0 + 3.2e-3) * sigma / top
    assert tip_ratio(vals, 1e-3, band, 4 * BLOCKS + 1, exact) == 0.5 and asked


def test_ratio_above_bounds_the_ratio_from_above():
    """One Cholesky's upper bound on the ratio (tip.ratio_above) next to where ten
    singular values collapse with different slopes: never below the SVD's ratio, and
    within a factor 2 of it (the inverse iteration mixes the collapsing values' vectors;
    measured 1.033 to 1.044 times it here, 2.0 on A02 with 32 loops)."""
    from cmm_dae.singular.tip import ratio_above

    rows, cols, _ = _blocks(0.0)
    band = banded.structure(rows, cols, 4 * BLOCKS)
    for dx in (1e-1, 1e-2, 1e-3, -1e-4):
        vals = _blocks(X_STAR + dx)[2]
        J = np.zeros((4 * BLOCKS, 4 * BLOCKS + 1))
        J[rows, cols] = vals
        s = np.linalg.svd(J, compute_uv=False)
        bound = ratio_above(vals, band, 4 * BLOCKS + 1)
        assert bound is not None and s[-1] / s[0] * (1.0 - 1e-12) <= bound <= 2.0 * s[-1] / s[0]
