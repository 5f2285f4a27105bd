"""greenloop-seq's candidate mode (``seqstream.Detector(index=...)``) with the named configuration:
its calibration, repeat gate, cell shift and reverse velocities, against the exact scan
(``index=None``), on small streams the tests make (tests/test_seqspeed.py's route: a random-walk
route, then a revisit driven backwards and one with a 30-frame stop)."""
import math

import numpy as np
import pytest

from greenloop.methods.greenloop_seq import candidates, seqmatch, seqstream
from tests.test_seqspeed import D, DEFAULT, EXCLUDE, N0, REVISIT, _detect, _drive, make_route, replay


def _stream(det, X, start=0):
    """Feed X[start:] to det: per frame (best match, its score, candidate count c) and the events."""
    out = []
    for j in range(start, len(X)):
        det.update_descriptor(X[j])
        out.append((*seqstream.best_candidate(det), j - det.exclude))
    return np.array(out), [(e["frame"], e["match"]) for e in det.events]


@pytest.fixture(scope="module")
def reverse_and_stop():
    """The route, a revisit driven the other way, then one with a 30-frame stop: (829, D)."""
    w, r = make_route()
    return np.concatenate([w, r[replay("reverse")], r[replay("stop")]]).astype(np.float32)


@pytest.mark.parametrize("kind", ["scan", "hnsw"])
def test_every_row_a_candidate_equals_the_exact_scan(reverse_and_stop, kind):
    """k >= the number stored: candidate mode scores every stored row, with the reference's pads and
    null, so its best matches, scores and events are the exact scan's (float rounding aside), on a
    stream whose revisits need the reverse velocities, the repeat gate (the stop), the cell shift and
    the calibration. The revisits close loops at their places."""
    X = reverse_and_stop
    ref, ref_events = _stream(seqstream.Detector(seqmatch.DEFAULT_THRESHOLD, exclude=EXCLUDE, **DEFAULT), X)
    det = seqstream.Detector(seqmatch.DEFAULT_THRESHOLD, exclude=EXCLUDE, index=kind, k=len(X), **DEFAULT)
    got, events = _stream(det, X)
    has = ref[:, 2] > 0
    assert np.array_equal(got[has, 0], ref[has, 0])
    np.testing.assert_allclose(got[has, 1], ref[has, 1], rtol=0, atol=1e-4)
    assert events == ref_events and len(events) > 300
    back = [m for f, m in events if N0 <= f < N0 + REVISIT]          # the reversed revisit: place 199 - k
    assert len(back) > 150 and all(abs(m - (N0 + REVISIT - 1 - f)) <= 2 for f, m in events if N0 + 20 <= f < N0 + REVISIT)


def test_candidate_mode_finds_the_reverse_revisit_and_the_stop(reverse_and_stop):
    """With k = 10 rows retrieved per shifted query (HNSW on a 64-d PCA of the stored rows fitted on
    the first 300 candidate rows): the exact scan's best match (within +-2 frames) on >= 95 % of the
    revisit frames, and its events on >= 97 % of all frames (both declare or both stay silent)."""
    X = reverse_and_stop
    ref, ref_events = _stream(seqstream.Detector(seqmatch.DEFAULT_THRESHOLD, exclude=EXCLUDE, **DEFAULT), X)
    det = seqstream.Detector(seqmatch.DEFAULT_THRESHOLD, exclude=EXCLUDE, index="hnsw", k=10, index_dim=64,
                             index_fit=300, **DEFAULT)
    got, events = _stream(det, X)
    rev = np.arange(len(X)) >= N0 + 20
    assert np.mean(np.abs(got[rev, 0] - ref[rev, 0]) <= 2) >= 0.95
    fired = np.zeros((2, len(X)), bool)
    fired[0, [f for f, _ in ref_events]], fired[1, [f for f, _ in events]] = True, True
    assert np.mean(fired[0] == fired[1]) >= 0.97 and len(events) > 300


def _iid_stream(n_unrelated: int, seed: int = 3):
    """n_unrelated frames of unrelated places, a 250-place route, then its first 100 places again
    seen through noise (std 3, thrice the places' own): (n + 350, D), every place i.i.d."""
    rng = np.random.default_rng(seed)
    route = rng.normal(size=(250, D))
    revisit = route[:100] + rng.normal(scale=3.0, size=(100, D))
    return np.concatenate([np.random.default_rng(20).normal(size=(n_unrelated, D)), route, revisit]).astype(np.float32)


def test_calibration_does_not_depend_on_the_number_stored():
    """The same 80 revisit queries (the last 80 frames) after 500 and after 5000 unrelated stored
    frames (every place i.i.d., so the exact scan's null is the same distribution at both sizes):
    candidate mode's calibrated best score stays on the exact scan's scale at both, the median over
    the queries within 0.5 of the exact scan's, and it moves with the number stored as the exact
    scan's does (the expected-maximum term sqrt(2 ln C) grows with C in both) within 0.5 too.
    The tolerance: the null's 128 sampled rows estimate its spread to a relative standard error of
    1 / sqrt(2 x 128) = 6 % per query, about 1.3 at these queries' z-scores (about 21), and the median
    over 80 queries scored against a rotating part of the sample carries a fraction of it (0.25
    measured). Taking C as the rows scored (about 100) instead of the query's candidate count would
    be 0.6 off at 500 and 1.2 at 5000; a null of the retrieved rows alone, several units."""
    med = {}
    for n in (500, 5000):
        X = _iid_stream(n)
        for kind in (None, "flat"):
            det = seqstream.Detector(None, exclude=50, index=kind, k=10, index_dim=64, **DEFAULT)
            det.preload(X[:n])
            got, _ = _stream(det, X, start=n)
            q = got[-80:]
            assert np.mean(np.abs(q[:, 0] - (np.arange(len(X) - 80, len(X)) - 250)) <= 2) >= 0.95   # at its place
            med[n, kind] = float(np.median(q[:, 1]))
    for n in (500, 5000):
        assert abs(med[n, "flat"] - med[n, None]) <= 0.5, med
    assert abs((med[5000, "flat"] - med[500, "flat"]) - (med[5000, None] - med[500, None])) <= 0.5, med
    assert med[5000, None] > 15                       # the revisit is clear at both sizes


def test_candidate_mode_is_silent_on_a_drive_without_a_revisit(tmp_path):
    """`detect --index hnsw` (the named default, its calibration and fixed threshold, no --threshold):
    silent on a 500-frame drive that never comes back, closing loops at their places on the same
    drive when its last 150 frames revisit places 0..149 (as the exact scan does, test_seqspeed)."""
    assert _detect(_drive(tmp_path / "once", range(500)), "--index", "hnsw") == []
    rows = _detect(_drive(tmp_path / "back", list(range(350)) + list(range(150))), "--index", "hnsw")
    assert len(rows) >= 75
    assert all(int(r[0]) >= 350 and abs(int(r[1]) - (int(r[0]) - 350)) <= 2 for r in rows)


def test_preload_then_stream_equals_the_stream(reverse_and_stop):
    """The named configuration in candidate mode (IVF on a 64-d PCA): the first 600 frames
    preloaded, the rest streamed, gives the uninterrupted stream's candidates, scores and events."""
    X = reverse_and_stop
    kw = dict(exclude=EXCLUDE, index="ivf", k=10, index_dim=64, index_fit=200,
              index_options={"nlist": 8, "nprobe": 2, "train_size": 300}, **DEFAULT)
    full, head = (seqstream.Detector(seqmatch.DEFAULT_THRESHOLD, **kw) for _ in range(2))
    streamed = [(full.update_descriptor(x), full.last_candidates.copy(), full.last_scores.copy())[1:] for x in X]
    head.preload(X[:600])
    assert head.frame_index == 600 and head.events == [] and head._index.n_stored == 600 - 1 - EXCLUDE
    got = [(head.update_descriptor(x), head.last_candidates.copy(), head.last_scores.copy())[1:] for x in X[600:]]
    for (c0, s0), (c1, s1) in zip(streamed[600:], got):
        assert np.array_equal(c0, c1) and np.array_equal(s0, s1)
    assert head.events == [e for e in full.events if e["frame"] >= 600] and len(head.events) > 50


def test_memory_per_stored_frame():
    """bytes_per_frame in candidate mode: the stored row (the centred descriptor, two windows joined:
    512 float32) plus the index's bytes per row (64 dims); the exact scan: the row plus its columns."""
    X = _iid_stream(1200)[:1300]
    det = seqstream.Detector(None, exclude=50, index="flat", k=10, index_dim=64, **DEFAULT)
    det.preload(X)
    assert det._index.n_stored == 1300 - 51 and det.bytes_per_frame == 2 * D * 4 + 64 * 4
    ref = seqstream.Detector(None, exclude=50, **DEFAULT)
    ref.preload(X[:200])
    assert ref.bytes_per_frame == 2 * D * 4 + 4 * DEFAULT["seq_len"]


def test_reservoir_is_uniform_and_the_same_in_any_batches():
    one = np.full(64, -1, np.int64)
    for r in range(3000):
        candidates.reservoir(one, r, r + 1)
    batched = candidates.reservoir(candidates.reservoir(np.full(64, -1, np.int64), 0, 1700), 1700, 3000)
    assert np.array_equal(one, batched) and len(set(one)) == 64 and one.max() < 3000
    counts = np.zeros(1000)
    for seed in range(200):
        counts[candidates.reservoir(np.full(50, -1, np.int64), 0, 1000, seed)] += 1
    assert counts.sum() == 200 * 50
    assert abs(counts[:500].mean() - counts[500:].mean()) < 1.5       # 10 per row either half (+- 0.2 sd)


def test_calibrate_sampled_is_the_exact_calibration_with_every_row_known():
    rng = np.random.default_rng(0)
    s = rng.normal(size=400)
    s[123] = 9.0
    rows = np.arange(400)
    for method in seqmatch.CALIBRATIONS:
        exact = seqmatch.calibrate_scores(s, method)
        got = seqmatch.calibrate_sampled(s, rows, np.ones(400, bool), np.zeros(400, bool), 400, method)
        np.testing.assert_allclose(got, exact, rtol=0, atol=1e-5)
    # the known rows 100..199 and a sample of 50 of the others: unbiased, C = 400 as exact
    pick = np.r_[np.arange(100, 200), rng.choice(np.r_[0:100, 200:400], 50, replace=False)]
    pick.sort()
    known = (pick >= 100) & (pick < 200)
    got = seqmatch.calibrate_sampled(s[pick], pick, known, ~known, 400)
    exact = seqmatch.calibrate_scores(s)
    assert abs(got[np.searchsorted(pick, 123)] - exact[123]) < 1.5
    assert abs(got[np.searchsorted(pick, 123)] + math.sqrt(2 * math.log(400)) - 9.0) < 3
