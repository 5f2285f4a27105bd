"""What greenloop-seq's candidate mode (``seqstream.Detector(index=...)``) needs beyond an index.

* :func:`reservoir`: a uniform sample of fixed size of the rows that have become candidates
  (reservoir sampling, Vitter's algorithm R) whose draws are a hash of the row number and a seed,
  so that the sample after c rows is one function of c however the rows arrived (one at a time in
  a stream, all at once in ``Detector.preload``). Candidate mode scores these rows besides the
  retrieved ones, as the calibration's null (``seqmatch.calibrate_sampled``) and for the mean of a
  shifted column.
* :class:`IndexSpace`: what the index holds: the stored rows as they are, or reduced by a PCA
  (mean-centred, no whitening) fitted on the first ``fit`` candidate rows, the stream's own past
  (causal), projected in float64 and rounded to float32, so that a row's projection does not
  depend on how many rows were projected with it (but where a float64 sum falls within its own
  rounding error of a float32 rounding boundary).
* :class:`CandidateMode`: candidate mode's own methods, which ``seqstream.Detector`` inherits (what
  it retrieves and scores per frame, the pads of its columns, the calibration's null from the
  sample), and the constants that set it (INDEX_FIT, NULL_SAMPLE, INDEX_DIM, FOLLOW, AROUND,
  NULL_GROUPS, FOLLOW_DEPTH, WARMUP), which ``seqstream`` names too.
"""
from __future__ import annotations

import numpy as np

from greenloop.methods.greenloop_seq.seqmatch import _EPS, calibrate_sampled
from greenloop.methods.lsh import retrieval
from greenloop.util import numba_kernels

__all__ = ["reservoir", "IndexSpace", "CandidateMode", "INDEX_FIT", "NULL_SAMPLE", "INDEX_DIM", "FOLLOW", "AROUND",
           "NULL_GROUPS", "FOLLOW_DEPTH", "WARMUP"]

# Candidate mode's defaults (``seqstream.Detector``): the PCA of the index is fitted on the first
# INDEX_FIT candidate rows, and a calibrated query scores NULL_SAMPLE sampled rows as its null beside
# the retrieved ones. INDEX_DIM: the index's dims where a caller asks for a reduced index (the CLI's
# --index and speed.scale's decisions).
INDEX_FIT, NULL_SAMPLE, INDEX_DIM = 1000, 128, 64
# The rows a frame scores beyond the retrieved ones (:meth:`CandidateMode._match_candidates`): the
# FOLLOW best of the previous frame's retrieved or followed rows moved one frame on (a trajectory
# the single-frame retrieval missed this frame; a row is followed at most FOLLOW_DEPTH frames
# without being retrieved again), the rows within AROUND of the best (the matched place's
# neighbours, the top of the exact null), and a NULL_GROUPS-th of the sample (the rest keep the
# scores of their last turn, at most NULL_GROUPS - 1 frames old). Chosen with
# tools/candidate_measure.py on Nordland (agreement with the exact scan against rows scored).
FOLLOW, AROUND, NULL_GROUPS, FOLLOW_DEPTH = 3, 16, 4, 8
# Candidate mode's preload streams this many frames more than the reference's
# (``seqstream.Detector.preload``): the rows followed and the sample's scores come from the frames before.
WARMUP = 4 * FOLLOW_DEPTH + NULL_GROUPS

_MASK = (1 << 64) - 1


def _mix(x: int) -> int:
    """splitmix64's finaliser of a 64-bit integer (Python ints, exact)."""
    x = (x + 0x9E3779B97F4A7C15) & _MASK
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK
    return x ^ (x >> 31)


def _mix_array(x: np.ndarray) -> np.ndarray:
    """:func:`_mix` of a uint64 array (wrapping arithmetic, the same bits)."""
    x = x + np.uint64(0x9E3779B97F4A7C15)
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def reservoir(slots: np.ndarray, lo: int, hi: int, seed: int = 0) -> np.ndarray:
    """Feed rows lo..hi-1 (in order) to a reservoir of len(slots) rows, in place; returns slots.

    slots: (size,) int64, -1 where empty, holding the sample of rows 0..lo-1. Row r < size fills
    slot r; a later row r is kept with probability size / (r + 1), in the slot its hash names, so
    every row 0..hi-1 is in the sample with the same probability (algorithm R). The draw of row r
    is a hash of (seed, r), never a generator's state: the same rows give the same sample.
    """
    size = len(slots)
    if hi - lo == 1:                                   # a stream's frame: no array overhead
        r = lo
        if r < size:
            slots[r] = r
            return slots
        h = _mix((seed << 40) ^ r)
        if (h >> 11) * 2.0 ** -53 * (r + 1) < size:
            slots[_mix(h) % size] = r
        return slots
    r = np.arange(lo, hi, dtype=np.int64)
    first = r[r < size]
    slots[first] = first
    r = r[r >= size]
    h = _mix_array((np.uint64(seed) << np.uint64(40)) ^ r.astype(np.uint64))
    keep = (h >> np.uint64(11)).astype(np.float64) * 2.0 ** -53 * (r + 1).astype(np.float64) < size
    rows, where = r[keep], (_mix_array(h[keep]) % np.uint64(size)).astype(np.int64)
    last = len(where) - 1 - np.unique(where[::-1], return_index=True)[1]      # the last row per slot
    slots[where[last]] = rows[last]
    return slots


class IndexSpace:
    """The rows an index holds: the stored rows (dim None, or >= theirs), or their first ``dim``
    principal components (L2-normalised afterwards by ``greenloop.methods.lsh.retrieval``).

    dim: the index's dimensions; fit: the candidate rows the PCA is fitted on, the stream's first
    ``fit`` (no later frame changes it). ``ready(c)``: whether an index can be built with c rows
    (always, without a PCA; with one, once c >= fit). ``fit_rows(rows)`` fits on rows (fit, D)
    float32; ``project(rows)`` (n, D) -> (n, dim) float32. Fixed memory: the mean (D float32) and the
    components (D x dim float64).
    """

    def __init__(self, dim: int | None, fit: int):
        self.dim, self.fit = dim, int(fit)
        self.mean = self.components = None

    def reduces(self, d: int) -> bool:
        """Whether rows of d dims are reduced (a PCA to fewer dims)."""
        return self.dim is not None and self.dim < d

    def ready(self, c: int, d: int) -> bool:
        return not self.reduces(d) or c >= self.fit

    def fit_rows(self, rows: np.ndarray) -> None:
        X = np.asarray(rows, dtype=np.float64)
        self.mean = X.mean(0)
        _, _, Vt = np.linalg.svd(X - self.mean, full_matrices=False)
        V = np.zeros((X.shape[1], self.dim))
        V[:, :min(self.dim, len(Vt))] = Vt[:self.dim].T
        self.mean, self.components = self.mean.astype(np.float32), np.ascontiguousarray(V)

    def project(self, rows: np.ndarray) -> np.ndarray:
        """rows (n, D) -> (n, dim) float32: (rows - mean) @ components in float64, rounded (a row
        gives the same bits alone or in a batch, module doc). Unreduced: the rows as float32."""
        rows = np.asarray(rows, dtype=np.float32)
        if self.components is None:
            return rows
        return ((rows - self.mean).astype(np.float64) @ self.components).astype(np.float32)


def _contains(sorted_rows: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(len(rows),) bool: whether each of rows is in sorted_rows (ascending, distinct)."""
    i = np.searchsorted(sorted_rows, rows)
    return (i < sorted_rows.size) & (sorted_rows[np.minimum(i, max(sorted_rows.size - 1, 0))] == rows) \
        if sorted_rows.size else np.zeros(np.shape(rows), bool)


def _accumulate(total: np.ndarray, R: np.ndarray, chunk: int = 65536) -> np.ndarray:
    """total (D,) float64 plus the rows R (n, D) added one after the other (so a batch gives the
    bits of n single additions), in chunks of rows: (D,) float64."""
    acc = total[None]
    for a in range(0, len(R), chunk):
        acc = np.add.accumulate(np.vstack([acc, R[a:a + chunk].astype(np.float32)]), axis=0)[-1:]
    return acc[0].copy()


class CandidateMode:
    """The methods of ``seqstream.Detector``'s candidate mode (``index=...``), which it inherits; the
    state they read and write is the Detector's (its stored rows ``_db``, the last seq_len queries
    kept ``_Q`` / ``_qc`` / ``_qpad``, the index and its space, the sample ``_slots``), set up by
    ``Detector.reset``. Entry point: :meth:`_match_candidates`, one frame.
    """

    def _match_candidates(self, Q: np.ndarray, gate: np.ndarray) -> dict | None:
        """Candidate mode: the sequence scores of the stored frames retrieved for query j.

        Q (S, D): the query under its S cell shifts (S = 1 without; Q[0] unshifted); gate: what the
        repeat gate compares, as in the reference. Frames 0..c-1 (c = j - exclude) are the
        candidates, each added to the index before query j (delayed insertion keeps the exclusion
        window). The rows scored (:meth:`_candidates`): every candidate while c <= k; else the rows
        retrieved for the newest query kept (on a repeat the one before it, whose column ends the
        trajectories: a standing camera's centred descriptor is close to 0), the previous frame's
        FOLLOW best rows moved one frame along a trajectory, and, when calibrating, a part of the
        sample; then the rows within AROUND of the best of them. A scored row i's trajectory points
        (i - round(v k), column j - k), negative velocities' on rows i + round(|v| k), are scored as
        in the reference; a point on a row the query k frames back did not have counts as that
        column's pad (:meth:`_pad`). The last seq_len queries that were no repeat are kept with
        their candidate counts and pads (a repeat is matched and stored but not kept: the
        reference's ring). Calibration: ``seqmatch.calibrate_sampled``, the reference's null
        estimated from the rows scored and the sample (:meth:`_calibrate`), C = c. Where every
        candidate is scored, scores and events are the reference's, float rounding aside, except a
        contrast-normalised column's pad: 0 (a z-score's expected value), not its mean z-score,
        which needs the whole column. Cost per frame: the search, and per scored row about seq_len
        x velocities dot products of D dims (times S, fewer where rows share points), independent
        of the number stored.
        """
        j, c = self.frame_index, max(self.frame_index - self.exclude, 0)
        if self._Q is None:
            self._Q = np.zeros((self.seq_len,) + Q.shape, np.float32)
        self._grow_index(c)
        kept = not self._is_repeat(gate)
        later = kept and self._pad_later(c)           # the pad from this frame's sampled rows
        if kept:
            self._push_query(Q, c, None if later else self._pad(Q, c))
        cand, picked, depth = self._candidates(self._Q[0], c)   # a repeat: the newest kept query's
        scores, first = self._candidate_scores(cand)
        if later:
            self._qpad[0] = self._sample_pad(cand, first, Q, c)
        self._follow = self._fdepth = None
        if c > self.k and cand.size:
            mine = np.flatnonzero(depth < FOLLOW_DEPTH)
            top = mine[np.argsort(-scores[mine], kind="stable")[:FOLLOW]]
            self._follow, self._fdepth = cand[top], depth[top]
            cand, picked, scores = self._around_best(cand, picked, scores, c)
        if self.calibrate and cand.size:
            scores = self._calibrate(cand, picked, scores, c)
        self.last_candidates, self.last_scores = cand, scores
        self._store(Q[0])
        self.frame_index += 1
        return self._declare(j, cand)

    def _around_best(self, cand, picked, scores, c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """cand (m,) ascending, picked (m,) bool, their scores (m,), with the rows within AROUND of
        the best one (below c) scored and merged in as picked: (rows, picked, scores), (m',) each."""
        b = int(cand[np.argmax(scores)])
        near = np.arange(max(b - AROUND, 0), min(b + AROUND + 1, c), dtype=np.int64)
        picked = picked | _contains(near, cand)
        extra = near[~_contains(cand, near)]
        if not extra.size:
            return cand, picked, scores
        rows = np.concatenate([cand, extra])
        order = np.argsort(rows, kind="stable")
        return (rows[order], np.concatenate([picked, np.ones(extra.size, bool)])[order],
                np.concatenate([scores, self._candidate_scores(extra)[0]])[order])

    def _calibrate(self, cand, picked, scores, c: int) -> np.ndarray:
        """The calibrated scores (m,) float32 of the rows cand (m,) scored this frame (picked: not
        for the sample alone). With c <= k every candidate is scored: the reference's calibration.
        Else the picked rows are the null's known rows and the sample the rest's: its rows scored
        this frame (:meth:`_group`) with these scores, the others with the scores they got when last
        scored, at most NULL_GROUPS - 1 frames ago (``seqmatch.calibrate_sampled``)."""
        if c <= self.k:
            return calibrate_sampled(scores, cand, picked, ~picked, c, self.calibrate)
        g = self._group()
        g = g[_contains(cand, self._slots[g])]
        self._nrow[g], self._nscore[g] = self._slots[g], scores[np.searchsorted(cand, self._slots[g])]
        valid = (self._nrow >= 0) & (self._nrow == self._slots)       # scored since the row came in
        old = valid & ~_contains(cand, self._nrow)
        rows, s = np.concatenate([cand, self._nrow[old]]), np.concatenate([scores, self._nscore[old]])
        sampled = _contains(np.sort(self._nrow[valid]), rows)
        known = np.zeros(rows.size, bool)
        known[:cand.size] = picked
        return calibrate_sampled(s, rows, known, sampled, c, self.calibrate, best_of=cand.size)[:cand.size]

    def _group(self) -> np.ndarray:
        """The sample's filled slots scored this frame: every NULL_GROUPS-th, from frame_index mod NULL_GROUPS."""
        g = np.arange(self.frame_index % NULL_GROUPS, self.null_sample, NULL_GROUPS)
        return g[self._slots[g] >= 0]

    def _grow_index(self, c: int) -> None:
        """Make rows 0..c-1 candidates: the new ones join the running sum (cosine pads, summed one
        row after the other), the sample and the index, which is made once its space is ready
        (:class:`IndexSpace`: with a PCA, when index_fit rows are candidates)."""
        if c > self._seen:
            if not self.cell_shift and not self.contrast_window:
                new = self._db[self._seen:c]
                self._sum = _accumulate(np.zeros(new.shape[1]) if self._sum is None else self._sum, new)
            if self._slots is not None:
                reservoir(self._slots, self._seen, c)
            self._seen = c
        d = 0 if self._db is None else self._db.shape[1]
        if self._index is None and c and self._space.ready(c, d):
            if self._space.reduces(d):
                self._space.fit_rows(self._db[:self._space.fit])
            dim = self._space.dim if self._space.reduces(d) else d
            self._index = retrieval.make_index(self.index_kind, dim, **self.index_options)
        for a in range(self._index.n_stored if self._index is not None else c, c, 65536):   # a preload: in chunks
            self._index.add(self._space.project(self._db[a:min(a + 65536, c)]))

    def _push_query(self, Q: np.ndarray, c: int, pad: float | None) -> None:
        """Keep query Q (S, D) with its c candidates and its pad (None: set after scoring, see
        :meth:`_pad_later`) as the newest of the last seq_len; columns from before the stream (no
        candidate) take the newest pad."""
        self._Q[1:], self._qc[1:], self._qpad[1:] = self._Q[:-1], self._qc[:-1], self._qpad[:-1]
        self._Q[0], self._qc[0], self._qpad[0] = Q, c, 0.0 if pad is None else pad
        if pad is not None:
            self._qpad[self._qc == 0] = pad

    def _pad_later(self, c: int) -> bool:
        """Whether the newest column's pad can wait for its scores: with a cell shift while
        calibrating with more than k candidates, no earlier column empty (no point of the newest
        column lies outside it: its rows are the candidates). It is then the mean of this frame's
        sampled rows' points (:meth:`_sample_pad`) instead of the whole sample's (:meth:`_pad`)."""
        return bool(self.cell_shift and self.calibrate and not self.contrast_window and c > self.k
                    and self._qc[:-1].all() and self._group().size)

    def _sample_pad(self, cand, first, Q, c: int) -> float:
        """The mean of the newest column's points on this frame's sampled rows (first: each row's point, NaN where none)."""
        v = first[_contains(np.sort(self._slots[self._group()]), cand)] if first is not None else np.zeros(0)
        v = v[np.isfinite(v)]
        return float(v.mean()) if v.size else self._pad(Q, c)

    def _pad(self, Q: np.ndarray, c: int) -> float:
        """A column's pad, the value of its points outside the stored frames: its mean cosine, exact
        from the running sum without a cell shift; with one the mean of its best-shift cosines over
        every candidate while c <= k (the reference's), else over the sample's rows (an unbiased
        estimate). 0 for contrast-normalised columns (a z-score's expected value) or no candidate."""
        if not c or self.contrast_window:
            return 0.0
        if not self.cell_shift:
            return float(self._sum @ Q[0] / c)
        rows = self._db[:c] if c <= self.k else self._db[self._sample()]
        return float(numba_kernels.max_dot(rows.astype(np.float32, copy=False), Q).mean())

    def _sample(self) -> np.ndarray:
        """The sampled candidate rows (at most null_sample), ascending int64."""
        return np.sort(self._slots[self._slots >= 0])

    def _candidates(self, Q: np.ndarray, c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows query Q (S, D) scores first, (m,) int64 ascending, whether each was picked (m,)
        bool, and each one's depth (m,) int64, the frames since it was last retrieved (FOLLOW_DEPTH:
        not to be followed): every candidate while c <= k (depth 0); else the rows retrieved
        (:meth:`_retrieve`, depth 0) and the previous frame's FOLLOW best retrieved or followed rows
        moved -1, 0, +1 and +2 rows (the next point of a trajectory they ended, at any velocity;
        their depth + 1), picked, and when calibrating this frame's part of the sample
        (:meth:`_group`), picked only if also picked otherwise."""
        if c <= self.k:
            return np.arange(c, dtype=np.int64), np.ones(c, bool), np.zeros(c, np.int64)
        rows, depth = self._retrieve(Q, c), None
        if self._follow is not None and self._follow.size:
            moved = (self._follow[:, None] + np.arange(-1, 3)).ravel()
            d = np.repeat(self._fdepth + 1, 4)
            rows = np.concatenate([rows, moved])
            depth = np.concatenate([np.zeros(rows.size - moved.size, np.int64), d])
            order = np.lexsort((depth, rows))              # per row its smallest depth first
            rows, depth = rows[order], depth[order]
            first = np.r_[True, rows[1:] != rows[:-1]]
            rows, depth = rows[first], depth[first]
        depth = np.zeros(rows.size, np.int64) if depth is None else depth
        keep = (rows >= 0) & (rows < c)
        rows, depth = rows[keep], depth[keep]
        if not self.calibrate:
            return rows, np.ones(rows.size, bool), depth
        cand = np.union1d(rows, self._slots[self._group()])
        inside = _contains(rows, cand)
        full = np.full(cand.size, FOLLOW_DEPTH, np.int64)
        full[inside] = depth
        return cand, inside, full

    def _retrieve(self, Q: np.ndarray, c: int) -> np.ndarray:
        """The union of the k rows retrieved for each row of Q (S, D), ascending int64: the index's
        search (its space's projection of Q), or an exact scan of the c stored rows while the
        index waits for its PCA's rows."""
        if self._index is None:
            S = self._db[:c].astype(np.float32, copy=False) @ Q.T                # (c, S)
            rows = np.arange(c, dtype=np.int64)
            ids = np.concatenate([retrieval.topk(S[:, t], rows, self.k)[1] for t in range(len(Q))])
        else:
            ids = self._index.search(self._space.project(Q), self.k)[1].ravel()
        return np.unique(ids[ids >= 0])

    def _candidate_scores(self, cand: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Best-trajectory scores (m,) float32 of the rows cand (m,) (ascending, distinct), and where
        computed each row's point in the newest column (m,) float32 (else None): for cosine columns
        of float32 rows ``numba_kernels.pair_scores`` (each needed point once), else
        numba_kernels.candidate_rows / candidate_scores over the similarities of the rows they need
        to the last seq_len queries (one BLAS product), or :meth:`_candidate_scores_numpy` without
        numba (the same values to float rounding)."""
        if not cand.size:
            return np.zeros(0, np.float32), None
        if not numba_kernels.available():
            return self._candidate_scores_numpy(cand), None
        off = self._margin - self._base
        if not self.contrast_window and self._db.dtype == np.float32:
            return numba_kernels.pair_scores(cand, self._db, self._Q, off, self._qc, self._qpad)
        h = self.contrast_window // 2
        cand, R = numba_kernels.candidate_rows(cand, self._margin + h, h + self._right, int(self._qc.max()))
        return numba_kernels.candidate_scores(cand, R, self._row_sims(R), off, self._qc, self._qpad,
                                              h if self.contrast_window else -1, _EPS), None

    def _row_sims(self, R: np.ndarray) -> np.ndarray:
        """(|R|, L) float64: the best-shift cosine of each stored row R with each of the last L queries."""
        G = self._db[R].astype(np.float32) @ self._Q.reshape(-1, self._Q.shape[2]).T    # (|R|, L * S)
        return G.reshape(len(R), self.seq_len, -1).max(2).astype(np.float64)

    def _candidate_scores_numpy(self, cand: np.ndarray) -> np.ndarray:
        """Best-trajectory scores (m,) float32 of the candidate rows cand (m,) (ascending), in NumPy."""
        off = self._margin - self._base                               # (V, L) row offsets
        P = cand[:, None, None] - off[None]                           # (m, V, L) trajectory rows
        ck = self._qc[None, None, :]
        inside = (P >= 0) & (P < ck)
        h = self.contrast_window // 2
        W = P[..., None] + np.arange(-h, h + 1)                       # (m, V, L, 2h + 1) window rows
        need = inside[..., None] & (W >= 0) & (W < ck[..., None])
        R = np.unique(W[need])                                        # every row a point needs
        G = self._row_sims(R)
        col = np.broadcast_to(np.arange(self.seq_len), P.shape)
        pi, pk = P[inside], col[inside]
        s = G[np.searchsorted(R, pi), pk]
        if self.contrast_window:
            lo, hi = np.maximum(pi - h, 0), np.minimum(pi + h + 1, self._qc[pk])
            C1 = np.vstack([np.zeros(self.seq_len), np.cumsum(G, 0)])
            C2 = np.vstack([np.zeros(self.seq_len), np.cumsum(G * G, 0)])
            a, b, n = np.searchsorted(R, lo), np.searchsorted(R, hi), hi - lo
            mu = (C1[b, pk] - C1[a, pk]) / n
            sd = np.sqrt(np.maximum((C2[b, pk] - C2[a, pk]) / n - mu * mu, 0.0))
            s = np.where(sd > _EPS, (s - mu) / np.maximum(sd, _EPS), 0.0)
        vals = np.broadcast_to(self._qpad, P.shape).astype(np.float32)
        vals[inside] = s.astype(np.float32)
        return (vals.sum(2, dtype=np.float64).max(1) / self.seq_len).astype(np.float32)
