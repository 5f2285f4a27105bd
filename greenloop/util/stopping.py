"""The early-stopping rule every trainer shares: Keras's ``EarlyStopping`` as a function of a curve.

NumPy only, no greenloop import. The main paper's CNN applies it to its training accuracy
(``methods.dictionary.cnn``), the Siamese networks to -log of their training loss
(``methods.siamese.siamese.plateaued``); tests/test_cnn.py checks it against Keras's callback.
"""
from __future__ import annotations

import numpy as np


def stops_here(curve, patience: int, min_delta: float) -> bool:
    """Keras's ``EarlyStopping(mode="max", patience, min_delta)`` rule after the last epoch of
    ``curve`` (one value per epoch, higher is better, e.g. training accuracies as fractions): True
    when none of the last ``patience`` epochs beat the best before it by more than min_delta (the
    best counts only improvements larger than min_delta, as Keras's does)."""
    best, wait = -np.inf, 0
    for a in curve:
        wait += 1
        if a - min_delta > best:
            best, wait = a, 0
    return len(curve) > 1 and wait >= patience
