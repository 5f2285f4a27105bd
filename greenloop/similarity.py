"""Descriptor post-processing and similarity matrices.

Conventions used by every function here
---------------------------------------
* Features ``X`` are one row per frame: shape ``(N, D)``, frames in capture order.
* A similarity matrix ``S`` has ``S[i, j]`` = similarity of database frame ``i`` and query frame
  ``j``, shape ``(N_db, N_query)``; **higher = more similar**. When one sequence is compared with
  itself (``N_db = N_query = N``) :mod:`greenloop.evaluate` reads ``S[i, j]`` for ``i < j``, i.e.
  the earlier frame is the database row and the later frame the query column.
* Similarity matrices are float32 (one 2261 x 2261 matrix is 20 MB); feature transforms keep a
  float32 input in float32 and return float64 otherwise.
* Bad input (wrong ``ndim``, empty arrays, mismatched feature length, NaN or inf) raises
  ``ValueError`` naming the problem.

Pipeline (Zhang 2017; the ResNet/Inception ZCA paper; Qi 2024)::

    X ─► l2_normalise ─► pca_whiten (PCA to 500 dims, divide by sqrt(lambda + eps))  ─┐
                     └─► zca_whiten (same, then rotate back to D dims)               ─┴─►
        cosine_matrix (Qi 2024)  or  distance_similarity (S = 1 - D / max D, Zhang 2017)
        ─► optional median_filter (ZCA paper)

Whitening is fitted on one set of frames and can be applied to another with
:func:`apply_projection` (fit on a tuning part, apply to the evaluation part).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from greenloop.util.checks import positive_int

__all__ = [
    "Projection", "l2_normalise", "pca_whiten", "zca_whiten", "apply_projection",
    "cosine_matrix", "distance_similarity", "median_filter", "whitened_similarities",
    "median_candidates", "rgbd_matrices", "whitening_candidates",
]

_COV_MODES = ("sample", "scatter")


# ----------------------------------------------------------------------------------- checks
def _features(X, name: str = "X") -> np.ndarray:
    """Validate a (N, D) feature matrix; keep float32, convert everything else to float64."""
    X = np.asarray(X)
    if X.dtype == object or not (np.issubdtype(X.dtype, np.number) or X.dtype == bool):
        raise ValueError(f"{name} must be a numeric array, got dtype {X.dtype}")
    if np.iscomplexobj(X):
        raise ValueError(f"{name} must be real, got dtype {X.dtype}")
    if X.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array of features, shape (N frames, D dims), "
                         f"got ndim={X.ndim} with shape {X.shape}; stack one row per frame")
    if X.shape[0] == 0 or X.shape[1] == 0:
        raise ValueError(f"{name} is empty (shape {X.shape}); need at least one frame and one dim")
    if X.dtype != np.float32:
        X = X.astype(np.float64)
    if not np.all(np.isfinite(X)):
        bad = np.argwhere(~np.isfinite(X))[0]
        raise ValueError(f"{name} contains NaN or inf (first at frame {bad[0]}, dim {bad[1]}); "
                         f"check the feature extractor or drop those frames")
    return X


def _same_dim(A: np.ndarray, B: np.ndarray, a: str, b: str) -> None:
    if A.shape[1] != B.shape[1]:
        raise ValueError(f"{a} and {b} must have the same feature length D: {a} has shape "
                         f"{A.shape}, {b} has shape {B.shape}")


def _check_eps(eps) -> float:
    eps = float(eps)
    if not (eps > 0 and np.isfinite(eps)):
        raise ValueError(f"eps must be a finite number > 0 (it keeps 1/sqrt(lambda + eps) "
                         f"finite), got {eps}")
    return eps


# ----------------------------------------------------------------------- normalisation
def l2_normalise(X) -> np.ndarray:
    """Scale every row to unit Euclidean length (Zhang 2017, step 1).

    X: (N, D) features. Returns (N, D), same float dtype (float32 kept, others -> float64);
    each row has L2 norm 1, except all-zero rows, which stay zero (no division by zero).
    """
    X = _features(X)
    norms = np.linalg.norm(X, axis=1, keepdims=True)
    return np.divide(X, norms, out=np.zeros_like(X), where=norms > 0)


# ----------------------------------------------------------------------------- whitening
@dataclass(frozen=True)
class Projection:
    """A fitted whitening, applicable to new frames with :func:`apply_projection`.

    mean: (D,) feature mean of the fitting frames (subtracted first).
    components: (D, k) orthonormal eigenvectors of the fitting frames' covariance, largest
        eigenvalue first (sign fixed so that each column's largest-magnitude entry is positive,
        which makes results reproducible).
    eigenvalues: (k,) the matching eigenvalues lambda (see ``cov`` of :func:`pca_whiten`).
    scale: (k,) ``1 / sqrt(eigenvalues + eps)``.
    kind: ``"pca"`` (output (M, k)) or ``"zca"`` (rotated back, output (M, D)).
    residual_scale: ZCA only: factor for the part of a frame outside the span of
        ``components`` (directions with eigenvalue 0, scaled by ``1/sqrt(eps)`` in exact ZCA);
        0 when that part is dropped.

    The map is linear: ``Y = (X - mean) @ W`` with ``W = self.matrix()``.
    """

    mean: np.ndarray
    components: np.ndarray
    eigenvalues: np.ndarray
    scale: np.ndarray
    kind: str = "pca"
    residual_scale: float = 0.0

    @property
    def input_dim(self) -> int:
        return int(self.mean.shape[0])

    @property
    def output_dim(self) -> int:
        return int(self.components.shape[1]) if self.kind == "pca" else self.input_dim

    def matrix(self) -> np.ndarray:
        """The whitening matrix W, (D, k) for PCA or (D, D) (symmetric) for ZCA, float64."""
        V, s = self.components, self.scale
        if self.kind == "pca":
            return V * s
        W = (V * s) @ V.T
        if self.residual_scale:
            W += self.residual_scale * (np.eye(self.input_dim) - V @ V.T)
        return W

    def __call__(self, X) -> np.ndarray:
        return apply_projection(X, self)


def _eig(Xc: np.ndarray, cov: str, keep: int | None = None):
    """Eigen-decomposition of the covariance of centred data Xc (N, D), float64.

    Returns (lam (r,), V (D, r)) for the numerically non-zero eigenvalues only, largest first,
    r <= min(N - 1, D) (only the first ``keep`` of them if given). For D > N the (N, N) Gram
    matrix Xc Xc^T is decomposed instead of the (D, D) covariance (same non-zero eigenvalues;
    V = Xc^T U / sqrt(w)), so 4096-D is fast.
    """
    n, d = Xc.shape
    denom = (n - 1) if cov == "sample" else 1
    if d <= n:
        w, V = np.linalg.eigh(Xc.T @ Xc)
        w, V = w[::-1], V[:, ::-1]
    else:
        w, U = np.linalg.eigh(Xc @ Xc.T)
        w, U = w[::-1], U[:, ::-1]
    tol = max(float(w[0]), 0.0) * max(n, d) * np.finfo(np.float64).eps * 10
    r = int(np.sum(w > tol)) if w[0] > 0 else 0
    if keep is not None:
        r = min(r, keep)
    w = w[:r]
    if d <= n:
        V = V[:, :r]
    else:
        V = (Xc.T @ U[:, :r]) / np.sqrt(w)
    # deterministic signs: largest-magnitude entry of each column positive
    if r:
        pick = np.abs(V).argmax(0)
        V = V * np.sign(V[pick, np.arange(r)])
    return w / denom, V


def _fit(X, eps, cov, name: str, keep: int | None = None):
    X = _features(X, name)
    eps = _check_eps(eps)
    if cov not in _COV_MODES:
        raise ValueError(f"cov must be one of {_COV_MODES}, got {cov!r}")
    if X.shape[0] < 2:
        raise ValueError(f"whitening needs at least 2 frames to estimate a covariance, got "
                         f"shape {X.shape}")
    X64 = X.astype(np.float64)
    mean = X64.mean(0)
    lam, V = _eig(X64 - mean, cov, keep)
    if lam.size == 0:
        raise ValueError(f"all {X.shape[0]} frames of {name} are identical: nothing to whiten")
    return X, mean, lam, V, eps


def pca_whiten(X, dim: int = 500, eps: float = 1e-5, cov: str = "sample"):
    """PCA to ``dim`` dimensions and whitening (Zhang 2017, steps 2-3).

    Y[:, j] = ((X - mean) @ u_j) / sqrt(lambda_j + eps), u_j the j-th principal axis.

    X: (N, D) features, usually L2-normalised first (:func:`l2_normalise`).
    dim: kept dimensions k (Zhang 2017: 500). If ``dim`` exceeds the rank of the centred data
        (at most ``min(N - 1, D)``: centring removes one degree of freedom, and further
        directions have eigenvalue 0 and no defined axis) it is clipped to that rank with a
        ``UserWarning``.
    eps: added to every eigenvalue before the square root (Zhang 2017: 1e-5); must be > 0.
    cov: which eigenvalues lambda are used.
        ``"sample"`` (default): of the sample covariance ``Xc^T Xc / (N - 1)``, so the output has
        identity covariance on the kept dims (up to lambda / (lambda + eps)) and eps means the
        same for any N.
        ``"scatter"``: of ``Xc^T Xc`` exactly as written in Zhang 2017 (step 5, ``cov = X^T X``);
        eigenvalues are N - 1 times larger, so eps weighs N - 1 times less. Only the relative
        weight of eps differs: cosine and 1 - D/max D similarities ignore the global scale.

    Returns (Y, projection): Y (N, k) whitened features (float32 if X is float32, else
    float64); projection a :class:`Projection` to apply the same map to other frames with
    :func:`apply_projection`.
    """
    positive_int("dim", dim)
    X, mean, lam, V, eps = _fit(X, eps, cov, "X", keep=dim)
    if dim > lam.size:
        warnings.warn(f"pca_whiten: dim={dim} exceeds the rank {lam.size} of the centred data "
                      f"(N={X.shape[0]} frames, D={X.shape[1]} dims); using dim={lam.size}",
                      UserWarning, stacklevel=2)
        dim = lam.size
    lam, V = lam[:dim], V[:, :dim]
    proj = Projection(mean=mean, components=V, eigenvalues=lam, scale=1.0 / np.sqrt(lam + eps),
                      kind="pca")
    return apply_projection(X, proj), proj


def zca_whiten(X, eps: float = 1e-5, dim: int | None = None, cov: str = "sample"):
    """ZCA ("zero-phase") whitening (ResNet/Inception LCD paper, Algorithm 1).

    Y = (X - mean) U diag(1 / sqrt(lambda + eps)) U^T: whiten along the principal axes, then
    rotate back, so Y stays in the original D-dim feature space and as close as possible to X.
    The whitening matrix W = U diag(.) U^T is symmetric (``projection.matrix()``).

    X: (N, D) features. For D > N the eigenvectors come from the (N, N) Gram matrix of the
        centred data (equivalent to its SVD), an (N, N) problem instead of a (D, D) one.
    eps: added to every eigenvalue (> 0; default 1e-5).
    dim: None (default) = exact ZCA with all D axes: directions the fitting frames do not span
        (eigenvalue 0, e.g. when D > N - 1) are scaled by 1/sqrt(eps) as the formula says. That
        changes nothing for the fitting frames (they have no such component) but applies to
        new frames given to :func:`apply_projection`.
        An integer keeps only the ``dim`` leading axes before rotating back (the paper's step 7,
        ``U[:, :d]``); the output is still (N, D) but of rank ``dim``. Clipped to the rank of the
        centred data with a ``UserWarning``.
    cov: ``"sample"`` or ``"scatter"``, as in :func:`pca_whiten`.

    Returns (Y (N, D), projection): Y float32 if X is float32, else float64; with N > D and
    ``cov="sample"`` the covariance of Y is ~identity (exactly lambda / (lambda + eps)).
    """
    X, mean, lam, V, eps = _fit(X, eps, cov, "X")
    residual = 0.0
    if dim is None:
        if lam.size < X.shape[1]:
            residual = 1.0 / np.sqrt(eps)
    else:
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
            raise ValueError(f"dim must be None or an integer >= 1, got {dim!r}")
        if dim > lam.size:
            warnings.warn(f"zca_whiten: dim={dim} exceeds the rank {lam.size} of the centred "
                          f"data; using dim={lam.size}", UserWarning, stacklevel=2)
            dim = lam.size
        lam, V = lam[:dim], V[:, :dim]
    proj = Projection(mean=mean, components=V, eigenvalues=lam, scale=1.0 / np.sqrt(lam + eps),
                      kind="zca", residual_scale=residual)
    return apply_projection(X, proj), proj


def whitening_candidates(X, dims, kind: str = "pca", eps: float = 1e-5, fit=None) -> dict:
    """The descriptors whitened at every candidate dimension, for tuning the dimension.

    X: (N, D) descriptors (L2-normalised ones in the notebooks). dims: candidate dimensions, in
    the order to try them. kind: "pca" (:func:`pca_whiten`) or "zca" (:func:`zca_whiten`).
    fit: optional (N,) bool mask of the frames the whitening is fitted on (the tuning part; every
    frame when None); every frame is then mapped (:func:`apply_projection`).
    Returns {kept dim: (N, k) float32 whitened descriptors}: the kept dim is the number of
    components actually kept (a candidate above the rank of the fitting frames is clipped, with
    its UserWarning silenced); the first candidate of each kept dim wins, later ones are skipped.
    """
    if kind not in ("pca", "zca"):
        raise ValueError(f"kind must be 'pca' or 'zca', got {kind!r}")
    X = _features(X)
    fit_X = X if fit is None else X[np.asarray(fit, dtype=bool)]
    out = {}
    for d in dims:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # dim clipped to the rank of the fitting data
            _, proj = (pca_whiten(fit_X, dim=d, eps=eps) if kind == "pca"
                       else zca_whiten(fit_X, eps=eps, dim=d))
        k = int(proj.components.shape[1])
        if k not in out:
            out[k] = apply_projection(X, proj)
    return out


def apply_projection(X_new, projection: Projection) -> np.ndarray:
    """Apply a fitted :class:`Projection` (from :func:`pca_whiten`/:func:`zca_whiten`) to frames.

    X_new: (M, D) features with the same D (and the same preprocessing, e.g. L2) as the
    fitting frames. Returns (M, k) for PCA or (M, D) for ZCA; float32 if X_new is float32,
    else float64. Applied to the fitting frames it reproduces the fitted output.
    """
    if not isinstance(projection, Projection):
        raise ValueError(f"projection must be a greenloop.similarity.Projection (the second "
                         f"value returned by pca_whiten/zca_whiten), got {type(projection)}")
    X = _features(X_new, "X_new")
    if X.shape[1] != projection.input_dim:
        raise ValueError(f"X_new has shape {X.shape} but the projection was fitted on "
                         f"{projection.input_dim}-dim features")
    Xc = X.astype(np.float64) - projection.mean
    V = projection.components
    Z = Xc @ V
    if projection.kind == "pca":
        Y = Z * projection.scale
    else:
        Y = (Z * projection.scale) @ V.T
        if projection.residual_scale:
            Y += projection.residual_scale * (Xc - Z @ V.T)
    return Y.astype(X.dtype, copy=False)


# -------------------------------------------------------------------------- similarities
def cosine_matrix(A, B=None) -> np.ndarray:
    """Cosine similarity of every pair of frames (Qi 2024).

    A: (N_db, D) database features; B: (N_query, D) query features, or None to compare A with
    itself. Returns S (N_db, N_query) float32 with S[i, j] = cos(A_i, B_j) in [-1, 1];
    higher = more similar. A zero row has similarity 0 with everything.
    Computed as one float32 matrix product of L2-normalised rows; float32 rounding is ~1e-6, far
    below any meaningful similarity difference.
    """
    A = _features(A, "A")
    An = l2_normalise(A.astype(np.float32, copy=False))
    if B is None:
        Bn = An
    else:
        B = _features(B, "B")
        _same_dim(A, B, "A", "B")
        Bn = l2_normalise(B.astype(np.float32, copy=False))
    S = An @ Bn.T
    np.clip(S, -1.0, 1.0, out=S)
    return S


def distance_similarity(X, normalise: bool = True) -> np.ndarray:
    """Normalised Euclidean similarity S = 1 - D / max(D) (Zhang 2017, Sec. III-C).

    X: (N, D) features (whitened ones in Zhang 2017).
    normalise: True (default, as in Zhang 2017) L2-normalises each row before the distance,
        D[i, j] = || x_i/|x_i| - x_j/|x_j| ||; False uses the raw rows.
    Returns S (N, N) float32 in [0, 1], symmetric, S[i, i] = 1; higher = more similar; the
    farthest pair gets 0. Zero distance gives 1. If all frames coincide (max D = 0) S is all 1.
    Distances are computed in float32 for float32 input and in float64 otherwise.
    """
    X = _features(X)
    if normalise:
        X = l2_normalise(X)
    sq = np.einsum("ij,ij->i", X, X)
    d2 = sq[:, None] + sq[None, :] - 2.0 * (X @ X.T)
    np.maximum(d2, 0.0, out=d2)
    np.fill_diagonal(d2, 0.0)
    D = np.sqrt(d2)
    dmax = D.max()
    if dmax == 0:
        return np.ones(D.shape, dtype=np.float32)
    S = 1.0 - D / dmax
    S = np.clip(S, 0.0, 1.0).astype(np.float32)
    return np.minimum(S, S.T)  # exact symmetry despite rounding in the matrix product


def median_filter(S, size: int, footprint: str = "square") -> np.ndarray:
    """Median filtering of a similarity matrix (ResNet/Inception ZCA paper).

    S: (N_db, N_query) similarity matrix, higher = more similar.
    size: odd integer >= 1, the window length in frames (1 returns a float32 copy of S).
    footprint: ``"square"`` (default, the paper's 2-D median filter): the size x size block
        centred on S[i, j]. ``"diagonal"``: only the ``size`` entries S[i + t, j + t],
        |t| <= size // 2, i.e. the same offset between database and query frame.
    Returns (N_db, N_query) float32, each entry replaced by the median of its window; edges are
    padded by repeating the border (``mode="nearest"``). A symmetric S stays symmetric.

    What it does to loops: a revisit traversed in the same direction shows up as a streak along
    a diagonal (frame i + t matches frame j + t for consecutive t), while a single look-alike
    frame is an isolated bright entry. Both footprints use neighbouring frames, so the filtered
    score carries *sequence information* and is no longer a single-image score:
    ``"diagonal"`` smooths strictly along the diagonals (a streak survives where it is longer
    than about size / 2 frames; isolated entries are removed); ``"square"`` keeps an entry high
    only where more than half of the block is high, so it keeps diagonal *bands* (slow motion
    makes neighbouring frames match too) but thins or erases one-frame-wide streaks, and it
    also removes isolated matches and fills isolated gaps. Revisits in the opposite direction
    are anti-diagonal streaks, which ``"diagonal"`` does not reinforce.
    The size is a tuned knob: tune it on one part of the sequence and score it on another
    (:func:`greenloop.evaluate.split_mask`), and keep the evaluation's exclusion band >= size.
    """
    S = np.asarray(S)
    if S.ndim != 2:
        raise ValueError(f"S must be a 2-D similarity matrix, got shape {S.shape}")
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)):
        raise ValueError(f"size must be an odd integer >= 1, got {size!r}")
    if size < 1 or size % 2 == 0:
        raise ValueError(f"size must be an odd integer >= 1 (a window centred on each entry), "
                         f"got {size}")
    if footprint not in ("square", "diagonal"):
        raise ValueError(f"footprint must be 'square' or 'diagonal', got {footprint!r}")
    if S.size and not np.all(np.isfinite(S)):
        raise ValueError("S contains NaN or inf; the median of a window with NaN is undefined")
    S = S.astype(np.float32, copy=True)
    if size == 1:
        return S
    if footprint == "square":
        return ndimage.median_filter(S, size=size, mode="nearest")
    return ndimage.median_filter(S, footprint=np.eye(size, dtype=bool), mode="nearest")


# ------------------------------------------------------------- candidate sets for tuning
def whitened_similarities(X, dims, kind: str = "pca", eps: float = 1e-5, fit=None) -> dict:
    """The similarity matrix of every candidate whitening dimension, for tuning the dimension.

    X, dims, kind, eps, fit: as :func:`whitening_candidates` (X (N, D), L2-normalised in the
    notebooks; fit an (N,) bool mask of the fitting frames or None for every frame).
    Returns {kept dim: (N, N) float32 S = 1 - D / max D} (:func:`distance_similarity` of the
    whitened descriptors), one per kept dim, in the order of dims.
    """
    return {k: distance_similarity(Y) for k, Y in whitening_candidates(X, dims, kind, eps, fit=fit).items()}


def median_candidates(S, sizes) -> dict:
    """The similarity matrix median-filtered at every candidate size, for tuning the size.

    S: (N_db, N_query) similarity matrix. sizes: odd window lengths in frames (:func:`median_filter`,
    square footprint). Returns {size: (N_db, N_query)}: S itself (not a copy) for size 1, the
    float32 filtered matrix for the others.
    """
    return {s: S if s == 1 else median_filter(S, s) for s in sizes}


def rgbd_matrices(X) -> dict:
    """Cosine similarity matrices of an RGB-D descriptor and of each of its halves (Qi 2024 Sec. 3.1.2).

    X: (N, 2 D) descriptors from ``features.extract_rgbd``: the RGB descriptor in the first D
    columns, the depth descriptor in the last D. Returns {"RGB": (N, N), "depth": (N, N),
    "RGB-D": (N, N)} float32 :func:`cosine_matrix` of X[:, :D], X[:, D:] and the whole X.
    """
    X = _features(X)
    if X.shape[1] % 2:
        raise ValueError(f"X must hold an RGB and a depth half of equal length, got {X.shape[1]} columns")
    D = X.shape[1] // 2
    return {"RGB": cosine_matrix(X[:, :D]), "depth": cosine_matrix(X[:, D:]), "RGB-D": cosine_matrix(X)}
