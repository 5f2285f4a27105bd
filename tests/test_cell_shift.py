"""greenloop-seq's cell shift (``seqmatch.shift_cells``, the Detector's ``cell_shift``): the
query's gradient grid moved one cell column sideways finds a revisit seen from a little to the
side, on a small sequence the test makes; the stream equals its score matrix; what it refuses."""
import numpy as np
import pytest

from greenloop import evaluate, similarity
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.util import numba_kernels

ROWS, COLS, BINS = seqmatch.CELL_GRID
D = ROWS * COLS * BINS
N0, REV, EX = 300, 150, 40
KNOBS = {k: v for k, v in seqmatch.DEFAULT_KNOBS.items() if k != "descriptor"}


def _cells(X):
    """Gradient-like rows: non-negative, each cell's histogram L2-normalised."""
    H = np.abs(X).reshape(len(X), ROWS, COLS, BINS)
    return (H / np.linalg.norm(H, axis=3, keepdims=True)).reshape(len(X), D).astype(np.float32)


@pytest.fixture(scope="module")
def sideways():
    """A route of N0 places (a smooth walk plus each place's detail), then its first REV places
    seen one cell column to the side: each frame's cells moved right by one, the column coming into
    view new, plus noise. Returns (X, GT +-2 places, revisit queries)."""
    rng = np.random.default_rng(0)
    walk = np.cumsum(rng.normal(size=(N0, D)), 0) * 0.15 + rng.normal(size=(N0, D))
    route = _cells(walk)
    seen = seqmatch.shift_cells(route[:REV], 1).reshape(REV, ROWS, COLS, BINS)
    seen[:, :, 0] = _cells(rng.normal(size=(REV, D))).reshape(REV, ROWS, COLS, BINS)[:, :, 0]
    X = np.concatenate([route, _cells(seen.reshape(REV, D) + rng.normal(scale=0.15, size=(REV, D)))])
    n = len(X)
    GT = np.zeros((n, n), bool)
    for k in range(REV):
        GT[max(k - 2, 0):k + 3, N0 + k] = True
    return X, GT | GT.T, np.arange(n) >= N0


def _r1(s, **knobs):
    X, GT, q = s
    return evaluate.per_query(seqstream.score_matrix(X, EX, **knobs), GT, EX, queries=q)["R@1"]


def test_shift_cells_by_hand():
    X = np.arange(2 * D, dtype=np.float32).reshape(1, 2 * D) + 1     # two joined parts, every value distinct
    H = X.reshape(2, ROWS, COLS, BINS)
    right = seqmatch.shift_cells(X, 1).reshape(2, ROWS, COLS, BINS)
    np.testing.assert_array_equal(right[:, :, 1:], H[:, :, :-1])     # each part's cells one column right
    assert not right[:, :, 0].any()                                   # the column moved in is empty
    left = seqmatch.shift_cells(X, -2).reshape(2, ROWS, COLS, BINS)
    np.testing.assert_array_equal(left[:, :, :-2], H[:, :, 2:])
    assert not left[:, :, -2:].any()
    np.testing.assert_array_equal(seqmatch.shift_cells(X, 0), X)
    W = np.random.default_rng(1).normal(size=(30, D)).astype(np.float32)   # shifting commutes with centring
    np.testing.assert_allclose(seqmatch.center(seqmatch.shift_cells(W, 1), 5),
                               seqmatch.shift_cells(seqmatch.center(W, 5), 1), atol=1e-6)
    assert seqmatch.cell_shifts(0) == (0,) and seqmatch.cell_shifts(2) == (0, -2, -1, 1, 2)
    for bad in (-1, COLS, 1.5, True):
        with pytest.raises(ValueError, match="cell_shift"):
            seqmatch.cell_shifts(bad)
    with pytest.raises(ValueError, match="gradients"):
        seqmatch.shift_cells(np.zeros((2, 100), np.float32), 1)


def test_a_revisit_seen_one_cell_to_the_side_is_found(sideways):
    """The named default's knobs with cell_shift 1 find the sideways revisit; without the shift
    the same knobs mostly do not (the check can fail)."""
    with_shift, without = _r1(sideways, **KNOBS), _r1(sideways, **dict(KNOBS, cell_shift=0))
    assert with_shift >= 0.9 and without <= with_shift - 0.3, (with_shift, without)


@pytest.mark.parametrize("compiled", [True, False])
def test_stream_equals_matrix_with_cell_shift(sideways, compiled, monkeypatch):
    """The streaming Detector (compiled one-pass product, or the BLAS products without numba)
    declares where its score matrix reaches the threshold, and its columns are the matrix's."""
    if not compiled:
        monkeypatch.setattr(numba_kernels, "available", lambda: False)
    X, _, _ = sideways
    S = seqstream.score_matrix(X, EX, **KNOBS)
    det = seqstream.Detector(seqmatch.DEFAULT_THRESHOLD, exclude=EX, **KNOBS)
    for j, x in enumerate(X):
        det.update_descriptor(x)
        if j in (EX + 3, N0 + 20, len(X) - 1):
            np.testing.assert_allclose(det.last_scores, S[:j - EX, j], rtol=1e-4, atol=1e-4)
    assert len(det.events) > REV // 2 and seqstream.stream_matches_matrix(det, S)
    assert det.bytes_per_frame == 2 * D * 4 + 4 * KNOBS["seq_len"]    # the stored frames are not shifted


def test_cell_shift_refuses_what_it_cannot_shift():
    with pytest.raises(ValueError, match="gradients"):
        seqstream.Detector(None, exclude=5, cell_shift=1).update_descriptor(np.ones(32, np.float32))
    proj = seqmatch.fit_projection(np.random.default_rng(0).normal(size=(50, D)), dim=8)
    with pytest.raises(ValueError, match="projection"):
        seqstream.Detector(None, cell_shift=1, projection=proj)
    with pytest.raises(ValueError, match="gradients"):        # candidate mode shifts as the exact scan does
        seqstream.Detector(None, exclude=5, cell_shift=1, index="flat").update_descriptor(np.ones(32, np.float32))
    assert isinstance(proj, similarity.Projection)
