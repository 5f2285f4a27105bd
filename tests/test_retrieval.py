"""greenloop.methods.lsh.retrieval: every index against the exact scan, the exclusion window, LSH reuse,
per-query metrics from top-k lists, and greenloop-seq's candidate mode against its reference."""
import numpy as np
import pytest
import scipy.sparse

from greenloop import evaluate
from greenloop.methods.greenloop_seq import seqstream
from greenloop.methods.lsh import lsh, retrieval


def _route(n_place=300, dim=32, passes=3, noise=0.25, seed=0):
    """A route of n_place places (a smooth random walk in dim-d) driven `passes` times, each
    pass its own noise: descriptors (passes * n_place, dim) and the place of each frame."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.standard_normal((n_place, dim)), 0) * 0.3 + rng.standard_normal(dim) * 2
    X = np.vstack([walk + noise * rng.standard_normal((n_place, dim)) for _ in range(passes)])
    return X.astype(np.float32), np.tile(np.arange(n_place), passes)


def _exact(X, Q, k):
    """Hand-rolled reference: cosine of unit rows, sorted by score desc then id asc."""
    Y = X / np.linalg.norm(X, axis=1, keepdims=True)
    P = Q / np.linalg.norm(Q, axis=1, keepdims=True)
    S = P @ Y.T
    order = np.array([np.lexsort((np.arange(len(Y)), -row))[:k] for row in S])
    return np.take_along_axis(S, order, 1), order


def test_topk_ties_and_padding():
    s, i = retrieval.topk(np.array([0.5, 0.9, 0.9, 0.1], np.float32), np.array([7, 3, 5, 1]), 2)
    assert i.tolist() == [3, 5] and s.tolist() == pytest.approx([0.9, 0.9])
    s, i = retrieval.topk(np.array([0.5, 0.9], np.float32), np.array([7, 3]), 4)
    assert i.tolist() == [3, 7, -1, -1] and np.isneginf(s[2:]).all()


@pytest.mark.parametrize("kind,opts", [("scan", {}), ("flat", {}),
                                       ("ivf", {"nlist": 8, "nprobe": 8, "train_size": 400})])
def test_exact_indexes_return_the_exact_neighbours(kind, opts):
    X, _ = _route()
    Q = X[::7] + 0.05
    ix = retrieval.make_index(kind, X.shape[1], **opts)
    ix.add(X[:500])
    ix.add(X[500:])                           # added in two batches, ids continue
    s, i = ix.search(Q, 5)
    s0, i0 = _exact(X, Q, 5)
    assert np.array_equal(i, i0)
    assert np.allclose(s, s0, atol=1e-5)


def test_stream_search_keeps_the_exclusion_window():
    X, _ = _route(n_place=120, passes=2)
    ex = 20
    s, i = retrieval.stream_search(retrieval.make_index("scan", X.shape[1]), X, k=3, exclude=ex)
    assert (i[:ex + 1] == -1).all()
    for t in (ex + 1, ex + 2, 100, 239):
        s0, i0 = _exact(X[:t - ex], X[t:t + 1], 3)
        assert np.array_equal(i[t][i[t] >= 0], i0[0][:min(3, t - ex)])


def test_approximate_indexes_reach_their_stated_recall():
    """Recall@1 against the exact scan on the route data (third pass queries the first two):
    HNSW and IVF (4 of 16 cells) >= 95 %, the paper's RHLSH >= 50 % (it scans few buckets)."""
    X, _ = _route(n_place=400)
    db, Q = X[:800], X[800:]
    _, i0 = _exact(db, Q, 1)
    need = {"hnsw": 0.95, "ivf": 0.95, "swp": 0.5, "qdp": 0.5}
    for kind, floor in need.items():
        ix = retrieval.make_index(kind, X.shape[1], nlist=16, nprobe=4, train_size=400)
        ix.add(db)
        _, i = ix.search(Q, 1)
        assert np.mean(i[:, 0] == i0[:, 0]) >= floor, kind


def test_lsh_index_is_lsh_py_matching():
    """The retrieval SWP/QDP index finds the same best match as lsh.incremental_match."""
    X, _ = _route(n_place=150, passes=2)
    for method in ("swp", "qdp"):
        ref = lsh.incremental_match(X, method, exclude=10, n_bits=8, radius=2)
        ix = retrieval.make_index(method, X.shape[1], n_bits=8, radius=2)
        _, i = retrieval.stream_search(ix, X, k=1, exclude=10)
        assert np.array_equal(i[:, 0], ref.best), method


def test_memory_per_frame():
    X, _ = _route()
    for kind, lo, hi in (("scan", 128, 128), ("flat", 128, 129), ("hnsw", 128 + 8 * 16, 128 + 8 * 16 * 2)):
        ix = retrieval.make_index(kind, 32, M=16)
        ix.add(X)
        assert lo <= ix.bytes_per_frame() <= hi, kind


def test_candidate_metrics_equal_the_dense_matrix_ones():
    X, place = _route(n_place=100, passes=2, noise=0.6, seed=3)
    n, ex = len(X), 30
    GT = np.abs(place[:, None] - place[None, :]) <= 1
    np.fill_diagonal(GT, False)
    scores, ids = retrieval.stream_search(retrieval.make_index("scan", X.shape[1]), X, k=10, exclude=ex)
    m = retrieval.candidate_matches(scores, ids, scipy.sparse.csr_array(GT), exclude=ex)
    Y = (X / np.linalg.norm(X, axis=1, keepdims=True)).astype(np.float32)
    dense = evaluate.per_query(Y @ Y.T, GT, exclude=ex, ks=(1, 5, 10))
    got = evaluate.query_metrics(m, ks=(1, 5, 10))
    assert got["queries"] == dense["queries"] == n - ex - 1
    assert got == pytest.approx(dense)
    assert 0 < got["R@1"] < 1                   # a test both sides could pass trivially is no test


def _revisit(seed=1):
    rng = np.random.default_rng(seed)
    base = np.cumsum(rng.standard_normal((300, 64)), 0).astype(np.float32) * 0.3 + rng.standard_normal(64) * 3
    return np.vstack([base, base[50:250] + 0.5 * rng.standard_normal((200, 64)).astype(np.float32)])


def _run(X, **kw):
    det = seqstream.Detector(kw.pop("threshold", None), seq_len=10, exclude=50, **kw)
    out = []
    for x in X:
        det.update_descriptor(x)
        out.append((det.last_scores.copy(), det.last_candidates.copy()))
    return det, out


def test_candidate_mode_equals_the_reference_where_the_index_returns_everything():
    X = _revisit()[:340]
    for cw in (0, 10):
        ref, a = _run(X, contrast_window=cw)
        cand, b = _run(X, contrast_window=cw, index="scan", k=len(X))
        for j, ((s0, _), (s1, ids)) in enumerate(zip(a, b)):
            c = s0.size
            assert np.array_equal(ids, np.arange(c))
            if cw == 0:                             # cosine: the pad is the exact column mean too
                assert np.allclose(s1, s0, atol=1e-5)
            elif j >= 80 and c > 14:                # z-scores: equal where every point is stored
                assert np.allclose(s1[11:c - 3], s0[11:c - 3], atol=1e-4)


def test_candidate_mode_closures_equal_the_reference():
    """Thresholded: the exact scan with k = 20 and an HNSW index declare the reference's closures."""
    X = _revisit()
    ref, _ = _run(X, threshold=1.5, contrast_window=10)
    assert len(ref.events) > 100 and all(e["frame"] >= 300 for e in ref.events)   # on the revisit
    for kind in ("scan", "hnsw"):
        det, _ = _run(X, threshold=1.5, contrast_window=10, index=kind, k=20)
        assert [(e["frame"], e["match"]) for e in det.events] == \
               [(e["frame"], e["match"]) for e in ref.events], kind


def _folder(path):
    """40 smooth random colour frames, then frames 0..24 again with a little noise: 65 .png files."""
    import cv2
    rng = np.random.default_rng(0)
    base = [cv2.GaussianBlur(rng.integers(0, 256, (32, 64, 3), dtype=np.uint8), (9, 9), 3) for _ in range(40)]
    frames = base + [np.clip(f.astype(int) + rng.integers(-4, 5, f.shape), 0, 255).astype(np.uint8) for f in base[:25]]
    path.mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(path / f"{i}.png"), f)
    return path


def _detect(argv, capsys):
    from greenloop.__main__ import main
    rc = main(argv)
    cap = capsys.readouterr()
    return rc, [line.split("\t")[:3] for line in cap.out.splitlines() if line[:1].isdigit()], cap.out + cap.err


def test_detect_resumes_from_its_state_with_the_same_closures(tmp_path, capsys, monkeypatch):
    from greenloop import detect
    folder = _folder(tmp_path / "rec")
    base = ["detect", str(folder), "--method", "greenloop-seq", "--descriptor", "pixels-patchnorm",
            "--exclude", "10", "--seq-len", "3", "--contrast-window", "0", "--threshold", "0.8",
            "--window", "4", "--index", "hnsw", "--candidates", "5"]
    rc, full, _ = _detect(base, capsys)
    assert rc == 0 and len(full) >= 10 and all(int(f) >= 40 and int(m) == int(f) - 40 for f, m, _ in full)
    state = tmp_path / "det.state"
    rc, part1, out = _detect(base + ["--state", str(state), "--stop-after", "30", "--save-every", "8"], capsys)
    assert rc == 0 and "stopped" in out and state.is_file() and part1 == []
    calls = {"n": 0}
    real_read = detect.read_window

    def interrupted(paths):                       # Ctrl-C during the 3rd window of the next run
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real_read(paths)
    monkeypatch.setattr(detect, "read_window", interrupted)
    rc, part2, _ = _detect(base + ["--state", str(state)], capsys)
    assert rc == 130
    monkeypatch.setattr(detect, "read_window", real_read)
    rc, part3, out = _detect(base + ["--state", str(state)], capsys)
    assert rc == 0 and "resumed at frame 38" in out and "65 frames" in out
    assert part1 + part2 + part3 == full
    rc, _, out = _detect(base[:-1] + ["6", "--state", str(state)], capsys)     # other options: refused
    assert rc == 2 and "another run" in out


def test_augmented_recording_is_the_same_in_any_chunk():
    from greenloop.datasets import augment
    rng = np.random.default_rng(0)
    src = rng.integers(0, 256, (4, 16, 24), dtype=np.uint8)
    whole = [f for _, _, f in augment.recording(src, 0, 11)]
    part = list(augment.recording(src, 6, 10))
    assert [(t, i) for t, i, _ in part] == [(t, t % 4) for t in range(6, 10)]
    assert all(np.array_equal(f, whole[t]) for t, _, f in part)
    assert not np.array_equal(whole[0], whole[4])          # a revisit is another view, not a copy
    assert augment.pass_condition(0, 0) == {"gain": 1.0, "offset": 0.0, "blur": 0.0}


def test_route_ground_truth_by_hand():
    from greenloop.speed import scale
    G = scale.route_ground_truth(12, 6, tolerance=1).toarray()
    # places (t mod 6) mod 3: 0 1 2 0 1 2 | 0 1 2 0 1 2; frame 0 (place 0) meets places 0 and 1
    assert np.flatnonzero(G[0]).tolist() == [1, 3, 4, 6, 7, 9, 10]
    assert np.flatnonzero(G[2]).tolist() == [1, 4, 5, 7, 8, 10, 11]
    assert (G == G.T).all() and not G.diagonal().any()


@pytest.mark.parametrize("kind", ["hnsw", "ivf", "qdp"])
def test_a_pickled_index_continues_as_if_never_stopped(kind):
    """Resume: an index pickled mid-stream and restored gives the uninterrupted run's graph /
    lists / buckets (HNSW: its level generator, which faiss does not save, is replayed)."""
    import pickle
    X, _ = _route(n_place=200)
    opts = dict(M=8, nlist=8, train_size=100)
    a = retrieval.make_index(kind, X.shape[1], **opts)
    for x in X:
        a.add(x)
    b = retrieval.make_index(kind, X.shape[1], **opts)
    for x in X[:250]:
        b.add(x)
    b = pickle.loads(pickle.dumps(b))
    for x in X[250:]:
        b.add(x)
    Q = X[::5] + 0.1
    assert np.array_equal(a.search(Q, 5)[1], b.search(Q, 5)[1])
    if kind == "hnsw":
        import faiss
        assert np.array_equal(faiss.serialize_index(a.index), faiss.serialize_index(b.index))


def test_ivf_trains_on_the_first_frames_however_they_are_added():
    """One add of N > train_size frames leaves the index N single adds leave (a stream's): the
    quantiser learns the first train_size frames, not all N; the same searches follow."""
    X, _ = _route(n_place=200, dim=16, passes=2)
    one, singles = (retrieval.make_index("ivf", 16, nlist=4, nprobe=1, train_size=160) for _ in range(2))
    one.add(X)
    for x in X:
        singles.add(x)
    assert one.n_stored == singles.n_stored == len(X)
    assert np.array_equal(one.search(X[::7], 5)[1], singles.search(X[::7], 5)[1])
    C1, C2 = (np.stack([ix._quantiser.reconstruct(i) for i in range(4)]) for ix in (one, singles))
    assert np.array_equal(C1, C2)
