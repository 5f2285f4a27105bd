"""greenloop-seq's candidate-mode preload (Detector.preload) against streaming, and the decision
benchmark of greenloop.speed.scale on a small recording the test makes."""
import numpy as np
import pandas as pd
import pytest

from greenloop import seqmatch
from greenloop.similarity import l2_normalise
from greenloop.speed import scale, seqstream

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
         ("hnsw", {"ef_search": 1000}, {}), ("scan", {}, {"projection": "pca"})]


@pytest.mark.parametrize("kind, opts, knobs", CASES)
def test_preload_then_stream_equals_the_stream(kind, opts, knobs):
    """Frames 0..n-1 streamed one by one vs frames 0..n-TAIL-1 preloaded and the last TAIL streamed:
    the same scores, candidates and events for the last TAIL frames, bit for bit (HNSW: searched
    exhaustively, ef_search above the stored count, since its graph depends on the insertion order)."""
    X = _route()
    knobs = {"threshold": 1.33, "contrast_window": 4, **knobs}     # about the tail's median best score
    if knobs.get("projection") == "pca":
        knobs["projection"] = seqmatch.fit_projection(X[:N_PLACE], dim=8)
    full, head = (seqstream.Detector(seq_len=5, exclude=20, index=kind, k=8, index_options=opts, **knobs)
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
    full = seqstream.Detector(None, seq_len=5, exclude=20, index="scan", k=8)
    head = seqstream.Detector(None, seq_len=5, exclude=20, index="scan", k=8)
    streamed, _ = _tail(full, X[:40])
    head.preload(X[:3])                                    # fewer frames than seq_len, none indexed
    got, _ = _tail(head, X[3:40])
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(streamed[3:], got))
    ref, ref_head = (seqstream.Detector(None, seq_len=5, exclude=20) for _ in range(2))   # the reference too
    ref_streamed, _ = _tail(ref, X[:120])
    ref_head.preload(X[:90])
    assert ref_head.frame_index == 90 and ref_head.last_scores.size == 0
    ref_got = [(ref_head.update_descriptor(x), ref_head.last_scores.copy())[1] for x in X[90:120]]
    assert all(np.array_equal(a[0], b) for a, b in zip(ref_streamed[90:], ref_got))
    with pytest.raises(ValueError, match=r"\(N, D\)"):
        head.preload(X[0])
    with pytest.raises(ValueError, match="NaN"):
        head.preload(np.full((4, 16), np.nan, np.float32))


def test_decisions_agree_with_an_uninterrupted_stream(tmp_path):
    """speed.scale.decisions (preload N, stream the next frames) against detectors streamed from
    frame 0: recall@1 and correct_% recomputed by hand from their best matches."""
    X = l2_normalise(_route())
    n, nq, kw = 240, 100, dict(seq_len=5, exclude=20, contrast_window=4, k=8)
    methods = (("scan", "scan", {}), ("SWP", "swp", {"n_bits": 10, "radius": 1}))
    got = scale.decisions(X, 2 * N_PLACE, sizes=[n], n_queries=nq, methods=methods, **kw).set_index("method")
    best = {}
    for label, kind, opts in methods:
        det = seqstream.Detector(0.0, index=kind, index_options={"nlist": 16, "train_size": n, **opts}, **kw)
        out, _ = _tail(det, X[:n + nq])
        best[label] = np.array([c[np.argmax(s)] for s, c in out[n:]])
    place = np.arange(len(X)) % N_PLACE
    for label in best:
        correct = np.abs(place[best[label]] - place[n:n + nq]) <= 2
        assert got.loc[label, "correct_%"] == pytest.approx(100 * correct.mean())
    recall = 100 * np.mean(best["SWP"] == best["scan"])
    assert got.loc["scan", "recall@1_%"] == 100 and 0 < recall < 100
    assert got.loc["SWP", "recall@1_%"] == pytest.approx(recall)
    assert (got.p50_ms <= got.p99_ms).all() and got.frames_per_s.values == pytest.approx(1e3 / got.mean_ms.values)
    lines = scale._decision_section(tmp_path, got.reset_index())
    assert pd.read_csv(tmp_path / "scale_decisions.csv").shape[0] == 2 and (tmp_path / "scale_decisions.png").is_file()
    assert any(line.startswith("| method") for line in lines)
    t = scale.decision_targets(got.reset_index()).set_index("method")
    assert t.loc["SWP", "recall@1 within 1 pt of exact"].startswith("not met")
    assert t.loc["scan", "correct_% within 1 pt of exact"] == "met (100.0 % vs 100.0 %)"


def test_descriptors_are_the_single_frame_path():
    """descriptors() in chunks gives the rows describe_ms times, one frame per call."""
    rng = np.random.default_rng(0)
    real = rng.integers(0, 256, (30, 32, 64), dtype=np.uint8)
    pca = scale.fit_pca(real, 8)
    X = scale.descriptors(real, pca, 25, 45, chunk=7, progress=False)
    frames = [f for _, _, f in scale.augment.recording(real, 25, 45)]
    assert np.allclose(X, np.vstack([scale.project([f], pca) for f in frames]), rtol=0, atol=1e-6)
    assert np.allclose(np.linalg.norm(X, axis=1), 1, atol=1e-6)
    ms = scale.describe_ms(real, pca, 25, 5)
    assert 0 < ms["describe_p50_ms"] <= ms["describe_p99_ms"]
