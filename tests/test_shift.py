import numpy as np
import pytest

from greenloop import shift


def test_shift_right_zero_fills_left_column():
    X = np.arange(1, 17, dtype=np.float32).reshape(1, 4, 4, 1)
    Y = shift.shift(X, dx=1)
    assert (Y[0, :, 0, 0] == 0).all()
    assert (Y[0, :, 1:, 0] == X[0, :, :-1, 0]).all()
    assert Y.shape == X.shape and Y.dtype == X.dtype


def test_shift_directions_and_large():
    X = np.random.default_rng(0).random((2, 5, 6, 3)).astype(np.float32)
    up = shift.shift(X, dx=0, dy=-2)
    assert (up[:, :3] == X[:, 2:]).all() and (up[:, 3:] == 0).all()
    left = shift.shift(X, dx=-1)
    assert (left[:, :, :5] == X[:, :, 1:]).all() and (left[:, :, 5] == 0).all()
    assert (shift.shift(X, dx=6) == 0).all()
    assert (shift.shift(X, 0, 0) == X).all()


def test_changed_pixels_counts_more_than_a_column():
    X = np.random.default_rng(0).random((3, 32, 32, 1)).astype(np.float32)
    n = shift.changed_pixels(X, shift.shift(X, dx=1))
    assert (n > 32 * 30).all()  # nearly all 1024 pixels change, not "32"
    flat = np.ones((1, 32, 32, 1), np.float32)
    assert shift.changed_pixels(flat, shift.shift(flat, dx=1))[0] == 32


def test_rotate_and_errors():
    X = np.zeros((1, 9, 9, 1), np.float32)
    X[0, 4, 4] = 1
    assert shift.rotate(X, 30)[0, 4, 4, 0] == pytest.approx(1, abs=1e-3)
    with pytest.raises(ValueError):
        shift.shift(np.zeros((4, 4)), 1)
