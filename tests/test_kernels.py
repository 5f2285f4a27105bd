"""greenloop.util.numba_kernels and threads against the libraries they replace, and the fused trainer against model.fit."""
import cv2
import numpy as np
import pytest

pytest.importorskip("numba")
keras = pytest.importorskip("keras")

from greenloop.methods.dictionary import cnn  # noqa: E402
from greenloop.datasets import sequence  # noqa: E402
from greenloop.util import numba_kernels as kernels  # noqa: E402
from greenloop.util import threads  # noqa: E402
from test_cnn import _toy  # noqa: E402  (the toy frames of the CNN tests)


@pytest.mark.parametrize("shape,size", [((480, 640), (32, 32)), ((120, 160), (32, 24)),
                                        ((96, 96), (32, 32)), ((64, 128), (16, 8))])
def test_area_shrink_is_bit_identical_to_opencv(shape, size):
    rng = np.random.default_rng(shape[0])
    for img in (rng.integers(0, 256, shape, dtype=np.uint8),
                np.full(shape, 255, np.uint8),  # the largest sums
                (np.indices(shape).sum(0) % 256).astype(np.uint8)):  # ramps: many exact halves
        ref = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        assert np.array_equal(kernels.area_shrink(img, size), ref)


def test_area_shrink_declines_what_it_cannot_do():
    img = np.zeros((100, 130), np.uint8)
    assert kernels.area_shrink(img, (32, 32)) is None  # 130 / 32 is not an integer
    assert kernels.area_shrink(img.astype(np.float32), (10, 10)) is None
    assert kernels.area_shrink(np.zeros((64, 64, 3), np.uint8), (32, 32)) is None
    assert kernels.area_shrink(np.zeros((64, 64), np.uint8), (32, 32)) is None   # 2 x 2: OpenCV's own path
    # preprocess_image still gives OpenCV's bytes then
    frame = np.random.default_rng(1).integers(0, 256, (100, 130, 3), dtype=np.uint8)
    ref = cv2.resize(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), (32, 32), interpolation=cv2.INTER_AREA)
    assert np.array_equal(sequence.preprocess_image(frame, (32, 32)), ref)


def test_preprocess_image_matches_opencv_on_640x480_frames():
    rng = np.random.default_rng(2)
    for _ in range(5):
        frame = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
        ref = cv2.resize(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), (32, 32), interpolation=cv2.INTER_AREA)
        assert np.array_equal(sequence.preprocess_image(frame, (32, 32)), ref)


def _conv_reference(X, K, b):
    """Keras Conv2D (valid, ReLU) with the same weights, flattened as Flatten does."""
    layer = keras.layers.Conv2D(K.shape[2], K.shape[:2], activation="relu")
    layer.build((None, *X.shape[1:], 1))
    layer.set_weights([K[:, :, None, :], b])
    return np.asarray(layer(X[..., None])).reshape(len(X), -1)


def test_conv_relu_and_its_gradients_match_keras():
    import tensorflow as tf

    rng = np.random.default_rng(3)
    X = rng.random((5, 12, 10), dtype=np.float32)
    K = rng.normal(0, 0.5, (3, 3, 4)).astype(np.float32)
    b = rng.normal(0, 0.1, 4).astype(np.float32)
    A = kernels.conv_relu(X, K, b)
    assert A.shape == (5, 10 * 8 * 4)
    np.testing.assert_allclose(A, _conv_reference(X, K, b), rtol=1e-5, atol=1e-6)
    # gradients of sum(U * relu(conv(X))) w.r.t. kernel and bias, by TensorFlow autodiff
    U = rng.normal(size=A.shape).astype(np.float32)
    Kv, bv = tf.Variable(K[:, :, None, :]), tf.Variable(b)
    with tf.GradientTape() as tape:
        z = tf.nn.relu(tf.nn.conv2d(X[..., None], Kv, 1, "VALID") + bv)
        loss = tf.reduce_sum(tf.reshape(z, (5, -1)) * U)
    gK, gb = tape.gradient(loss, [Kv, bv])
    dK, db = kernels.conv_grad(X, U, A)
    np.testing.assert_allclose(dK, gK.numpy()[:, :, 0, :], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(db, gb.numpy(), rtol=1e-4, atol=1e-5)


def test_dense_backward_adam_and_matmul_match_numpy():
    rng = np.random.default_rng(4)
    A = np.maximum(rng.normal(size=(7, 3000)), 0).astype(np.float32)
    G = rng.normal(size=(7, 11)).astype(np.float32)
    W0 = rng.normal(size=(3000, 11)).astype(np.float32)
    W, M, V = W0.copy(), np.zeros_like(W0), np.zeros_like(W0)
    dW, dA = np.empty_like(W), np.empty_like(A)
    np.testing.assert_allclose(kernels.matmul(A, W), A @ W, rtol=1e-4, atol=1e-3)
    kernels.dense_backward_adam(A, G, W, M, V, 1e-3, dW, dA)
    np.testing.assert_allclose(dW, A.T @ G, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(dA, G @ W0.T, rtol=1e-4, atol=1e-4)  # with the weights before the step
    w, m, v = W0.copy(), np.zeros_like(W0), np.zeros_like(W0)
    kernels.adam(w, dW, m, v, 1e-3)
    np.testing.assert_allclose(W, w, rtol=1e-6, atol=1e-7)
    assert np.abs(W - W0).max() > 1e-4  # it moved


def test_adam_matches_keras_adam():
    rng = np.random.default_rng(5)
    w0 = rng.normal(size=(40, 3)).astype(np.float32)
    grads = [rng.normal(size=w0.shape).astype(np.float32) for _ in range(4)]
    var = keras.Variable(w0.copy())
    opt = keras.optimizers.Adam(learning_rate=1e-3)
    w, m, v = w0.copy(), np.zeros_like(w0), np.zeros_like(w0)
    for t, g in enumerate(grads, 1):
        opt.apply_gradients([(keras.ops.convert_to_tensor(g), var)])
        alpha = 1e-3 * np.sqrt(1 - 0.999 ** t) / (1 - 0.9 ** t)
        kernels.adam(w, g, m, v, alpha)
    np.testing.assert_allclose(w, np.asarray(var), rtol=1e-6, atol=1e-7)


def test_run_chunked_covers_the_range_and_raises():
    seen = np.zeros(50, int)

    def work(idx):
        seen[idx] += 1

    threads.run_chunked(work, 50)
    assert (seen == 1).all()

    def boom(idx):
        if 0 in idx:
            raise RuntimeError("chunk failed")

    with pytest.raises(RuntimeError, match="chunk failed"):
        threads.run_chunked(boom, 50)


def test_fused_trainer_follows_model_fit():
    """With one batch per epoch the shuffle order cannot matter, so the fused trainer and a plain
    model.fit from the same seeded initial weights must land on the same weights and history."""
    X, y = _toy(n=64, L=16)
    n_train = len(cnn.split_indices(y, 0)[0])
    kw = dict(seed=0, epochs=4, batch_size=n_train, cache=False, progress=False)
    fused, hf, sf = cnn.train(X, y, trainer="fused", **kw)
    plain, hp, sp = cnn.train(X, y, trainer="plain", **kw)
    assert (sf["test"] == sp["test"]).all()
    for a, b in zip(fused.get_weights(), plain.get_weights()):
        np.testing.assert_allclose(a, b, rtol=1e-3, atol=2e-5)
    for k in ("loss", "val_loss", "accuracy", "val_accuracy"):
        np.testing.assert_allclose(hf[k], hp[k], rtol=1e-3, atol=1e-4, err_msg=k)
    assert type(fused).__name__ == "Sequential" and fused.get_layer("conv").kernel.shape == (3, 3, 1, 32)


def test_trainer_choice():
    assert cnn.resolve_trainer("plain") == "plain" and cnn.resolve_trainer("xla") == "xla"
    assert cnn.resolve_trainer("auto") == "fused"  # numba present, no GPU on the build machine
    for bad in ("turbo", True, False):
        with pytest.raises(ValueError, match="trainer must be"):
            cnn.resolve_trainer(bad)


def _fit_epochwise(X, Y, tr, orders, n_classes):
    """A plain Keras model from seed 0, fitted one unshuffled epoch per given order."""
    keras.utils.set_random_seed(0)
    model = cnn.build(n_classes, jit_compile=False)
    for o in orders:
        model.fit(X[tr[o]], Y[tr[o]], epochs=1, batch_size=32, shuffle=False, verbose=0)
    return model


def test_fit_orders_are_the_orders_of_model_fit():
    """model.fit(shuffle=True) over 3 epochs and model.fit fed cnn.fit_orders' orders unshuffled
    reach the same weights (bit-identical on the build machine); a different epoch-2 order does
    not (so the check can fail)."""
    X, y = _toy(n=150, L=50)
    C = int(y.max() + 1)
    tr, _ = cnn.split_indices(y, 0)
    assert len(tr) % 32 != 0  # a partial last batch
    plain, _, _ = cnn.train(X, y, seed=0, epochs=3, trainer="plain", cache=False, progress=False)
    keras.utils.set_random_seed(0)
    cnn.build(C, jit_compile=False)  # fit_orders starts where model.fit would: after the build
    it = cnn.fit_orders(len(tr), 32)
    orders = [next(it) for _ in range(3)]
    assert all(sorted(o) == list(range(len(tr))) for o in orders)
    assert any((o != np.arange(len(tr))).any() for o in orders)
    Y = keras.utils.to_categorical(y, C).astype(np.float32)
    same = _fit_epochwise(X, Y, tr, orders, C)
    for a, b in zip(plain.get_weights(), same.get_weights()):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)  # bit-identical here; another order: > 1e-4
    other = _fit_epochwise(X, Y, tr, [orders[0], orders[1][::-1], orders[2]], C)
    assert max(float(np.abs(a - b).max()) for a, b in zip(plain.get_weights(), other.get_weights())) > 1e-4


@pytest.mark.parametrize("n, L, epochs", [(150, 50, 1), (160, 40, 5)])
def test_fused_trainer_matches_model_fit(n, L, epochs):
    """The fused trainer and model.fit, both as cnn.train runs them (same seed, same split, same
    batch order): the same weights and history to float rounding, with a partial last batch
    (150 frames) and over five epochs (160)."""
    X, y = _toy(n=n, L=L)
    kw = dict(seed=0, epochs=epochs, cache=False, progress=False)
    fused, hf, _ = cnn.train(X, y, trainer="fused", **kw)
    plain, hp, _ = cnn.train(X, y, trainer="plain", **kw)
    for a, b in zip(fused.get_weights(), plain.get_weights()):
        np.testing.assert_allclose(a, b, rtol=2e-3, atol=5e-5)
    for k in ("loss", "val_loss", "accuracy", "val_accuracy"):
        np.testing.assert_allclose(hf[k], hp[k], rtol=1e-3, atol=1e-4, err_msg=k)


def test_one_blas_thread_limits_numpys_blas_inside_only():
    from threadpoolctl import threadpool_info

    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    before = blas_threads()
    with threads.one_blas_thread():
        assert blas_threads() and set(blas_threads()) == {1}
    assert blas_threads() == before


# ---- greenloop-seq's candidate verification ----------------------------------------------------
def test_candidate_rows_are_the_union_of_the_candidates_windows():
    ids = np.array([40, -1, 7, 40, 12, 95, 0], np.int64)
    cand, rows = kernels.candidate_rows(ids, before=6, after=2, limit=90)
    assert cand.tolist() == [0, 7, 12, 40, 95]
    want = sorted({r for i in cand for r in range(i - 6, i + 3) if 0 <= r < 90})
    assert rows.tolist() == want
    cand, rows = kernels.candidate_rows(np.full(4, -1, np.int64), 6, 2, 90)
    assert cand.size == 0 and rows.size == 0


@pytest.mark.parametrize("contrast_window, velocities, seq_len, store", [
    (10, (0.8, 1.0, 1.25), 10, "float32"), (0, (0.8, 1.0, 1.25, 2.0), 5, "float16"),
    (1, (1.0,), 3, "float32"), (7, (0.5, 1.0, 1.5), 8, "float32")])
def test_candidate_kernel_equals_the_numpy_verification(contrast_window, velocities, seq_len, store):
    """A candidate-mode stream over a revisit: every frame's candidates and scores from the kernels
    equal the NumPy verification's of the same state (np.unique of the retrieved rows, then
    _candidate_scores_numpy), and a revisit frame's best candidate is its own first visit."""
    from greenloop.methods.greenloop_seq import seqstream

    rng = np.random.default_rng(0)
    base = rng.normal(size=(200, 32)).astype(np.float32)
    X = np.concatenate([base, base + np.float32(0.3) * rng.normal(size=base.shape).astype(np.float32)])
    det = seqstream.Detector(0.0, seq_len=seq_len, exclude=20, contrast_window=contrast_window,
                             velocities=velocities, index="scan", k=10, store_dtype=store)
    compared, found = 0, 0
    for j, x in enumerate(X):
        det.update_descriptor(x)
        if det.last_candidates.size:
            assert np.array_equal(det.last_candidates, np.unique(det.last_candidates))
            ref = det._candidate_scores_numpy(det.last_candidates)
            assert np.allclose(det.last_scores, ref, rtol=0, atol=1e-6)
            compared += 1
            if j >= 200 + seq_len:
                found += abs(int(det.last_candidates[np.argmax(det.last_scores)]) - (j - 200)) <= 1
    assert compared == len(X) - 21
    if contrast_window == 1:    # a one-row window has no spread: every point normalises to 0
        assert not det.last_scores.any() and found < 0.5 * (200 - seq_len)
    else:
        assert found >= 0.9 * (200 - seq_len)


def test_max_dot_equals_the_best_of_the_products():
    """max_dot's compiled pass (three queries) and its BLAS path (any other count) are the best
    product per stored row, to float rounding."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(1003, 512)).astype(np.float32)
    for m in (1, 3, 5):
        Q = rng.normal(size=(m, 512)).astype(np.float32)
        ref = (A.astype(np.float64) @ Q.T.astype(np.float64)).max(1)
        out = kernels.max_dot(A, Q)
        assert out.shape == (1003,) and out.dtype == np.float32
        np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-3)
        assert (np.argmax(A @ Q.T, 1) == np.argmax(A.astype(np.float64) @ Q.T.astype(np.float64), 1)).mean() > 0.99


def test_scaled_max_dot_is_the_best_product_of_the_dequantised_rows():
    """scaled_max_dot's compiled passes (one and three queries) and its fallback (any other count)
    give scale[i] * max_s <A[i], Q[s]> of int8 rows, to float rounding; a zero scale gives 0."""
    rng = np.random.default_rng(7)
    A = rng.integers(-127, 128, size=(1003, 300)).astype(np.int8)
    scale = rng.uniform(0, 1e-2, 1003).astype(np.float32)
    scale[:3] = 0
    for m in (1, 3, 4):
        Q = rng.normal(size=(m, 300)).astype(np.float32)
        ref = ((A.astype(np.float64) * scale[:, None].astype(np.float64)) @ Q.T.astype(np.float64)).max(1)
        out = kernels.scaled_max_dot(A, scale, Q)
        assert out.shape == (1003,) and out.dtype == np.float32
        np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-4)
        assert not out[:3].any()
    with pytest.raises(ValueError, match="must agree"):
        kernels.scaled_max_dot(A, scale[:-1], Q)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_ring_best_is_the_numpy_trajectory_search_bit_for_bit(dtype):
    from greenloop.methods.greenloop_seq import seqstream
    rng = np.random.default_rng(6)
    R = rng.normal(size=(10, 900)).astype(np.float32)
    base = rng.integers(0, 40, (8, 10))
    rows = rng.permutation(10)
    compiled = seqstream._ring_scores(R, rows, 800, base, dtype)
    Rd = R[rows, :int(base.max()) + 800].astype(dtype)
    acc = np.zeros((8, 800), dtype)
    for v in range(8):
        for k in range(10):
            acc[v] += Rd[k, base[v, k]:base[v, k] + 800]
    assert np.array_equal(compiled, (acc.max(0) / 10).astype(np.float32))
