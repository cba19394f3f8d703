"""Time-driven smoothing for live channels: the One Euro filter, an exponential filter, a rate limit.

Every filter is driven by the samples' own timestamps (``t_ns``, ``time.monotonic_ns()``), never
by an assumed sampling rate, so irregular and bursty input is filtered as it really arrived.

* ``OneEuro`` -- the 1€ filter of Casiez, Roussel and Vogel ("1€ Filter: A Simple Speed-based
  Low-pass Filter for Noisy Input in Interactive Systems", CHI 2012), as the paper's pseudocode
  gives it: a first-order low-pass filter whose cutoff rises with the (low-pass filtered) speed,
  ``cutoff = min_cutoff + beta * |dx|``, with ``alpha = 1 / (1 + tau / te)``,
  ``tau = 1 / (2 pi cutoff)`` and ``te`` the time since the previous sample. The speed is taken
  against the previous *filtered* value (the paper's ``xfilt.hatxprev()``; the authors' later
  reference code uses the previous raw value instead). The first sample passes through, with
  speed 0.
* ``Exponential`` -- ``y += (1 - exp(-te / tau)) * (x - y)``: the exact discretisation of
  ``tau dy/dt = x - y`` for an input held between samples, so a step reaches ``1 - exp(-t / tau)``
  at time ``t`` whatever the sample spacing.
* ``RateLimit`` -- the output moves toward the input by at most ``rate * te``.

Readings of one device read are stamped together, so a reading stamped at the same instant as the
previous one supersedes it: the filter redoes its last step with the newer value (otherwise a
batch would leave the filter on its oldest reading). A reading stamped before the previous one
is ignored: time never goes back.

``step(x, t_ns)`` filters one sample and keeps the state. ``peek(x, t_ns)`` says what ``step``
would return, without changing anything: a face drawn between the samples of an event-driven
device (MIDI, HID reports on change) still settles while the input is held.
"""

from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi
NS = 1e-9


class _TimedFilter:
    """What every filter here shares: a state advanced by timestamped readings (``_next``).

    ``_state`` is a tuple whose first item is the output. A reading older than the last is
    ignored; one of the same instant supersedes the last (the step is redone from the state
    before it); the very first passes through.
    """

    __slots__ = ("_t", "_state", "_before")

    def reset(self) -> None:
        self._t: int | None = None
        self._state: tuple[float, ...] = (0.0,)
        self._before: tuple[int, tuple[float, ...]] | None = None  # (t, state) before the last step

    def _initial(self, x: float) -> tuple[float, ...]:
        return (x,)

    def _next(self, x: float, t_ns: int) -> tuple[float, ...]:
        """The state after reading ``x`` at ``t_ns`` (> the last reading's time)."""
        raise NotImplementedError

    def step(self, x: float, t_ns: int) -> float:
        if self._t is not None and t_ns < self._t:
            return self._state[0]
        if self._t is not None and t_ns == self._t:  # a newer reading of the same instant
            if self._before is None:
                self._t = None
            else:
                self._t, self._state = self._before
        if self._t is None:
            self._t, self._state, self._before = t_ns, self._initial(x), None
            return x
        self._before = (self._t, self._state)
        self._state, self._t = self._next(x, t_ns), t_ns
        return self._state[0]

    def snapshot(self) -> list:
        """The filter's state as JSON-able data (floats kept exact), for ``restore``."""
        before = None if self._before is None else [self._before[0], list(self._before[1])]
        return [self._t, list(self._state), before]

    def restore(self, data: list) -> None:
        t, state, before = data
        self._t, self._state = t, tuple(state)
        self._before = None if before is None else (before[0], tuple(before[1]))

    def peek(self, x: float, t_ns: int) -> float:
        if self._t is None or t_ns <= self._t:
            return x if self._t is None else self._state[0]
        return self._next(x, t_ns)[0]


class OneEuro(_TimedFilter):
    """The 1€ filter; ``min_cutoff`` and ``d_cutoff`` in Hz, ``beta`` in 1 / (units per second).

    Its state is (previous output -- the paper's hatxprev --, previous filtered speed).
    """

    __slots__ = ("min_cutoff", "beta", "d_cutoff")

    def __init__(self, min_cutoff: float = 1.0, beta: float = 0.0, d_cutoff: float = 1.0) -> None:
        if min_cutoff <= 0 or d_cutoff <= 0 or beta < 0:
            raise ValueError("One Euro filter: min_cutoff and d_cutoff must be > 0 and beta >= 0")
        self.min_cutoff, self.beta, self.d_cutoff = float(min_cutoff), float(beta), float(d_cutoff)
        self.reset()

    def _initial(self, x: float) -> tuple[float, ...]:
        return (x, 0.0)

    def _next(self, x: float, t_ns: int) -> tuple[float, ...]:
        previous, speed = self._state
        te = (t_ns - self._t) * NS
        r = TWO_PI * self.d_cutoff * te          # alpha = 1 / (1 + tau / te) = r / (1 + r)
        a = r / (1.0 + r)
        dx = a * ((x - previous) / te) + (1.0 - a) * speed
        r = TWO_PI * (self.min_cutoff + self.beta * abs(dx)) * te
        a = r / (1.0 + r)
        return (a * x + (1.0 - a) * previous, dx)


class Exponential(_TimedFilter):
    """First-order low-pass filter with time constant ``tau`` seconds."""

    __slots__ = ("tau",)

    def __init__(self, tau: float) -> None:
        if tau <= 0:
            raise ValueError("exponential filter: tau must be > 0 seconds")
        self.tau = float(tau)
        self.reset()

    def _next(self, x: float, t_ns: int) -> tuple[float, ...]:
        y = self._state[0]
        te = (t_ns - self._t) * NS
        return (y + (1.0 - math.exp(-te / self.tau)) * (x - y),)


class RateLimit(_TimedFilter):
    """The output follows the input at most ``rate`` units per second."""

    __slots__ = ("rate",)

    def __init__(self, rate: float) -> None:
        if rate <= 0:
            raise ValueError("rate limit must be > 0 units per second")
        self.rate = float(rate)
        self.reset()

    def _next(self, x: float, t_ns: int) -> tuple[float, ...]:
        y = self._state[0]
        step = self.rate * (t_ns - self._t) * NS
        d = x - y
        return (y + step if d > step else y - step if d < -step else x,)
