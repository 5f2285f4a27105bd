"""greenloop-seq's streaming detector, and what is computed by streaming it (the speed path).

``Detector`` (moved here from ``greenloop.seqmatch``: streaming code lives in ``speed/``) takes one
frame or descriptor at a time and declares closures; :func:`score_matrix` is the (N, N) matrix
the stream thresholds, computed by feeding a Detector column by column, so S[:, j] is exactly what
the stream sees at query j; :func:`tune_knobs` scores a knob grid by it, and
:func:`stream_check` compares a stream's events with a matrix. The stages the detector is built
of (descriptors, normalisation, contrast normalisation, calibration) and the scoring of its
matrices stay in ``greenloop.seqmatch`` (its module doc describes the method, its units and the
memory per stored frame); ``greenloop.detectors.greenloop_seq`` registers it.
"""
from __future__ import annotations

import math

import numpy as np

from greenloop import evaluate, features, retrieval
from greenloop.seqmatch import (_EPS, COLORS, DEFAULT_VELOCITIES, STORE_DTYPES, _check_descriptor, _join,
                                SHIFTABLE_DIMS, calibrate_scores, cell_shifts, check_calibration, center, center_stored, center_windows,
                                columns_to_scores, contrast_normalise, describe_frames, matrix_events, normalise,
                                shift_cells, threshold_range)
from greenloop.similarity import l2_normalise
from greenloop.util import numba_kernels
from greenloop.util.checks import positive_int
from greenloop.util.threads import one_blas_thread

__all__ = ["Detector", "best_candidate", "score_matrix", "tune_knobs", "stream_disagreements", "stream_matches_matrix", "stream_check"]


def _offsets(seq_len: int, velocities) -> np.ndarray:
    """Distinct row offsets round(v k), k = 0..seq_len-1: (V, seq_len) int, one row per velocity."""
    rows = sorted({tuple(int(round(v * k)) for k in range(seq_len)) for v in velocities})
    return np.asarray(rows, dtype=np.int64).reshape(len(rows), seq_len)


def _ring_scores(R, rows, c: int, base, dtype=np.float64) -> np.ndarray:
    """Best-trajectory score of each candidate row i < c of the newest query.

    R: (L, W) float32 ring of padded normalised columns: the column of the query k frames back is
    ring row rows[k], its value for database row r at R[rows[k], margin + r], its mean (a point
    outside the stored frames) everywhere else. base: (V, L) margin - offsets.
    Returns (c,) float32: max over velocities of the mean along the trajectory ending at (i, j).
    The sum runs over k = 0..L-1 in order in ``dtype`` (float64: the scores before the calibrated
    option existed, bit for bit; float32: 4x faster, for calibrated scores), one slice per point.
    """
    Rd = R[rows, :int(base.max()) + c].astype(dtype)             # one cast; the same values
    best = numba_kernels.ring_best(Rd, base, c)                  # the same sums in one compiled pass
    if best is not None:
        return (best / R.shape[0]).astype(np.float32)
    acc = np.zeros((base.shape[0], c), dtype)
    for v in range(base.shape[0]):
        a = acc[v]
        for k in range(base.shape[1]):
            b = base[v, k]
            np.add(a, Rd[k, b:b + c], out=a)
    return (acc.max(0) / R.shape[0]).astype(np.float32)

def _check_threshold(threshold, contrast_window: int, calibrated: bool = False):
    if threshold is None:
        return None
    if calibrated:
        if not math.isfinite(float(threshold)):
            raise ValueError(f"threshold must be a finite z-score for calibrated scores, got {threshold!r}")
        return float(threshold)
    lo, hi = threshold_range(contrast_window)
    t = float(threshold)
    if not (math.isfinite(t) and lo <= t <= hi):
        kind = "cosine" if contrast_window == 0 else f"z-score (contrast_window {contrast_window})"
        raise ValueError(f"threshold must lie in [{lo:.3g}, {hi:.3g}] for {kind} scores, got {threshold!r}")
    return t

class Detector:
    """Streaming greenloop-seq: one frame (or descriptor) in, a closure event or None out.

    threshold: declare a closure at query j when its best sequence score >= threshold (range:
        :func:`threshold_range`); None only scores (``last_scores``) and declares nothing.
    descriptor: one of DESCRIPTORS (raw frames) -- ignored by ``update_descriptor``.
    seq_len: L, frames per trajectory (1 = single-frame matching). velocities: database frames
        per query frame along a trajectory (SeqSLAM's V_min..V_max). exclude: only stored frames
        i with j - i > exclude are candidates. contrast_window: SeqSLAM R_window (0 = off).
    projection: optional ``similarity.Projection`` (see :func:`fit_projection`).
    store_dtype: "float32" or "float16" for the stored descriptors. color: "bgr" or "rgb".
    index: None (the reference: every stored frame is scored) or a ``greenloop.retrieval`` kind
        ("scan", "flat", "ivf", "hnsw", "swp", "qdp"): candidate mode, the sequence score is
        computed only for the ``k`` stored frames the index retrieves for the newest query
        (``index_options``: keyword arguments of ``retrieval.make_index``). See
        :meth:`_match_candidates` for what it computes and where it may differ from the reference.
    Options (off by default, the behaviour before them):
    center_window: W > 0 subtracts from each raw descriptor the mean of the last W raw descriptors
        (itself included, :func:`center`) before normalising: a buffer of W x D float32, fixed.
        A list of windows centres on each and joins the L2-normalised parts (K windows: K * D
        stored dims, a buffer of the longest window). While the longest window fills, the stored
        frames are centred again on every frame so far (:func:`center_stored`), so the start of the
        recording can be recognised.
    calibrate: score each candidate as a z-score against the query's own candidates
        (:func:`calibrate_scores`): True or "zscore" against all of them, "neighbourhood" against
        those away from the best one; the threshold is then a z-score (any finite float).
    repeat_cos: a query whose raw descriptor (L2-normalised, before centring) has cosine >=
        repeat_cos with the previous frame's is a repeat (the camera stopped, or a frame duplicated by a slower replay): it is
        matched and stored, but its column does not enter the trajectory ring, so a stop or a
        half-speed replay keeps the trajectories' velocities. None: off.
    cell_shift: s > 0 matches the query's "gradients" grid moved sideways by -s..s cell columns
        (:func:`greenloop.seqmatch.shift_cells`, after centring) against each stored frame as it
        was stored, keeping the best cosine: a revisit seen from a little to the left or right
        (another aisle side, a camera mounted elsewhere). The stored frames are not shifted, so
        memory is unchanged; the match reads every stored frame once for s = 1
        (``numba_kernels.max_dot``), 2s + 1 times otherwise. Needs a descriptor that begins with
        the gradients grid (``seqmatch.SHIFTABLE_DIMS``; the fused descriptor's CNN part is not
        shifted) and no projection.
    Negative velocities search revisits driven the opposite way (database rows increasing while
    the query goes back in time); a trajectory point on a row not yet a candidate counts as the
    column's mean, as one before the first stored frame.
    Attributes: ``events`` (list of {'frame', 'match', 'score'}), ``frame_index``, ``last_scores``
    ((C,) float32 scores of the newest query's candidates: every stored row 0..C-1, or in candidate
    mode the rows ``last_candidates`` (C,) int64, ascending), ``bytes_per_frame``.
    """

    def __init__(self, threshold=None, descriptor: str = "pixels", seq_len: int = 10,
                 velocities=DEFAULT_VELOCITIES, exclude: int = 150, contrast_window: int = 10,
                 projection=None, store_dtype: str = "float32", color: str = "bgr", weights="auto",
                 index: str | None = None, k: int = 20, index_options: dict | None = None,
                 center_window: int | list = 0, calibrate: bool | str = False, repeat_cos=None, cell_shift: int = 0):
        if index is not None and index not in retrieval.KINDS:
            raise ValueError(f"index must be None (score every stored frame) or one of "
                             f"{retrieval.KINDS}, got {index!r}")
        self.index_kind, self.k = index, positive_int("k", k, 1, whole_floats=True)
        self.index_options = dict(index_options or {})
        self.descriptor = _check_descriptor(descriptor)
        self.seq_len = positive_int("seq_len", seq_len, 1, whole_floats=True)
        self.exclude = positive_int("exclude", exclude, 0, whole_floats=True)
        self.contrast_window = positive_int("contrast_window", contrast_window, 0, whole_floats=True)
        self._windows = center_windows(center_window)  # validates; center_window stays as given
        self.center_window = list(center_window) if isinstance(center_window, tuple) else center_window
        self._W = max(self._windows, default=0)        # the centring buffer's length: the longest window
        self.calibrate = check_calibration(calibrate)   # False, "zscore" or "neighbourhood"
        self._shifts = cell_shifts(cell_shift)
        self.cell_shift = len(self._shifts) // 2
        if self.cell_shift and projection is not None:
            raise ValueError("cell_shift moves the cells of the gradients grid, which a projection mixes: pass one or the other")
        self.threshold = _check_threshold(threshold, self.contrast_window, self.calibrate)
        if repeat_cos is not None and not (math.isfinite(float(repeat_cos)) and -1 <= float(repeat_cos) <= 1):
            raise ValueError(f"repeat_cos must be a cosine in [-1, 1] or None, got {repeat_cos!r}")
        self.repeat_cos = None if repeat_cos is None else float(repeat_cos)
        v = [float(x) for x in np.atleast_1d(velocities)]
        if not v or not all(math.isfinite(x) and x != 0 for x in v):
            raise ValueError(f"velocities must be non-zero numbers (negative: reverse revisits), got {velocities!r}")
        if store_dtype not in STORE_DTYPES:
            raise ValueError(f"store_dtype must be one of {STORE_DTYPES}, got {store_dtype!r}")
        if color not in COLORS:
            raise ValueError(f"color must be one of {COLORS}, got {color!r}")
        if index is not None and (self.calibrate or repeat_cos is not None or min(v) < 0 or self.cell_shift):
            raise ValueError("candidate mode (index=...) scores the retrieved frames only and does not yet "
                             "support calibrate, repeat_cos, cell_shift or negative (reverse) velocities: pass index=None, "
                             "or knobs without them (e.g. the CLI's --threshold with --index)")
        self.velocities, self.projection, self.color, self.weights = tuple(v), projection, color, weights
        self._resolved = None   # features.resolve(descriptor, weights), at the first frame
        self.store_dtype = np.dtype(store_dtype)
        off = _offsets(self.seq_len, self.velocities)
        self._margin = int(off.max())
        self._base = self._margin - off
        self.reset()

    def reset(self) -> None:
        """Forget every stored frame and event."""
        self._db = None                       # (capacity, D) stored descriptors
        L = self.seq_len
        self._right = max(int(self._base.max()) - self._margin, 0)    # room for negative offsets
        self._ring = np.zeros((L, self._margin + self._right + 256), np.float32)   # see _ring_scores
        self._pads = np.zeros(L, np.float32)
        self._empty = np.ones(L, bool)        # ring rows holding no column yet, or an empty one
        self._newest = 0
        self.frame_index = 0
        self.events: list[dict] = []
        self.last_scores = np.zeros(0, np.float32)
        self.last_candidates = np.zeros(0, np.int64)
        self._frame_shape = None
        self._index = None                    # candidate mode: the retrieval index, made at frame 0
        self._Q = None                        # (L, D) the last L query descriptors, newest first
        self._qc = np.zeros(L, np.int64)      # their candidate counts c = j - exclude (0: none yet)
        self._qpad = np.zeros(L, np.float32)  # their columns' pads (points outside stored frames)
        self._sum = None                      # (D,) float64 sum of the indexed rows (cosine pads)
        self._recent = None                   # (center_window, D) raw descriptors, oldest first
        self._n_recent = 0
        self._previous = None                 # the previous frame's normalised descriptor

    @property
    def bytes_per_frame(self) -> int:
        """Bytes held per stored frame: D * itemsize (descriptor) + 4 * seq_len (column buffer);
        in candidate mode D * itemsize + the index's ``bytes_per_frame()`` (no column buffer);
        0 before the first frame (D unknown)."""
        if self._db is None:
            return 0
        if self._index is not None:
            return int(self._db.shape[1] * self.store_dtype.itemsize + self._index.bytes_per_frame())
        return int(self._db.shape[1] * self.store_dtype.itemsize + 4 * self.seq_len)

    def _store(self, y: np.ndarray) -> None:
        j = self.frame_index
        if self._db is None:
            self._db = np.empty((256, y.size), self.store_dtype)
        elif y.size != self._db.shape[1]:
            raise ValueError(f"descriptor {j} has {y.size} dims, the stream's first had {self._db.shape[1]}")
        if j == len(self._db):
            self._db = np.concatenate([self._db, np.empty_like(self._db)])
        self._db[j] = y

    def _ensure_width(self, c: int) -> None:
        """Grow the ring (doubling, new room filled with each column's mean) to hold c rows."""
        R = self._ring
        if self._margin + c + self._right > R.shape[1]:
            grown = np.empty((R.shape[0], max(2 * R.shape[1], self._margin + c + self._right)), np.float32)
            grown[:, :R.shape[1]] = R
            grown[:, R.shape[1]:] = self._pads[:, None]
            self._ring = grown

    def _push_column(self, s: np.ndarray) -> None:
        """Write the newest normalised column into the ring (dropping the one seq_len back)."""
        self._ensure_width(s.size)
        R, m = self._ring, self._margin
        r = self._newest = (self._newest - 1) % self.seq_len
        pad = float(s.mean()) if s.size else 0.0
        R[r, :] = pad
        R[r, m:m + s.size] = s
        self._pads[r], self._empty[r] = pad, s.size == 0
        if s.size and self._empty.any():   # before the stream began: no evidence, the newest mean
            R[self._empty] = pad
            self._pads[self._empty] = pad

    def update_descriptor(self, x) -> dict | None:
        """Match one raw descriptor x (D,) (L2-normalised and projected here), then store it.
        Returns the closure event {'frame': j, 'match': i, 'score': s} or None."""
        x = np.asarray(x, dtype=np.float32).reshape(1, -1)
        if x.shape[1] == 0 or not np.all(np.isfinite(x)):
            raise ValueError(f"descriptor {self.frame_index} is empty or has NaN/inf values")
        self._check_shiftable(x.shape[1])
        parts = self._centered(x)
        if self.cell_shift:
            Q = self._shifted(parts)                         # (S, K * D) the query under each shift
            y = Q[0]
        else:
            y = normalise(_join(parts), self.projection)[0]
        self._recenter_stored()
        j, c = self.frame_index, max(self.frame_index - self.exclude, 0)
        if self._db is not None and y.size != self._db.shape[1]:
            raise ValueError(f"descriptor {j} has {y.size} dims, the stream's first had {self._db.shape[1]}")
        if self.index_kind is not None:
            return self._match_candidates(y)
        gate = normalise(x)[0] if self.repeat_cos is not None else y
        if not c:
            return self._match(y, np.zeros(0, np.float32), gate)
        with one_blas_thread():   # a 2-thread gemv stalls on a loaded 2-core machine
            if self.cell_shift:
                s = numba_kernels.max_dot(self._db[:c].astype(np.float32, copy=False), Q)
            else:
                s = self._db[:c].astype(np.float32, copy=False) @ y
        return self._match(y, s, gate)

    def _check_shiftable(self, dims: int) -> None:
        """ValueError when a cell shift is asked of raw descriptors of ``dims`` dims that do not begin
        with the gradients grid (``seqmatch.SHIFTABLE_DIMS``)."""
        if self.cell_shift and dims not in SHIFTABLE_DIMS:
            raise ValueError(f"cell_shift needs a descriptor that begins with the 'gradients' grid (seqmatch.CELL_GRID): "
                             f"'gradients' or 'gradients+efficientnetlite0' ({' or '.join(map(str, SHIFTABLE_DIMS))} "
                             f"dims), got {dims} dims")

    def _shifted(self, parts: list) -> np.ndarray:
        """The query under each of its cell shifts (``_shifts``, 0 first), (S, K * D) float32: row t is
        what ``normalise(center(shift_cells(X, t)))`` gives for this frame (the same operations row
        by row, so row 0 is the unshifted query bit for bit), for all shifts and parts at once."""
        joined = np.hstack(parts)                                             # (1, K * D)
        Q = np.vstack([shift_cells(joined, t, parts[0].shape[1]) for t in self._shifts])   # (S, K * D)
        if len(parts) > 1:                                                  # _join: each part L2-normalised
            Q = l2_normalise(Q.reshape(-1, parts[0].shape[1])).reshape(len(Q), -1)
        return normalise(Q)

    def _centered(self, x: np.ndarray) -> list:
        """The parts of x (1, D) centred (:func:`center`): per window, x minus the mean of the last
        window raw descriptors, x included, each (1, D), before ``_join`` joins them; [x] without centring."""
        W = self._W
        if not W:
            return [x]
        if self._recent is None or self._recent.shape[1] != x.shape[1]:
            if self._recent is not None:
                raise ValueError(f"descriptor {self.frame_index} has {x.shape[1]} dims, the stream's "
                                 f"first had {self._recent.shape[1]}")
            self._recent = np.zeros((W, x.shape[1]), np.float32)
        self._recent[:-1] = self._recent[1:].copy()
        self._recent[-1] = x[0]
        self._n_recent = min(self._n_recent + 1, W)
        return [x - self._recent[W - min(w, self._n_recent):].mean(axis=0) for w in self._windows]

    def _recenter_stored(self) -> None:
        """While the centring window fills (frame j < center_window), centre the stored frames 0..j-1
        again on the mean of frames 0..j, the mean frame j was centred on (:func:`center_stored`);
        in candidate mode the index (at most center_window rows) is rebuilt from them."""
        W, j = self._W, self.frame_index
        if not W or not 0 < j < W or self._db is None:
            return
        raw = self._recent[W - self._n_recent:]           # frames 0..j, oldest first
        self._db[:j] = normalise(center_stored(raw, self.center_window), self.projection)[:j]
        if self._index is not None and self._index.n_stored:
            n_in = self._index.n_stored
            self._index = retrieval.make_index(self.index_kind, self._db.shape[1], **self.index_options)
            self._index.add(self._db[:n_in].astype(np.float32))
            self._sum = self._db[:n_in].astype(np.float32).sum(0, dtype=np.float64)

    def _is_repeat(self, y: np.ndarray) -> bool:
        prev, self._previous = self._previous, y.copy()
        return self.repeat_cos is not None and prev is not None and float(prev @ y) >= self.repeat_cos

    def _match(self, y: np.ndarray, s: np.ndarray, gate=None) -> dict | None:
        """The stages after the similarity: s (C,) cosine to the C candidates of query j = frame_index.
        gate: what the repeat gate compares with the previous frame's (default y): the L2-normalised
        raw descriptor, so that a standing camera is a repeat however its centring window fills."""
        j, c = self.frame_index, s.size
        s = contrast_normalise(s, self.contrast_window)
        if not self._is_repeat(y if gate is None else gate):
            self._push_column(s)
        if c:
            self._ensure_width(c)
            rows = (self._newest + np.arange(self.seq_len)) % self.seq_len
            self.last_scores = _ring_scores(self._ring, rows, c, self._base,
                                            np.float32 if self.calibrate else np.float64)
            if self.calibrate:
                self.last_scores = calibrate_scores(self.last_scores, self.calibrate)
        else:
            self.last_scores = s
        self._store(y)
        self.frame_index += 1
        if c and self.threshold is not None:
            i = int(np.argmax(self.last_scores))
            if self.last_scores[i] >= self.threshold:
                event = {"frame": j, "match": i, "score": float(self.last_scores[i])}
                self.events.append(event)
                return event
        return None

    def _match_candidates(self, y: np.ndarray) -> dict | None:
        """Candidate mode: the sequence score of the k frames the index retrieves for query j.

        Frames 0..c-1 (c = j - exclude) are added to the index before query j (delayed insertion
        keeps the exclusion window). For each candidate i the trajectory points (i - round(v k),
        column j - k) are scored as in the reference: the cosine of query j - k with that stored
        row, contrast-normalised over rows within contrast_window // 2 clipped to the c_k rows that
        query had (:func:`contrast_normalise`), computed for the rows the points need only (one
        (rows, L) product). Where the index returns every stored row the scores equal the
        reference's except at points outside the stored frames: those count as the column's pad,
        the exact column mean for cosine scores (contrast_window 0, from a running sum of the
        stored rows) but 0 (a z-score's expected value) instead of the column's mean z-score
        otherwise, since that mean needs the whole column. Cost per frame: k x L x (window + 1)
        dot products, independent of the number stored (plus the index's search).
        """
        j, c, L = self.frame_index, max(self.frame_index - self.exclude, 0), self.seq_len
        if self._index is None:
            self._index = retrieval.make_index(self.index_kind, y.size, **self.index_options)
            self._Q, self._sum = np.zeros((L, y.size), np.float32), np.zeros(y.size)
        n_in = self._index.n_stored
        if c > n_in:
            new = self._db[n_in:c].astype(np.float32)
            self._index.add(new)
            self._sum += new.sum(0, dtype=np.float64)
        pad = float(self._sum @ y / c) if c and self.contrast_window == 0 else 0.0
        self._Q[1:], self._qc[1:], self._qpad[1:] = self._Q[:-1], self._qc[:-1], self._qpad[:-1]
        self._Q[0], self._qc[0], self._qpad[0] = y, c, pad
        self._qpad[self._qc == 0] = pad            # empty / pre-stream columns: the newest pad
        self.last_candidates, self.last_scores = np.zeros(0, np.int64), np.zeros(0, np.float32)
        if c:
            self.last_candidates, self.last_scores = self._candidate_scores(self._index.search(y, self.k)[1][0])
        self._store(y)
        self.frame_index += 1
        if c and self.threshold is not None and self.last_scores.size:
            i = int(np.argmax(self.last_scores))
            if self.last_scores[i] >= self.threshold:
                event = {"frame": j, "match": int(self.last_candidates[i]),
                         "score": float(self.last_scores[i])}
                self.events.append(event)
                return event
        return None

    def _candidate_scores(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The retrieved rows ids (k,) (-1: none) -> (candidates (m,) int64 ascending and distinct,
        their best-trajectory scores (m,) float32): numba_kernels.candidate_rows / candidate_scores
        over the similarities of the rows they need to the last seq_len queries (one BLAS product),
        or :meth:`_candidate_scores_numpy` without numba (the same values to float rounding)."""
        if not numba_kernels.available():
            cand = np.unique(ids[ids >= 0])
            return cand, self._candidate_scores_numpy(cand)
        h = self.contrast_window // 2
        cand, R = numba_kernels.candidate_rows(ids, self._margin + h, h, int(self._qc.max()))
        with one_blas_thread():
            G = (self._db[R].astype(np.float32) @ self._Q.T).astype(np.float64)   # (|R|, L)
        return cand, numba_kernels.candidate_scores(cand, R, G, self._margin - self._base, self._qc, self._qpad,
                                                    h if self.contrast_window else -1, _EPS)

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
        with one_blas_thread():
            G = (self._db[R].astype(np.float32) @ self._Q.T).astype(np.float64)   # (|R|, L)
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

    def preload(self, X) -> None:
        """Candidate mode: start as if the raw descriptors X (N, D) of an already-recorded stream
        had been fed to :meth:`update_descriptor` in order, without deciding on them (a long
        recording's store in seconds, instead of N decisions).

        Resets, then sets what later frames read: the N stored descriptors, the index holding the
        first max(N - 1 - exclude, 0) of them (one ``add``), the running sum of those rows, the last
        seq_len queries (descriptors, candidate counts, pads), the centring buffer; frame_index = N.
        The frames streamed after it then get the uninterrupted stream's scores and events, bit for
        bit, for "scan", "flat", "ivf" (its quantiser learns the first train_size frames either way),
        "swp" and "qdp"; an HNSW graph depends on the order of insertion (faiss inserts a batch
        level by level, shuffled), so its approximate neighbours may differ. ``events`` stays empty
        and ``last_scores`` / ``last_candidates`` hold nothing: preloaded frames are stored, not
        decided. Memory while it runs: about three float32 copies of X beyond what it keeps.
        """
        if self.index_kind is None:
            raise ValueError("preload needs candidate mode (index=...): the reference detector keeps every "
                             "stored frame's similarity columns; stream the frames through update_descriptor")
        X = np.asarray(X, dtype=np.float32)
        if X.ndim != 2 or 0 in X.shape or not np.all(np.isfinite(X)):
            raise ValueError(f"X must be (N, D) finite descriptors with N, D >= 1, got shape {X.shape} "
                             f"(NaN/inf: fix the descriptors first)")
        self.reset()
        n, d, L, W = len(X), X.shape[1], self.seq_len, self._W
        Y = normalise(center(X, self.center_window), self.projection)           # each frame as a query
        self._db = np.empty((256 * 2 ** max(math.ceil(math.log2(n / 256)), 0), Y.shape[1]), self.store_dtype)
        self._db[:n] = normalise(center_stored(X, self.center_window), self.projection) if W else Y
        c = max(n - 1 - self.exclude, 0)                   # rows indexed before query n - 1
        self._index = retrieval.make_index(self.index_kind, Y.shape[1], **self.index_options)
        if c:
            self._index.add(self._db[:c].astype(np.float32))
        first = max(c - L, 0)
        S = _running_sums(self._db[:c], first)             # S[i]: sum of rows 0..first + i - 1
        self._sum, self._Q = S[-1].copy(), np.zeros((L, Y.shape[1]), np.float32)
        for k, j in enumerate(range(n - 1, max(n - 1 - L, -1), -1)):     # query j, k frames back
            cj = max(j - self.exclude, 0)
            self._Q[k], self._qc[k] = Y[j], cj
            self._qpad[k] = float(S[cj - first].copy() @ Y[j] / cj) if cj and self.contrast_window == 0 else 0.0
        self._qpad[self._qc == 0] = self._qpad[0]          # pre-stream columns: the newest pad
        if W:
            m = min(n, W)
            self._recent, self._n_recent = np.zeros((W, d), np.float32), m
            self._recent[W - m:] = X[n - m:]
        self.frame_index = n

    def _check_frame(self, frame, index: int) -> None:
        if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim not in (2, 3) \
                or (frame.ndim == 3 and frame.shape[2] not in (1, 3)) or 0 in frame.shape:
            got = f"{frame.dtype} {frame.shape}" if isinstance(frame, np.ndarray) else type(frame).__name__
            raise ValueError(f"frame {index} must be a non-empty (H, W, 3) or (H, W) uint8 array, "
                             f"got {got}")
        if self._frame_shape is None:
            self._frame_shape = frame.shape
        elif frame.shape != self._frame_shape:
            raise ValueError(f"frame {index} has shape {frame.shape}, but the stream started with "
                             f"{self._frame_shape}: one camera, one frame size")

    def update(self, frame) -> dict | None:
        """One raw frame (H, W, 3) uint8 BGR (RGB with color="rgb") or (H, W) gray -> event or None."""
        return self._update_frames([frame])[0]

    def update_many(self, frames) -> list[dict]:
        """A window of raw frames (one batched descriptor pass) -> the events declared in it."""
        return [e for e in self._update_frames(list(frames)) if e is not None]

    def decide_many(self, frames) -> list[dict]:
        """A window of raw frames -> one decision per frame, closures or not: {'frame': j, 'match':
        its best candidate (stored frame number, -1 while none is a candidate), 'score': that
        candidate's score (NaN when none), 'closure': whether a closure was declared}."""
        out = []
        for x in self._describe(list(frames)):
            j, event = self.frame_index, self.update_descriptor(x)
            match, score = best_candidate(self)
            out.append({"frame": j, "match": match, "score": score, "closure": event is not None})
        return out

    def _describe(self, frames: list) -> np.ndarray:
        """The window's raw descriptors (N, D), each frame checked; the weights looked up once."""
        for k, f in enumerate(frames):
            self._check_frame(f, self.frame_index + k)
        if self._resolved is None:   # the weights are looked up at the first frame, not at every one
            self._resolved = features.resolve(self.descriptor, self.weights)
        return describe_frames(frames, self.descriptor, self.color, resolved=self._resolved)

    def _update_frames(self, frames) -> list:
        if not frames:
            return []
        return [self.update_descriptor(x) for x in self._describe(frames)]


def best_candidate(det) -> tuple[int, float]:
    """The newest query's best candidate of a descriptor-fed stream (this module's Detector or a
    subclass, after ``update_descriptor``): (stored frame number, score), (-1, NaN) when the query
    had no candidate. In candidate mode the frame number is the retrieved row's."""
    s = det.last_scores
    if not s.size:
        return -1, float("nan")
    i = int(np.argmax(s))
    rows = getattr(det, "last_candidates", None) if det.index_kind is not None else None
    return (int(rows[i]) if rows is not None else i), float(s[i])

def _running_sums(R, first: int, chunk: int = 65536) -> np.ndarray:
    """Running float64 sums of the rows R (c, D) added one at a time, as a candidate-mode stream
    adds them (so bit for bit the same): (c - first + 1, D), row i = the sum of R[:first + i]."""
    acc = np.zeros((1, R.shape[1]))
    for a in range(0, first, chunk):
        acc = np.add.accumulate(np.vstack([acc, R[a:min(a + chunk, first)]]), axis=0)[-1:]
    return np.add.accumulate(np.vstack([acc, R[first:]]), axis=0)


def score_matrix(X, exclude: int = 150, seq_len: int = 10, velocities=DEFAULT_VELOCITIES,
                 contrast_window: int = 10, projection=None, store_dtype: str = "float32",
                 center_window: int | list = 0, calibrate: bool | str = False, repeat_cos=None,
                 cell_shift: int = 0) -> np.ndarray:
    """The (N, N) score matrix the streaming detector thresholds, for ``greenloop.evaluate``.

    X: (N, D) raw descriptors in stream order (:func:`describe`). The other arguments are those
    of :class:`Detector`. The columns are computed by feeding X to a Detector one row at a time,
    so S[:, j] is exactly what the stream sees at query j.
    Returns S (N, N) float32: S[i, j] = sequence score of database frame i for query j where
    j - i > exclude; every other entry holds the smallest filled score (0 if none), so it never
    ranks above a candidate. N = 0 gives a (0, 0) matrix.
    """
    X = np.asarray(X, dtype=np.float32)
    if X.ndim != 2:
        raise ValueError(f"X must be (N, D) descriptors, got shape {X.shape}")
    n = len(X)
    det = Detector(None, seq_len=seq_len, velocities=velocities, exclude=exclude,
                   contrast_window=contrast_window, projection=projection, store_dtype=store_dtype,
                   center_window=center_window, calibrate=calibrate, repeat_cos=repeat_cos, cell_shift=cell_shift)
    if n == 0:
        return np.zeros((0, 0), np.float32)
    if not np.all(np.isfinite(X)):
        raise ValueError("X has NaN or inf values")
    det._check_shiftable(X.shape[1])
    W, cw, f32 = det._W, det.center_window, np.float32
    Ys = [normalise(center(shift_cells(X, t, X.shape[1]) if t else X, cw), projection) for t in det._shifts]   # the queries
    stored = normalise(center_stored(X, cw), projection) if W else Ys[0]
    stored = stored.astype(det.store_dtype).astype(f32)
    G = stored @ Ys[0].T                                     # stored rows x queries, one product per shift
    for Y in Ys[1:]:
        np.maximum(G, stored @ Y.T, out=G)
    for j in range(det.exclude + 1, min(W - 1, n)):           # the window still filling: rows centred on 0..j
        c = j - det.exclude
        rows = normalise(center_stored(X[:j + 1], cw), projection)[:c].astype(det.store_dtype).astype(f32)
        G[:c, j] = np.max([rows @ Y[j] for Y in Ys], axis=0)
    return columns_to_scores(det, Ys[0], G, normalise(X) if det.repeat_cos is not None else None)

def tune_knobs(descriptors: dict, GT, exclude: int, tune, seq_lens, contrast_windows,
               velocities=DEFAULT_VELOCITIES, projections=None) -> list[dict]:
    """Per-query AUC-PR on the tuning queries of every knob combination (the one tuning criterion).

    descriptors: {name: (N, D) descriptors of the described frames} (:func:`describe`), in the
    order to try them. GT: (N, N) bool ground truth; exclude: in frames of that stream.
    tune: (N,) bool tuning queries (``evaluate.split_mask``); only their labels are read.
    seq_lens, contrast_windows: candidate knobs, in frames (seq_len 1 = a single-frame method with
    local contrast normalisation as its knob); velocities as in :func:`score_matrix`.
    projections: optional {descriptor name: {label: ``similarity.Projection`` or None}}, the
    whitening candidates of that descriptor (fitted on tuning frames, :func:`fit_projection`);
    a descriptor not listed gets {"none": None}.
    Returns one dict per combination (descriptor-major, then whitening, seq_len, contrast_window):
    descriptor, whitening (label), seq_len, contrast_window, AUC-PR_tune_% and R@1_tune_%
    (``evaluate.per_query`` on the tuning queries, loop-closure mode, in %, 2 decimals).
    """
    rows = []
    projections = projections or {}
    for d, X in descriptors.items():
        for w, proj in projections.get(d, {"none": None}).items():
            for L in seq_lens:
                for cw in contrast_windows:
                    q = evaluate.per_query(score_matrix(X, exclude, L, velocities, cw, proj), GT, exclude,
                                           queries=tune, ks=(1,))
                    rows.append({"descriptor": d, "whitening": w, "seq_len": L, "contrast_window": cw,
                                 "AUC-PR_tune_%": round(100 * q["AUC-PR"], 2), "R@1_tune_%": round(100 * q["R@1"], 2)})
    return rows

def stream_disagreements(detector: Detector, S, tol: float = 1e-5) -> tuple[list[int], list[int]]:
    """The query frames where a streaming :class:`Detector`'s events and the score matrix S (N, N),
    computed on the same descriptors, disagree (:func:`matrix_events` over the
    ``detector.frame_index`` frames it has seen), split in two: (frames whose best matrix score
    lies farther than ``tol * max(1, |threshold|)`` from the threshold, frames within it).

    The stream scores a frame with matrix-vector products and S comes from one matrix product:
    the two round differently in the last bits, so a frame whose score *is* the threshold (a
    threshold picked among the tuning scores often is one) may fire on one side only. Those
    frames are the second list; the first must be empty."""
    if detector.threshold is None:
        raise ValueError("the detector has no threshold, so it declares nothing to compare")
    streamed = {e["frame"] for e in detector.events}
    batch = set(matrix_events(S, detector.threshold, detector.exclude, detector.frame_index))
    S = np.asarray(S)
    margin = tol * max(1.0, abs(float(detector.threshold)))
    gap = {j: abs(float(S[:j - detector.exclude, j].max()) - detector.threshold) for j in streamed ^ batch}
    return sorted(j for j, g in gap.items() if g > margin), sorted(j for j, g in gap.items() if g <= margin)


def stream_matches_matrix(detector: Detector, S, tol: float = 1e-5) -> bool:
    """Whether a streaming :class:`Detector`'s events fall on exactly the query frames where the
    score matrix S (N, N), computed on the same descriptors, reaches its threshold, up to float
    rounding at the threshold itself (:func:`stream_disagreements`' first list is empty)."""
    return not stream_disagreements(detector, S, tol)[0]


def stream_check(detector: Detector, X, S, GT) -> dict:
    """Stream every descriptor of X through ``detector`` (reset first) and compare its events with
    the thresholded score matrix S: the check that can fail, on a stream that holds the revisit.

    detector: a thresholded :class:`Detector` (or ``seqslam_stream.Detector``) with the knobs S was made
    with. X: (N, D) descriptors in stream order; S: (N, N) its score matrix; GT: (N, N) bool.
    Returns dict(equal (:func:`stream_matches_matrix`), at_threshold (frames declared on one side
    only whose score is the threshold up to float rounding, :func:`stream_disagreements`), events
    (declared), correct_events (events whose match is a ground-truth partner), revisit_queries
    (frames with a partner among their candidates)). ``equal`` with correct_events 0 says little:
    report both.
    """
    X = np.asarray(X)
    if len(X) != len(S):
        raise ValueError(f"X has {len(X)} frames but S is {np.shape(S)}: the same stream, please")
    G = np.asarray(GT, dtype=bool)
    detector.reset()
    for x in X:
        detector.update_descriptor(x)
    ok = [e for e in detector.events if G[e["match"], e["frame"]]]
    hard, at_threshold = stream_disagreements(detector, S)
    return {"equal": not hard, "at_threshold": len(at_threshold), "events": len(detector.events),
            "correct_events": len(ok), "revisit_queries": int(evaluate.revisit_queries(G, detector.exclude).sum())}
