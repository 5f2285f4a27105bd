"""The one clock: every wall time greenloop reports or prints is read by :func:`timed`
(``time.perf_counter``): the measuring layer (``greenloop.speed``: the timing definition, the
benchmarks) and a user's ``detect`` run (its frames/s) alike."""
from __future__ import annotations

import time


def timed(fn, *args):
    """One call ``fn(*args)`` on the wall clock (``time.perf_counter``).
    Returns (its result, seconds)."""
    t0 = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0
