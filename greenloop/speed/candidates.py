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
"""
from __future__ import annotations

import numpy as np

__all__ = ["reservoir", "IndexSpace"]

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
    principal components (L2-normalised afterwards by ``greenloop.retrieval``).

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
