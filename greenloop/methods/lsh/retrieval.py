"""Candidate retrieval: the k stored frames nearest a query, on an index made for it.

One interface, six implementations (``make_index(kind, dim, ...)``):

* ``"scan"``: the reference, an exact NumPy/BLAS cosine scan of every stored frame.
* ``"flat"``: faiss ``IndexFlatIP``, exact inner product (cosine: rows are L2-normalised here).
* ``"ivf"``: faiss ``IndexIVFFlat`` (inverted lists over ``nlist`` k-means cells, ``nprobe`` of
  them searched). A stream has no training set: the first ``train_size`` frames are scanned
  exactly (a flat index) until there are that many, then the coarse quantiser is trained on them
  and every frame moves into the IVF index. The same happens however the frames arrive: one
  ``add`` of N > train_size frames trains on the first train_size of them, as N single adds do.
* ``"hnsw"``: faiss ``IndexHNSWFlat`` (graph with ``M`` links per node, ``ef_search``,
  ``ef_construction``).
* ``"swp"`` / ``"qdp"``: the paper's random-hyperplane LSH with step-wise or query-directed
  probing (greenloop.methods.lsh.lsh, reused): the stored rows of the probed buckets, ranked by cosine.

Every index has ``add(X)`` (X (M, D) float rows, stored after the earlier ones: ids are the
order of arrival 0, 1, ...), ``search(Q, k) -> (scores (M, k) float32 cosine, ids (M, k) int64)``
(best first; ties: smaller id first for the exact ones; -inf / -1 where fewer than k stored
frames were found), ``n_stored``, ``exact`` (whether search equals the exact scan) and
``bytes_per_frame()`` (index memory divided by the frames stored: the faiss index as
``faiss.serialize_index`` writes it; the scan's buffer; for LSH the rows, codes and the Python
table).

The exclusion window (query t never sees frames t - exclude .. t) is handled by the caller
delaying insertion: frame i is added just before query i + exclude + 1 (:func:`stream_search`,
and ``greenloop.methods.greenloop_seq.seqstream.Detector`` with ``index=``).

Rows are L2-normalised in float32 on the way in (queries too), so every score is a cosine.
Searches run one query at a time on one thread in the streaming callers; call
``one_thread()`` once in a process that times them (faiss's OpenMP pool, one BLAS thread).
"""
from __future__ import annotations

import sys
import time

import faiss
import numpy as np
import scipy.sparse

from greenloop import evaluate
from greenloop.methods.lsh import lsh
from greenloop.similarity import l2_normalise
from greenloop.util.checks import positive_int

KINDS = ("scan", "flat", "ivf", "hnsw", "swp", "qdp")
EXACT = ("scan", "flat")

__all__ = ["KINDS", "EXACT", "make_index", "stream_search", "one_thread", "topk", "candidate_matches"]


def one_thread() -> None:
    """faiss on one OpenMP thread (per-query latency on a shared machine; BLAS callers use
    ``greenloop.util.threads.one_blas_thread``)."""
    faiss.omp_set_num_threads(1)


def _rows(X, dim: int, name: str = "X") -> np.ndarray:
    X = np.asarray(X)
    if X.ndim == 1:
        X = X.reshape(1, -1)
    if X.ndim != 2 or X.shape[1] != dim or not np.issubdtype(X.dtype, np.number):
        raise ValueError(f"{name} must be (M, {dim}) real descriptors (the index's dim), got "
                         f"shape {X.shape} dtype {X.dtype}")
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{name} contains NaN or inf; fix the descriptors first")
    return np.ascontiguousarray(l2_normalise(X.astype(np.float32, copy=False)), np.float32)


def topk(sims, ids, k: int):
    """The k best of one query's candidates: sims (C,) float32 cosines of the candidate ids (C,)
    int64. Returns (scores (k,) float32, ids (k,) int64), best first, ties: smaller id first,
    padded with -inf / -1 when C < k."""
    out_s, out_i = np.full(k, -np.inf, np.float32), np.full(k, -1, np.int64)
    if sims.size > k:
        keep = np.argpartition(-sims, k - 1)[:k]
        cut = sims[keep].min()                          # every candidate tied with the k-th
        keep = np.flatnonzero(sims >= cut)
        sims, ids = sims[keep], ids[keep]
    order = np.lexsort((ids, -sims))[:k]
    out_s[:order.size], out_i[:order.size] = sims[order], ids[order]
    return out_s, out_i


class _Scan:
    """Exact NumPy/BLAS scan: a float32 buffer of the stored rows (grows by doubling)."""
    exact = True

    def __init__(self, dim: int):
        self.dim, self.n_stored = dim, 0
        self._X = np.zeros((0, dim), np.float32)

    def add(self, X) -> None:
        Y = _rows(X, self.dim)
        n, m = self.n_stored, len(Y)
        if n + m > len(self._X):
            grown = np.zeros((max(2 * len(self._X), n + m), self.dim), np.float32)
            grown[:n] = self._X[:n]
            self._X = grown
        self._X[n:n + m] = Y
        self.n_stored = n + m

    def search(self, Q, k: int):
        Q, k = _rows(Q, self.dim, "Q"), positive_int("k", k, 1)
        S = self._X[:self.n_stored] @ Q.T                 # (n, M)
        ids = np.arange(self.n_stored, dtype=np.int64)
        pairs = [topk(S[:, q], ids, k) for q in range(len(Q))]
        return _stack(pairs, k)

    def vectors(self) -> np.ndarray:
        """The stored unit rows (n, D) float32 (a view)."""
        return self._X[:self.n_stored]

    def bytes_per_frame(self) -> float:
        return self._X.nbytes / max(self.n_stored, 1)


def _stack(pairs, k: int):
    if not pairs:
        return np.zeros((0, k), np.float32), np.zeros((0, k), np.int64)
    return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])


class _Faiss:
    """faiss flat / IVF / HNSW on inner product of unit rows (ids = arrival order)."""

    def __init__(self, kind: str, dim: int, nlist: int, nprobe: int, train_size: int, M: int,
                 ef_search: int, ef_construction: int):
        self.kind, self.dim, self.exact = kind, dim, kind == "flat"
        self.nlist, self.nprobe, self.train_size = nlist, nprobe, train_size
        if kind == "hnsw":
            self.index = faiss.IndexHNSWFlat(dim, M, faiss.METRIC_INNER_PRODUCT)
            self.index.hnsw.efSearch, self.index.hnsw.efConstruction = ef_search, ef_construction
        else:                      # ivf starts flat, exact, until train_size frames arrived
            self.index = faiss.IndexFlatIP(dim)
        self.trained = kind != "ivf"

    @property
    def n_stored(self) -> int:
        return int(self.index.ntotal)

    def __setstate__(self, state: dict) -> None:
        """Unpickling (a resumed stream): faiss does not serialise HNSW's level generator, so
        its draws (one per stored frame) are replayed, and frames added after a resume get the
        levels, hence the graph, of an uninterrupted run."""
        self.__dict__.update(state)
        if self.kind == "hnsw":
            rng = self.index.hnsw.rng
            for _ in range(self.index.ntotal):
                rng.rand_float()

    def add(self, X) -> None:
        Y = _rows(X, self.dim)
        if not self.trained:       # the quantiser learns the first train_size frames, however added
            head = self.train_size - self.index.ntotal
            self.index.add(Y[:head])
            Y = Y[head:]
            if self.index.ntotal >= self.train_size:
                self._train()
        if len(Y):
            self.index.add(Y)

    def _train(self) -> None:
        """IVF: train the coarse quantiser on the train_size frames stored flat, move them in."""
        flat = self.index
        Y = flat.reconstruct_n(0, flat.ntotal)
        quantiser = faiss.IndexFlatIP(self.dim)
        ivf = faiss.IndexIVFFlat(quantiser, self.dim, self.nlist, faiss.METRIC_INNER_PRODUCT)
        ivf.cp.seed = 0
        ivf.train(Y)
        ivf.add(Y)
        ivf.nprobe = self.nprobe
        self._quantiser, self.index, self.trained = quantiser, ivf, True

    def search(self, Q, k: int):
        Q, k = _rows(Q, self.dim, "Q"), positive_int("k", k, 1)
        D, I = self.index.search(Q, k)
        D = np.where(I >= 0, D, -np.inf).astype(np.float32)
        return D, I.astype(np.int64)

    def bytes_per_frame(self) -> float:
        return faiss.serialize_index(self.index).nbytes / max(self.n_stored, 1)


class _Lsh:
    """The paper's RHLSH (greenloop.methods.lsh.lsh): a growing BucketIndex, candidates ranked by cosine."""
    exact = False

    def __init__(self, kind: str, dim: int, n_bits: int, seed: int, radius: int, qdp_probes, offset):
        self.dim, self.o = dim, lsh.options(kind, radius, qdp_probes)
        H = lsh.hyperplanes(dim, n_bits, seed)
        self.index = lsh.build_index(np.zeros((1, dim), np.float32), H, n_stored=0, offset=offset)
        self.last_scanned = 0

    @property
    def n_stored(self) -> int:
        return self.index.n_stored

    def add(self, X) -> None:
        lsh.append(self.index, _rows(X, self.dim))

    def search(self, Q, k: int):
        Q, k = _rows(Q, self.dim, "Q"), positive_int("k", k, 1)
        pairs = []
        for q in Q:
            rows = lsh.probe_candidates(self.index, q, self.o)[0] if self.n_stored else np.zeros(0, np.int64)
            self.last_scanned = rows.size
            pairs.append(topk(self.index.Xn[rows] @ q, rows, k))
        return _stack(pairs, k)

    def bytes_per_frame(self) -> float:
        ix, n = self.index, max(self.index.n_stored, 1)
        table = sys.getsizeof(ix.table) + sum(sys.getsizeof(v) for v in ix.table.values())
        ints = 28 * max(ix.n_stored - 257, 0)                 # a Python int object per row id
        dense = 0 if ix.occupied is None else ix.occupied.nbytes
        return (ix.Xn.nbytes + ix.codes.nbytes + table + ints + dense) / n


def make_index(kind: str, dim: int, nlist: int = 1024, nprobe: int = 16, train_size: int | None = None,
               M: int = 32, ef_search: int = 64, ef_construction: int = 40, n_bits: int = 16,
               seed: int = 0, radius: int = 4, qdp_probes=(1000, 1500, 500), offset=None):
    """An empty index of ``kind`` (one of KINDS) over dim-dimensional descriptors.

    ivf: nlist cells, nprobe searched, trained on the first train_size frames (default
    40 * nlist; exact flat search until then). hnsw: M links, ef_search, ef_construction.
    swp / qdp: n_bits hyperplanes (seed), Hamming radius (SWP), qdp_probes (QDP, Table 5's
    (small, large, threshold)), offset None or (D,) the point the hyperplanes pass through
    (see greenloop.methods.lsh.lsh). Returns the index object (add / search / n_stored / exact /
    bytes_per_frame, module doc).
    """
    dim = positive_int("dim", dim, 1)
    if kind == "scan":
        return _Scan(dim)
    if kind in ("flat", "ivf", "hnsw"):
        nlist = positive_int("nlist", nlist, 1)
        train = 40 * nlist if train_size is None else positive_int("train_size", train_size, nlist)
        return _Faiss(kind, dim, nlist, positive_int("nprobe", nprobe, 1), train,
                      positive_int("M", M, 2), positive_int("ef_search", ef_search, 1),
                      positive_int("ef_construction", ef_construction, 1))
    if kind in ("swp", "qdp"):
        return _Lsh(kind, dim, n_bits, seed, radius, qdp_probes, offset)
    raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")


def stream_search(index, X, k: int = 10, exclude: int = 0, timed: bool = False):
    """Run a recording through an index as a robot does: frame t searches the frames stored so
    far, none within ``exclude`` frames of it (frame t - exclude - 1 is added just before query
    t). index: an empty :func:`make_index`; X: (N, D) descriptors in capture order.
    Returns (scores (N, k) float32, ids (N, k) int64 (-1 where fewer than k were stored), and
    with timed (N,) float64 seconds per frame: the insert plus the search, wall clock).
    Memory O(N k) beyond the index: no N x N matrix."""
    X = np.asarray(X)
    k, exclude = positive_int("k", k, 1), positive_int("exclude", exclude, 0)
    n = len(X)
    scores, ids = np.full((n, k), -np.inf, np.float32), np.full((n, k), -1, np.int64)
    secs = np.zeros(n)
    for t in range(n):
        t0 = time.perf_counter()
        if t - exclude - 1 >= 0:
            index.add(X[t - exclude - 1])
        if index.n_stored:
            s, i = index.search(X[t], k)
            scores[t], ids[t] = s[0], i[0]
        secs[t] = time.perf_counter() - t0
    return (scores, ids, secs) if timed else (scores, ids)


def candidate_matches(scores, ids, GT, exclude: int = 0) -> evaluate.Matches:
    """Per-query matches (``evaluate.matches``) of a loop-closure stream from its top-k lists.

    scores, ids: (N, k) from :func:`stream_search` (query t = frame t; ids -1 where fewer than k
    frames were stored); GT: the ground truth as a sparse (N, N) bool matrix (scipy.sparse; a
    dense bool array is converted), memory O(pairs). exclude: the window stream_search used, so
    that has_partner counts partners i < t - exclude, whether retrieved or not. Queries with no
    candidate (t <= exclude) are left out, as in ``evaluate.best_matches``. hit_rank: the rank of
    the first partner in the list, k when none is in it. Memory O(N k): no N x N matrix; feed the
    result to ``evaluate.query_metrics``.
    """
    scores, ids = np.asarray(scores), np.asarray(ids)
    if scores.shape != ids.shape or ids.ndim != 2:
        raise ValueError(f"scores and ids must be (N, k) arrays of one shape, got {scores.shape} and {ids.shape}")
    n, k = ids.shape
    G = scipy.sparse.csr_array(GT, dtype=bool)
    if G.shape != (n, n):
        raise ValueError(f"GT must be ({n}, {n}) for {n} queries, got shape {G.shape}")
    exclude = positive_int("exclude", exclude, 0)
    q = np.flatnonzero(ids[:, 0] >= 0)
    hit = np.zeros((len(q), k), bool)
    has = np.zeros(len(q), bool)
    for r, t in enumerate(q):
        partners = G.indices[G.indptr[t]:G.indptr[t + 1]]       # column t's partners (GT symmetric)
        has[r] = np.any(partners < t - exclude)
        hit[r] = np.isin(ids[t], partners) & (ids[t] >= 0)
    rank = np.where(hit.any(1), hit.argmax(1), k)
    return evaluate.matches(q, ids[q, 0], scores[q, 0], hit[:, 0], has, rank, k)
