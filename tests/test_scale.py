"""greenloop-seq's candidate-mode preload (Detector.preload) against streaming, and the decision
benchmark of greenloop.speed.scale on a small recording the test makes."""
import numpy as np
import pytest

from greenloop import seqmatch

N_PLACE, PASSES, TAIL = 120, 3, 120     # the tail: the third pass, from the route's first place


def _route(dim=16, noise=0.2, seed=0):
    """A route of N_PLACE places (a smooth random walk in dim-d) driven PASSES times with fresh noise."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.standard_normal((N_PLACE, dim)), 0) * 0.3 + rng.standard_normal(dim) * 2
    return np.vstack([walk + noise * rng.standard_normal((N_PLACE, dim)) for _ in range(PASSES)]).astype(np.float32)


def _tail(det, X):
    """Stream X through det; (scores, candidates) of each frame and the events declared."""
    out = []
    for x in X:
        det.update_descriptor(x)
        out.append((det.last_scores.copy(), det.last_candidates.copy()))
    return out, list(det.events)


CASES = [("scan", {}, {}), ("flat", {}, {}), ("ivf", {"nlist": 4, "nprobe": 1, "train_size": 160}, {}),
         ("swp", {"n_bits": 6}, {}), ("scan", {}, {"contrast_window": 0, "threshold": 0.997}),
         ("scan", {}, {"center_window": 7}), ("flat", {}, {"store_dtype": "float16"}),
         ("hnsw", {"ef_search": 1000}, {})]


@pytest.mark.parametrize("kind, opts, knobs", CASES)
def test_preload_then_stream_equals_the_stream(kind, opts, knobs):
    """Frames 0..n-1 streamed one by one vs frames 0..n-TAIL-1 preloaded and the last TAIL streamed:
    the same scores, candidates and events for the last TAIL frames, bit for bit (HNSW: searched
    exhaustively, ef_search above the stored count, since its graph depends on the insertion order)."""
    X = _route()
    knobs = {"threshold": 1.33, "contrast_window": 4, **knobs}     # about the tail's median best score
    full, head = (seqmatch.Detector(seq_len=5, exclude=20, index=kind, k=8, index_options=opts, **knobs)
                  for _ in range(2))
    streamed, events = _tail(full, X)
    head.preload(X[:-TAIL])
    assert head.frame_index == len(X) - TAIL and head.events == []
    assert head._index.n_stored == len(X) - TAIL - 1 - 20
    got, got_events = _tail(head, X[-TAIL:])
    for (s0, c0), (s1, c1) in zip(streamed[-TAIL:], got):
        assert np.array_equal(c0, c1) and np.array_equal(s0, s1)
    tail_events = [e for e in events if e["frame"] >= len(X) - TAIL]
    assert 5 < len(tail_events) < TAIL                     # some frames decide a closure, not all
    assert got_events == tail_events


def test_preload_shorter_than_the_window_and_bad_input():
    X = _route()
    full = seqmatch.Detector(None, seq_len=5, exclude=20, index="scan", k=8)
    head = seqmatch.Detector(None, seq_len=5, exclude=20, index="scan", k=8)
    streamed, _ = _tail(full, X[:40])
    head.preload(X[:3])                                    # fewer frames than seq_len, none indexed
    got, _ = _tail(head, X[3:40])
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(streamed[3:], got))
    with pytest.raises(ValueError, match="candidate mode"):
        seqmatch.Detector(None).preload(X)
    with pytest.raises(ValueError, match=r"\(N, D\)"):
        head.preload(X[0])
    with pytest.raises(ValueError, match="NaN"):
        head.preload(np.full((4, 16), np.nan, np.float32))
