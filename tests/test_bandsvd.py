"""The singular-value ratio from a reordered band (LAPACK's dgbbrd and dlasq1 through
scipy's cython_lapack) against numpy's dense SVD, which is independent of it (LAPACK's
dgesdd on the whole matrix): both are backward stable, so the ratios agree to round-off
times the largest singular value, absolute."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cmm_dae.description import iftomm
from cmm_dae.equations import bandsvd, kinematics, rank
from cmm_dae.simulation.runner import run_dae
from cmm_dae.singular import approach


def _shuffled_band(rng: np.random.Generator, m: int, n: int, kl: int, ku: int
                   ) -> np.ndarray:
    """A random m x n band matrix, its rows and columns shuffled (the band hidden)."""
    A = np.zeros((m, n))
    for i in range(m):
        lo, hi = max(i - kl, 0), min(i + ku + 1, n)
        A[i, lo:hi] = rng.standard_normal(hi - lo)
    return A[rng.permutation(m)][:, rng.permutation(n)]


def _ratio(A: np.ndarray) -> float | None:
    rows, cols = np.nonzero(A)
    st = bandsvd.structure(rows, cols, *A.shape)
    return bandsvd.ratio(st, A[rows, cols])


@pytest.mark.parametrize(("m", "n", "kl", "ku"), [(120, 121, 2, 3), (150, 150, 4, 4),
                                                   (90, 130, 1, 6), (1, 4, 0, 3)])
def test_band_ratio_is_the_svds(m, n, kl, ku):
    rng = np.random.default_rng(m + n)
    A = _shuffled_band(rng, m, n, kl, ku)
    s = np.linalg.svd(A, compute_uv=False)
    assert _ratio(A) == pytest.approx(s[-1] / s[0], rel=1e-10, abs=1e-14)


def test_band_ratio_of_nearly_dependent_rows():
    """Two rows made dependent but for 1e-12: a ratio of about 1e-13, found to round-off
    (the Gram matrix's eigenvalues, squared singular values, cannot resolve it)."""
    rng = np.random.default_rng(7)
    A = _shuffled_band(rng, 100, 101, 2, 2)
    i, j = np.flatnonzero(A[:, np.flatnonzero(A[0])[0]])[:2]  # two rows sharing a column
    A[j] = A[i] * 2.0
    A[j, np.flatnonzero(A[i])[0]] += 1e-12
    s = np.linalg.svd(A, compute_uv=False)
    assert s[-1] / s[0] < 1e-12
    assert abs(_ratio(A) - s[-1] / s[0]) <= 1e-15


def test_band_ratio_refuses_non_finite_values():
    A = _shuffled_band(np.random.default_rng(3), 100, 101, 1, 1)
    A[np.nonzero(A)[0][5], np.nonzero(A)[1][5]] = np.nan
    assert _ratio(A) is None


def test_singular_ratio_of_a_long_chain_near_its_singular_position(monkeypatch):
    """A02 with 32 loops (194 constraint rows): at every state the crossing of its
    singular position asked about, the banded ratio against the dense SVD's of the same
    Jacobian. A branch rule makes the run cross it (without one, IDA steps over it: the
    chain has no locks, so its multipliers are out of the error test)."""
    seen: list[tuple[float, float]] = []

    def spy(model, q, t, p):
        J = model.constraints(q, t, p).Phi_q[model.active_rows(p)]
        seen.append((kinematics.singular_ratio(model, q, t, p), rank.ratio(J)))
        return seen[-1][0]

    monkeypatch.setattr(approach, "ratio", spy)
    res = run_dae(iftomm.a02_four_bar(32), 0.8, rtol=1e-3, compiled=False,
                  branch=("G0", -1))
    assert [e.side for e in res.events] == ["continue (G0 -)"]
    assert len(seen) >= 5  # 12: the search for the instant ahead
    assert min(b for _, b in seen) < 1e-8  # it came to the singular position (2.4e-9)
    # below GRAM_RATIO_FROM the band's bidiagonal form: to round-off of the largest
    # singular value; from it on the Gram matrix's band: round-off of its square over
    # twice the ratio (measured 2.6e-10 of the ratio at most)
    small = [(a, b) for a, b in seen if b < bandsvd.GRAM_RATIO_FROM]
    assert small and max(abs(a - b) for a, b in small) <= 1e-15
    assert max(abs(a - b) / b for a, b in seen if b >= bandsvd.GRAM_RATIO_FROM) <= 1e-9


@pytest.mark.parametrize(("m", "n", "kl", "ku"), [(120, 121, 2, 3), (150, 150, 4, 4)])
def test_gram_band_ratio_is_the_svds_where_it_is_not_small(m, n, kl, ku):
    """The ratio from the Gram matrix's band (dsbtrd and bisection) against the dense
    SVD: to 1e-10 of itself on random band matrices (measured 1.3e-9 at worst on A02's
    states with 128 loops at ratios from 1e-4 on); a ratio about 1e-9 (one row scaled
    down) it cannot resolve (round-off of the squares), so the combined ratio takes the
    bidiagonal form there and agrees with the SVD to round-off of the largest singular
    value."""
    from cmm_dae.equations import banded

    rng = np.random.default_rng(7 * m + n)
    A = _shuffled_band(rng, m, n, kl, ku)
    rows, cols = np.nonzero(A)
    st_g = banded.structure(rows, cols, m)  # the Gram matrix's band
    low = banded.lower_blocks(st_g, A[rows, cols][:, None])
    s = np.linalg.svd(A, compute_uv=False)
    assert bandsvd.gram_ratio(low) == pytest.approx(s[-1] / s[0], rel=1e-10)
    B = A.copy()
    B[m // 2] *= 1e-9  # one row nearly zero: a ratio about 1e-9, the pattern kept
    sb = np.linalg.svd(B, compute_uv=False)
    assert sb[-1] / sb[0] < 1e-8
    low_b = banded.lower_blocks(st_g, B[rows, cols][:, None])
    st = bandsvd.structure(rows, cols, m, n)
    assert bandsvd.ratio(st, B[rows, cols], low_b) == pytest.approx(sb[-1] / sb[0], abs=1e-14)
    assert bandsvd.ratio(st, B[rows, cols], low_b) == bandsvd.ratio(st, B[rows, cols])


def test_tridiagonal_form_eigenvalues_and_counts_against_the_closed_form():
    """The second-difference matrix (2 on the diagonal, -1 beside it, written with a
    zero second band) has the eigenvalues 2 - 2 cos(k pi / (m + 1)): each by bisection
    on the band's tridiagonal form within 1e-13 of the largest, and the Sturm counts
    between them exact."""
    m = 150
    low = np.zeros((3, m), order="F")
    low[0], low[1, :m - 1] = 2.0, -1.0
    exact = 2.0 - 2.0 * np.cos(np.arange(1, m + 1) * np.pi / (m + 1))
    tri = bandsvd.gram_tridiagonal(low)
    got = np.array([bandsvd.eigenvalue(tri, i) for i in range(1, m + 1)])
    assert np.max(np.abs(got - exact)) <= 1e-13 * exact[-1]
    mids = 0.5 * (exact[:-1] + exact[1:])
    assert [bandsvd.count_below(tri, x) for x in mids] == list(range(1, m))
    assert bandsvd.count_below(tri, 0.5 * exact[0]) == 0
    assert bandsvd.count_below(tri, 4.0) == m


def test_ratio_shown_above_a_bound_against_the_closed_form():
    """bandsvd.above on the second-difference matrix, whose Gershgorin bound (4) is within
    1.1e-4 of its largest eigenvalue: it shows the ratio above 0.999 of sqrt(lambda_1 / 4)
    and never above the ratio itself (nor 1.001 of that bound, where its shifted Cholesky
    must fail)."""
    m = 150
    low = np.zeros((3, m), order="F")
    low[0], low[1, :m - 1] = 2.0, -1.0
    lam = 2.0 - 2.0 * np.cos(np.arange(1, m + 1) * np.pi / (m + 1))
    exact = math.sqrt(lam[0] / lam[-1])
    shown = math.sqrt(lam[0] / 4.0)
    assert bandsvd.above(low, 0.999 * shown)
    assert not bandsvd.above(low, 1.001 * shown)
    assert not bandsvd.above(low, exact * (1.0 + 1e-9))
    singular = low.copy()
    singular[0, 0] = singular[0, -1] = 1.0  # (both ends free: constants, ratio 0)
    assert not bandsvd.above(singular, 1e-12)
