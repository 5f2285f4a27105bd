"""greenloop.methods.seqslam.seqslam: SeqSLAM at OpenSeqSLAM's parameters, causal, stream equal to its matrix."""
import math

import cv2
import numpy as np
import pytest

from greenloop import evaluate
from greenloop.datasets import sequence
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.methods.seqslam import seqslam, seqslam_stream

from conftest import write_frames

N0, REPEAT, EXCLUDE, DIM = 120, 60, 30, 64


def _walk(n, seed, a=0.9):
    rng = np.random.default_rng(seed)
    x = np.zeros((n, DIM), np.float32)
    x[0] = rng.normal(size=DIM)
    for t in range(1, n):
        x[t] = a * x[t - 1] + math.sqrt(1 - a * a) * rng.normal(size=DIM)
    return x


@pytest.fixture(scope="module")
def revisit():
    """N0 frames, then frames 0..REPEAT-1 again with noise; GT: |i - (j - N0)| <= 2."""
    w = _walk(N0, 0)
    X = np.concatenate([w, w[:REPEAT] + np.random.default_rng(1).normal(scale=0.8, size=(REPEAT, DIM))])
    n = len(X)
    GT = np.zeros((n, n), bool)
    for k in range(REPEAT):
        GT[max(k - 2, 0):k + 3, N0 + k] = True
    return X.astype(np.float32), GT | GT.T


def test_published_parameters():
    assert seqslam.SIZE == (64, 32) and seqslam.PATCH == 8 and seqslam.R_WINDOW == 10 and seqslam.DS == 10
    assert seqslam.velocities() == pytest.approx((0.8, 0.9, 1.0, 1.1, 1.2))
    off = seqslam.offsets()
    assert off.shape == (5, 11)
    assert off[0].tolist() == [0, 0, 1, 2, 3, 4, 4, 5, 6, 7, 8]          # floor(0.8 k)
    assert off[-1].tolist() == [0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 12]       # floor(1.2 k)
    assert seqslam_stream.Detector(None).seq_len == 11


def test_difference_similarity_by_hand():
    db = np.array([[0, 0], [1, 3]], np.float32)
    assert seqslam.difference_similarity(db, [1, 2]).tolist() == [-1.5, -0.5]
    X = np.array([[0, 0], [1, 3], [1, 2]], np.float32)
    S = seqslam.similarity_matrix(X)
    assert S[0, 2] == -1.5 and S[1, 2] == -0.5 and S[2, 2] == 0 and np.allclose(S, S.T)


def _reference(X, exclude, ds, window):
    """SeqSLAM written out loop by loop from its definition (the causal form of the module doc)."""
    n, D = len(X), seqslam.similarity_matrix(X)
    cols = []
    for j in range(n):
        s = D[:max(j - exclude, 0), j].astype(np.float64)
        z = np.zeros(len(s))
        for i in range(len(s)):
            w = s[max(i - window // 2, 0):min(i + window // 2 + 1, len(s))]
            z[i] = (s[i] - w.mean()) / w.std() if w.std() > 1e-6 else 0.0
        cols.append(z)
    S = np.full((n, n), np.nan)
    for j in range(n):
        for i in range(max(j - exclude, 0)):
            best = -np.inf
            for v in seqslam.velocities(ds):
                vals = []
                for k in range(ds + 1):
                    jj, ii = j - k, i - int(math.floor(v * k + 1e-9))
                    col = cols[jj] if jj >= 0 and len(cols[jj]) else cols[j]     # no column yet: the newest's mean
                    vals.append(col[ii] if jj >= 0 and len(cols[jj]) and 0 <= ii < len(col) else col.mean())
                best = max(best, np.mean(vals))
            S[i, j] = best
    return S


def test_score_matrix_is_the_definition_written_out():
    X = _walk(40, 3)
    S = seqslam_stream.score_matrix(X, exclude=8, ds=4, contrast_window=4)
    R = _reference(X, 8, 4, 4)
    m = np.isfinite(R)
    assert m.sum() > 300 and np.allclose(S[m], R[m], atol=1e-4)


def test_causal_future_frames_change_nothing(revisit):
    X, _ = revisit
    j = N0 + 20
    Y = X.copy()
    Y[j + 1:] = np.random.default_rng(9).normal(size=Y[j + 1:].shape)
    S, T = (seqslam_stream.score_matrix(Z, EXCLUDE) for Z in (X, Y))
    assert np.array_equal(S[:j - EXCLUDE, :j + 1], T[:j - EXCLUDE, :j + 1])
    assert not np.array_equal(S[:, j + 1:], T[:, j + 1:])


def test_stream_equals_matrix_over_the_revisit(revisit):
    X, GT = revisit
    S = seqslam_stream.score_matrix(X, EXCLUDE)
    rev = evaluate.best_matches(S, GT, EXCLUDE)
    thr = float(np.quantile(rev.score[rev.correct], 0.3))          # fires on most of the revisit
    det = seqslam_stream.Detector(thr, exclude=EXCLUDE)
    for j, x in enumerate(X):
        det.update_descriptor(x)
        c = max(j - EXCLUDE, 0)
        assert np.allclose(det.last_scores, S[:c, j], atol=1e-5)
    ev = det.events
    right = [e for e in ev if GT[e["match"], e["frame"]]]
    assert len(right) >= REPEAT // 2 and all(e["frame"] >= N0 for e in ev)   # closures in the revisit
    assert seqstream.stream_matches_matrix(det, S)
    det.events.pop(0)
    assert not seqstream.stream_matches_matrix(det, S)
    assert det.bytes_per_frame == DIM * 4 + 4 * 11


def test_sequence_beats_one_frame_on_the_revisit(revisit):
    X, GT = revisit
    r1 = {ds: evaluate.per_query(seqslam_stream.score_matrix(X, EXCLUDE, ds=ds), GT, EXCLUDE, ks=(1,))["R@1"]
          for ds in (0, 10)}
    assert r1[10] > r1[0] and r1[10] >= 0.8


def test_frames_give_the_descriptors_of_the_folder(tmp_path):
    folder = write_frames(tmp_path / "seq", 6, size=(128, 96))
    X = seqslam.describe(folder)
    raw = [cv2.imread(str(p), cv2.IMREAD_COLOR) for p in sequence.list_frames(folder)]
    assert X.shape == (6, 2048) and np.allclose(X, seqslam.describe_frames(raw), atol=1e-5)
    det = seqslam_stream.Detector(None, exclude=2)
    det.update_many(raw)
    assert det.frame_index == 6 and np.allclose(det.last_scores, seqslam_stream.score_matrix(X, 2)[:3, 5], atol=1e-5)
    # patch normalised: every 8x8 block of every frame has mean 0, std 1
    b = X.reshape(6, 4, 8, 8, 8).mean(axis=(2, 4))
    assert np.allclose(b, 0, atol=1e-5)


def test_bad_inputs():
    with pytest.raises(ValueError, match="finite"):
        seqslam_stream.Detector(float("nan"))
    with pytest.raises(ValueError, match="integer move"):
        seqslam.velocities(10, 1.21, 1.29)
    det = seqslam_stream.Detector(None, exclude=0)
    det.update_descriptor(np.ones(8))
    with pytest.raises(ValueError, match="dims"):
        det.update_descriptor(np.ones(9))
    with pytest.raises(ValueError, match="NaN"):
        det.update_descriptor(np.full(8, np.nan))


def test_tune_knobs_rows_are_the_score_matrices_scored(revisit):
    X, GT = revisit
    tune, _ = evaluate.split_mask(len(X), 0.5, gt=GT, gap=12)
    rows = seqslam_stream.tune_knobs(X, GT, EXCLUDE, tune, [1, 11], [0, 10])
    assert [(r["seq_len"], r["contrast_window"]) for r in rows] == [(1, 0), (1, 10), (11, 0), (11, 10)]
    q = evaluate.per_query(seqslam_stream.score_matrix(X, EXCLUDE, ds=10, contrast_window=10), GT, EXCLUDE, queries=tune, ks=(1,))
    assert rows[3]["AUC-PR_tune_%"] == round(100 * q["AUC-PR"], 2) and rows[3]["descriptor"] == "seqslam"
    knobs, _ = seqmatch.pick_knobs(rows, {"SeqSLAM": (["seqslam"], [1, 11])})
    assert knobs["SeqSLAM"]["seq_len"] in (1, 11)


def test_stream_check_reports_the_revisit_events(revisit):
    X, GT = revisit
    S = seqslam_stream.score_matrix(X, EXCLUDE)
    m = evaluate.best_matches(S, GT, EXCLUDE)
    det = seqslam_stream.Detector(float(np.median(m.score[m.correct])), exclude=EXCLUDE)
    c = seqstream.stream_check(det, X, S, GT)
    assert c["equal"] and c["correct_events"] >= REPEAT // 3 and c["events"] >= c["correct_events"]
    assert c["revisit_queries"] == REPEAT
    S2 = S.copy()
    S2[:, det.events[0]["frame"]] = S.min()                     # a matrix the stream did not make
    assert not seqstream.stream_check(det, X, S2, GT)["equal"]
