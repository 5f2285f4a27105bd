import cv2
import numpy as np
import pytest

from greenloop.datasets import sequence
from greenloop.methods.dictionary import shift


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


def test_replicate_border_copies_the_edge():
    X = np.arange(1, 17, dtype=np.float32).reshape(1, 4, 4, 1)   # rows 1-4, 5-8, 9-12, 13-16
    right = shift.shift(X, dx=1, border="replicate")[0, ..., 0]
    assert right[0].tolist() == [1, 1, 2, 3]                       # column 0 copied into column 1
    assert (right[:, 0] == X[0, :, 0, 0]).all() and (right[:, 1] == X[0, :, 0, 0]).all()
    up = shift.shift(X, dy=-1, dx=0, border="replicate")[0, ..., 0]
    assert up[:, 0].tolist() == [5, 9, 13, 13]                     # the bottom row repeated
    two = shift.shift(X, dx=-2, dy=1, border="replicate")[0, ..., 0]
    assert two.tolist() == [[3, 4, 4, 4], [3, 4, 4, 4], [7, 8, 8, 8], [11, 12, 12, 12]]
    assert (shift.shift(X, dx=9, border="replicate")[0, ..., 0] == X[0, :, :1, 0]).all()  # all edge
    Y = shift.shift(X.astype(np.uint8), dx=1, border="replicate")
    assert Y.dtype == np.uint8 and Y.shape == X.shape
    with pytest.raises(ValueError):
        shift.shift(X, 1, border="wrap")


def test_pixel_change_counts_and_mean_abs():
    X = np.zeros((1, 2, 2, 1), np.float32)
    Y = X.copy()
    Y[0, 0, 0], Y[0, 1, 1] = 1.0, 0.5
    n, m = shift.pixel_change(X, Y)
    assert n.tolist() == [2] and m[0] == pytest.approx(0.375)       # (1 + 0.5) / 4 pixels
    C = np.zeros((1, 1, 2, 3), np.float32)
    D = C.copy()
    D[0, 0, 0, 1] = 0.3                                              # one channel of one pixel
    n, m = shift.pixel_change(C, D)
    assert n.tolist() == [1] and m[0] == pytest.approx(0.3 / 6)
    assert shift.pixel_change(X, Y, atol=0.6)[0].tolist() == [1]
    with pytest.raises(ValueError):
        shift.pixel_change(X, C)


def test_pixel_change_of_a_one_pixel_shift():
    flat = np.full((1, 32, 32, 1), 0.5, np.float32)
    n, m = shift.pixel_change(flat, shift.shift(flat, dx=1))
    assert n[0] == 32 and m[0] == pytest.approx(32 * 0.5 / 1024)      # only the black column
    assert [v[0] for v in shift.pixel_change(flat, shift.shift(flat, dx=1, border="replicate"))] == [0, 0]
    X = np.random.default_rng(0).random((3, 32, 32, 1)).astype(np.float32)
    n, m = shift.pixel_change(X, shift.shift(X, dx=1))
    assert (n > 32 * 30).all()  # nearly all 1024 pixels change, not "32"
    ramp = np.tile(np.arange(32, dtype=np.float32) / 31, (32, 1))[None, ..., None]
    n, m = shift.pixel_change(ramp, shift.shift(ramp, dx=1, border="replicate"))
    assert n[0] == 31 * 32 and m[0] == pytest.approx(31 * 32 * (1 / 31) / 1024)   # one grey step each


def test_full_resolution_offset():
    assert shift.full_resolution_offset((480, 640), 1, 1) == (20, 15)
    assert shift.full_resolution_offset((480, 640), -2, 0.5) == (-40, 8)      # 7.5 rounds to even
    assert shift.full_resolution_offset((120, 160), 0, 1) == (0, 4)           # 3.75 px -> 4


@pytest.fixture()
def frames_folder(tmp_path):
    """Four smooth 64x48 colour frames, downsampled 4x (to 16x12) exactly."""
    yy, xx = np.mgrid[0:48, 0:64]
    (tmp_path / "rgb").mkdir()
    for i in range(4):
        img = np.stack([(xx * 3 + yy * i) % 256, (yy * 5 + i * 40) % 256, (xx * yy) % 256], -1)
        cv2.imwrite(str(tmp_path / "rgb" / f"{i}.png"), img.astype(np.uint8))
    return tmp_path


def test_shift_before_downsampling_uses_the_cnn_preprocessing(frames_folder):
    X = sequence.load_frames(frames_folder, size=(16, 12))
    full = sequence.load_frames(frames_folder, size=None, dtype=np.uint8)
    assert full.shape == (4, 48, 64, 1)
    same = shift.shift_before_downsampling(full, 0, 0, size=(16, 12))
    assert same.dtype == np.float32 and np.array_equal(same, X)               # no shift: the CNN input
    # integer factors: shifting 4 full-res px then averaging 4x4 blocks = shifting 1 px after
    for dx, dy in ((1, 0), (0, -1), (-3, 2)):
        assert np.array_equal(shift.shift_before_downsampling(full, dx, dy, (16, 12)), shift.shift(X, dx, dy))
    rep = shift.shift_before_downsampling(full, 1, 0, (16, 12), border="replicate")
    edge = full[:, :, :1, 0].astype(np.float32).reshape(4, 12, 4).mean(-1) / 255   # full-res column 0
    assert np.allclose(rep[:, :, 0, 0], edge, atol=0.5 / 255 + 1e-6)
    assert np.array_equal(rep[:, :, 1:], X[:, :, :-1])
    with pytest.raises(ValueError):
        shift.shift_before_downsampling(full.astype(np.float32), 1)


def test_control_inputs(frames_folder):
    X = sequence.load_frames(frames_folder, size=(16, 12))
    full = sequence.load_frames(frames_folder, size=None, dtype=np.uint8)
    c = shift.control_inputs(X, full, dx=1)
    assert list(c) == list(shift.CONTROLS)
    assert all(v.shape == X.shape and v.dtype == np.float32 for v in c.values())
    assert np.array_equal(c["zero border (paper)"], c["full-res shift, zero border"])    # 4x factors
    assert (c["replicate border"][:, :, 0] == X[:, :, 0]).all()
    assert (c["zero border (paper)"][:, :, 0] == 0).all()
    with pytest.raises(ValueError):
        shift.control_inputs(X, full[:2])


def test_rotate_and_errors():
    X = np.zeros((1, 9, 9, 1), np.float32)
    X[0, 4, 4] = 1
    assert shift.rotate(X, 30)[0, 4, 4, 0] == pytest.approx(1, abs=1e-3)
    with pytest.raises(ValueError):
        shift.shift(np.zeros((4, 4)), 1)
