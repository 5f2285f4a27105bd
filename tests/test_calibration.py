"""seqmatch.calibrate_scores' two methods (one threshold for 60-frame and 10^6-frame recordings): "zscore" against every candidate,
"neighbourhood" against the candidates away from the best one, the named configurations'. What the
second claims: the unit of a calibrated score is an unrelated candidate's spread, however many frames
are stored; the stream still equals its score matrix."""
import math

import numpy as np
import pytest

from greenloop.methods.greenloop_seq import seqmatch, seqstream


def test_neighbourhood_by_hand():
    """The best candidate and its NEIGHBOURHOOD rows either side leave the null; what remains sets the
    mean and std. With fewer than NULL_MIN rows left, every candidate does, as "zscore"."""
    assert seqmatch.NEIGHBOURHOOD == 2 and seqmatch.NULL_MIN == 30
    null = np.tile([1.0, -1.0], 20)                       # 40 rows: mean 0, population std 1
    s = np.concatenate([null[:20], [2.0, 3.0, 9.0, 3.0, 2.0], null[20:]])   # the matched place, best at row 22
    expected = s - math.sqrt(2 * math.log(len(s)))        # (s - 0) / 1 - sqrt(2 ln C), C = 45 candidates
    np.testing.assert_allclose(seqmatch.calibrate_scores(s, "neighbourhood"), expected, rtol=1e-6)
    z = seqmatch.calibrate_scores(s, "zscore")            # the hump in the std: the same best, lower
    assert z.argmax() == 22 and z[22] < expected[22] - 3
    few = np.concatenate([null[:10], [2.0, 3.0, 9.0, 3.0, 2.0], null[10:20]])   # 20 rows left < NULL_MIN
    np.testing.assert_array_equal(seqmatch.calibrate_scores(few, "neighbourhood"), seqmatch.calibrate_scores(few))
    assert not seqmatch.calibrate_scores(np.ones(50), "neighbourhood").any()
    assert seqmatch.calibrate_scores([3.0], "neighbourhood").tolist() == [0.0]
    with pytest.raises(ValueError, match="method must be one of"):
        seqmatch.calibrate_scores(s, "robust")


def _best_z(C: int, method: str, seeds: int = 200) -> float:
    """Mean over seeds of the matched place's z-score (the calibrated score plus sqrt(2 ln C)) among C
    candidates: unrelated ones N(0, 1), the place and its two neighbours either side a hump peaking at 6."""
    out = []
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        s = rng.normal(size=C)
        i = int(rng.integers(10, C - 10))
        s[i - 2:i + 3] = [3.0, 5.0, 6.0, 5.0, 3.0]
        out.append(float(seqmatch.calibrate_scores(s, method)[i]) + math.sqrt(2 * math.log(C)))
    return float(np.mean(out))


def test_the_unit_does_not_depend_on_how_many_frames_are_stored():
    """Adding unrelated candidates (40 -> 2000) leaves the matched place's neighbourhood z within 0.5 of
    6, its height over the null in the null's units (0.5: a std from 35 values runs low); the zscore's
    rises from about 3 to about 6, as the matched rows' share of the candidates, and so of the std,
    shrinks: why a short recording's revisit stayed under the threshold a long one's clears."""
    zs = {C: _best_z(C, "neighbourhood") for C in (40, 100, 400, 2000)}
    assert max(zs.values()) - min(zs.values()) <= 0.5 and all(abs(z - 6.0) <= 0.5 for z in zs.values()), zs
    old = {C: _best_z(C, "zscore") for C in (40, 2000)}
    assert old[2000] - old[40] > 2.0, old


def test_calibrate_knob():
    assert seqmatch.check_calibration(True) == "zscore" and seqmatch.check_calibration(False) is False
    assert seqmatch.check_calibration("neighbourhood") == "neighbourhood"
    assert seqmatch.DEFAULT_KNOBS["calibrate"] == seqmatch.CNN_KNOBS["calibrate"] == "neighbourhood"
    with pytest.raises(ValueError, match="calibrate must be"):
        seqstream.Detector(None, calibrate="median")


@pytest.mark.parametrize("method", [True, "zscore", "neighbourhood"])
def test_stream_equals_matrix_under_each_calibration(method):
    """A revisit of a random-walk route: the Detector's last_scores are the score matrix's columns and
    its events fall where the matrix reaches the threshold, whichever calibration."""
    rng = np.random.default_rng(3)
    w = np.cumsum(rng.normal(size=(150, 64)), 0) * 0.3 + rng.normal(size=(150, 64))
    X = np.concatenate([w, w[:60] + rng.normal(scale=0.8, size=(60, 64))]).astype(np.float32)
    knobs = dict(seq_len=5, contrast_window=0, center_window=10, calibrate=method)
    S = seqstream.score_matrix(X, 30, **knobs)
    det = seqstream.Detector(2.0, exclude=30, **knobs)
    for x in X:
        det.update_descriptor(x)
    np.testing.assert_allclose(det.last_scores, S[:len(X) - 1 - 30, -1], rtol=1e-4, atol=1e-4)
    assert len(det.events) > 10 and seqstream.stream_matches_matrix(det, S)
