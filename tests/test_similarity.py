"""Unit tests of greenloop.similarity (small arrays, fast)."""
import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.distance import cdist

from greenloop.similarity import (Projection, apply_projection, cosine_matrix, distance_similarity,
                                  l2_normalise, median_filter, pca_whiten, zca_whiten)


def correlated(n, d, seed=0, scale=1.0):
    """Gaussian data with a non-trivial covariance: std 1 to 10 along random axes (>> eps)."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((d, d)))
    M = np.geomspace(1, 10, d)[:, None] * Q
    return scale * rng.standard_normal((n, d)) @ M + rng.standard_normal(d)


# ---------------------------------------------------------------------------- l2 / cosine
def test_l2_rows_have_unit_norm_and_zero_rows_stay_zero():
    X = correlated(20, 7)
    X[3] = 0
    Y = l2_normalise(X)
    norms = np.linalg.norm(Y, axis=1)
    assert np.allclose(np.delete(norms, 3), 1.0)
    assert np.all(Y[3] == 0)
    assert l2_normalise(X.astype(np.float32)).dtype == np.float32
    assert l2_normalise(np.arange(6).reshape(2, 3)).dtype == np.float64


def test_cosine_matrix_matches_naive_loop():
    rng = np.random.default_rng(1)
    A, B = rng.standard_normal((7, 5)), rng.standard_normal((4, 5))
    A[2] = 0
    S = cosine_matrix(A, B)
    assert S.shape == (7, 4) and S.dtype == np.float32
    for i in range(7):
        for j in range(4):
            na, nb = np.linalg.norm(A[i]), np.linalg.norm(B[j])
            want = 0.0 if na == 0 else A[i] @ B[j] / (na * nb)
            assert S[i, j] == pytest.approx(want, abs=1e-6)
    SA = cosine_matrix(A)
    assert SA.shape == (7, 7)
    assert np.allclose(SA, cosine_matrix(A, A), atol=1e-6)
    assert np.allclose(np.delete(np.diag(SA), 2), 1.0, atol=1e-6)


@pytest.mark.parametrize("bad, match", [
    (np.ones(5), "2-D"),
    (np.ones((2, 3, 4)), "2-D"),
    (np.zeros((0, 4)), "empty"),
    (np.array([[1.0, np.nan], [0.0, 1.0]]), "NaN"),
    (np.array([[1.0, np.inf], [0.0, 1.0]]), "NaN"),
    (np.array([["a", "b"]]), "numeric"),
])
def test_bad_features_raise(bad, match):
    for f in (l2_normalise, cosine_matrix, distance_similarity):
        with pytest.raises(ValueError, match=match):
            f(bad)


def test_mismatched_dims_raise():
    with pytest.raises(ValueError, match=r"same feature length.*\(3, 4\).*\(2, 5\)"):
        cosine_matrix(np.ones((3, 4)), np.ones((2, 5)))
    _, proj = pca_whiten(correlated(30, 4), dim=2)
    with pytest.raises(ValueError, match="4-dim"):
        apply_projection(np.ones((2, 5)), proj)
    with pytest.raises(ValueError, match="Projection"):
        apply_projection(np.ones((2, 4)), {"mean": 0})


# ----------------------------------------------------------------------------------- PCA
def test_pca_whiten_identity_covariance_and_reapply():
    X = correlated(400, 20)
    Y, proj = pca_whiten(X, dim=10)
    assert isinstance(proj, Projection) and Y.shape == (400, 10)
    assert np.allclose(np.cov(Y.T), np.eye(10), atol=1e-4)
    assert np.allclose(Y.mean(0), 0, atol=1e-10)
    assert np.all(np.diff(proj.eigenvalues) <= 0)            # largest first
    assert np.allclose(apply_projection(X, proj), Y)
    assert np.allclose(proj(X), Y)
    assert np.allclose((X - proj.mean) @ proj.matrix(), Y)
    # fit on one part, apply to another
    Z = apply_projection(correlated(5, 20, seed=9), proj)
    assert Z.shape == (5, 10)


def test_pca_whiten_high_dim_matches_svd_reference():
    """D > N uses the Gram matrix; it must equal the SVD of the centred data."""
    X = correlated(40, 300, seed=2)
    eps = 1e-5
    Y, proj = pca_whiten(X, dim=25, eps=eps)
    Xc = X - X.mean(0)
    _, sv, Vt = np.linalg.svd(Xc, full_matrices=False)
    lam = sv[:25] ** 2 / (len(X) - 1)
    assert np.allclose(proj.eigenvalues, lam, rtol=1e-8)
    ref = Xc @ Vt[:25].T / np.sqrt(lam + eps)
    signs = np.sign(np.sum(ref * Y, axis=0))                  # eigenvector signs are arbitrary
    assert np.allclose(Y, ref * signs, atol=1e-8)
    assert np.allclose(np.cov(Y.T), np.eye(25), atol=1e-6)
    assert np.allclose(proj.components.T @ proj.components, np.eye(25), atol=1e-10)


def test_pca_dim_clipped_with_warning_and_bad_args():
    X = correlated(6, 20)
    with pytest.warns(UserWarning, match="rank 5"):
        Y, proj = pca_whiten(X, dim=500)
    assert Y.shape == (6, 5)
    with pytest.raises(ValueError, match="dim"):
        pca_whiten(X, dim=0)
    with pytest.raises(ValueError, match="eps"):
        pca_whiten(X, dim=2, eps=0)
    with pytest.raises(ValueError, match="at least 2 frames"):
        pca_whiten(X[:1], dim=1)
    with pytest.raises(ValueError, match="cov"):
        pca_whiten(X, dim=2, cov="biased")


def test_pca_scatter_mode_is_global_rescale_when_eps_negligible():
    X = correlated(200, 8)
    Ys, _ = pca_whiten(X, dim=8)
    Yt, _ = pca_whiten(X, dim=8, cov="scatter")
    assert np.allclose(Yt * np.sqrt(len(X) - 1), Ys, rtol=1e-5)
    assert np.allclose(Yt.T @ Yt, np.eye(8), atol=1e-5)        # Zhang 2017: cov = X^T X


def test_pca_keeps_float32():
    Y, _ = pca_whiten(correlated(50, 6).astype(np.float32), dim=3)
    assert Y.dtype == np.float32


# ----------------------------------------------------------------------------------- ZCA
def test_zca_identity_covariance_symmetric_matrix():
    X = correlated(500, 10, seed=3)
    Y, proj = zca_whiten(X)
    assert Y.shape == X.shape
    assert np.allclose(np.cov(Y.T), np.eye(10), atol=1e-4)
    W = proj.matrix()
    assert W.shape == (10, 10)
    assert np.allclose(W, W.T, atol=1e-12)
    assert np.allclose((X - proj.mean) @ W, Y)
    assert np.allclose(apply_projection(X, proj), Y)
    # ZCA = PCA whitening rotated back
    Yp, pp = pca_whiten(X, dim=10)
    assert np.allclose(Yp @ pp.components.T, Y)


def test_zca_high_dim_is_exact_zca():
    """D > N: equals the full-eigendecomposition formula, for fitted and for new frames."""
    X = correlated(30, 60, seed=4)
    eps = 1e-5
    Y, proj = zca_whiten(X, eps=eps)
    Xc = X - X.mean(0)
    lam, U = np.linalg.eigh(Xc.T @ Xc / (len(X) - 1))
    lam = np.clip(lam, 0, None)
    W_ref = (U / np.sqrt(lam + eps)) @ U.T
    W = proj.matrix()
    assert np.allclose(W, W.T, atol=1e-9)
    assert np.allclose(W, W_ref, rtol=1e-6, atol=1e-4 * np.abs(W_ref).max())
    assert np.allclose(Y, Xc @ W_ref, atol=1e-6)
    new = correlated(3, 60, seed=5)
    assert np.allclose(apply_projection(new, proj), (new - proj.mean) @ W_ref,
                       rtol=1e-6, atol=1e-6 * np.abs((new - proj.mean) @ W_ref).max())
    # the paper's truncated variant (U[:, :d]) has rank d
    Yd, pd = zca_whiten(X, dim=5)
    assert Yd.shape == X.shape and np.linalg.matrix_rank(Yd) == 5 and pd.residual_scale == 0


# ---------------------------------------------------------------------- distance similarity
def test_distance_similarity_range_and_reference():
    X = correlated(12, 5, seed=6)
    X[4] = 3.0 * X[1]                      # same direction: zero normalised distance
    S = distance_similarity(X)
    assert S.dtype == np.float32 and S.shape == (12, 12)
    assert S.min() >= 0 and S.max() <= 1
    assert np.allclose(np.diag(S), 1)
    assert S[1, 4] == pytest.approx(1.0, abs=1e-6)
    assert S.min() == pytest.approx(0.0, abs=1e-6)
    assert np.array_equal(S, S.T)
    Xn = X / np.linalg.norm(X, axis=1, keepdims=True)
    D = cdist(Xn, Xn)
    assert np.allclose(S, 1 - D / D.max(), atol=1e-6)
    Sr = distance_similarity(X, normalise=False)
    Dr = cdist(X, X)
    assert np.allclose(Sr, 1 - Dr / Dr.max(), atol=1e-6)
    assert np.all(distance_similarity(np.ones((3, 2))) == 1)


# --------------------------------------------------------------------------- median filter
@pytest.mark.parametrize("size", [0, -1, 2, 4, 2.5, True, "3"])
def test_median_filter_bad_size(size):
    with pytest.raises(ValueError, match="size"):
        median_filter(np.zeros((5, 5)), size)


def test_median_filter_behaviour():
    rng = np.random.default_rng(7)
    S = rng.random((20, 20)).astype(np.float32)
    assert np.array_equal(median_filter(S, 1), S)
    assert np.array_equal(median_filter(S, 5), ndimage.median_filter(S, size=5, mode="nearest"))
    with pytest.raises(ValueError, match="2-D"):
        median_filter(np.zeros(5), 3)
    with pytest.raises(ValueError, match="NaN"):
        median_filter(np.full((3, 3), np.nan), 3)
    with pytest.raises(ValueError, match="footprint"):
        median_filter(S, 3, footprint="round")
    # an isolated match disappears, a diagonal streak (a revisit) survives the diagonal filter
    T = np.zeros((30, 30), dtype=np.float32)
    T[3, 20] = 1
    for t in range(10):
        T[5 + t, 15 + t] = 1
    F = median_filter(T, 5, footprint="diagonal")
    assert F[3, 20] == 0
    assert np.all([F[5 + t, 15 + t] == 1 for t in range(2, 8)])
    assert F.sum() == pytest.approx(sum(F[5 + t, 15 + t] for t in range(10)))
    Sym = S + S.T
    assert np.allclose(median_filter(Sym, 5), median_filter(Sym, 5).T)


def test_whitening_candidates_fit_on_the_mask_and_keep_each_rank_once():
    import warnings
    from greenloop.similarity import whitening_candidates

    X = l2_normalise(correlated(40, 12, seed=3))
    fit = np.arange(40) < 8                            # 8 frames: rank 7 after centring
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # the clipping warning stays inside
        c = whitening_candidates(X, [2, 4, 16, 32], "pca", 1e-5, fit=fit)
    assert list(c) == [2, 4, 7]                        # 16 and 32 clipped to 7: counted once
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _, proj = pca_whiten(X[fit], dim=16, eps=1e-5)
    np.testing.assert_array_equal(c[7], apply_projection(X, proj))
    assert proj.output_dim == 7 and c[7].shape == (40, 7)
    z = whitening_candidates(X, [3], "zca", 1e-5)    # every frame fitted
    _, pz = zca_whiten(X, eps=1e-5, dim=3)
    np.testing.assert_array_equal(z[3], apply_projection(X, pz))
    assert pz.output_dim == 12                         # ZCA maps back to the input dimension
    with pytest.raises(ValueError, match="kind must be"):
        whitening_candidates(X, [3], "ica")


def test_candidate_sets_for_tuning():
    from greenloop.similarity import (l2_normalise, median_candidates, median_filter, whitened_similarities,
                                      whitening_candidates)
    rng = np.random.default_rng(0)
    Xn = l2_normalise(rng.standard_normal((30, 6)))
    fit = np.arange(30) < 20
    got = whitened_similarities(Xn, [2, 4, 50], "pca", fit=fit)   # 50 is clipped to the rank (6)
    ref = whitening_candidates(Xn, [2, 4, 50], "pca", fit=fit)
    assert list(got) == list(ref) == [2, 4, 6]
    for k in ref:
        assert np.array_equal(got[k], distance_similarity(ref[k]))
    S = distance_similarity(Xn)
    m = median_candidates(S, [1, 3])
    assert m[1] is S and np.array_equal(m[3], median_filter(S, 3))


def test_rgbd_matrices_split_the_descriptor_in_halves():
    from greenloop.similarity import rgbd_matrices
    X = np.array([[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0]])      # RGB halves orthogonal, depth halves equal
    S = rgbd_matrices(X)
    assert list(S) == ["RGB", "depth", "RGB-D"]
    assert np.allclose(S["RGB"], np.eye(2)) and np.allclose(S["depth"], 1.0)
    assert np.allclose(S["RGB-D"], [[1.0, 0.5], [0.5, 1.0]])
    with pytest.raises(ValueError, match="equal length"):
        rgbd_matrices(np.ones((2, 3)))
