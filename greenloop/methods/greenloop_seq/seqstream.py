"""greenloop-seq's streaming detector, and what is computed by streaming it (the speed path).

``Detector`` (moved here from ``greenloop.methods.greenloop_seq.seqmatch``: streaming code lives in ``speed/``) takes one
frame or descriptor at a time and declares closures; :func:`score_matrix` is the (N, N) matrix
the stream thresholds, computed by feeding a Detector column by column, so S[:, j] is exactly what
the stream sees at query j; :func:`tune_knobs` scores a knob grid by it, and
:func:`stream_check` compares a stream's events with a matrix. The stages the detector is built
of (descriptors, normalisation, contrast normalisation, calibration) and the scoring of its
matrices stay in ``greenloop.methods.greenloop_seq.seqmatch`` (its module doc describes the method, its units and the
memory per stored frame); ``greenloop.methods.greenloop_seq.entry`` registers it. Candidate mode's own
methods (``index=...``: what a frame retrieves and scores, the calibration's sampled null) are in
``greenloop.methods.greenloop_seq.candidates`` (``CandidateMode``, which ``Detector`` inherits).
"""
from __future__ import annotations

import math

import numpy as np

from greenloop import evaluate, features
from greenloop.methods.lsh import retrieval
from greenloop.methods.greenloop_seq.seqmatch import (COLORS, DEFAULT_VELOCITIES, STORE_DTYPES, _check_descriptor, _join,
                                quantise_rows, stored_values,
                                SHIFTABLE_DIMS, calibrate_scores, cell_shifts, check_calibration, center, center_stored, center_windows,
                                columns_to_scores, contrast_normalise, matrix_events, normalise,
                                shift_cells, threshold_range)
from greenloop.methods.greenloop_seq import candidates
from greenloop.similarity import l2_normalise
from greenloop.methods.greenloop_seq.candidates import (AROUND, FOLLOW, FOLLOW_DEPTH, INDEX_DIM, INDEX_FIT, NULL_GROUPS,  # noqa: F401
                                        NULL_SAMPLE, WARMUP, CandidateMode)
from greenloop.groundtruth import DEFAULT_EXCLUDE
from greenloop.util import numba_kernels
from greenloop.util.checks import positive_int
from greenloop.util.threads import one_blas_thread

__all__ = ["Detector", "INDEX_FIT", "NULL_SAMPLE", "INDEX_DIM", "best_candidate", "score_matrix", "tune_knobs", "stream_disagreements", "stream_matches_matrix", "stream_check"]


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

class Detector(CandidateMode):
    """Streaming greenloop-seq: one frame (or descriptor) in, a closure event or None out.

    threshold: declare a closure at query j when its best sequence score >= threshold (range:
        :func:`threshold_range`); None only scores (``last_scores``) and declares nothing.
    descriptor: one of DESCRIPTORS (raw frames) -- ignored by ``update_descriptor``.
    seq_len: L, frames per trajectory (1 = single-frame matching). velocities: database frames
        per query frame along a trajectory (SeqSLAM's V_min..V_max). exclude: only stored frames
        i with j - i > exclude are candidates. contrast_window: SeqSLAM R_window (0 = off).
    projection: optional ``similarity.Projection`` (see :func:`fit_projection`).
    store_dtype: "float32", "float16" or "int8" for the stored descriptors (int8: each row as int8 with
        a float32 scale, ``seqmatch.quantise_rows``, compared by ``numba_kernels.scaled_max_dot``: a
        quarter of float32's bytes read per frame; not in candidate mode). :func:`score_matrix`
        compares with the stored values, so the stream equals its matrix to float rounding. color: "bgr" or "rgb".
    index: None (the reference: every stored frame is scored) or a ``greenloop.methods.lsh.retrieval`` kind
        ("scan", "flat", "ivf", "hnsw", "swp", "qdp"): candidate mode, the sequence score is
        computed only for the ``k`` stored frames the index retrieves for the newest query (for
        each of its cell shifts) and, when calibrating, a fixed-size sample of the others
        (``index_options``: keyword arguments of ``retrieval.make_index``). Every option below
        applies to it as to the reference. See :meth:`_match_candidates` for what it computes and
        where it may differ from the reference.
    index_dim: candidate mode: the index holds the stored rows (the centred, normalised descriptor
        the detector compares) reduced to index_dim dims by a PCA fitted on the first ``index_fit``
        candidate rows (``candidates.IndexSpace``; causal: until that many rows are
        candidates the stored rows are scanned exactly, and the PCA never changes afterwards);
        None: the rows as they are. The sequence scores always use the full stored rows. Bytes
        per stored frame in candidate mode (``bytes_per_frame``): the stored row, D x itemsize (the
        named default: two centred 256-d parts joined, 512 float32 = 2048 B), plus the index's copy
        (index_dim float32 and what the kind adds: IVF's list ids, HNSW's links); no column buffer.
    null_sample: candidate mode with calibrate: the size of the sample of stored rows scored as
        the calibration's null beside the retrieved ones (``candidates.reservoir``, seeded);
        with cell_shift also what the mean of a shifted column (a point outside the stored frames)
        is estimated from.
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
        (:func:`greenloop.methods.greenloop_seq.seqmatch.shift_cells`, after centring) against each stored frame as it
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
    mode the rows scored, ``last_candidates`` (C,) int64, ascending), ``bytes_per_frame``.
    """

    _scale = None   # int8 store: (capacity,) float32 scale of each row (a class default for states saved before it)

    def __init__(self, threshold=None, descriptor: str = "pixels", seq_len: int = 10,
                 velocities=DEFAULT_VELOCITIES, exclude: int = DEFAULT_EXCLUDE, contrast_window: int = 10,
                 projection=None, store_dtype: str = "float32", color: str = "bgr", weights="auto",
                 index: str | None = None, k: int = 20, index_options: dict | None = None,
                 center_window: int | list = 0, calibrate: bool | str = False, repeat_cos=None, cell_shift: int = 0,
                 index_dim: int | None = None, index_fit: int = INDEX_FIT, null_sample: int = NULL_SAMPLE):
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
        if store_dtype == "int8" and index is not None:
            raise ValueError("store_dtype 'int8' is for the scan of every stored frame (index=None): candidate mode "
                             "reads the stored rows as float; store 'float32' or 'float16' with an index")
        if color not in COLORS:
            raise ValueError(f"color must be one of {COLORS}, got {color!r}")
        self._space = candidates.IndexSpace(None if index_dim is None else positive_int("index_dim", index_dim, 1),
                                            positive_int("index_fit", index_fit, 2))
        self.null_sample = positive_int("null_sample", null_sample, 2)
        self.velocities, self.projection, self.color, self.weights = tuple(v), projection, color, weights
        self._descriptor = None   # features.get(descriptor, weights), at the first frame
        self.store_dtype = np.dtype(store_dtype)
        off = _offsets(self.seq_len, self.velocities)
        self._margin = int(off.max())
        self._base = self._margin - off
        self.reset()

    def reset(self) -> None:
        """Forget every stored frame and event."""
        self._db = None                       # (capacity, D) stored descriptors
        self._scale = None
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
        self._Q = None                        # (L, S, D) the last L queries (S cell shifts), newest first
        self._qc = np.zeros(L, np.int64)      # their candidate counts c = j - exclude (0: none yet)
        self._qpad = np.zeros(L, np.float32)  # their columns' pads (points outside stored frames)
        self._sum = None                      # (D,) float64 sum of the candidate rows (cosine pads)
        self._seen = 0                        # candidate rows seen (summed, offered to the sample)
        self._space.mean = self._space.components = None    # the index's PCA, fitted again
        sample = self.index_kind is not None and (self.calibrate or self.cell_shift)
        self._slots = np.full(self.null_sample, -1, np.int64) if sample else None   # sampled candidate rows
        self._nrow = np.full(self.null_sample, -1, np.int64)    # the row each slot's score belongs to
        self._nscore = np.zeros(self.null_sample, np.float32)   # its score when its group was last scored
        self._follow = None                   # the previous frame's best rows (candidate mode)
        self._recent = None                   # (center_window, D) raw descriptors, oldest first
        self._n_recent = 0
        self._previous = None                 # the previous frame's normalised descriptor

    @property
    def bytes_per_frame(self) -> int:
        """Bytes held per stored frame: D * itemsize (descriptor) + 4 * seq_len (column buffer);
        in candidate mode D * itemsize + the index's ``bytes_per_frame()`` (no column buffer; the
        index holds index_dim or D dims per row); 0 before the first frame (D unknown). What does
        not grow with the stream is left out: the last seq_len queries (seq_len x shifts x D
        float32), the sample (null_sample rows), the index's PCA ((D + 1) x index_dim)."""
        if self._db is None:
            return 0
        if self.index_kind is not None:
            index = self._index.bytes_per_frame() if self._index is not None else 0
            return int(self._db.shape[1] * self.store_dtype.itemsize + index)
        return int(self._db.shape[1] * self.store_dtype.itemsize + 4 * (self._scale is not None) + 4 * self.seq_len)

    def _store(self, y: np.ndarray) -> None:
        j = self.frame_index
        if self._db is None:
            self._allocate(256, y.size)
        elif y.size != self._db.shape[1]:
            raise ValueError(f"descriptor {j} has {y.size} dims, the stream's first had {self._db.shape[1]}")
        if j == len(self._db):
            self._db = np.concatenate([self._db, np.empty_like(self._db)])
            if self._scale is not None:
                self._scale = np.concatenate([self._scale, np.zeros_like(self._scale)])
        self._put(j, y[None])

    def _allocate(self, rows: int, dims: int) -> None:
        """An empty store of ``rows`` rows of ``dims`` dims (and their scales for int8)."""
        self._db = np.empty((rows, dims), self.store_dtype)
        self._scale = np.zeros(rows, np.float32) if self.store_dtype == np.int8 else None

    def _put(self, a: int, Y: np.ndarray) -> None:
        """Store the normalised rows Y (n, D) float32 as rows a..a+n-1, in ``store_dtype``."""
        if self._scale is None:
            self._db[a:a + len(Y)] = Y
        else:
            self._db[a:a + len(Y)], self._scale[a:a + len(Y)] = quantise_rows(Y)

    def _products(self, c: int, Q: np.ndarray) -> np.ndarray:
        """(c,) float32: each stored row i < c's best product with the queries Q (m, D) (their cell
        shifts; m = 1 without), as the stored values give it (``seqmatch.stored_values``)."""
        if self._scale is not None:
            return numba_kernels.scaled_max_dot(self._db[:c], self._scale[:c], Q)
        if len(Q) > 1:
            return numba_kernels.max_dot(self._db[:c].astype(np.float32, copy=False), Q)
        return self._db[:c].astype(np.float32, copy=False) @ Q[0]

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
        gate = normalise(x)[0] if self.repeat_cos is not None else y
        if self.index_kind is not None:
            with one_blas_thread():   # every product of candidate mode (and a scan index's) on one thread
                return self._match_candidates(Q if self.cell_shift else y[None], gate)
        if not c:
            return self._match(y, np.zeros(0, np.float32), gate)
        with one_blas_thread():   # a 2-thread gemv stalls on a loaded 2-core machine
            s = self._products(c, Q if self.cell_shift else y[None])
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
        in candidate mode the index and the sum of the candidate rows (at most center_window rows)
        are made again from them."""
        W, j = self._W, self.frame_index
        if not W or not 0 < j < W or self._db is None:
            return
        raw = self._recent[W - self._n_recent:]           # frames 0..j, oldest first
        self._put(0, normalise(center_stored(raw, self.center_window), self.projection)[:j])
        if self._seen:
            self._index, self._space.mean, self._space.components = None, None, None
            self._sum = self._db[:self._seen].astype(np.float32).sum(0, dtype=np.float64)
            self._grow_index(self._seen)

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

    def _declare(self, j: int, rows=None) -> dict | None:
        """The closure of query j when the best of ``last_scores`` reaches the threshold: an event
        {'frame': j, 'match': its stored frame (rows[i], or i without rows), 'score'}, or None."""
        if self.threshold is None or not self.last_scores.size:
            return None
        i = int(np.argmax(self.last_scores))
        if self.last_scores[i] < self.threshold:
            return None
        event = {"frame": j, "match": int(rows[i]) if rows is not None else i, "score": float(self.last_scores[i])}
        self.events.append(event)
        return event

    def preload(self, X) -> None:
        """Start as if the raw descriptors X (N, D) of an already-recorded stream had been fed to
        :meth:`update_descriptor` in order, without deciding on most of them (a long recording's
        store in seconds instead of N decisions); in candidate mode and in the reference.

        Resets; sets the stored rows of the frames before the tail at once, and what a stream holds
        after them: candidate mode's running sum, sample and index of the candidate rows (one
        ``add``; the PCA fitted on the same first rows), the centring buffer, the repeat gate's last
        frame; then streams the tail through update_descriptor, which fills the last seq_len
        queries (candidate mode) or the ring of columns (the reference) as an uninterrupted stream
        does. The tail begins where the last seq_len frames that were no repeat and had candidates
        begin (:meth:`_tail_start`; all N frames when that is within the centring window), in
        candidate mode WARMUP frames earlier. Later frames then get the uninterrupted stream's
        scores and events, bit for bit, in the reference; in candidate mode too with "scan",
        "flat", "ivf" (its quantiser learns the first train_size rows either way), "swp" and "qdp"
        once the rows followed from frame to frame (FOLLOW) are the same, which the warm-up makes
        them in the tests but cannot promise (a row followed for FOLLOW_DEPTH frames may have won
        its place over one from long before); an HNSW graph depends on the order of insertion
        (faiss inserts a batch level by level, shuffled), so its approximate neighbours may differ. ``events`` stays empty and
        ``last_scores`` / ``last_candidates`` hold nothing. Memory while it runs: about three
        float32 copies of the stored rows beyond what it keeps.
        """
        X = np.asarray(X, dtype=np.float32)
        if X.ndim != 2 or 0 in X.shape or not np.all(np.isfinite(X)):
            raise ValueError(f"X must be (N, D) finite descriptors with N, D >= 1, got shape {X.shape} "
                             f"(NaN/inf: fix the descriptors first)")
        self.reset()
        self._check_shiftable(X.shape[1])
        t0 = self._tail_start(X)
        if t0:
            self._bulk(X, t0)
        for x in X[t0:]:
            self.update_descriptor(x)
        self.events = []
        self.last_scores, self.last_candidates = np.zeros(0, np.float32), np.zeros(0, np.int64)

    def _bulk(self, X: np.ndarray, t0: int, chunk: int = 65536) -> None:
        """:meth:`preload`'s state after frames 0..t0-1 of X (N, D), with room for N stored rows. The
        stored rows are made chunk rows at a time (a row's centring reads the W raw rows up to it,
        so a chunk starts W - 1 rows early and gives the bits of the whole: row-wise operations)."""
        n, d, W = len(X), X.shape[1], self._W
        for a in range(0, t0, chunk):
            b = min(a + chunk, t0)
            if not W:
                Y = normalise(X[a:b], self.projection)
            elif a == 0:
                Y = normalise(center_stored(X[:b], self.center_window), self.projection)
            else:
                Y = normalise(center(X[a - W + 1:b], self.center_window), self.projection)[W - 1:]
            if self._db is None:
                self._allocate(256 * 2 ** max(math.ceil(math.log2(n / 256)), 0), Y.shape[1])
            self._put(a, Y)
        self.frame_index = t0
        if self.index_kind is not None:
            self._grow_index(max(t0 - 1 - self.exclude, 0))     # the rows indexed before query t0 - 1
        if W:
            m = min(t0, W)
            self._recent, self._n_recent = np.zeros((W, d), np.float32), m
            self._recent[W - m:] = X[t0 - m:t0]
        if self.repeat_cos is not None:
            self._previous = normalise(X[t0 - 1:t0])[0]

    def _tail_start(self, X: np.ndarray) -> int:
        """The first frame :meth:`preload` streams: the earliest of the last seq_len frames of X
        (N, D) that had candidates (j > exclude) and were no repeat (the gate of ``repeat_cos``,
        on each frame alone as the stream computes it), in candidate mode WARMUP frames before it;
        0 when there are fewer or it lies within the centring window (every frame is then streamed)."""
        found, prev = 0, None
        for j in range(len(X) - 1, self.exclude, -1):
            repeat = False
            if self.repeat_cos is not None:            # frame j's gate, then frame j - 1's
                cur, prev = (normalise(X[j:j + 1])[0] if prev is None else prev), normalise(X[j - 1:j])[0]
                repeat = float(prev @ cur) >= self.repeat_cos
            found += not repeat
            if found == self.seq_len:
                j -= WARMUP if self.index_kind is not None else 0
                return j if j >= max(self._W, 1) else 0
        return 0

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
        if getattr(self, "_descriptor", None) is None:   # looked up at the first frame (and in a state saved before it had one)
            self._descriptor = features.get(self.descriptor, self.weights)
        return self._descriptor(features.stack_frames(frames), color=self.color)

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

def score_matrix(X, exclude: int = DEFAULT_EXCLUDE, seq_len: int = 10, velocities=DEFAULT_VELOCITIES,
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
    W, cw = det._W, det.center_window
    Ys = [normalise(center(shift_cells(X, t, X.shape[1]) if t else X, cw), projection) for t in det._shifts]   # the queries
    stored = normalise(center_stored(X, cw), projection) if W else Ys[0]
    stored = stored_values(stored, store_dtype)
    G = stored @ Ys[0].T                                     # stored rows x queries, one product per shift
    for Y in Ys[1:]:
        np.maximum(G, stored @ Y.T, out=G)
    for j in range(det.exclude + 1, min(W - 1, n)):           # the window still filling: rows centred on 0..j
        c = j - det.exclude
        rows = stored_values(normalise(center_stored(X[:j + 1], cw), projection)[:c], store_dtype)
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
