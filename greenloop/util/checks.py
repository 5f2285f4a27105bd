"""Argument checks shared by every stage: one rule and one message form for integer arguments.

NumPy only, no greenloop import.
"""
from __future__ import annotations

import numpy as np


def positive_int(name: str, value, minimum: int = 1, maximum: int | None = None, unit: str = "",
                 whole_floats: bool = False) -> int:
    """``value`` as an int within [minimum, maximum], or ValueError naming ``name``.

    name: the argument's name as the caller knows it (e.g. "exclude", "--step").
    unit: an optional note appended in parentheses, e.g. "frames" -> "... >= 0 (frames), got 3.5".
    whole_floats: also accept floats that hold a whole number (3.0); by default only int and
        NumPy integer types pass. bool never passes (True is not a count).
    Returns int(value).
    """
    ok = not isinstance(value, bool) and (
        isinstance(value, (int, np.integer))
        or (whole_floats and isinstance(value, (float, np.floating)) and float(value).is_integer()))
    if ok:
        ok = value >= minimum and (maximum is None or value <= maximum)
    if not ok:
        rng = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        note = f" ({unit})" if unit else ""
        raise ValueError(f"{name} must be an integer {rng}{note}, got {value!r}")
    return int(value)
