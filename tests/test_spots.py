import numpy as np
import pytest

from greenloop import spots


@pytest.mark.parametrize("L, k, last", [(50, 46, 10), (60, 38, 40), (70, 33, 20)])
def test_paper_spot_counts(L, k, last):
    y = spots.group(2260, L)
    assert y.max() + 1 == k == spots.n_spots(2260, L)
    assert np.bincount(y)[-1] == last
    assert (np.diff(y) >= 0).all() and np.bincount(y)[0] == L


def test_reject_bad_frames_per_spot():
    for bad in (0, -3, 2.5):
        with pytest.raises(ValueError, match="frames_per_spot"):
            spots.group(100, bad)


def test_by_place_relabels_revisits():
    n = 100
    gt = np.zeros((n, n), bool)
    for k in range(10):  # frames 90..99 revisit frames 0..9
        gt[k, 90 + k] = gt[90 + k, k] = True
    y = spots.by_place(20, gt)
    assert (y[90:] == y[0]).all()
    assert y.max() + 1 == 5  # spot 4 (frames 80..99) keeps frames 80..89
    assert (y[:90] == spots.group(n, 20)[:90]).all()
