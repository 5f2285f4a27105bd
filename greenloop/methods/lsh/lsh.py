"""Random-hyperplane LSH with multi-probe matching (Qi 2024, Sec. 2.2 and 3.2, Tables 5-6).

What it does
------------
Each descriptor x (a row of ``X``, shape ``(N, D)``) is hashed by ``n_bits`` random hyperplanes
through the origin (normals ``H[:, j]`` drawn from N(0, I), Qi 2024 Sec. 2.2): bit j is
``x . H[:, j] >= 0`` and the frame's code is the integer ``sum_j bit_j << j`` (uint32). Frames with
the same code share a bucket of a dict-of-lists table. A query probes a sequence of buckets and
scans the frames it finds there linearly by cosine similarity; its match is the best-scoring one.
Beyond the paper, ``offset`` (``centre_frames`` in ``incremental_match``) moves every hyperplane
to pass through a given point, e.g. the mean of the first frames: non-negative descriptors all
lie in one orthant, where planes through the origin separate few of them.

Probe sequences (both start with the query's own bucket):

* **SWP** (step-wise probing): every bucket within Hamming distance 0, 1, ..., ``radius`` of the
  query's code (Table 5: ``m = 4``; 16 bits give 1 + 16 + 120 + 560 + 1820 = 2517 buckets).
* **QDP** (query-directed probing, Lv et al. 2007 "Multi-probe LSH", Sec. 4.3-4.4): bit j costs
  the query's distance to hyperplane j (``qdp_costs``); a perturbation set (the bits flipped)
  costs the sum of its bits' costs; the ``M`` cheapest sets are generated in cost order by the
  shift/expand min-heap over the bits sorted by cost (``perturbation_sets``; compiled with numba
  where it is installed, else Python's heapq: the same sets in the same order). ``M`` follows the
  paper's rule on the number of non-empty buckets N1 (``qdp_n_probes``).

Matching as a robot runs it (``incremental_match``): frame t queries the frames stored so far,
never its recent neighbours ``|i - t| <= exclude``, and is then stored. The exact baselines are a
NumPy brute-force cosine scan (the arithmetic of ``similarity.cosine_matrix``) and scikit-learn's
``NearestNeighbors(metric="cosine", algorithm="brute")``. ``query_index`` / ``static_match`` query
a table filled all at once (the scaling test). Every query is timed on one BLAS thread.

Why this module exists: no maintained Python library does what the paper describes. FALCONN has
hyperplane LSH with multi-probe but its last release (2017) ships no wheel for current Pythons;
faiss's ``IndexBinaryHash`` probes Hamming balls but ranks candidates by Hamming distance, not by
the cosine of the real descriptors, and has no query-directed order.

Conventions: descriptors are float (any dtype; scanned in float32 after L2 normalisation), codes
uint32, indices int64, times in seconds (wall clock, ``time.perf_counter``). Bad input raises
``ValueError`` naming the problem.
"""
from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from greenloop.similarity import l2_normalise
from greenloop.util import numba_kernels
from greenloop.util.checks import positive_int
from greenloop.util.threads import one_blas_thread

__all__ = [
    "MAX_BITS", "METHODS", "hyperplanes", "codes", "hamming_masks", "probe_order_swp", "qdp_costs",
    "perturbation_sets", "probe_order_qdp", "qdp_n_probes", "BucketIndex", "build_index", "insert",
    "append", "options", "probe_candidates",
    "MatchResult", "incremental_match", "query_index", "static_match",
]

MAX_BITS = 32                       # codes are uint32
DENSE_BITS = 24                     # up to this many bits, bucket occupancy is a dense bool array
METHODS = ("brute", "sklearn", "swp", "qdp")
NO_MATCH = -1                       # best index of a query that found no candidate (score -inf)


# ----------------------------------------------------------------------------------- checks
def _check_H(H) -> np.ndarray:
    H = np.asarray(H, dtype=np.float64)
    if H.ndim != 2 or not 1 <= H.shape[1] <= MAX_BITS or H.shape[0] < 1:
        raise ValueError(f"H must be (D, n_bits) hyperplane normals with 1 <= n_bits <= {MAX_BITS} "
                         f"(from lsh.hyperplanes), got shape {H.shape}")
    return H


def _check_X(X, H: np.ndarray, name: str = "X") -> np.ndarray:
    X = np.asarray(X)
    if X.ndim != 2 or not np.issubdtype(X.dtype, np.number) or np.iscomplexobj(X):
        raise ValueError(f"{name} must be a real (N, D) array, one descriptor per row, got "
                         f"shape {X.shape} dtype {X.dtype}")
    if X.shape[1] != H.shape[0]:
        raise ValueError(f"{name} has D={X.shape[1]} dims but the hyperplanes have "
                         f"{H.shape[0]}; draw them with lsh.hyperplanes({X.shape[1]}, n_bits)")
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{name} contains NaN or inf; fix the descriptors first")
    return X


# ----------------------------------------------------------------------------- hashing
def hyperplanes(dim: int, n_bits: int = 16, seed: int = 0) -> np.ndarray:
    """Random hyperplane normals: (dim, n_bits) float64, i.i.d. N(0, 1) entries (seeded
    ``numpy.random.default_rng(seed)``), so every direction is equally likely (Qi 2024 Sec. 2.2).
    n_bits: 1 ..  MAX_BITS (32). Table 5 uses 16."""
    dim = positive_int("dim", dim, 1)
    n_bits = positive_int("n_bits", n_bits, 1, MAX_BITS)
    return np.random.default_rng(seed).standard_normal((dim, n_bits))


def codes(X, H, offset=None) -> np.ndarray:
    """Hash codes of descriptors: (N,) uint32, bit j = ``(X[i] - offset) . H[:, j] >= 0``.

    X: (N, D) descriptors (with offset None, any scale: the sign of a projection ignores it).
    H: (D, n_bits) from :func:`hyperplanes`. offset: None (hyperplanes through the origin, as
    in the paper) or (D,) a point every hyperplane passes through instead.
    Raises ValueError on wrong dims or non-finite values.
    """
    H = _check_H(H)
    X = _check_X(X, H)
    X = X if X.dtype == np.float32 else X.astype(np.float64)
    if offset is not None:
        X = X - _check_X(np.asarray(offset, X.dtype).reshape(1, -1), H, "offset")
    bits = (X @ H.astype(X.dtype)) >= 0
    weights = np.left_shift(np.uint64(1), np.arange(H.shape[1], dtype=np.uint64))
    return (bits.astype(np.uint64) @ weights).astype(np.uint32)


# ------------------------------------------------------------------------------ SWP
@lru_cache(maxsize=32)
def _masks(n_bits: int, radius: int) -> np.ndarray:
    out = [sum(1 << b for b in combo) for r in range(radius + 1)
           for combo in itertools.combinations(range(n_bits), r)]
    a = np.array(out, dtype=np.uint32)
    a.setflags(write=False)
    return a


def hamming_masks(n_bits: int, radius: int) -> np.ndarray:
    """XOR masks of every code within Hamming distance ``radius``: (P,) uint32, read-only,
    ordered by distance 0, 1, ..., radius (within one distance: lexicographic bit combinations),
    P = sum_{r <= radius} C(n_bits, r). radius: 0 .. n_bits."""
    n_bits = positive_int("n_bits", n_bits, 1, MAX_BITS)
    radius = positive_int("radius", radius, 0, n_bits)
    return _masks(n_bits, radius)


def probe_order_swp(code: int, n_bits: int = 16, radius: int = 4) -> np.ndarray:
    """Step-wise probing sequence of one query: (P,) uint32 bucket codes, the query's own code
    first, then every code at Hamming distance 1, 2, ..., radius (Table 5: radius m = 4)."""
    masks = hamming_masks(n_bits, radius)
    return np.uint32(positive_int("code", code, 0, (1 << n_bits) - 1)) ^ masks


# ------------------------------------------------------------------------------ QDP
def qdp_costs(q, H, score: str = "margin", theta: float = np.pi / 4) -> np.ndarray:
    """Per-bit flip costs of one query for query-directed probing: (n_bits,) float64 >= 0.

    q: (D,) query descriptor (any scale; it is L2-normalised). H: (D, n_bits).
    score: ``"margin"``: the unit query's distance to hyperplane j, ``|q . h_j| / ||h_j||``
        (Lv et al. 2007: flipping the bit whose boundary is nearest is most likely to find a
        neighbour); ``"log_odds"``: Qi 2024 Eq. 1-2, ``log(P_j / (1 - P_j))`` with
        ``P_j = Phi(|q . h_j| / (||q|| tan theta))`` the probability that a neighbour at angle
        ``theta`` (radians, in (0, pi/2)) falls on the query's side of hyperplane j. Both grow
        with the margin, but their sums order multi-bit sets differently.
    """
    H = _check_H(H)
    q = _check_X(np.asarray(q).reshape(1, -1), H, "q")[0].astype(np.float64)
    nq = np.linalg.norm(q)
    proj = np.abs(q @ H) / (nq if nq > 0 else 1.0)
    if score == "margin":
        return proj / np.linalg.norm(H, axis=0)
    if score == "log_odds":
        if not 0 < theta < np.pi / 2:
            raise ValueError(f"theta must be in (0, pi/2) radians, got {theta}")
        from scipy.stats import norm
        z = proj / np.tan(theta)
        return np.maximum(norm.logcdf(z) - norm.logsf(z), 0.0)
    raise ValueError(f"score must be 'margin' or 'log_odds', got {score!r}")


def _heap_python(c: np.ndarray, order: np.ndarray, n: int):
    """The shift/expand min-heap over the costs c (k,) sorted by ``order``: the n cheapest
    sets as (flips (n,) uint32 XOR masks over the bits, scores (n,) float64)."""
    z = c[order].tolist()
    k = len(z)
    heap, pos_masks, scores = [(z[0], 0, 1)], [], []
    push, replace, pop = heapq.heappush, heapq.heapreplace, heapq.heappop
    for _ in range(n):
        s, top, mask = heap[0]                         # entry: (score, largest position, set)
        pos_masks.append(mask)
        scores.append(s)
        if top + 1 < k:
            nxt, z1 = 1 << (top + 1), z[top + 1]
            replace(heap, (s - z[top] + z1, top + 1, (mask ^ (1 << top)) | nxt))   # shift
            push(heap, (s + z1, top + 1, mask | nxt))                              # expand
        else:
            pop(heap)
    pm = np.array(pos_masks, dtype=np.uint64)               # sets of sorted positions -> bits
    bits = (pm[:, None] >> np.arange(k, dtype=np.uint64)) & np.uint64(1)
    flips = bits @ np.left_shift(np.uint64(1), order.astype(np.uint64))
    return flips.astype(np.uint32), np.array(scores, dtype=np.float64)


@lru_cache(maxsize=1)
def _heap_compiled():
    """The same heap compiled with numba (arrays instead of tuples; the pop order is that of
    the tuples (score, largest position, set), a strict total order, so it is identical), or
    None without numba. Compiled and run once here, so no timed query pays the compilation."""
    if not numba_kernels.available():
        return None
    from numba import njit

    @njit(cache=True, nogil=True)
    def sets(z, order, n, out_flip, out_score):
        # heap entries: score hs, tie key hk = top << 32 | mask (the tuple order (score, top, mask))
        k, low = z.size, (np.int64(1) << 32) - 1
        hs, hk = np.empty(n + 2), np.empty(n + 2, np.int64)
        hs[0], hk[0], size = z[0], 1, 1
        for i in range(n):
            s, top, mask = hs[0], hk[0] >> 32, hk[0] & low
            flip = np.int64(0)
            for p in range(top + 1):
                if (mask >> p) & 1:
                    flip |= np.int64(1) << order[p]
            out_flip[i], out_score[i] = flip, s
            grow = top + 1 < k
            if grow:                                   # root := shift(A); expand(A) pushed below
                nxt, z1 = np.int64(1) << (top + 1), z[top + 1]
                shifted = (mask ^ (np.int64(1) << top)) | nxt
                hs[0], hk[0] = s - z[top] + z1, ((top + 1) << 32) | shifted
            else:                                      # root := last entry
                size -= 1
                hs[0], hk[0] = hs[size], hk[size]
            j = 0                                      # sift the root down
            while 2 * j + 1 < size:
                c = 2 * j + 1
                d = c + 1
                if d < size and (hs[d] < hs[c] or (hs[d] == hs[c] and hk[d] < hk[c])):
                    c = d
                if not (hs[c] < hs[j] or (hs[c] == hs[j] and hk[c] < hk[j])):
                    break
                hs[c], hs[j], hk[c], hk[j] = hs[j], hs[c], hk[j], hk[c]
                j = c
            if grow:                                   # push expand(A) and sift it up
                j = size
                hs[j], hk[j] = s + z1, ((top + 1) << 32) | mask | nxt
                size += 1
                while j > 0:
                    u = (j - 1) // 2
                    if not (hs[j] < hs[u] or (hs[j] == hs[u] and hk[j] < hk[u])):
                        break
                    hs[u], hs[j], hk[u], hk[j] = hs[j], hs[u], hk[j], hk[u]
                    j = u

    def run(c: np.ndarray, order: np.ndarray, n: int):
        out_flip, out_score = np.empty(n, np.int64), np.empty(n)
        sets(c[order], order.astype(np.int64), n, out_flip, out_score)
        return out_flip.astype(np.uint32), out_score

    run(np.array([0.3, 0.1, 0.2]), np.array([1, 2, 0]), 7)
    return run


def perturbation_sets(costs, n_sets: int, compiled: bool | None = None):
    """The ``n_sets`` cheapest non-empty sets of bits to flip, in non-decreasing total cost.

    costs: (k,) float >= 0, the cost of flipping each bit (:func:`qdp_costs`). Generated as in
    Lv et al. 2007 (Fig. 5): sort the bits by cost; start the min-heap with {1st cheapest};
    each pop yields a set A and pushes shift(A) (its largest position replaced by the next) and
    expand(A) (the next position added). Every non-empty subset is reached exactly once, so
    ``n_sets`` is capped at 2**k - 1. compiled: None = the numba heap where numba is installed,
    else Python's heapq; True / False force one (same output).
    Returns (flips (n,) uint32 XOR masks over the original bit positions, scores (n,) float64).
    """
    c = np.asarray(costs, dtype=np.float64)
    if c.ndim != 1 or not 1 <= c.size <= MAX_BITS or np.any(~np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"costs must be (k,) finite values >= 0 with 1 <= k <= {MAX_BITS}, got "
                         f"shape {c.shape}")
    k = c.size
    n = min(positive_int("n_sets", n_sets, 0), (1 << k) - 1)
    order = np.argsort(c, kind="stable")
    fast = _heap_compiled() if compiled in (None, True) else None
    if compiled and fast is None:
        raise ValueError("compiled=True needs numba, which is not installed")
    return (fast or _heap_python)(c, order, n)


def probe_order_qdp(code: int, costs, n_probes: int):
    """Query-directed probing sequence of one query: the query's own bucket (cost 0), then the
    buckets of its ``n_probes`` cheapest perturbation sets (:func:`perturbation_sets`).
    Returns (probes (1 + n,) uint32 bucket codes, scores (1 + n,) float64 non-decreasing)."""
    flips, scores = perturbation_sets(costs, n_probes)
    code = positive_int("code", code, 0, (1 << np.size(costs)) - 1)
    probes = np.concatenate([[np.uint32(code)], np.uint32(code) ^ flips]).astype(np.uint32)
    return probes, np.concatenate([[0.0], scores])


def qdp_n_probes(n_buckets: int, small: int = 1000, large: int = 1500, threshold: int = 500) -> int:
    """The probing count M of QDP as a function of the number of non-empty buckets N1.

    Qi 2024 Table 5: M = 1000 when N1 < 500, 1500 when N1 >= 500 (the defaults). Its text
    (Sec. 2.2) states the reverse (1000 above 500 buckets, else 1500): pass
    ``small=1500, large=1000`` for that reading.
    """
    n_buckets = positive_int("n_buckets", n_buckets, 0)
    small, large = positive_int("small", small, 0), positive_int("large", large, 0)
    return small if n_buckets < positive_int("threshold", threshold, 0) else large


# ------------------------------------------------------------------------ bucket index
@dataclass
class BucketIndex:
    """A hash table over the rows of one descriptor array, filled in capture order.

    H: (D, n_bits) float64 hyperplanes; H32 the same in float32 (hashing the queries).
    Xn: (N, D) float32 L2-normalised descriptors of every frame that may be stored (row i =
    frame i); codes: (N,) uint32 their hash codes. n_stored: rows 0 .. n_stored - 1 are stored.
    offset: None or (D,) float32, the point the hyperplanes pass through (see :func:`codes`);
    it moves the bucket boundaries only: matches are still scored by the cosine of Xn rows.
    table: {code: [row, ...]} of the stored rows (a dict of lists). occupied: (2**n_bits,) bool,
    True where a bucket is non-empty (None above DENSE_BITS bits: the dict is asked instead).
    bit_values (n_bits,) int64 = 2**j and h_norms (n_bits,) = ||H[:, j]|| are derived.
    nn / nn_rows: the scikit-learn NearestNeighbors fitted on the first ``nn_rows`` rows.
    """
    H: np.ndarray
    H32: np.ndarray
    Xn: np.ndarray
    codes: np.ndarray
    n_stored: int = 0
    offset: np.ndarray | None = None
    table: dict = field(default_factory=dict)
    occupied: np.ndarray | None = None
    nn: object = None
    nn_rows: int = -1

    def __post_init__(self):
        self.bit_values = np.left_shift(1, np.arange(self.n_bits, dtype=np.int64))
        self.h_norms = np.linalg.norm(self.H, axis=0)
        self.bias = None if self.offset is None else self.offset @ self.H32

    @property
    def n_bits(self) -> int:
        return int(self.H.shape[1])

    @property
    def n_buckets(self) -> int:
        """N1: the number of non-empty buckets."""
        return len(self.table)


def build_index(X, H, n_stored: int | None = None, offset=None) -> BucketIndex:
    """A :class:`BucketIndex` over X (N, D) with hyperplanes H (D, n_bits), its first
    ``n_stored`` rows stored (None: all of them; 0: none, fill with :func:`insert`).
    offset: None or (D,), subtracted from the L2-normalised rows before hashing."""
    H = _check_H(H)
    X = _check_X(X, H)
    if X.shape[0] == 0:
        raise ValueError("X is empty: need at least one descriptor")
    Xn = np.ascontiguousarray(l2_normalise(X.astype(np.float32, copy=False)))
    n = X.shape[0] if n_stored is None else positive_int("n_stored", n_stored, 0, X.shape[0])
    if offset is not None:
        offset = _check_X(np.asarray(offset, np.float32).reshape(1, -1), H, "offset")[0]
    c = codes(Xn, H, offset)
    dense = np.zeros(1 << H.shape[1], bool) if H.shape[1] <= DENSE_BITS else None
    idx = BucketIndex(H=H, H32=H.astype(np.float32), Xn=Xn, codes=c, n_stored=n, offset=offset,
                      occupied=dense)
    if n:
        order = np.argsort(c[:n], kind="stable")
        uniq, starts = np.unique(c[order], return_index=True)
        idx.table = {int(u): s.tolist() for u, s in zip(uniq, np.split(order, starts[1:]))}
        if idx.occupied is not None:
            idx.occupied[uniq] = True
    return idx


def append(index: BucketIndex, X) -> None:
    """Add the rows X (M, D) after those already stored (a stream's new frames): they are
    L2-normalised, hashed with the index's hyperplanes and offset, and stored in order. Xn and
    codes grow by doubling, so rows beyond the stored ones are spare capacity."""
    X = _check_X(X, index.H)
    n, m = index.n_stored, X.shape[0]
    if n + m > len(index.Xn):
        cap = max(2 * len(index.Xn), n + m)
        Xn, c = np.zeros((cap, index.Xn.shape[1]), np.float32), np.zeros(cap, np.uint32)
        Xn[:n], c[:n] = index.Xn[:n], index.codes[:n]
        index.Xn, index.codes = Xn, c
    index.Xn[n:n + m] = l2_normalise(X.astype(np.float32, copy=False))
    index.codes[n:n + m] = codes(index.Xn[n:n + m], index.H, index.offset)
    for i in range(n, n + m):
        insert(index, i)


def insert(index: BucketIndex, i: int) -> None:
    """Store row i of ``index.Xn`` (rows are stored in capture order: i must be n_stored)."""
    if i != index.n_stored:
        raise ValueError(f"frames are stored in capture order: the next row is "
                         f"{index.n_stored}, got {i}")
    c = int(index.codes[i])
    index.table.setdefault(c, []).append(i)
    if index.occupied is not None:
        index.occupied[c] = True
    index.n_stored += 1


def options(method, radius=4, qdp_probes=(1000, 1500, 500), qdp_score="margin",
            theta=np.pi / 4) -> dict:
    """The validated matching options of one method (a dict for :func:`probe_candidates`):
    method in METHODS, radius (SWP), qdp_probes / qdp_score / theta (QDP), as in
    :func:`incremental_match`. Loads the compiled QDP heap now, so no timed query pays for it."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    radius = positive_int("radius", radius, 0)
    if len(tuple(qdp_probes)) != 3:
        raise ValueError(f"qdp_probes must be (small, large, threshold) for qdp_n_probes, got "
                         f"{qdp_probes!r}")
    qdp_n_probes(0, *qdp_probes)                       # validates the three integers
    if method == "qdp":
        _heap_compiled()                               # load/compile now, not in a timed query
    if qdp_score not in ("margin", "log_odds") or not 0 < theta < np.pi / 2:
        raise ValueError(f"qdp_score must be 'margin' or 'log_odds' and theta in (0, pi/2), got "
                         f"{qdp_score!r}, {theta}")
    return dict(method=method, radius=radius, qdp_probes=tuple(int(v) for v in qdp_probes),
                qdp_score=qdp_score, theta=float(theta))


def _probes(index: BucketIndex, qn: np.ndarray, o: dict) -> np.ndarray:
    """The probing sequence (P,) uint32 of the unit float32 query qn for method swp / qdp."""
    proj = qn @ index.H32
    if index.bias is not None:
        proj = proj - index.bias
    code = int(np.dot(proj >= 0, index.bit_values))
    if o["method"] == "swp":
        return np.uint32(code) ^ _masks(index.n_bits, min(o["radius"], index.n_bits))
    if o["qdp_score"] == "margin":                     # qdp_costs without re-validating q
        costs = np.abs(proj.astype(np.float64)) / index.h_norms
    else:
        costs = qdp_costs(qn if index.offset is None else qn - index.offset, index.H, "log_odds",
                          o["theta"])
    return probe_order_qdp(code, costs, qdp_n_probes(index.n_buckets, *o["qdp_probes"]))[0]


def _gather(index: BucketIndex, probes: np.ndarray) -> np.ndarray:
    """The stored rows (k,) int64 of the probed buckets, bucket by bucket in probing order."""
    table = index.table
    if index.occupied is not None:
        hit = probes[index.occupied[probes]].tolist()
    else:
        hit = [c for c in probes.tolist() if c in table]
    return np.fromiter(itertools.chain.from_iterable(table[c] for c in hit), np.int64)


def probe_candidates(index: BucketIndex, qn, o: dict):
    """The rows SWP or QDP scans for one query: (rows (k,) int64 stored rows of the probed
    buckets, number of buckets probed). qn: (D,) float32 unit query; o: :func:`options` of
    method "swp" or "qdp" (the cosine scan of those rows is the caller's)."""
    if o["method"] not in ("swp", "qdp"):
        raise ValueError(f"probe_candidates needs method 'swp' or 'qdp', got {o['method']!r}")
    probes = _probes(index, np.asarray(qn, np.float32), o)
    return _gather(index, probes), int(probes.size)


def _search(index: BucketIndex, qn: np.ndarray, o: dict):
    """One unit float32 query qn (D,) against the stored rows.
    Returns (best row or NO_MATCH, its cosine or -inf, scanned rows (k,) int64 or None for
    "every stored row", number scanned, number of buckets probed, seconds spent making the
    probing sequence)."""
    n = index.n_stored
    if n == 0:
        return NO_MATCH, -np.inf, None, 0, 0, 0.0
    if o["method"] == "brute":
        sims = index.Xn[:n] @ qn
        j = int(sims.argmax())
        return j, float(sims[j]), None, n, 0, 0.0
    if o["method"] == "sklearn":
        if index.nn_rows != n:                         # no incremental add: refit on the prefix
            from sklearn.neighbors import NearestNeighbors
            index.nn = NearestNeighbors(n_neighbors=1, metric="cosine", algorithm="brute")
            index.nn.fit(index.Xn[:n])
            index.nn_rows = n
        d, ind = index.nn.kneighbors(qn[None, :], n_neighbors=1)
        return int(ind[0, 0]), float(1.0 - d[0, 0]), None, n, 0, 0.0
    t0 = time.perf_counter()
    probes = _probes(index, qn, o)
    t_probe = time.perf_counter() - t0
    cand = _gather(index, probes)
    if cand.size == 0:
        return NO_MATCH, -np.inf, cand, 0, probes.size, t_probe
    sims = index.Xn[cand] @ qn
    j = int(sims.argmax())
    return int(cand[j]), float(sims[j]), cand, int(cand.size), int(probes.size), t_probe


# ------------------------------------------------------------------------------ matching
@dataclass(frozen=True)
class MatchResult:
    """Per-query results of :func:`incremental_match` or :func:`static_match` (Q queries).

    method: "brute" | "sklearn" | "swp" | "qdp". best: (Q,) int64 matched row (NO_MATCH = -1
    where nothing was scanned). score: (Q,) float32 cosine similarity of that match (-inf where
    none). seconds: (Q,) float64 wall time of each query (hashing it, probing, bucket look-ups,
    the cosine scan and the arg-max; one BLAS thread). probe_seconds: (Q,) float64 the part
    spent making the probing sequence (0 for brute/sklearn). n_stored: (Q,) int64 frames stored when
    it ran. n_candidates: (Q,) int64 frames it scanned (brute force: all stored). n_probes: (Q,)
    int64 buckets probed (0 for brute/sklearn). n_buckets: (Q,) int64 non-empty buckets N1 then.
    candidates: None, or a list of Q entries, each the (k,) int64 rows scanned or None meaning
    "all stored rows" (brute/sklearn). params: the options used (``mode`` "incremental" or
    "static"). Arrays are shorter than Q when a time budget stopped the queries early.
    """
    method: str
    best: np.ndarray
    score: np.ndarray
    seconds: np.ndarray
    probe_seconds: np.ndarray
    n_stored: np.ndarray
    n_candidates: np.ndarray
    n_probes: np.ndarray
    n_buckets: np.ndarray
    candidates: list | None
    params: dict

    @property
    def timed(self) -> np.ndarray:
        """(Q,) bool: queries that had at least one stored frame (the ones worth timing)."""
        return self.n_stored > 0

    @property
    def ms_per_query(self) -> float:
        """Mean wall time per query in milliseconds, over the timed queries."""
        t = self.timed
        return float(self.seconds[t].mean() * 1e3) if t.any() else float("nan")


def _run(index: BucketIndex, queries: np.ndarray, o: dict, keep: bool, exclude: int | None,
         max_seconds: float | None = None):
    """Query every row of the unit float32 (Q, D) queries; with ``exclude`` (incremental mode)
    row t - exclude - 1 is stored before query t. With ``max_seconds`` stop once the queries so
    far took that long (at least one query). Returns the per-query arrays."""
    Q = queries.shape[0]
    best = np.full(Q, NO_MATCH, np.int64)
    score = np.full(Q, -np.inf, np.float32)
    secs, probe_secs = np.zeros(Q), np.zeros(Q)
    n_stored, n_cand, n_probe, n_buck = (np.zeros(Q, np.int64) for _ in range(4))
    kept, spent, done = ([] if keep else None), 0.0, Q
    with one_blas_thread():   # stable per-query timings
        for t in range(Q):
            if exclude is not None and t - exclude - 1 >= 0:
                insert(index, t - exclude - 1)
            n_stored[t], n_buck[t] = index.n_stored, index.n_buckets
            t0 = time.perf_counter()
            b, s, cand, nc, npb, tp = _search(index, queries[t], o)
            secs[t] = time.perf_counter() - t0
            best[t], score[t], n_cand[t], n_probe[t], probe_secs[t] = b, s, nc, npb, tp
            if keep:
                kept.append(cand)
            spent += secs[t]
            if max_seconds is not None and spent >= max_seconds:
                done = t + 1
                break
    arrays = dict(best=best, score=score, seconds=secs, probe_seconds=probe_secs,
                  n_stored=n_stored, n_candidates=n_cand, n_probes=n_probe, n_buckets=n_buck)
    return {**{k: v[:done] for k, v in arrays.items()}, "candidates": kept}


def incremental_match(X, method: str = "swp", exclude: int = 0, n_bits: int = 16, seed: int = 0,
                      radius: int = 4, qdp_probes=(1000, 1500, 500), qdp_score: str = "margin",
                      theta: float = np.pi / 4, centre_frames: int = 0,
                      keep_candidates: bool = False) -> MatchResult:
    """Match a sequence as a robot does: frame t queries frames i < t - exclude, then is stored.

    X: (N, D) descriptors in capture order (L2-normalised here, scanned in float32).
    method: "brute" (NumPy cosine scan of every stored frame), "sklearn" (NearestNeighbors,
        cosine, brute force, refitted whenever a frame was stored: it has no incremental add),
        "swp" (Hamming radius ``radius``) or "qdp" (M probes from ``qdp_probes`` = (small, large,
        threshold) of :func:`qdp_n_probes`, costs ``qdp_score``/``theta`` of :func:`qdp_costs`).
    exclude: frames |i - t| <= exclude are never candidates (integer >= 0). Frame i is stored just
        before query i + exclude + 1 (the same as storing it right after its own query and
        skipping recent frames, without scanning them). n_bits, seed: the hyperplanes.
    centre_frames: 0 (the paper: hyperplanes through the origin) or k in [1, exclude + 1]: the
        hyperplanes pass through the mean of the first k L2-normalised frames instead. Beyond the
        paper: non-negative descriptors (ReLU + pooling, pixels) all lie in one orthant, where
        planes through the origin cut few of them apart. Causal: those k frames are all seen
        before the first frame is stored (just before query exclude + 1).
    keep_candidates: record every query's scanned rows (``experiments.lsh_matching.scanned_matrix``).
    Returns a :class:`MatchResult` with one entry per frame (query t = frame t).
    """
    o = options(method, radius, qdp_probes, qdp_score, theta)
    exclude = positive_int("exclude", exclude, 0)
    X = np.asarray(X)
    if X.ndim != 2:
        raise ValueError(f"X must be (N, D) descriptors, got shape {X.shape}")
    k = positive_int("centre_frames", centre_frames, 0, exclude + 1)
    offset = l2_normalise(X[:k].astype(np.float32)).mean(0) if k else None
    index = build_index(X, hyperplanes(X.shape[1], n_bits, seed), n_stored=0, offset=offset)
    out = _run(index, index.Xn, o, keep_candidates, exclude)
    return MatchResult(method=method, **out, params=dict(
        o, mode="incremental", exclude=exclude, n_bits=n_bits, seed=seed, centre_frames=k))


def query_index(index: BucketIndex, Q, method: str = "swp", radius: int = 4,
                qdp_probes=(1000, 1500, 500), qdp_score: str = "margin", theta: float = np.pi / 4,
                max_seconds: float | None = None) -> MatchResult:
    """Query Q (M, D) against the rows stored in ``index`` (nothing is added to it).

    Same methods and options as :func:`incremental_match`. For "sklearn" the NearestNeighbors
    is fitted before timing starts (``params["fit_seconds"]``). max_seconds: stop after the
    queries so far took this many seconds in all (at least one query; None: all M).
    Returns a :class:`MatchResult` over the queries run (best = stored row).
    """
    o = options(method, radius, qdp_probes, qdp_score, theta)
    if max_seconds is not None and not max_seconds > 0:
        raise ValueError(f"max_seconds must be > 0 or None, got {max_seconds}")
    Qn = np.ascontiguousarray(l2_normalise(_check_X(Q, index.H, "Q").astype(np.float32)))
    fit = 0.0
    if method == "sklearn" and index.nn_rows != index.n_stored and index.n_stored:
        from sklearn.neighbors import NearestNeighbors
        t0 = time.perf_counter()
        index.nn = NearestNeighbors(n_neighbors=1, metric="cosine", algorithm="brute")
        index.nn.fit(index.Xn[:index.n_stored])
        index.nn_rows, fit = index.n_stored, time.perf_counter() - t0
    out = _run(index, Qn, o, False, None, max_seconds)
    return MatchResult(method=method, **out, params=dict(
        o, mode="static", n_bits=index.n_bits, fit_seconds=fit))


def static_match(X_db, Q, method: str = "swp", n_bits: int = 16, seed: int = 0, radius: int = 4,
                 qdp_probes=(1000, 1500, 500), qdp_score: str = "margin",
                 theta: float = np.pi / 4, offset=None, max_seconds: float | None = None):
    """Query Q (M, D) against a database X_db (N, D) stored all at once: :func:`build_index`
    (hyperplanes ``n_bits``/``seed``, ``offset``), then :func:`query_index` with the rest.
    Returns a :class:`MatchResult` over the queries (best = row of X_db)."""
    X_db = np.asarray(X_db)
    if X_db.ndim != 2:
        raise ValueError(f"X_db must be (N, D) descriptors, got shape {X_db.shape}")
    index = build_index(X_db, hyperplanes(X_db.shape[1], n_bits, seed), offset=offset)
    return query_index(index, Q, method, radius, qdp_probes, qdp_score, theta, max_seconds)
