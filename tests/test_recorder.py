"""The run's sample store (integrators.contract.Recorder) against a plain list of its
samples: blocks and single samples in any order, then sample lookups, the samples since
an index and truncations, as the run driver asks for them after each event; and a
segment's output grid, built from its start on, against the whole grid filtered."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cmm_dae.hybrid import policy as ev
from cmm_dae.integrators.contract import Recorder, RunOptions
from cmm_dae.integrators.ida_steps import _output_times


@pytest.mark.parametrize("seed", range(10))
def test_recorder_lookups_are_the_plain_lists(seed):
    rng = np.random.default_rng(seed)
    rec, plain = Recorder(), []  # plain: (t, q, v, c) per sample
    t = 0.0
    for _ in range(int(rng.integers(20, 120))):
        what = rng.integers(0, 4)
        if what == 0:  # a block
            k = int(rng.integers(1, 6))
            ts = t + np.cumsum(rng.uniform(0.01, 0.1, k))
            q, v, c = rng.standard_normal((k, 3)), rng.standard_normal((k, 3)), int(
                rng.integers(0, 3))
            rec.add_block(ts, q, v, c)
            plain += [(ts[j], q[j], v[j], c) for j in range(k)]
            t = float(ts[-1])
        elif what == 1:  # a single sample (an event's)
            t += 0.01
            q, v, c = rng.standard_normal(3), rng.standard_normal(3), int(rng.integers(0, 3))
            rec.add(t, q, v, c)
            plain.append((t, q, v, c))
        elif what == 2 and plain:  # a stretch taken again
            n = int(rng.integers(0, len(plain) + 1))
            rec.truncate(n)
            plain = plain[:n]
            t = plain[-1][0] if plain else 0.0
        assert len(rec) == len(plain)
        for i in rng.integers(0, len(plain), 5) if plain else []:
            ti, qi, vi, ci = rec.at(int(i))
            assert (ti, ci) == (plain[i][0], plain[i][3])
            assert np.array_equal(qi, plain[i][1]) and np.array_equal(vi, plain[i][2])
        n0 = int(rng.integers(0, len(plain) + 2))
        ts, qs, vs = rec.since(n0)
        assert np.array_equal(ts, np.array([s[0] for s in plain[n0:]]))
        if plain[n0:]:
            assert np.array_equal(qs, np.array([s[1] for s in plain[n0:]]))
            assert np.array_equal(vs, np.array([s[2] for s in plain[n0:]]))
    with pytest.raises(IndexError):
        rec.at(len(plain))
    with pytest.raises(IndexError):
        rec.at(-1)


def test_a_segments_grid_is_the_whole_grid_after_its_start():
    rng = np.random.default_rng(4)
    for _ in range(500):
        dt, t_end = float(10 ** rng.uniform(-4, -1)), float(rng.uniform(0.01, 20.0))
        opts = RunOptions(t_end=t_end, output_dt=dt)
        on = round(rng.uniform(0.0, t_end) / dt) * dt
        for t0 in (0.0, t_end, float(rng.uniform(0.0, t_end)), on, on - 1e-13, on + 1e-13):
            n = int(math.floor(t_end / dt + 1e-9))
            whole = dt * np.arange(1, n + 1)
            whole = whole[whole > t0 + ev.ZENO_DT * max(1.0, t_end)]
            if whole.size == 0 or whole[-1] < t_end - 1e-12 * t_end:
                whole = np.append(whole, t_end)
            assert np.array_equal(_output_times(opts, t0), whole)
