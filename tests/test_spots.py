import numpy as np
import pytest

from greenloop.methods.dictionary import spots


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


def _revisit_gt(n_ref=6, n=10):
    """Frames n_ref.. revisit frames 0.. in order: frame n_ref + k is a loop with frame k."""
    gt = np.zeros((n, n), bool)
    for k in range(n - n_ref):
        gt[k, n_ref + k] = gt[n_ref + k, k] = True
    return gt


def test_first_revisit_and_targets():
    gt = _revisit_gt()
    assert spots.first_revisit(gt) == 6
    labels = spots.group(6, 3)                       # spots [0 0 0 1 1 1]
    gt[9, 4] = gt[4, 9] = True                        # frame 9 revisits frames 3 and 4 (spot 1)
    queries, ok = spots.revisit_targets(labels, gt, 6)
    assert queries.tolist() == [6, 7, 8, 9]
    assert ok.tolist() == [[True, False], [True, False], [True, False], [False, True]]
    with pytest.raises(ValueError, match="never revisits"):
        spots.first_revisit(np.zeros((4, 4), bool))
    with pytest.raises(ValueError, match="n_reference"):
        spots.revisit_targets(labels, gt, 10)
    with pytest.raises(ValueError, match="does not revisit"):
        late_only = np.zeros((10, 10), bool)
        late_only[4, 8] = late_only[8, 4] = True    # a loop, but not with frames 0..2
        spots.revisit_targets(spots.group(3, 3), late_only, 3)
