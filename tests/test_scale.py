"""greenloop-seq's candidate-mode preload (Detector.preload) against streaming, and the decision
benchmark of greenloop.speed.scale on a small recording the test makes."""
import numpy as np
import pandas as pd
import pytest

from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.similarity import l2_normalise
from greenloop.speed import scale

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
    """speed.scale.decisions (the named configuration, preload N, stream the next frames) against
    detectors streamed from frame 0, the exact scan and candidate mode: the agreement columns,
    closures and correct_% recomputed by hand from their best matches and closures."""
    X = _route(dim=256)
    n, nq = 240, 100
    methods = (("exact", None, {}), ("SWP", "swp", {"n_bits": 10, "radius": 1}))
    got = scale.decisions(X, 2 * N_PLACE, sizes=[n], n_queries=nq, methods=methods, k=8, exclude=20,
                          index_dim=None).set_index("method")
    knobs, threshold = seqmatch.NAMED[scale.DECISION_NAME]
    knobs = {key: v for key, v in knobs.items() if key != "descriptor"}
    res = {}
    for label, kind, opts in methods:
        index = {} if kind is None else dict(index=kind, k=8, index_options={"nlist": 16, "train_size": n, **opts})
        det = seqstream.Detector(threshold, exclude=20, **knobs, **index)
        best, fired = [], []
        for x in X[:n + nq]:
            event = det.update_descriptor(x)
            best.append(seqstream.best_candidate(det)[0])
            fired.append(event is not None)
        res[label] = (np.array(best[n:]), np.array(fired[n:]))
    (b0, f0), (b1, f1) = res["exact"], res["SWP"]
    place = np.arange(len(X)) % N_PLACE
    assert got.loc["SWP", "best_agree_%"] == pytest.approx(100 * np.mean(np.abs(b1 - b0) <= 2))
    assert got.loc["SWP", "events_agree_%"] == pytest.approx(100 * np.mean(f1 == f0))
    assert got.loc["SWP", "closures"] == f1.sum() and got.loc["exact", "closures"] == f0.sum()
    for label, (b, _) in res.items():
        assert got.loc[label, "correct_%"] == pytest.approx(100 * np.mean(np.abs(place[b] - place[n:n + nq]) <= 2))
    assert got.loc["exact", "best_agree_%"] == got.loc["exact", "events_agree_%"] == 100
    assert 5 < f0.sum() < nq and got.loc["exact", "correct_%"] > 90           # the third pass closes loops
    assert got.loc["exact", "bytes_per_frame"] == 2 * 256 * 4 + 4 * knobs["seq_len"]
    assert (got.p50_ms <= got.p99_ms).all() and got.frames_per_s.values == pytest.approx(1e3 / got.mean_ms.values)
    lines = scale._decision_section(tmp_path, got.reset_index())
    assert pd.read_csv(tmp_path / "scale_decisions.csv").shape[0] == 2 and (tmp_path / "scale_decisions.png").is_file()
    assert any(line.startswith("| method") for line in lines)
    t = scale.decision_targets(got.reset_index()).set_index("method")
    assert list(t.index) == ["SWP"] and t.loc["SWP", "bytes per stored frame"] == f"{got.loc['SWP', 'bytes_per_frame']:.0f} B"


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
