"""Where a crossing of a passage IDA stepped over would start: the last sample before it
whose singular-value ratio reaches START_RATIO, found by galloping back and halving,
against the sample-by-sample walk it replaced (on ratios rising back from the passage,
as they do: they fall linearly to it)."""

from __future__ import annotations

import numpy as np
import pytest

from cmm_dae.simulation.passage_start import (
    START_RATIO,
    dips,
    end_may_dip,
    falling_to_zero,
    predicted_start,
    start_before,
)


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
    assert start_before(a, r) == _walk(a, ratios)
    assert len(asked) <= 2 * max(n, 2).bit_length() + 1  # not one per sample


def test_no_sample_reaches_the_start_ratio():
    ratios = np.full(129, 0.5 * START_RATIO)
    asked: list[int] = []
    assert start_before(128, lambda i: asked.append(i) or float(ratios[i])) == 0
    assert len(asked) == 9  # 128, then 127, 126, 124, 120, 112, 96, 64, 0


@pytest.mark.parametrize("seed", range(20))
def test_any_guess_gives_the_walks_start(seed):
    """A guess (right, wrong on either side, out of range) never changes the answer."""
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 300))
    ratios = np.cumsum(rng.uniform(0.0, 3.0 * START_RATIO / n, n))[::-1]
    a = n - 1
    for guess in (None, -1, 0, int(rng.integers(0, n)), a - 1, a, _walk(a, ratios)):
        assert start_before(a, lambda i: float(ratios[i]), guess) == _walk(a, ratios)


def test_a_right_guess_costs_three_ratios():
    ratios = np.linspace(10.0 * START_RATIO, 0.0, 200)
    answer = _walk(199, ratios)
    asked: list[int] = []
    assert start_before(199, lambda i: asked.append(i) or float(ratios[i]), answer) == answer
    assert asked == [199, answer, answer + 1]


@pytest.mark.parametrize("k", [1, 8, 32])
def test_predicted_start_from_the_log_determinant(k):
    """Next to a passage at sample 150 the smallest k singular values fall linearly to
    zero together and the others stay (log det(J J^T) = 2 k log sigma_min + const): the
    prediction from two known ratios next to the dip is the walk's answer."""
    i = np.arange(200)
    ratio = 2e-4 * np.abs(i - 150.3)
    logdet = 2.0 * k * np.log(ratio) + 7.0
    a = 150
    known = {a: float(ratio[a]), a - 1: float(ratio[a - 1]), 0: float(ratio[0])}
    assert predicted_start(a, logdet, known) == _walk(a, ratio)
    assert predicted_start(a, None, known) is None
    assert predicted_start(a, logdet, {a: float(ratio[a])}) is None


def test_parabolas_find_the_minimum_of_the_squared_ratio():
    """The instant of a passage on the samples' interpolant: successive parabolas through
    the three best points of the ratio's square. On a parabola, one step and a check; on
    a V squared with a cubic term and a floor (a near miss), within the tolerance of the
    minimum found by a fine grid; None where no convex parabola fits."""
    from cmm_dae.singular.instant import parabola_minimum

    calls: list[float] = []

    def square(x: float) -> float:
        calls.append(x)
        return 4.0 * (x - 0.3141592653589793) ** 2

    pts = {x: square(x) for x in (0.25, 0.3, 0.4)}
    calls.clear()
    x = parabola_minimum(square, pts, 0.25, 0.4)
    assert abs(x - 0.3141592653589793) <= 1e-12 and len(calls) <= 2

    def bent(x: float) -> float:
        d = x - 0.61803398875
        return (3.0 * d + 40.0 * d ** 3) ** 2 + 1e-14

    grid = np.linspace(0.6, 0.64, 400_001)
    ref = grid[np.argmin([bent(g) for g in grid])]
    x = parabola_minimum(bent, {x: bent(x) for x in (0.6, 0.61, 0.64)}, 0.6, 0.64)
    assert x is not None and abs(x - ref) <= 2e-7  # the grid's own spacing: 1e-7
    concave = {0.1: -0.01, 0.2: -0.04, 0.3: -0.09}
    assert parabola_minimum(lambda x: -x * x, concave, 0.0, 1.0) is None


def test_logged_passages_skip_the_walk_back():
    """A passage only logged (branch "continue") does not look for its crossing's start:
    the same instants and minimum ratios as with the search, its start -1 and the
    ratio its rank drop is counted against START_RATIO (A02 with 8 loops, whose ratio
    is far above it away from the passages), with fewer exact ratios."""
    import cmm_dae as cd
    from cmm_dae.description import iftomm
    from cmm_dae.simulation import passage, passage_start

    mech = iftomm.a02_four_bar(8)
    model = cd.Model(mech)
    res = cd.run_dae(mech, 2.0, rtol=1e-3, model=model)
    p, t, q, v = model.params(), res.t, res.data["q"], res.data["v"]
    counted = []
    ratio = passage.singular_ratio

    def counting(*args):
        counted.append(1)
        return ratio(*args)

    runs = {}
    for start in (True, False):
        counted.clear()
        passage.singular_ratio = passage_start.singular_ratio = counting
        try:
            runs[start] = (passage.passages(model, p, t, q, v, start=start), len(counted))
        finally:
            passage.singular_ratio = passage_start.singular_ratio = ratio
    (full, n_full), (logged, n_logged) = runs[True], runs[False]
    assert len(full) == len(logged) == 2
    assert [(x.t, x.ratio, x.interval) for x in full] == [
        (x.t, x.ratio, x.interval) for x in logged]
    assert all(x.start >= 0 and x.start_ratio >= START_RATIO for x in full)
    assert all(x.start == -1 and x.start_ratio == START_RATIO for x in logged)
    # no exact ratio: the dips' bounded from above, their neighbours shown above that
    # bound, by a Cholesky each
    assert n_logged == 0 < n_full


@pytest.mark.parametrize("seed", range(30))
def test_neighbours_shown_above_give_the_same_dips(seed):
    """Following candidates down the ratio with neighbours shown above a value (here
    where the ratio is at least 1.5 times it, as a Cholesky bound would) instead of
    their exact ratios: the same dips, never more exact ratios."""
    rng = np.random.default_rng(300 + seed)
    n = int(rng.integers(3, 40))
    ratios = rng.uniform(0.0, 1.0, n) ** 3
    candidates = sorted(set(rng.integers(0, n, 4).tolist()))
    asked: dict[bool, list[int]] = {False: [], True: []}

    def ratio(cheap: bool):
        return lambda i: asked[cheap].append(i) or float(ratios[i])

    def exceeds(j: int, x: float) -> bool:
        return True if ratios[j] >= 1.5 * x else float(ratio(True)(j)) > x

    exact = dips(candidates, n, ratio(False), 0.3)
    assert dips(candidates, n, ratio(True), 0.3, exceeds) == exact
    assert len(set(asked[True])) <= len(set(asked[False]))
    # with a bound on a candidate's ratio (here 1.2 times it) standing for it where the
    # neighbours are shown above the bound: the same dips again
    assert dips(candidates, n, ratio(True), 0.3, exceeds,
                lambda i: 1.2 * float(ratios[i])) == exact


def _logdet(t: np.ndarray, t_star: float, k: int) -> np.ndarray:
    """log det(J J^T) where k singular values fall linearly to zero at t_star and the
    others (product e^3) stay: 2 k log|t - t_star| + 3."""
    with np.errstate(divide="ignore"):
        return 2.0 * k * np.log(np.abs(t - t_star)) + 3.0


@pytest.mark.parametrize("k", [1, 10])
def test_an_end_next_to_a_passage_is_asked_of_the_ratios(k):
    t = np.linspace(0.0, 0.1, 11)  # intervals of 0.01 s
    # beyond the last sample by half an interval, inside the last interval next to the
    # end, beyond the first sample, exactly at the end: each end may dip
    for t_star, end, a, b in ((0.105, 10, 9, 8), (0.097, 10, 9, 8), (-0.004, 0, 1, 2),
                              (0.1, 10, 9, 8)):
        assert end_may_dip(_logdet(t, t_star, k), t, end, a, b, 0.01), (t_star, end)
    # far beyond an end (five intervals; fifty where ten collapse, whose determinant's
    # line errs towards asking), or rising towards it: the ratios are not asked
    far = 0.05 if k == 1 else 0.5
    for t_star, end, a, b in ((0.1 + far, 10, 9, 8), (-far, 0, 1, 2), (0.095, 0, 1, 2)):
        assert not end_may_dip(_logdet(t, t_star, k), t, end, a, b, 0.01), (t_star, end)


def test_a_level_determinant_asks_no_ratio_at_the_ends():
    t = np.linspace(0.0, 2.0, 201)
    rng = np.random.default_rng(3)
    d = -7.7 + 1e-12 * rng.standard_normal(t.size)  # level to round-off (A02's ends)
    assert not end_may_dip(d, t, 0, 1, 2, 0.01)
    assert not end_may_dip(d, t, 200, 199, 198, 0.01)
    d[0] = -np.inf  # a sample singular to round-off is always asked
    assert end_may_dip(d, t, 0, 1, 2, 0.01)
    assert not end_may_dip(d, t, 1, 0, 2, 0.01)  # (its neighbour: rising from it)


@pytest.mark.parametrize("seed", range(30))
def test_a_passage_between_uneven_samples_is_a_candidate(seed):
    """The smallest singular value falls linearly to zero at t_star and rises again
    (k of them together); IDA's steps around it uneven (a step cut right after it): the
    interval holding t_star always gives the sample nearer the instant as the one
    candidate, though the samples' own drop can be as small as 0.5 (the DIP rule, which
    assumed even steps, then missed it)."""
    rng = np.random.default_rng(500 + seed)
    k = int(rng.choice([1, 3, 10]))
    h = 10.0 ** rng.uniform(-6, -2, 40)
    t = np.cumsum(h)
    a = int(rng.integers(2, 37))
    t_star = t[a] + rng.uniform(0.05, 0.95) * (t[a + 1] - t[a])
    found = falling_to_zero(t, _logdet(t, t_star, k))
    nearer = a if t_star - t[a] < t[a + 1] - t_star else a + 1
    assert found == [nearer]


def test_a_level_or_gently_bent_determinant_gives_no_candidate():
    rng = np.random.default_rng(7)
    t = np.cumsum(10.0 ** rng.uniform(-9, -2, 300))  # steps over seven decades
    assert falling_to_zero(t, -7.7 + 1e-12 * rng.standard_normal(t.size)) == []
    # a ratio dipping to half its value and back (a swing that does not near a singular
    # position): its lines never reach zero within a step
    s = 1.0 - 0.5 * np.sin(np.pi * t / t[-1])
    assert falling_to_zero(t, 2.0 * np.log(s)) == []
    assert falling_to_zero(t[:2], np.zeros(2)) == []


def test_a02_passage_with_a_step_cut_after_it_is_logged():
    """A02 (one loop) sampled around its first singular position as IDA had (rtol 1e-8,
    atol 1e-10, 10 s: its 8th passage went unlogged): 2 ms steps up to 1.2 ms before the
    instant, the next sample 0.8 ms after it, then steps of 10 us. The ratio at the
    sample after it is 0.67 of the one before; the screen finds the passage, at the
    instant a tight run's crossing gives (within 1e-6 s)."""
    import cmm_dae as cd
    from cmm_dae.description import iftomm
    from cmm_dae.simulation import passage

    mech = iftomm.a02_four_bar(1)
    model = cd.Model(mech)
    tight = cd.run_dae(mech, 0.75, rtol=1e-10, model=model, output_dt=1e-5)
    t_s = next(e.t for e in tight.events if e.kind == "singular")
    want = np.concatenate([t_s - 1.2e-3 - 2e-3 * np.arange(6)[::-1],
                           t_s + 0.8e-3 + 1e-5 * np.arange(6)])
    idx = np.unique(np.searchsorted(tight.t, want))
    t, q, v = tight.t[idx], tight.data["q"][idx], tight.data["v"][idx]
    found = passage.passages(model, model.params(), t, q, v, start=False)
    assert len(found) == 1 and abs(found[0].t - t_s) <= 1e-6


def test_loop_free_configurations_are_named_and_never_lose_rank():
    """A configuration whose joints close no loop has no singular position, so the
    stepped-over screen skips it. The classification of shipped configurations (the cam
    follower in flight and in contact, a locked pendulum, the loops of the double-folded
    mechanism and the Bennett linkage), and, for every loop-free one, the active rows'
    Jacobian of full rank at 20 random positions (smallest over largest singular value
    above 1e-6: a tree's Jacobian is block triangular with blocks of full rank anywhere,
    on the constraints or off them)."""
    import cmm_dae as cd
    from cmm_dae.equations.rank import loop_free
    from cmm_dae.simulation import cache

    want = {"cam_valve_train": [True, False], "pendulum_stop": [True, True],
            "crank_pendulum": [True], "collar_on_shaft": [True, True],
            "spherical_pendulum": [True], "double_folded": [False, False],
            "bennett_linkage": [False], "slider_crank": [False], "curved_slot": [False, False]}
    rng = np.random.default_rng(11)
    for name, flags in want.items():
        model = cache.built(cd.load(cd.example(name)))
        ps = [model.params()] + [model.params(locked={j: 0.0}) for j in model.locks]
        got = [loop_free(model, model.active_rows(p)) for p in ps]
        assert got == flags, name
        for p, free in zip(ps, got, strict=True):
            if not free:
                continue
            act = model.active_rows(p)
            for _ in range(20):
                q = rng.uniform(-2.0, 2.0, model.nq)
                s = np.linalg.svd(model.constraints(q, 0.3, p).Phi_q[act], compute_uv=False)
                assert s[-1] > 1e-6 * s[0], name
