"""numba kernels: the fused CNN trainer's arithmetic, and the area shrink of the paper's preprocessing.

* ``conv_relu`` / ``conv_grad``: the paper CNN's 3x3 convolution (valid, stride 1, one input
  channel) forward with its ReLU, and its kernel and bias gradients.
* ``adam``: Keras's Adam update of one float32 array, in place, in one pass over memory, with
  its moments flushed to zero below float32's smallest normal number, as TensorFlow's FTZ does.
* ``dense_backward_adam`` / ``matmul``: the dense layer's backward pass with its Adam update, and
  A @ W split over the worker threads (``greenloop.util.threads``).
* ``area_shrink``: OpenCV's INTER_AREA shrink of a gray uint8 image by integer factors (the
  main paper's 640x480 -> 32x32 is 20 x 15), bit-identical to ``cv2.resize`` and faster than
  it (OpenCV runs a scalar loop for factors other than 2); ``greenloop.datasets.sequence.preprocess_image``
  uses it after checking it against OpenCV once per image shape.
* ``candidate_rows`` / ``candidate_scores``: greenloop-seq's sequence verification in candidate
  mode (``seqstream.Detector``): the stored rows its candidates' trajectories and contrast
  windows need, and the best-trajectory score of each candidate from those rows' similarities to
  the last seq_len queries, in one compiled pass instead of some thirty small NumPy calls.
* ``pair_scores``: the same verification for cosine columns (no contrast window) under a cell
  shift: each (stored row, query) point a trajectory needs is computed once, as the best of the
  query's shifted copies, in one compiled pass (no product of every needed row with every query).
* ``ring_best``: greenloop-seq's search over straight trajectories in its ring of columns.
* ``max_dot``: greenloop-seq's similarity under a cell shift (``seqmatch.shift_cells``): each
  stored row's best cosine with the query's shifted copies, reading the stored rows once.
* ``scaled_max_dot``: the same for rows stored as int8 with a float32 scale per row
  (``seqmatch.quantise_rows``): a quarter of the bytes read per stored row.

Each kernel is checked against the library it replaces in tests/test_kernels.py. numba is imported
lazily; ``available()`` says whether it is installed, and callers fall back to plain
NumPy / OpenCV / Keras when it is not. Kernels compile on first use and are cached
on disk next to this file (numba's ``cache=True``).
"""
from __future__ import annotations

import functools

import numpy as np

from greenloop.util.threads import run_slices, split_rows

@functools.lru_cache(maxsize=1)
def available() -> bool:
    """True when numba imports."""
    try:
        import numba  # noqa: F401
    except Exception:  # pragma: no cover - depends on the install
        return False
    return True


# ---------------------------------------------------------------------------------------------
# compiled kernels
# ---------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _compiled():
    """The numba kernels, compiled (or loaded from numba's disk cache) once per process.

    Returns {'conv3_relu', 'conv3_grad', 'adam1d', 'area_u8', 'cand_rows', 'cand_scores', 'pair_scores',
    'max_dot3', 'scaled_dot1', 'scaled_dot3', 'ring_best'}:
    serial kernels that release the
    GIL; ``run_slices`` spreads them over the cores, so numba's own thread pool is never started
    (its spinning workers would compete with the BLAS calls on the other cores).
    """
    from numba import njit

    # What makes LLVM vectorise them (checked in the assembly): error_model="numpy" (numba's
    # default "python" model tests every division for zero, which keeps Adam scalar), inner loops
    # over 1-D views indexed by plain range() variables (an offset index makes numba test it for
    # negative wraparound), and accumulators in local arrays. fastmath: reassociation and FMA
    # contraction only (no nnan/ninf), so sums may be reordered as any BLAS does while NaNs and
    # infinities behave as in NumPy.
    opts = dict(fastmath={"reassoc", "contract"}, error_model="numpy", cache=True, nogil=True)
    return {"conv3_relu": _compile_conv_relu(njit, opts), "conv3_grad": _compile_conv_grad(njit, opts),
            "adam1d": _compile_adam(njit, opts), "area_u8": _compile_area(njit),
            **_compile_candidates(njit), "pair_scores": _compile_pair_scores(njit, opts),
            "max_dot3": _compile_max_dot3(njit, opts), **_compile_scaled_dot(njit, opts),
            "ring_best": _compile_ring_best(njit)}


def _compile_ring_best(njit):
    """ring_best(R, base, c, out): see :func:`ring_best` (no fastmath: each sum in the order written)."""
    @njit(cache=True, nogil=True)
    def ring_best(R, base, c, out):
        nv, L = base.shape
        acc = np.empty(c, R.dtype)
        for v in range(nv):
            acc[:] = 0
            for k in range(L):
                seg = R[k, base[v, k]:base[v, k] + c]      # a view: plain indices vectorise
                for i in range(c):
                    acc[i] += seg[i]
            if v == 0:
                out[:] = acc
            else:
                for i in range(c):
                    out[i] = max(out[i], acc[i])
        return out
    return ring_best


def _compile_pair_scores(njit, opts: dict):
    """pair_scores(cand, db, Q, off, qc, qpad, out, first): see :func:`pair_scores`. The dot products are
    compiled with ``opts`` (fastmath: vectorised); the trajectory sums without (in the order written)."""
    @njit(**opts)
    def dot_max(a, Qk):
        if Qk.shape[0] == 3:                          # a cell shift of one: one pass over the row
            q0, q1, q2 = Qk[0], Qk[1], Qk[2]
            t0, t1, t2 = np.float32(0.0), np.float32(0.0), np.float32(0.0)
            for d in range(a.shape[0]):
                x = a[d]
                t0 += x * q0[d]
                t1 += x * q1[d]
                t2 += x * q2[d]
            return max(t0, max(t1, t2))
        best = np.float32(-np.inf)
        for s in range(Qk.shape[0]):
            q = Qk[s]
            t = np.float32(0.0)
            for d in range(a.shape[0]):
                t += a[d] * q[d]
            best = max(best, t)
        return best

    @njit(cache=True, nogil=True)
    def pair_scores(cand, db, Q, off, qc, qpad, out, first):
        nv, L = off.shape
        lo = off.min()
        nu = off.max() - lo + 1
        need = np.zeros((nu, L), np.bool_)             # which queries a row at offset o is needed for
        for v in range(nv):
            for k in range(L):
                need[off[v, k] - lo, k] = True
        size = 16
        while size < 2 * len(cand) * nu * L:
            size *= 2
        keys = np.full(size, -1, np.int64)            # open addressing: key p * L + k, value its cosine
        vals = np.empty(size, np.float32)
        local = np.empty((nu, L), np.float32)         # one candidate's points: (offset, query)
        for c in range(len(cand)):
            for o in range(nu):                       # row by row: a row is read once per candidate
                p = cand[c] - (o + lo)
                for k in range(L):
                    if not need[o, k]:
                        continue
                    if p < 0 or p >= qc[k]:
                        local[o, k] = np.float32(qpad[k])
                        continue
                    key = p * L + k
                    h = (key * 40503) & (size - 1)
                    while keys[h] != -1 and keys[h] != key:
                        h = (h + 1) & (size - 1)
                    if keys[h] == -1:
                        keys[h] = key
                        vals[h] = dot_max(db[p], Q[k])
                    local[o, k] = vals[h]
            best = -np.inf
            for v in range(nv):
                acc = 0.0
                for k in range(L):
                    acc += np.float64(local[off[v, k] - lo, k])
                best = max(best, acc)
            out[c] = np.float32(best / L)
            if 0 <= cand[c] < qc[0]:
                first[c] = local[-lo, 0]
        return out
    return pair_scores


def _compile_max_dot3(njit, opts: dict):
    """max_dot3(A, Q, out): out[i] = max over the 3 rows q of Q of <A[i], q>, one pass over A."""
    @njit(**opts)
    def max_dot3(A, Q, out):
        q0, q1, q2 = Q[0], Q[1], Q[2]
        for i in range(A.shape[0]):
            a = A[i]
            t0, t1, t2 = np.float32(0.0), np.float32(0.0), np.float32(0.0)
            for k in range(A.shape[1]):
                x = a[k]
                t0 += x * q0[k]
                t1 += x * q1[k]
                t2 += x * q2[k]
            out[i] = max(t0, max(t1, t2))
        return out
    return max_dot3


def _compile_scaled_dot(njit, opts: dict) -> dict:
    """{'scaled_dot1', 'scaled_dot3'}: out[i] = scale[i] * max over the 1 or 3 rows q of Q of
    <float32(A[i]), q>, A int8, one pass over A (the int8 -> float32 conversion vectorises)."""
    @njit(**opts)
    def scaled_dot1(A, scale, Q, out):
        q0 = Q[0]
        for i in range(A.shape[0]):
            a = A[i]
            t0 = np.float32(0.0)
            for k in range(A.shape[1]):
                t0 += np.float32(a[k]) * q0[k]
            out[i] = scale[i] * t0
        return out

    @njit(**opts)
    def scaled_dot3(A, scale, Q, out):
        q0, q1, q2 = Q[0], Q[1], Q[2]
        for i in range(A.shape[0]):
            a = A[i]
            t0, t1, t2 = np.float32(0.0), np.float32(0.0), np.float32(0.0)
            for k in range(A.shape[1]):
                x = np.float32(a[k])
                t0 += x * q0[k]
                t1 += x * q1[k]
                t2 += x * q2[k]
            out[i] = scale[i] * max(t0, max(t1, t2))
        return out
    return {"scaled_dot1": scaled_dot1, "scaled_dot3": scaled_dot3}


def _compile_conv_relu(njit, opts: dict):
    """conv3_relu(X (n, h, w) f32, K (kh, kw, f) f32, bias (f,) f32, out (n, ho*wo*f) f32): valid
    convolution plus ReLU, flattened (row, column, filter) into ``out`` (njit with ``opts``)."""
    @njit(**opts)
    def conv3_relu(X, K, bias, out):
        n, h, w = X.shape
        kh, kw, nf = K.shape
        ho, wo = h - kh + 1, w - kw + 1
        acc = np.empty(nf, np.float32)
        for b in range(n):
            o = out[b]
            x = X[b]
            for r in range(ho):
                for c in range(wo):
                    for f in range(nf):
                        acc[f] = bias[f]
                    for dy in range(kh):
                        for dx in range(kw):
                            v = x[r + dy, c + dx]
                            k = K[dy, dx]
                            for f in range(nf):
                                acc[f] += v * k[f]
                    dst = o[(r * wo + c) * nf:(r * wo + c + 1) * nf]
                    for f in range(nf):
                        dst[f] = acc[f] if acc[f] > 0.0 else np.float32(0.0)
        return out

    return conv3_relu


def _compile_conv_grad(njit, opts: dict):
    """conv3_grad(X (n, h, w) f32, dZ (n, ho*wo*f) f32, A (n, ho*wo*f) f32 the forward output,
    kh, kw, total (kh*kw + 1, f) f32): kernel gradients (rows dy*kw + dx) and the bias gradient
    (last row) summed over the frames, written into ``total`` (njit with ``opts``)."""
    @njit(**opts)
    def conv3_grad(X, dZ, A, kh, kw, total):
        n, h, w = X.shape
        ho, wo = h - kh + 1, w - kw + 1
        nf = total.shape[1]
        acc = np.zeros((kh * kw + 1, nf), np.float32)
        g = np.empty(nf, np.float32)
        for b in range(n):
            d = dZ[b]
            a = A[b]
            x = X[b]
            for r in range(ho):
                for c in range(wo):
                    db = d[(r * wo + c) * nf:(r * wo + c + 1) * nf]
                    ab = a[(r * wo + c) * nf:(r * wo + c + 1) * nf]
                    for f in range(nf):
                        g[f] = db[f] if ab[f] > 0.0 else np.float32(0.0)
                    for dy in range(kh):
                        for dx in range(kw):
                            v = x[r + dy, c + dx]
                            t = acc[dy * kw + dx]
                            for f in range(nf):
                                t[f] += v * g[f]
                    t = acc[kh * kw]
                    for f in range(nf):
                        t[f] += g[f]
        total[:, :] = acc
        return total

    return conv3_grad


def _compile_adam(njit, opts: dict):
    """adam1d(w, g, m, v (k,) f32, alpha, one_minus_b1, one_minus_b2, eps f32): Keras's Adam step
    on one flat array, in place (njit with ``opts``).

    The moments are flushed to zero below float32's smallest normal number, as TensorFlow's
    threads run (FTZ): the first moment of a weight whose gradient is zero (a dead ReLU unit)
    decays by beta_1 every step and would enter the subnormal range after ~800 steps, where x86
    arithmetic is far slower.
    """
    tiny = np.float32(np.finfo(np.float32).tiny)

    @njit(**opts)
    def adam1d(w, g, m, v, alpha, one_minus_b1, one_minus_b2, eps):
        for i in range(w.shape[0]):
            mi = m[i] + (g[i] - m[i]) * one_minus_b1
            vi = v[i] + (g[i] * g[i] - v[i]) * one_minus_b2
            mi = mi if abs(mi) >= tiny else np.float32(0.0)
            vi = vi if vi >= tiny else np.float32(0.0)
            m[i] = mi
            v[i] = vi
            w[i] -= (mi * alpha) / (np.sqrt(vi) + eps)

    return adam1d


def _compile_area(njit):
    """area_u8(g (h, w) uint8, fy, fx, out (h // fy, w // fx) uint8): OpenCV's INTER_AREA shrink
    by integer factors, bit-identical (no fastmath: the rounding must match)."""
    @njit(cache=True, nogil=True)
    def area_u8(g, fy, fx, out):
        h, w = g.shape
        oh, ow = out.shape
        scale = np.float32(1.0) / np.float32(fy * fx)
        col = np.zeros(w, np.int32)
        for by in range(oh):
            col[:] = 0
            for r in range(fy):
                row = g[by * fy + r]
                for x in range(w):
                    col[x] += row[x]
            for bx in range(ow):
                blk = col[bx * fx:(bx + 1) * fx]
                s = 0
                for k in range(fx):
                    s += blk[k]
                # OpenCV's INTER_AREA for integer factors: saturate_cast<uchar>(sum * (1.f/area)),
                # i.e. round half to even of a float32 product
                out[by, bx] = np.uint8(np.rint(np.float32(s) * scale))
        return out

    return area_u8


def _compile_candidates(njit) -> dict:
    """{'cand_rows', 'cand_scores'}: see :func:`candidate_rows` and :func:`candidate_scores` (no
    fastmath: each sum runs in the order written, in float64)."""
    @njit(cache=True, nogil=True)
    def cand_rows(ids, before, after, limit):
        c = np.sort(ids[ids >= 0])
        keep = np.ones(len(c), np.bool_)
        for t in range(1, len(c)):
            keep[t] = c[t] != c[t - 1]
        cand = c[keep]
        rows = np.empty(len(cand) * (before + after + 1), np.int64)
        n, nxt = 0, 0                      # nxt: the first row not yet listed (cand ascending)
        for i in cand:
            for r in range(max(i - before, nxt, 0), min(i + after + 1, limit)):
                rows[n] = r
                n += 1
            nxt = max(nxt, i + after + 1)
        return cand, rows[:n]

    @njit(cache=True, nogil=True)
    def cand_scores(cand, rows, G, off, qc, qpad, h, eps, out):
        nv, L = off.shape
        for c in range(len(cand)):
            best = -np.inf
            for v in range(nv):
                acc = 0.0
                for k in range(L):
                    p = cand[c] - off[v, k]
                    if p < 0 or p >= qc[k]:
                        acc += np.float64(np.float32(qpad[k]))
                        continue
                    a = np.searchsorted(rows, p)
                    s = G[a, k]
                    if h >= 0:
                        lo, hi = max(p - h, 0), min(p + h + 1, qc[k])
                        s1, s2 = 0.0, 0.0
                        for t in range(a - (p - lo), a + (hi - p)):
                            s1 += G[t, k]
                            s2 += G[t, k] * G[t, k]
                        mu = s1 / (hi - lo)
                        sd = np.sqrt(max(s2 / (hi - lo) - mu * mu, 0.0))
                        s = (s - mu) / max(sd, eps) if sd > eps else 0.0
                    acc += np.float64(np.float32(s))
                best = max(best, acc)
            out[c] = np.float32(best / L)
        return out

    return {"cand_rows": cand_rows, "cand_scores": cand_scores}


def ring_best(R: np.ndarray, base: np.ndarray, c: int) -> np.ndarray | None:
    """greenloop-seq's trajectory search (``seqstream._ring_scores`` without the division):
    out[i] = max over v of sum over k = 0..L-1 (in that order) of R[k, base[v, k] + i], i < c.

    R: (L, W) float32 or float64 ring rows, oldest last; base: (V, L) int64 column offsets. Returns
    (c,) in R's dtype, the same bits as the NumPy loop (the same additions in the same order); None
    without numba.
    """
    if not available():
        return None
    return _compiled()["ring_best"](np.ascontiguousarray(R), np.ascontiguousarray(base, dtype=np.int64), int(c),
                                    np.empty(int(c), R.dtype))


def max_dot(A: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The best of several queries for every stored row: (C,) float32, out[i] = max_s <A[i], Q[s]>.

    A: (C, D) float32 stored rows (C-contiguous); Q: (m, D) float32 queries. m = 3 (a cell shift
    of one, greenloop-seq's default) runs one compiled pass that reads each row of A once instead
    of three times (needs numba); any other m, or without numba, is m BLAS matrix-vector products
    and their maximum. Sums may be reordered as any BLAS does.
    """
    A, Q = np.ascontiguousarray(A, dtype=np.float32), np.ascontiguousarray(Q, dtype=np.float32)
    if len(Q) == 3 and available() and len(A):
        return _compiled()["max_dot3"](A, Q, np.empty(len(A), np.float32))
    out = A @ Q[0]
    for q in Q[1:]:
        np.maximum(out, A @ q, out=out)
    return out


def scaled_max_dot(A: np.ndarray, scale: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """:func:`max_dot` of rows stored as int8 with a scale each: (C,) float32,
    out[i] = scale[i] * max_s <A[i], Q[s]> (scale >= 0, so the maximum of the scaled products).

    A: (C, D) int8 stored rows (C-contiguous); scale: (C,) float32 >= 0; Q: (m, D) float32
    queries. m = 1 or 3 run one compiled pass over A (needs numba); any other m, or without numba,
    converts A to float32 and takes :func:`max_dot`. Sums may be reordered as any BLAS does.
    """
    A, Q = np.ascontiguousarray(A, dtype=np.int8), np.ascontiguousarray(Q, dtype=np.float32)
    scale = np.ascontiguousarray(scale, dtype=np.float32)
    if A.shape[0] != scale.shape[0] or Q.ndim != 2 or A.shape[1] != Q.shape[1]:
        raise ValueError(f"A (C, D), scale (C,) and Q (m, D) must agree, got {A.shape}, {scale.shape}, {Q.shape}")
    if len(Q) in (1, 3) and available() and len(A):
        return _compiled()[f"scaled_dot{len(Q)}"](A, scale, Q, np.empty(len(A), np.float32))
    return (max_dot(A.astype(np.float32), Q) * scale).astype(np.float32)


def candidate_rows(ids: np.ndarray, before: int, after: int, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """The candidates of one query and the stored rows their verification needs.

    ids: (k,) int64 retrieved rows (-1: none). before / after: rows needed before / after each
    candidate i (its trajectories reach i - max offset, its contrast windows h more on each side).
    limit: rows >= limit are not stored yet. Returns (cand (m,) int64 ascending, distinct;
    rows (r,) int64 ascending, distinct: the union of [i - before, i + after] over the candidates,
    clipped to [0, limit)). Needs numba (:func:`available`).
    """
    return _compiled()["cand_rows"](np.ascontiguousarray(ids, dtype=np.int64), int(before), int(after), int(limit))


def candidate_scores(cand, rows, G, off, qc, qpad, half_window: int, eps: float) -> np.ndarray:
    """Best-trajectory scores (m,) float32 of the candidates cand (m,) of :func:`candidate_rows`.

    rows (r,): the stored rows of :func:`candidate_rows`; G (r, L) float64: their cosine with the
    last L queries (column k: the query k frames back). off (V, L) int64: the trajectories' row
    offsets. qc (L,) int64: the rows each of those queries had (a point p counts when 0 <= p <
    qc[k]); qpad (L,) float64: the value of a point outside them. half_window h: each point's
    similarity is contrast-normalised over the rows p - h .. p + h within [0, qc[k]) (mean, then
    population std; a std <= eps gives 0: seqmatch's own floor); h < 0: not normalised. Each point's value is rounded to
    float32, summed over k in float64, maximised over v, divided by L, rounded to float32.
    """
    out = np.empty(len(cand), np.float32)
    return _compiled()["cand_scores"](cand, rows, np.ascontiguousarray(G, dtype=np.float64),
                                      np.ascontiguousarray(off, dtype=np.int64),
                                      np.ascontiguousarray(qc, dtype=np.int64),
                                      np.ascontiguousarray(qpad, dtype=np.float64), int(half_window),
                                      float(eps), out)


def pair_scores(cand, db, Q, off, qc, qpad) -> tuple[np.ndarray, np.ndarray]:
    """Best-trajectory scores (m,) float32 of the candidate rows cand (m,) int64, for cosine columns,
    and each row's point in the newest column, (m,) float32 (NaN where outside it).

    db (N, D) float32: the stored rows (C-contiguous); Q (L, S, D) float32: the last L queries, each
    under its S cell shifts (``seqmatch.shift_cells``; S = 1 without). off (V, L) int64: the
    trajectories' row offsets (negative: a reverse revisit). qc (L,) int64: the rows each query had
    (a point p counts when 0 <= p < qc[k]); qpad (L,) float64: the value of a point outside them.
    A point's value is the best cosine of stored row p with query k's shifted copies (float32 sums,
    vectorised, so reordered as a BLAS product may be), computed once however many trajectories
    pass through it (a candidate's rows in order, each read once); rounded to float32, summed over
    k in float64, maximised over v, divided by L, rounded to float32, as :func:`candidate_scores`.
    Needs numba (:func:`available`).
    """
    out, first = np.empty(len(cand), np.float32), np.full(len(cand), np.nan, np.float32)
    _compiled()["pair_scores"](np.ascontiguousarray(cand, dtype=np.int64), db, np.ascontiguousarray(Q, dtype=np.float32),
                               np.ascontiguousarray(off, dtype=np.int64), np.ascontiguousarray(qc, dtype=np.int64),
                               np.ascontiguousarray(qpad, dtype=np.float64), out, first)
    return out, first


def conv_relu(X: np.ndarray, K: np.ndarray, bias: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """relu(Conv2D(X)) of gray frames, valid padding, stride 1, flattened as Keras's Flatten does.

    X: (N, H, W) float32 C-contiguous. K: (kh, kw, f) float32 (Conv2D's kernel without its
    in-channel axis). bias: (f,) float32. Frames are split over the worker threads.
    Returns (N, (H-kh+1)*(W-kw+1)*f) float32, ordered (row, column, filter).
    """
    n, h, w = X.shape
    kh, kw, nf = K.shape
    if out is None:
        out = np.empty((n, (h - kh + 1) * (w - kw + 1) * nf), np.float32)
    fn = _compiled()["conv3_relu"]
    run_slices(lambda k, s: fn(X[s], K, bias, out[s]), split_rows(n))
    return out


def conv_grad(X: np.ndarray, dA: np.ndarray, A: np.ndarray, k=(3, 3)) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the kernel and bias of ``A = relu(conv(X))`` (valid, stride 1).

    X: (N, H, W) float32, the conv's input. dA: (N, Ho*Wo*f) float32, the loss gradient at A,
    laid out like ``conv_relu``'s output; A: the same shape, the conv's output (its ReLU mask
    A > 0 is applied here). k: (kh, kw). Frames are split over the worker threads.
    Returns (dK (kh, kw, f), dbias (f,)) float32, summed over frames and positions.
    """
    kh, kw = k
    n, h, w = X.shape
    nf = dA.shape[1] // ((h - kh + 1) * (w - kw + 1))
    parts = split_rows(n)
    totals = np.zeros((len(parts), kh * kw + 1, nf), np.float32)
    fn = _compiled()["conv3_grad"]
    run_slices(lambda i, s: fn(X[s], dA[s], A[s], kh, kw, totals[i]), parts)
    total = totals.sum(0)
    return total[:-1].reshape(kh, kw, nf), total[-1]


def adam(w: np.ndarray, g: np.ndarray, m: np.ndarray, v: np.ndarray, alpha: float,
         beta_1: float = 0.9, beta_2: float = 0.999, epsilon: float = 1e-7) -> None:
    """Keras's ``Adam.update_step`` on float32 C-contiguous arrays of one shape, in place:
    m += (g - m)(1 - beta_1); v += (g^2 - v)(1 - beta_2); w -= m * alpha / (sqrt(v) + epsilon),
    where alpha = lr * sqrt(1 - beta_2^t) / (1 - beta_1^t). Large arrays are split over the
    worker threads."""
    w1, g1, m1, v1 = (a.reshape(-1) for a in (w, g, m, v))
    run_slices(lambda k, s: _adam_rows(w1[s], g1[s], m1[s], v1[s], alpha, beta_1, beta_2, epsilon),
               split_rows(len(w1)) if len(w1) >= 65536 else [slice(None)])


def _adam_rows(w, g, m, v, alpha, beta_1=0.9, beta_2=0.999, epsilon=1e-7) -> None:
    """``adam`` on one thread (the compiled loop over flattened C-contiguous arrays)."""
    f32 = np.float32
    _compiled()["adam1d"](w.reshape(-1), g.reshape(-1), m.reshape(-1), v.reshape(-1), f32(alpha),
                          f32(1.0 - beta_1), f32(1.0 - beta_2), f32(epsilon))


def dense_backward_adam(A: np.ndarray, G: np.ndarray, W: np.ndarray, M: np.ndarray, V: np.ndarray,
                        alpha: float, dW: np.ndarray, dA: np.ndarray) -> None:
    """Backward pass through ``Z = A @ W`` and Keras's Adam step on W, the rows of W split over
    the worker threads: each computes its rows of dW = A^T G and its columns of dA = G W^T
    (single-threaded BLAS), then runs ``adam`` on those rows while they are in cache.

    A: (B, n_in), G: (B, n_out) the loss gradient at Z, all float32. W, M, V: (n_in, n_out)
    float32 C-contiguous, updated in place (weights, Adam's moments); alpha as in ``adam``.
    Writes the buffers dW (n_in, n_out) and dA (B, n_in); dA uses W *before* the update.
    """
    def rows(k, s):
        np.matmul(A[:, s].T, G, out=dW[s])
        np.matmul(G, W[s].T, out=dA[:, s])
        _adam_rows(W[s], dW[s], M[s], V[s], alpha)

    run_slices(rows, split_rows(W.shape[0]))


def matmul(A: np.ndarray, W: np.ndarray) -> np.ndarray:
    """A @ W, the inner dimension split over the worker threads (single-threaded BLAS each).
    A: (B, K), W: (K, N) float32. Returns (B, N) float32."""
    parts = split_rows(W.shape[0])
    out = np.empty((len(parts), A.shape[0], W.shape[1]), np.float32)
    run_slices(lambda k, s: np.matmul(A[:, s], W[s], out=out[k]), parts)
    return out.sum(0)


def area_shrink(gray: np.ndarray, size) -> np.ndarray | None:
    """``cv2.resize(gray, size, interpolation=cv2.INTER_AREA)`` for integer shrink factors.

    gray: (H, W) uint8 C-contiguous. size: (width, height) dividing (W, H) exactly.
    Returns (height, width) uint8, or None when the kernel does not apply (numba missing, factors
    not integers, not uint8 2-D, or 2 x 2: OpenCV's own vectorised path for that factor rounds
    sums of exact halves its own way) so that the caller uses OpenCV.
    """
    h, w = gray.shape[:2]
    ow, oh = int(size[0]), int(size[1])
    if (gray.ndim != 2 or gray.dtype != np.uint8 or ow < 1 or oh < 1 or w % ow or h % oh
            or (w == ow and h == oh) or (w == 2 * ow and h == 2 * oh) or not available()):
        return None
    fn = _checked_area((h, w, oh, ow))
    if fn is None:
        return None
    return fn(np.ascontiguousarray(gray), h // oh, w // ow, np.empty((oh, ow), np.uint8))


@functools.lru_cache(maxsize=64)
def _checked_area(shape):
    """The area kernel for one (h, w, oh, ow), or None if it disagrees with this OpenCV on a random
    image of that shape (a future OpenCV could round differently; then OpenCV is used, and a
    warning goes to the log, which greenloop sends to the terminal, not into a notebook)."""
    import logging

    import cv2

    h, w, oh, ow = shape
    fn = _compiled()["area_u8"]
    img = np.random.default_rng(0).integers(0, 256, (h, w), dtype=np.uint8)
    ours = fn(img, h // oh, w // ow, np.empty((oh, ow), np.uint8))
    if not np.array_equal(ours, cv2.resize(img, (ow, oh), interpolation=cv2.INTER_AREA)):
        logging.getLogger(__name__).warning(f"area_shrink differs from cv2.resize on {w}x{h} -> {ow}x{oh}; "
                                            f"using OpenCV")
        return None
    return fn


