"""The channel filters: One Euro against a second transcription of the paper, exponential step
response, rate limit slope, zero elapsed time, and peek leaving the state alone."""

import math
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from puppet.live.filters import Exponential, OneEuro, RateLimit

# -- an independent transcription of the 1€ filter -------------------------------------------
# Casiez, Roussel & Vogel, CHI 2012, the pseudocode as printed: a LowPassFilter object that keeps
# hatxprev, and a OneEuroFilter whose rate comes from the timestamps, whose derivative is taken
# against xfilt.hatxprev(), and whose alpha is 1 / (1 + tau / te) with tau = 1 / (2 pi fc).


class PaperLowPassFilter:
    def __init__(self):
        self.first_time = True
        self.hatxprev = None
        self.xprev = None

    def filter(self, x, alpha):
        if self.first_time:
            self.first_time = False
            self.hatxprev = x
        hatx = alpha * x + (1 - alpha) * self.hatxprev
        self.xprev = x
        self.hatxprev = hatx
        return hatx


class PaperOneEuroFilter:
    def __init__(self, mincutoff, beta, dcutoff):
        self.mincutoff, self.beta, self.dcutoff = mincutoff, beta, dcutoff
        self.first_time = True
        self.xfilt = PaperLowPassFilter()
        self.dxfilt = PaperLowPassFilter()
        self.last_time = None

    @staticmethod
    def alpha(rate, cutoff):
        tau = 1.0 / (2 * math.pi * cutoff)
        te = 1.0 / rate
        return 1.0 / (1.0 + tau / te)

    def filter(self, x, timestamp_ns):
        # rate from the timestamps (integer nanoseconds, so the interval is exact)
        rate = 1.0 if self.last_time is None else 1e9 / (timestamp_ns - self.last_time)
        self.last_time = timestamp_ns
        if self.first_time:
            self.first_time = False
            dx = 0.0
        else:
            dx = (x - self.xfilt.hatxprev) * rate
        edx = self.dxfilt.filter(dx, self.alpha(rate, self.dcutoff))
        cutoff = self.mincutoff + self.beta * abs(edx)
        return self.xfilt.filter(x, self.alpha(rate, cutoff))


def noisy_input(seed, n=2000):
    """A noisy signal with slow and fast parts, at irregular (jittered, bursty) timestamps."""
    rng = random.Random(seed)
    t_ns, out = 5_000_000_000, []
    for i in range(n):
        t_ns += rng.choice([rng.randint(200_000, 2_000_000), rng.randint(8_000_000, 40_000_000), 1])
        t = t_ns * 1e-9
        x = math.sin(2 * math.pi * 0.5 * t) + (0.8 if (i // 300) % 2 else 0.0) + rng.gauss(0, 0.05)
        out.append((t_ns, x))
    return out


@pytest.mark.parametrize("params", [(1.0, 0.0, 1.0), (1.0, 0.007, 1.0), (0.5, 2.0, 1.0),
                                    (3.0, 0.3, 2.5), (0.05, 50.0, 0.5)])
@pytest.mark.parametrize("seed", [1, 2])
def test_one_euro_matches_the_papers_pseudocode(params, seed):
    ours = OneEuro(*params)
    paper = PaperOneEuroFilter(*params)
    for t_ns, x in noisy_input(seed):
        assert ours.step(x, t_ns) == pytest.approx(paper.filter(x, t_ns), abs=1e-12, rel=0)


def test_one_euro_first_sample_passes_and_stillness_is_kept():
    f = OneEuro(1.0, 0.5, 1.0)
    assert f.step(0.3, 10) == 0.3
    for k in range(1, 100):
        assert f.step(0.3, 10 + k * 10_000_000) == pytest.approx(0.3, abs=1e-15)


def test_one_euro_beta_cuts_lag():
    """The point of the filter: a fast move lags less with beta > 0, a still input jitters less
    with a lower min_cutoff."""
    slow, fast = OneEuro(1.0, 0.0), OneEuro(1.0, 5.0)
    for k in range(50):
        t = k * 10_000_000
        x = 0.0 if k < 10 else 1.0
        a, b = slow.step(x, t), fast.step(x, t)
    assert 1 - b < (1 - a) / 5


def test_a_reading_of_the_same_instant_supersedes_and_an_older_one_is_ignored():
    for make in (lambda: OneEuro(1.0, 1.0), lambda: Exponential(0.05), lambda: RateLimit(2.0)):
        f, only_newest = make(), make()
        f.step(0.0, 1_000)
        only_newest.step(0.0, 1_000)
        f.step(1.0, 2_000_000)
        y = f.step(5.0, 2_000_000)                # same stamp: a newer reading of the same read
        assert y == only_newest.step(5.0, 2_000_000)
        assert f.step(-5.0, 1_500_000) == y       # earlier stamp: never goes back in time
        assert f.step(1.0, 3_000_000) != y        # time moves again: the filter moves again
        first = make()
        first.step(0.3, 10)
        assert first.step(0.7, 10) == 0.7         # two readings of the very first instant: the newer


def test_peek_is_step_without_keeping():
    for make in (lambda: OneEuro(1.0, 0.3), lambda: Exponential(0.05), lambda: RateLimit(3.0)):
        a, b = make(), make()
        for t_ns, x in noisy_input(3, 200):
            peeked = a.peek(x, t_ns)
            assert a.peek(x, t_ns) == peeked     # peeking twice: same answer, nothing kept
            assert a.step(x, t_ns) == peeked == b.step(x, t_ns)


@settings(max_examples=50, deadline=None)
@given(tau=st.floats(0.005, 2.0), gaps=st.lists(st.integers(1, 50_000_000), min_size=1, max_size=60))
def test_exponential_step_response_is_exact_at_any_spacing(tau, gaps):
    f = Exponential(tau)
    t0 = 7_000_000
    assert f.step(0.0, t0) == 0.0
    t = t0
    for gap in gaps:
        t += gap
        y = f.step(1.0, t)
        assert y == pytest.approx(1.0 - math.exp(-(t - t0) * 1e-9 / tau), abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(rate=st.floats(0.1, 100.0),
       steps=st.lists(st.tuples(st.integers(1, 30_000_000), st.floats(-2.0, 2.0)), min_size=2, max_size=80))
def test_rate_limit_bounds_the_slope_and_reaches_what_it_can(rate, steps):
    f = RateLimit(rate)
    t = 1_000_000_000
    y_prev = f.step(steps[0][1], t)
    for gap, x in steps[1:]:
        t += gap
        y = f.step(x, t)
        allowed = rate * gap * 1e-9
        assert abs(y - y_prev) <= allowed + 1e-12
        if abs(x - y_prev) <= allowed:
            assert y == x
        else:
            assert abs(y - y_prev) == pytest.approx(allowed, abs=1e-12)
        y_prev = y


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError):
        OneEuro(0.0)
    with pytest.raises(ValueError):
        OneEuro(1.0, -1.0)
    with pytest.raises(ValueError):
        Exponential(0.0)
    with pytest.raises(ValueError):
        RateLimit(-1.0)
