"""Scaling benchmark of candidate retrieval: ``make bench-scale`` -> results/bench/scale.{md,csv,png}.

Data (never random vectors): Nordland's 7152 real 64x32 frames (summer then winter, the route
order of ``greenloop.datasets.nordland``) augmented into a long recording of passes over the route
(``greenloop.datasets.augment.recording``: per-pass gain/offset/blur, per-frame shift/zoom/
brightness jitter/noise). Each frame -> the study's "pixels-patchnorm" descriptor (32x32 gray,
SeqSLAM 8x8 patch normalisation, 1024-d; ``seqmatch.describe_frames``) -> PCA to ``dim``
components (mean-centred, no whitening) fitted on the 7152 real frames only -> L2.

Stored frames: the first N of the recording (N in ``sizes``); queries: frames of a later pass
(the recording beyond the largest size), so every query revisits stored places but is no stored
frame. Per size and method: build (add the N frames in one batch) and insert (frames added one at a
time afterwards, mean per frame) times, per-query search latency for k = 10 (one query per call,
one thread) p50 / p99, recall@1 = share of queries whose best candidate is the exact scan's best
(same score within 1e-6 counts), candidates scanned (LSH), and memory per stored frame.
Nearest-neighbour similarity quantiles of the real and the augmented descriptors are written
beside (``neighbourhood``).

The whole decision (:func:`decisions`, scale_decisions.csv): the named configuration
(``seqmatch.DEFAULT_KNOBS``: its "gradients" descriptor of the same augmented frames, centred,
cell-shifted, its reverse velocities, repeat gate and calibration, at its fixed threshold) with N
frames already stored (``seqstream.Detector.preload``), then the recording's next frames streamed
one at a time (they revisit the route), in candidate mode and in the exact scan (every stored frame
scored, the reference): insert + search + sequence verification + calibration + store per frame,
p50 / p99, the agreement of its best matches and of its closures with the exact scan's, memory per
stored frame; the descriptor's own cost per frame (:func:`describe_ms`) in a column of its own.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.sparse

from greenloop import evaluate, report
from greenloop.datasets import augment
from greenloop.groundtruth import DEFAULT_EXCLUDE
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.methods.lsh import retrieval
from greenloop.similarity import l2_normalise
from greenloop.speed.timing import timed
from greenloop.util.progress import bar
from greenloop.util.threads import one_blas_thread

SIZES = (10_000, 100_000, 1_000_000)
K = 10
# (label, kind, [search settings]): one build per kind, searched at each setting
METHODS = (("NumPy scan", "scan", [{}]), ("faiss flat", "flat", [{}]),
           ("IVF", "ivf", [{"nprobe": 8}, {"nprobe": 16}, {"nprobe": 64}]),
           ("HNSW", "hnsw", [{"ef_search": 32}, {"ef_search": 128}]),
           ("SWP-RHLSH", "swp", [{}]), ("QDP-RHLSH", "qdp", [{}]))
QUANTILES = (0.01, 0.1, 0.5, 0.9, 0.99)
# the whole decision: (label, Detector index kind, index options beyond nlist / train_size); the
# exact scan (kind None: every stored frame scored) first, the reference of the agreement columns
DECISIONS = (("exact scan", None, {}), ("NumPy scan", "scan", {}), ("IVF nprobe 16", "ivf", {"nprobe": 16}),
             ("HNSW ef 128", "hnsw", {"ef_search": 128}))
DECISION_NAME = seqmatch.DEFAULT_NAME           # the configuration the decision runs


def fit_pca(real: np.ndarray, dim: int):
    """(mean (1024,), components (1024, dim)) of the real frames' pixels-patchnorm descriptors."""
    X = seqmatch.describe_frames(list(real), "pixels-patchnorm")
    mean = X.mean(0)
    _, _, Vt = np.linalg.svd(X - mean, full_matrices=False)
    return mean, np.ascontiguousarray(Vt[:dim].T)


def descriptors(real, pca, start: int, stop: int, seed: int = 0, chunk: int = 20_000,
                progress: bool = True) -> np.ndarray:
    """Frames start..stop-1 of the augmented recording as (n, D) float32 descriptors: pca (mean,
    components) gives :func:`project`'s unit rows (n, dim); a callable, its own of a list of frames
    (e.g. :func:`gradients`)."""
    describe = pca if callable(pca) else (lambda frames: project(frames, pca))
    out, frames, t0 = None, [], start
    it = augment.recording(real, start, stop, seed)
    for t, _, f in bar(it, total=stop - start, desc="descriptors", unit="frame", disable=not progress):
        frames.append(f)
        if len(frames) == chunk or t == stop - 1:
            Y = describe(frames)
            out = np.empty((stop - start, Y.shape[1]), np.float32) if out is None else out
            out[t0 - start:t + 1 - start] = Y
            frames, t0 = [], t + 1
    return out


def gradients(frames) -> np.ndarray:
    """Decoded frames (list of (H, W) uint8) -> (n, D) float32 raw descriptors of the decision's
    configuration (DECISION_NAME's, "gradients": what its Detector is fed, no PCA)."""
    return seqmatch.describe_frames(frames, seqmatch.NAMED[DECISION_NAME][0]["descriptor"])


def project(frames, pca) -> np.ndarray:
    """Decoded frames (list of (H, W) uint8) -> (n, dim) float32 unit descriptors: pixels-patchnorm,
    minus the PCA mean, onto its components, L2 (a batch's rows equal single frames' to float32
    rounding: the product's summation order depends on the batch)."""
    mean, V = pca
    return l2_normalise(((seqmatch.describe_frames(frames, "pixels-patchnorm") - mean) @ V)
                        .astype(np.float32)).astype(np.float32)


def describe_ms(real, pca, start: int, n: int, seed: int = 0) -> dict:
    """The descriptor's own cost: frames start..start+n-1 of the recording described one per call
    (:func:`project` of one decoded frame, or pca's own if it is a callable as in :func:`descriptors`;
    one BLAS thread): p50 / p99 / mean ms per frame."""
    describe = pca if callable(pca) else (lambda frames: project(frames, pca))
    secs = np.zeros(n)
    with one_blas_thread():
        for r, (_, _, f) in enumerate(augment.recording(real, start, start + n, seed)):
            secs[r] = timed(describe, [f])[1]
    return {"describe_p50_ms": 1e3 * np.median(secs), "describe_p99_ms": 1e3 * np.quantile(secs, 0.99),
            "describe_mean_ms": 1e3 * secs.mean()}


def nn_similarity(X, Q=None, block: int = 4096) -> np.ndarray:
    """(M,) cosine of each row of Q (default X itself, excluding the row) to its nearest row of X."""
    same = Q is None
    Q = X if same else Q
    out = np.empty(len(Q), np.float32)
    for a in range(0, len(Q), block):
        S = X @ Q[a:a + block].T
        if same:
            S[np.arange(a, min(a + block, len(Q))), np.arange(S.shape[1])] = -np.inf
        out[a:a + block] = S.max(0)
    return out


def neighbourhood(real_X, aug_X, aug_Q, sizes=SIZES) -> pd.DataFrame:
    """NN-similarity quantiles side by side: the 7152 real frames among themselves, the same
    number of augmented frames (one pass-length slice), and the queries against every stored size."""
    n = len(real_X)
    rows = {"real Nordland (7152, each vs the others)": nn_similarity(real_X),
            f"augmented, first {n} (each vs the others)": nn_similarity(aug_X[:n])}
    for size in sorted(sizes):
        if size <= len(aug_X):
            rows[f"queries vs {size:,} augmented stored"] = nn_similarity(aug_X[:size], aug_Q)
    return pd.DataFrame([{"set": k, **{f"q{int(100 * q)}": float(np.quantile(v, q)) for q in QUANTILES}}
                         for k, v in rows.items()])


def _setting(index, opts: dict) -> str:
    """Apply a search setting to a built index; returns its label suffix."""
    if "nprobe" in opts:
        index.index.nprobe = opts["nprobe"]
        return f" nprobe {opts['nprobe']}"
    if "ef_search" in opts:
        index.index.hnsw.efSearch = opts["ef_search"]
        return f" ef {opts['ef_search']}"
    return ""


def _add_singly(index, rows) -> None:
    """Insert the rows (n, D) one call each, as a stream adds its frames."""
    for x in rows:
        index.add(x)


def _stream_search(kind: str, X, k: int, exclude: int):
    """A fresh index of ``kind`` streamed over X (N, D): ``retrieval.stream_search``'s (scores, ids)."""
    index = retrieval.make_index(kind, X.shape[1], nlist=316, train_size=12_640)
    with one_blas_thread():
        return retrieval.stream_search(index, X, k, exclude)


def _search_all(index, Q, exact_best, exact_score) -> dict:
    secs, best, score, scanned = np.zeros(len(Q)), np.zeros(len(Q), np.int64), np.zeros(len(Q)), []
    for q in range(len(Q)):
        (s, i), secs[q] = timed(index.search, Q[q], K)
        best[q], score[q] = i[0, 0], s[0, 0]
        scanned.append(getattr(index, "last_scanned", np.nan))
    hit = (best == exact_best) | (np.abs(score - exact_score) <= 1e-6)
    return {"p50_ms": 1e3 * np.median(secs), "p99_ms": 1e3 * np.quantile(secs, 0.99),
            "mean_ms": 1e3 * secs.mean(), "recall@1_%": 100 * hit.mean(),
            "scanned_%": 100 * np.nanmean(scanned) / index.n_stored if np.isfinite(scanned).all() else np.nan}


def bench_one(kind: str, settings, X, Q, exact_best, exact_score, n_insert: int, dim: int,
              n_stored: int) -> list[dict]:
    """Build on X[:n_stored], time the searches of Q at each setting, then insert n_insert more
    frames singly. Returns one dict per setting (label suffix under "setting")."""
    nlist = max(16, int(round(np.sqrt(n_stored))))
    index = retrieval.make_index(kind, dim, nlist=nlist, train_size=min(n_stored, 40 * nlist))
    with one_blas_thread():
        build = timed(index.add, X[:n_stored])[1]
        mem = index.bytes_per_frame()
        rows = [{"setting": _setting(index, o), **_search_all(index, Q, exact_best, exact_score)}
                for o in settings]
        insert = timed(_add_singly, index, X[n_stored:n_stored + n_insert])[1] / max(n_insert, 1)
    return [{**r, "build_s": build, "insert_us": 1e6 * insert, "bytes_per_frame": mem} for r in rows]


def run(src, out, sizes=SIZES, dim: int = 64, queries=(2000, 1000, 300), n_insert: int = 1000,
        seed: int = 0, methods=METHODS, note: str = "", decision_queries: int = 2000,
        decision_sizes=None) -> pd.DataFrame:
    """The whole benchmark (module doc); writes out/scale.{csv,md,png}, scale_decisions.{csv,png},
    neighbourhood.{csv,md} and scale.json (``report.provenance()``: date, commit, environment hash,
    CPU; the library versions, the run's wall seconds (``timing.timed``) and ``note``).
    decision_sizes: the stored counts of the whole decision (default sizes)."""
    table, wall = timed(_measure, src, Path(out), sizes, dim, queries, n_insert, seed, methods, note,
                        decision_queries, decision_sizes)
    report.write_json(Path(out) / "scale.json", {**report.provenance(), "versions": report.versions(),
                                                 "wall_seconds": wall, "note": note})
    return table


def _measure(src, out: Path, sizes, dim: int, queries, n_insert: int, seed: int, methods, note: str,
             decision_queries: int, decision_sizes) -> pd.DataFrame:
    """:func:`run`'s measurements and tables (everything but scale.json)."""
    retrieval.one_thread()
    real = augment.nordland_route(src)
    pca = fit_pca(real, dim)
    decision_sizes = sorted(decision_sizes or sizes)
    top = max(sizes) + max(n_insert, decision_queries)
    X = descriptors(real, pca, 0, top, seed)
    qstart = (top // len(real) + 1) * len(real)          # a later pass than any stored frame
    Qall = descriptors(real, pca, qstart, qstart + max(queries), seed, progress=False)
    realX = project(list(real), pca)
    nb = neighbourhood(realX, X[:max(sizes)], Qall[:min(queries)], sizes)
    report.write_table(nb, out / "neighbourhood", "Nearest-neighbour cosine similarity quantiles")
    rows = []
    for n, nq in zip(sorted(sizes), queries):
        Q = Qall[:nq]
        S = X[:n] @ Q.T
        exact_best, exact_score = S.argmax(0), S.max(0)
        del S
        for label, kind, settings in bar(methods, desc=f"N={n:,}", unit="method"):
            for r in bench_one(kind, settings, X, Q, exact_best, exact_score, n_insert, dim, n):
                name = label + r.pop("setting")
                rows.append({"stored": n, "method": name, "kind": kind, "queries": nq, "dim": dim, **r})
                print(f"N={n} {name}: " + ", ".join(f"{k} {v:.4g}" for k, v in r.items()), flush=True)
    table = pd.DataFrame(rows)
    metrics = long_run_metrics(X, len(real), min(100_000, len(X)))
    print(metrics.to_string(), flush=True)
    del X, Qall
    G = descriptors(real, gradients, 0, max(decision_sizes) + decision_queries, seed, chunk=1000)   # small chunks: the
    # histograms' intermediate arrays grow with the chunk
    decide = decisions(G, len(real), decision_sizes, decision_queries)
    decide = decide.assign(**describe_ms(real, gradients, max(decision_sizes), decision_queries, seed))
    _write(out, table, nb, dim, len(real), seed, decide, note, metrics)
    return table


def decisions(X, m: int, sizes=SIZES, n_queries: int = 2000, methods=DECISIONS, k: int = K,
              exclude: int = DEFAULT_EXCLUDE, tolerance: int = 2, name: str = DECISION_NAME,
              index_dim: int = seqstream.INDEX_DIM) -> pd.DataFrame:
    """A named configuration's whole per-frame decision with N frames already stored, candidate
    mode against the exact scan.

    X: (>= max(sizes) + n_queries, D) raw descriptors of the recording in capture order, the
    configuration's (``seqmatch.NAMED[name]``'s descriptor: :func:`gradients`); m: the route's
    length in frames (:func:`route_places`). Per size N and method (label, kind, options): a
    ``seqstream.Detector`` with the configuration's knobs and fixed threshold, exclude, and for a
    kind candidate mode (index=kind, k rows per shifted query, the index reduced to index_dim dims;
    IVF's nlist and train size as the search table's; kind None: the exact scan), preloaded with
    X[:N] (``Detector.preload``, timed: preload_s), then frames N..N+n_queries-1 streamed one per
    ``update_descriptor`` call, each timed (insert, search, verification, calibration, store,
    threshold). Returns one row per (N, method): p50 / p99 / mean ms per frame, frames/s;
    best_agree_% (frames whose best match is within +-tolerance frames of the exact scan's),
    place_agree_% (whose best match shows the exact scan's best's place +- tolerance route frames:
    another pass of the same place counts), closures (declared), events_agree_% (frames where both
    declare a closure or both stay silent), match_agree_% (of the frames both declare, the match
    within +-tolerance frames of the exact scan's; NaN if none), all % of the n_queries frames and
    NaN without an exact scan first in methods; correct_% (best match at the query's place
    +-tolerance route frames); bytes_per_frame (``Detector.bytes_per_frame``), preload_s, stream_s
    (the n_queries frames' total), peak_rss_GB (the process's peak resident memory so far).
    """
    X = np.asarray(X)
    knobs, threshold = seqmatch.NAMED[name]
    knobs = {key: v for key, v in knobs.items() if key != "descriptor"}
    places, rows = route_places(len(X), m), []
    for n in sorted(sizes):
        if n + n_queries > len(X):
            raise ValueError(f"decisions at {n:,} stored frames need {n + n_queries:,} descriptors, got {len(X):,}")
        nlist, ref = max(16, int(round(np.sqrt(n)))), None
        for label, kind, opts in methods:
            index = {} if kind is None else dict(index=kind, k=k, index_dim=index_dim, index_options={
                "nlist": nlist, "train_size": min(n, 40 * nlist), **opts})
            det = seqstream.Detector(threshold, exclude=exclude, **knobs, **index)
            preload = timed(det.preload, X[:n])[1]
            secs, best, fired = _stream(det, X[n:n + n_queries])
            if kind is None:
                ref = (best, fired)
            row = {"stored": n, "method": label, "kind": kind or "exact", "queries": n_queries,
                   "dim": det._db.shape[1], "p50_ms": 1e3 * np.median(secs), "p99_ms": 1e3 * np.quantile(secs, 0.99),
                   "mean_ms": 1e3 * secs.mean(), "frames_per_s": n_queries / secs.sum(),
                   **_agreement(best, fired, ref, places, tolerance), "closures": int(fired.sum()),
                   "correct_%": 100 * np.mean(np.abs(places[best] - places[n:n + n_queries]) <= tolerance),
                   "bytes_per_frame": det.bytes_per_frame, "preload_s": preload, "stream_s": secs.sum(),
                   "peak_rss_GB": _peak_rss_gb()}
            rows.append(row)
            print(f"decision N={n} {label}: " + ", ".join(f"{c} {v:.4g}" for c, v in row.items()
                                                          if isinstance(v, float)), flush=True)
            del det
    return pd.DataFrame(rows)


def _agreement(best, fired, ref, places, tolerance: int) -> dict:
    """:func:`decisions`' agreement columns of one method's best matches (M,) and closures (M,) bool
    against the exact scan's ``ref`` = (best, fired) (None: NaN)."""
    if ref is None:
        return dict.fromkeys(("best_agree_%", "place_agree_%", "events_agree_%", "match_agree_%"), np.nan)
    b0, f0 = ref
    both = fired & f0
    near = np.abs(best - b0) <= tolerance
    return {"best_agree_%": 100 * np.mean(near),
            "place_agree_%": 100 * np.mean(np.abs(places[best] - places[b0]) <= tolerance),
            "events_agree_%": 100 * np.mean(fired == f0),
            "match_agree_%": 100 * np.mean(near[both]) if both.any() else np.nan}


def _peak_rss_gb() -> float:
    """The process's peak resident memory so far, GB (ru_maxrss: kB on Linux)."""
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def _stream(det, Q):
    """Feed Q (M, D) to det one frame per call: (seconds (M,), best match (M,) int64 (-1: no
    candidate), whether a closure was declared (M,) bool)."""
    secs, best, fired = np.zeros(len(Q)), np.zeros(len(Q), np.int64), np.zeros(len(Q), bool)
    with one_blas_thread():
        for q, x in enumerate(Q):
            event, secs[q] = timed(det.update_descriptor, x)
            best[q], fired[q] = seqstream.best_candidate(det)[0], event is not None
    return secs, best, fired


STREAM_HEADING = "## A long recording streamed end to end through the CLI"


def route_places(n: int, m: int) -> np.ndarray:
    """(n,) int64 place of each frame of a recording of passes over a route of m frames whose two
    halves are the same places (Nordland: summer, then winter): (t mod m) mod m/2."""
    return (np.arange(n) % m) % (m // 2)


def route_ground_truth(n: int, m: int, tolerance: int = 2) -> scipy.sparse.csr_array:
    """Sparse (n, n) bool ground truth of the first n frames of a recording of passes over a
    route of m frames whose two halves are the same places (Nordland: summer, then winter): frames
    t and u are a loop when their places ((t mod m) mod m/2) differ by at most ``tolerance``."""
    place = route_places(n, m)
    order = np.argsort(place, kind="stable")
    rows, cols = [], []
    bounds = np.searchsorted(place[order], np.arange(m // 2 + 1))
    for p in range(m // 2):
        a = order[bounds[p]:bounds[p + 1]]
        b = order[bounds[max(p - tolerance, 0)]:bounds[min(p + tolerance, m // 2 - 1) + 1]]
        rows.append(np.repeat(a, len(b)))
        cols.append(np.tile(b, len(a)))
    r, c = np.concatenate(rows), np.concatenate(cols)
    keep = r != c
    return scipy.sparse.csr_array((np.ones(keep.sum(), bool), (r[keep], c[keep])), shape=(n, n))


def long_run_metrics(X, m: int, n: int = 100_000, kinds=("scan", "hnsw"), k: int = K,
                     exclude: int = DEFAULT_EXCLUDE) -> pd.DataFrame:
    """Per-query metrics of single-frame retrieval over an n-frame stream, no N x N matrix:
    retrieval.stream_search (top-k lists, O(N k)) -> candidate_matches with the sparse
    :func:`route_ground_truth` -> evaluate.query_metrics, for each index kind."""
    X = X[:n]
    GT = route_ground_truth(len(X), m)
    rows = []
    for kind in kinds:
        (scores, ids), secs = timed(_stream_search, kind, X, k, exclude)
        met = evaluate.query_metrics(retrieval.candidate_matches(scores, ids, GT, exclude), ks=(1, 5, 10))
        rows.append({"frames": len(X), "index": kind, "k": k, "stream_s": secs,
                     **{key: (100 * v if key not in ("queries", "revisits") else v) for key, v in met.items()},
                     "topk_MB": (scores.nbytes + ids.nbytes) / 1e6, "GT_pairs": int(GT.nnz)})
    return pd.DataFrame(rows)


COLUMNS = ("stored", "method", "kind", "queries", "dim", "p50_ms", "p99_ms", "recall@1_%", "scanned_%",
           "bytes_per_frame")


def read_results(folder) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The committed benchmark, for notebook 11: (scale table, neighbourhood table) from
    ``folder``/scale.csv and neighbourhood.csv as ``make bench-scale`` writes them.

    scale: one row per (stored, method) with at least COLUMNS (latencies in ms, recall in %,
    bytes per stored frame). neighbourhood: the nearest-neighbour cosine quantiles of the real and
    augmented sets. Raises FileNotFoundError naming ``make bench-scale`` when either is missing,
    ValueError when a column is.
    """
    folder = Path(folder)
    paths = [folder / "scale.csv", folder / "neighbourhood.csv"]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"{', '.join(missing)} not found: run `make bench-scale` (about 20 min on "
                                f"2 cores) to measure the retrieval indexes, or point scale_results at "
                                f"the folder it wrote")
    table, nb = (pd.read_csv(p) for p in paths)
    lost = [c for c in COLUMNS if c not in table.columns]
    if lost:
        raise ValueError(f"{paths[0]} lacks columns {lost}: rerun `make bench-scale`")
    return table, nb


def crossover(table: pd.DataFrame, method: str, reference: str = "NumPy scan") -> int | None:
    """The smallest stored count at which ``method``'s median latency is below ``reference``'s
    (rows of :func:`read_results`), or None when it never is."""
    p = table.pivot(index="stored", columns="method", values="p50_ms")
    wins = p.index[p[method] < p[reference]]
    return int(wins.min()) if len(wins) else None


def targets(table: pd.DataFrame) -> pd.DataFrame:
    """The retrieval targets at the largest size (p99 <= 1 ms, recall@1 within 1 point of the exact scan, <= 1 KB per frame), per method: met / not met (measured values)."""
    big = table[table.stored == table.stored.max()]
    exact = big[big.kind == "scan"]["recall@1_%"].iloc[0]
    return pd.DataFrame([{"method": r.method, "stored": r.stored,
                          "p99 <= 1 ms": f"{'met' if r.p99_ms <= 1 else 'not met'} ({r.p99_ms:.3g} ms)",
                          "recall@1 within 1 pt of exact": f"{'met' if r['recall@1_%'] >= exact - 1 else 'not met'} "
                                                          f"({r['recall@1_%']:.1f} %)",
                          "<= 1 KB per frame": f"{'met' if r.bytes_per_frame <= 1024 else 'not met'} "
                                               f"({r.bytes_per_frame:.0f} B)"}
                         for _, r in big.iterrows()])


def lsh_vs_faiss(table: pd.DataFrame) -> list[str]:
    """One line per size: the RHLSH variants against the fastest faiss index with recall >= theirs."""
    lines = []
    for n, g in table.groupby("stored"):
        fa = g[g.kind.isin(["flat", "ivf", "hnsw"])]
        for _, r in g[g.kind.isin(["swp", "qdp"])].iterrows():
            ok = fa[fa["recall@1_%"] >= r["recall@1_%"]]
            if ok.empty:
                lines.append(f"- N = {n:,}: {r.method} (recall@1 {r['recall@1_%']:.1f} %, p99 {r.p99_ms:.3g} ms) "
                             f"has a higher recall@1 than every faiss index measured")
                continue
            b = ok.sort_values("p99_ms").iloc[0]
            verdict = "wins" if r.p99_ms < b.p99_ms else "loses"
            lines.append(f"- N = {n:,}: {r.method} {verdict}: p99 {r.p99_ms:.3g} ms at recall@1 "
                         f"{r['recall@1_%']:.1f} % (scanning {r['scanned_%']:.1f} % of the stored frames), "
                         f"against {b.method}'s {b.p99_ms:.3g} ms at {b['recall@1_%']:.1f} %; memory "
                         f"{r.bytes_per_frame:.0f} vs {b.bytes_per_frame:.0f} B per frame")
    return lines


def _plot(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for m, g in table.groupby("method", sort=False):
        line, = ax[0].loglog(g.stored, g.p99_ms, "o-", label=m)
        ax[0].loglog(g.stored, g.p50_ms, "x--", color=line.get_color(), lw=0.8)
        ax[1].semilogx(g.stored, g["recall@1_%"], "o-", label=m)
        ax[2].semilogx(g.stored, g.bytes_per_frame, "o-", label=m)
    ax[0].axhline(1.0, color="k", ls=":", lw=1)
    ax[2].axhline(1024, color="k", ls=":", lw=1)
    for a, t in zip(ax, ("search latency, k = 10 (ms): p99 solid, p50 dashed", "recall@1 vs exact scan (%)",
                         "index memory per stored frame (B)")):
        a.set_xlabel("stored frames")
        a.set_title(t)
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    report.save_figure(fig, path)
    plt.close(fig)


def _write(out: Path, table, nb, dim: int, n_real: int, seed: int, decide: pd.DataFrame | None = None,
           note: str = "", metrics: pd.DataFrame | None = None) -> None:
    report.write_atomic(out / "scale.csv", lambda p: table.to_csv(p, index=False))
    _plot(table, out / "scale.png")
    cols = ["stored", "method", "queries", "p50_ms", "p99_ms", "recall@1_%", "bytes_per_frame",
            "build_s", "insert_us", "scanned_%"]
    md = [f"# Scaling benchmark: candidate retrieval at {', '.join(f'{n:,}' for n in sorted(table.stored.unique()))} stored frames",
          "", f"Machine: {report.cpu_model()}, searches on 1 thread (faiss OpenMP and BLAS); "
              f"written {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} by `make bench-scale` "
              f"(greenloop.speed.scale). {note}".rstrip(), "",
          f"Descriptors: Nordland's {n_real} real 64x32 frames (summer, winter) augmented into passes over "
          f"the route (greenloop.datasets.augment, seed {seed}: per pass gain U(0.7, 1.3), offset U(-30, 30) "
          f"grey levels, Gaussian blur sigma U(0, 1.2) px; per frame zoom U(1, 1.1), shift U(-3, 3) px, "
          f"brightness jitter U(-8, 8), noise N(0, 4^2)); each frame -> pixels-patchnorm (32x32, 1024-d) "
          f"-> PCA to {dim} dims fitted on the real frames only -> L2. Stored: the first N frames of the "
          f"recording; queries: frames of a later pass (not stored). k = {K}.", "",
          "## Results", "", table[cols].to_markdown(index=False, floatfmt=".4g"), "",
          "p50/p99: per-query search latency (one query per call); recall@1: share of queries whose best "
          "candidate is the exact scan's (equal score within 1e-6 counts); bytes_per_frame: the index's "
          "memory / stored frames (faiss: serialize_index size; scan: its float32 buffer; RHLSH: rows, codes, "
          "the Python bucket table and the occupancy array); insert_us: mean time to add one frame to the "
          "built index; scanned_%: stored frames the LSH probes scanned per query. On a machine whose cores "
          "another job keeps busy, p99 holds the time slices a query waits for a core (a few ms whatever the "
          "index, even where p50 is tens of microseconds); p50 and the mean (scale.csv) show the index's own cost.", "",
          "![scale](scale.png)", "", "## Targets at the largest size", "",
          targets(table).to_markdown(index=False), "", "## RHLSH against faiss", "", *lsh_vs_faiss(table), "",
          "## Are the augmented descriptors realistic? Nearest-neighbour cosine quantiles", "",
          nb.to_markdown(index=False, floatfmt=".3f"), "",
          "Read it as: the first two rows compare one pass of augmented frames with the real frames at the "
          "same count; the others show how close a query's nearest stored frame is as N grows. Every pass "
          "revisits every place, so a larger store holds more near-copies of a query's place (its nearest "
          "neighbour grows more similar with N): the large stores are denser than one real traversal, which "
          "makes retrieval easier for every index alike. The real set's upper tail (q90 ~ 1) is exact "
          "duplicates, frames where the train stood still.", ""]
    if decide is not None:
        md += _decision_section(out, decide)
    if metrics is not None:
        report.write_atomic(out / "long_run_metrics.csv", lambda p: metrics.to_csv(p, index=False))
        md += ["## Per-query metrics of a long stream without an N x N matrix", "",
               f"Single-frame retrieval (k = {K}, exclusion {DEFAULT_EXCLUDE} frames) over the first {int(metrics.frames.iloc[0]):,} "
               "frames of the recording, scored from the (N, k) top-k lists (retrieval.candidate_matches -> "
               "evaluate.query_metrics, loop-closure mode) against a sparse ground truth: frames of the same "
               "place +-2 route frames in any pass or season (speed.scale.route_ground_truth). Metrics in %; "
               "topk_MB: the lists' memory (a dense float32 matrix would be 4 N^2 bytes).", "",
               metrics.to_markdown(index=False, floatfmt=".4g"), ""]
    report.write_atomic(out / "scale.md", "\n".join(md + stream_section(out / "scale.md")))


def stream_section(md: Path) -> list[str]:
    """The lines of ``md`` from :data:`STREAM_HEADING` on (the long CLI stream's section that
    ``make bench-stream`` writes, ``speed.long_stream``), kept when the benchmark rewrites scale.md."""
    lines = md.read_text().split("\n") if md.is_file() else []
    return next((lines[i:] for i, l in enumerate(lines) if l == STREAM_HEADING), [])


def _decision_section(out: Path, decide: pd.DataFrame) -> list[str]:
    """Write scale_decisions.{csv,png}; scale.md's lines on the whole decision (:func:`decisions`)."""
    report.write_atomic(out / "scale_decisions.csv", lambda p: decide.to_csv(p, index=False))
    _plot_decisions(decide, out / "scale_decisions.png")
    cols = ["stored", "method", "queries", "p50_ms", "p99_ms", "frames_per_s", "best_agree_%", "place_agree_%",
            "events_agree_%", "match_agree_%", "closures", "correct_%", "bytes_per_frame", "preload_s", "peak_rss_GB",
            "describe_p50_ms", "describe_p99_ms"]
    cols, r = [c for c in cols if c in decide.columns], decide.iloc[0]
    knobs, threshold = seqmatch.NAMED[DECISION_NAME]
    return ["## greenloop-seq's whole decision per frame with N frames stored: candidate mode against the exact scan", "",
            f"The named configuration {DECISION_NAME} as `detect --index` runs it ({knobs['descriptor']} of the same "
            f"augmented frames, centred over windows {list(knobs['center_window'])}, cell shift {knobs['cell_shift']}, "
            f"velocities {list(knobs['velocities'])}, repeat gate {knobs['repeat_cos']}, calibration "
            f"'{knobs['calibrate']}', fixed threshold {threshold:g}; exclude {DEFAULT_EXCLUDE}) in a seqstream.Detector preloaded "
            f"with the recording's first N descriptors (Detector.preload: the state streaming them leaves; "
            f"preload_s), then its next {int(r.queries):,} frames (a later pass: every one revisits the route) "
            f"streamed one per call. Exact scan: every stored frame scored (the reference). Candidate mode: k = "
            f"{K} rows retrieved per shifted query from an index holding the stored rows reduced to "
            f"{seqstream.INDEX_DIM} dims (a PCA fitted on the first {seqstream.INDEX_FIT} candidate rows), plus the "
            f"previous frame's best rows moved on, the rows around the best and a {seqstream.NULL_SAMPLE}-row sample "
            f"for the calibration's null; IVF's nlist and training frames as in the search table. p50 / p99: the "
            f"whole per-frame decision with the descriptor given (insert, search, verification, calibration, store, "
            f"threshold). best_agree_%: frames whose best match is within +-2 frames of the exact scan's; "
            f"place_agree_%: whose best match shows the exact scan's best's place (+-2 route frames; every pass "
            f"holds a copy of each place, so another pass's copy counts); events_agree_%: frames where both declare "
            f"a closure or both stay silent; match_agree_%: of the frames both declare, the match within +-2 "
            f"frames; correct_%: best match at the query's place +-2 route frames (route_ground_truth's rule). "
            f"bytes_per_frame: Detector.bytes_per_frame (the stored descriptor, {knobs['descriptor']} centred over "
            f"two windows and joined: 512 float32 = 2048 B, plus the index's copy in candidate mode or the "
            f"seq_len columns' 40 B in the exact scan; the store grows by doubling, so up to twice the descriptor's "
            f"part is allocated). peak_rss_GB: the benchmark process's peak memory so far (descriptors of the "
            f"whole recording included). describe_*: the descriptor's own cost per frame, measured apart "
            f"({knobs['descriptor']} of one decoded 64x32 frame per call).", "",
            decide[cols].to_markdown(index=False, floatfmt=".4g"), "", "![decisions](scale_decisions.png)", "",
            *_decision_budget(decide), "",
            "Targets at the largest size, the whole decision against the exact scan:", "",
            decision_targets(decide).to_markdown(index=False), ""]


def _decision_budget(decide: pd.DataFrame) -> list[str]:
    """What the largest size cost (memory, time), so that a size that would not fit is seen as such."""
    big = decide[decide.stored == decide.stored.max()]
    ex = big[big.kind == "exact"]
    said = [f"At {int(big.stored.iloc[0]):,} stored frames the benchmark peaked at {big.peak_rss_GB.max():.1f} GB "
            f"resident (the machine's memory: {_ram_gb():.0f} GB)"]
    if len(ex):
        said.append(f"the exact scan took {ex.stream_s.iloc[0]:.3g} s for its {int(ex.queries.iloc[0]):,} frames "
                    f"({ex.mean_ms.iloc[0]:.4g} ms per frame: it reads every stored row)")
    return ["; ".join(said) + ". Preload builds the stored rows and the index in 65,536-row chunks, so beyond the "
            "stored rows (N x 2048 B in each detector, one detector at a time) and the recording's raw descriptors "
            "(N x 1024 B) it holds little."]


def _ram_gb() -> float:
    """The machine's memory, GB (os.sysconf)."""
    import os
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9


def decision_targets(decide: pd.DataFrame) -> pd.DataFrame:
    """The whole decision's targets at the largest size, per candidate-mode method: p99 <= 1 ms, its
    best match and its closures agreeing with the exact scan's on >= 99 % of frames, and the memory
    per stored frame stated: met / not met (measured values)."""
    big = decide[(decide.stored == decide.stored.max()) & (decide.kind != "exact")]
    def mark(ok, what):
        return f"{'met' if ok else 'not met'} ({what})"
    return pd.DataFrame([{"method": r.method, "stored": r.stored, "p99 <= 1 ms": mark(r.p99_ms <= 1, f"{r.p99_ms:.3g} ms"),
                          "best match +-2 frames >= 99 %": mark(r["best_agree_%"] >= 99, f"{r['best_agree_%']:.1f} %"),
                          "same place >= 99 %": mark(r["place_agree_%"] >= 99, f"{r['place_agree_%']:.1f} %"),
                          "closures agree >= 99 %": mark(r["events_agree_%"] >= 99, f"{r['events_agree_%']:.1f} %"),
                          "bytes per stored frame": f"{r.bytes_per_frame:.0f} B"}
                         for _, r in big.iterrows()])


def _plot_decisions(decide: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for m, g in decide.groupby("method", sort=False):
        line, = ax.loglog(g.stored, g.p99_ms, "o-", label=m)
        ax.loglog(g.stored, g.p50_ms, "x--", color=line.get_color(), lw=0.8)
    ax.axhline(1.0, color="k", ls=":", lw=1)
    ax.set_xlabel("stored frames")
    ax.set_title("greenloop-seq decision per frame (ms): p99 solid, p50 dashed", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    report.save_figure(fig, path)
    plt.close(fig)
