import json

import numpy as np
import pytest

from greenloop.methods.dictionary import cnn, spots
from greenloop.util.cache import cache_key


def _toy(n=120, L=30, seed=0):
    rng = np.random.default_rng(seed)
    y = spots.group(n, L)
    X = (rng.random((n, 32, 32, 1)) * 0.3 + (y[:, None, None, None] + 1) / 6).astype(np.float32)
    return X, y


def test_build_is_the_papers_model():
    m = cnn.build(38)
    kinds = [type(l).__name__ for l in m.layers]
    assert kinds == ["Conv2D", "Flatten", "Dense", "Dense"]
    conv, _, dense, out = m.layers
    assert conv.filters == 32 and conv.kernel_size == (3, 3) and conv.activation.__name__ == "relu"
    assert dense.units == 68 and out.units == 38 and out.activation.__name__ == "softmax"
    assert m.count_params() == 320 + 30 * 30 * 32 * 68 + 68 + 68 * 38 + 38
    assert m.optimizer.learning_rate.numpy() == pytest.approx(1e-3)
    with pytest.raises(ValueError):
        cnn.build(1)


def test_random_split_sizes_match_paper():
    tr, te = cnn.split_indices(spots.group(2260, 60), seed=0)
    assert (len(tr), len(te)) == (1808, 452) and len(np.intersect1d(tr, te)) == 0


def test_blocked_split_keeps_neighbours_out():
    y = spots.group(600, 60)
    tr, te = cnn.split_indices(y, seed=3, split="blocked", gap=5)
    assert len(np.intersect1d(tr, te)) == 0
    dist = np.abs(te[:, None] - tr[None, :]).min(1)
    assert dist.min() > 5  # every test frame is more than `gap` frames from any training frame
    assert set(np.unique(y[te])) == set(np.unique(y))  # every spot is tested
    assert len(te) == 10 * 12
    with pytest.raises(ValueError, match="split must be"):
        cnn.split_indices(y, 0, split="stratified")


def test_centred_blocks_stay_inside_their_spot():
    y = spots.group(600, 60)
    tr, te = cnn.split_indices(y, seed=3, split="blocked", gap=10, block="centre")
    # each spot of 60 frames: the 12 test frames are 24..35, the gap drops 14..23 and 36..45
    assert list(te[:12]) == list(range(24, 36))
    assert list(tr[:14]) == list(range(14)) and tr[14] == 46
    # no frame of another spot is dropped: every spot keeps 60 - 12 - 20 training frames
    assert (np.bincount(y[tr]) == 28).all()
    # the seed does not move a centred block
    assert (cnn.split_indices(y, seed=4, split="blocked", gap=10, block="centre")[1] == te).all()
    with pytest.raises(ValueError, match="block must be"):
        cnn.split_indices(y, 0, split="blocked", block="left")


def test_gap_widens_the_distance_to_training():
    y = spots.group(600, 60)
    for gap in (0, 5, 20):
        tr, te = cnn.split_indices(y, seed=1, split="blocked", gap=gap)
        assert np.abs(te[:, None] - tr[None, :]).min() == gap + 1
    with pytest.raises(ValueError, match="gap must be"):
        cnn.split_indices(y, 0, split="blocked", gap=-1)


def test_train_size_subsamples_the_training_frames():
    y = spots.group(2260, 60)
    tr_full, te_full = cnn.split_indices(y, seed=2)
    tr, te = cnn.split_indices(y, seed=2, train_size=1430)
    assert len(tr) == 1430 and set(tr) <= set(tr_full) and (te == te_full).all()
    assert (tr == cnn.split_indices(y, seed=2, train_size=1430)[0]).all()  # seeded
    with pytest.raises(ValueError, match="train_size must be"):
        cnn.split_indices(y, 0, train_size=1809)


def test_train_is_deterministic_and_learns(tmp_path):
    X, y = _toy()
    a = cnn.train(X, y, seed=1, epochs=3, cache=False, progress=False)
    b = cnn.train(X, y, seed=1, epochs=3, cache=False, progress=False)
    assert a[1]["val_loss"] == b[1]["val_loss"]
    assert (a[2]["test"] == b[2]["test"]).all()
    c = cnn.train(X, y, seed=2, epochs=3, cache=False, progress=False)
    assert a[1]["val_loss"] != c[1]["val_loss"]
    model, hist, split = cnn.train(X, y, seed=1, epochs=15, cache=False, progress=False)
    assert hist["accuracy"][-1] > hist["accuracy"][0]
    assert np.mean(cnn.predict(model, X[split["test"]]) == y[split["test"]]) > 0.5


def test_cache_reuses_and_key_changes(tmp_path):
    X, y = _toy()
    base = dict(seed=0, epochs=2, batch_size=32, test_size=0.2, split="random", n_classes=4, fast="fused",
                gap=None, batch_order="model.fit")
    k0 = cache_key(X, y, **base)
    for name, value in [("seed", 1), ("epochs", 3), ("batch_size", 16), ("test_size", 0.3),
                        ("split", "blocked"), ("n_classes", 5), ("fast", "plain")]:
        assert cache_key(X, y, **dict(base, **{name: value})) != k0, name
    X2 = X.copy(); X2[0, 0, 0, 0] += 0.01
    assert cache_key(X2, y, **base) != k0
    assert cache_key(X, y[::-1].copy(), **base) != k0

    m1, h1, s1 = cnn.train(X, y, seed=0, epochs=2, cache=tmp_path, progress=False)
    folders = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(folders) == 1 and (folders[0] / "model.keras").is_file()
    assert json.loads((folders[0] / "params.json").read_text())["epochs"] == 2
    # the key still names the trainer "fast", as before train(trainer=...): older caches stay valid
    assert folders[0].name == k0
    m2, h2, s2 = cnn.train(X, y, seed=0, epochs=2, cache=tmp_path, progress=False)
    assert h2 == h1 and (s2["test"] == s1["test"]).all()
    assert np.allclose(m2.predict(X[:4], verbose=0), m1.predict(X[:4], verbose=0))
    assert not list(tmp_path.glob(".tmp-*"))


def test_run_seeds_reports_accuracy(tmp_path):
    X, y = _toy()
    runs = cnn.run_seeds(X, y, [0, 1], epochs=2, cache=tmp_path, progress=False)
    assert [r["seed"] for r in runs] == [0, 1]
    for r in runs:
        assert r["test_accuracy"] == pytest.approx(np.mean(r["test_pred"] == y[r["split"]["test"]]))


def test_train_rejects_bad_input():
    X, y = _toy()
    with pytest.raises(ValueError, match="X must be"):
        cnn.train(X[:, :, :, 0], y, seed=0, cache=False)
    with pytest.raises(ValueError, match="epochs"):
        cnn.train(X, y, seed=0, epochs=0, cache=False)


def test_keras_private_array_data_adapter_still_exists():
    """fit_orders (the fused trainer's batch order) needs Keras's private ArrayDataAdapter; if a Keras
    upgrade moves it, say so here rather than fail deep inside cnn.train."""
    try:
        adapter = cnn._array_data_adapter()
    except ImportError as e:
        pytest.fail(f"keras.src.trainers.data_adapters.array_data_adapter.ArrayDataAdapter is gone "
                    f"in this Keras ({e}); greenloop.methods.dictionary.cnn._array_data_adapter must follow it, or the "
                    f"fused trainer cannot reproduce model.fit's batch order")
    batches = list(adapter(np.arange(10), batch_size=4, shuffle=True).get_numpy_iterator())
    assert [len(b) for b in batches] == [4, 4, 2], "ArrayDataAdapter no longer yields index batches"
    assert sorted(np.concatenate(batches).tolist()) == list(range(10))
    order = next(cnn.fit_orders(10, 4))
    assert sorted(order.tolist()) == list(range(10))


def _train_in_subprocess(cache):
    X, y = _toy()
    _, h, _ = cnn.train(X, y, seed=5, epochs=2, cache=cache, progress=False)
    return h["val_loss"], h["seconds"]


def test_concurrent_runs_share_one_cache_entry(tmp_path):
    """Two processes asking for the same model at once (make -j2): one trains, the other waits on
    the lock and loads it; the cache holds one complete entry and no temporary folders."""
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(2) as pool:
        a, b = pool.map(_train_in_subprocess, [tmp_path, tmp_path])
    assert a == b  # identical histories, training seconds included: the second one loaded it
    entries = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(entries) == 1 and not list(tmp_path.glob(".tmp-*"))


def test_forward_is_the_keras_model_and_one_conv_with_or_without_numba():
    """cnn.forward (the fused trainer's and the stream's NumPy pass) gives Keras's logits; the
    im2col conv used without numba equals the numba kernel; other architectures get no weights."""
    import keras

    from greenloop.util import numba_kernels as kernels
    keras.utils.set_random_seed(3)
    model = cnn.build(5, (10, 12, 1), jit_compile=False)
    X = np.random.default_rng(0).random((7, 10, 12, 1), dtype=np.float32)
    params = cnn.paper_weights(model)
    assert [a.shape for a in params] == [(3, 3, 32), (32,), (8 * 10 * 32, 68), (68,), (68, 5), (5,)]
    A, Z2, Z3 = cnn.forward(np.ascontiguousarray(X[..., 0]), params)
    keras_logits = keras.Model(model.inputs, model.get_layer("output").output)  # softmax of the logits
    np.testing.assert_allclose(np.exp(Z3) / np.exp(Z3).sum(1, keepdims=True), keras_logits.predict(X, verbose=0), atol=1e-5)
    assert np.array_equal(cnn.forward(np.ascontiguousarray(X[..., 0]), params, threads=False)[2].argmax(1), Z3.argmax(1))
    im2col = cnn._conv_relu_im2col(np.ascontiguousarray(X[..., 0]), params[0], params[1])
    if kernels.available():
        np.testing.assert_allclose(im2col, kernels.conv_relu(np.ascontiguousarray(X[..., 0]), params[0], params[1]), atol=1e-5)
    np.testing.assert_allclose(im2col, A, atol=1e-5)
    other = keras.Sequential([keras.Input((10, 12, 1)), keras.layers.Flatten(), keras.layers.Dense(3)])
    assert cnn.paper_weights(other) is None


def _keras_stop_epoch(accuracy, patience):
    """The epoch (1-based) at which Keras's own EarlyStopping on 'accuracy' stops, or None."""
    import keras

    class _Model:
        stop_training = False
    cb = keras.callbacks.EarlyStopping(monitor="accuracy", mode="max", patience=patience,
                                       min_delta=cnn.STOP_MIN_DELTA)
    cb.set_model(_Model())
    cb.on_train_begin()
    for e, a in enumerate(accuracy):
        cb.on_epoch_end(e, {"accuracy": a})
        if cb.model.stop_training:
            return e + 1
    return None


def test_early_stopping_rule_is_keras_early_stopping():
    rng = np.random.default_rng(0)
    curves = [np.minimum(1, np.cumsum(rng.random(60) * 0.02)),             # rising, then flat at 1
              np.r_[np.linspace(0.1, 0.6, 20), np.full(40, 0.6)],        # a plateau below fitting
              np.r_[np.linspace(0.1, 0.6, 20), 0.6 + 0.004 * np.arange(40)],  # rises by less than min_delta
              0.5 + 0.02 * np.arange(60) % 0.3]                          # saw-tooth
    curves += [np.round(rng.random(40), 2) for _ in range(8)]
    for acc in curves:
        for patience in (1, 3, 10):
            ours = next((e for e in range(1, len(acc) + 1) if cnn.stops_here(acc[:e], patience, cnn.STOP_MIN_DELTA)), None)
            assert ours == _keras_stop_epoch(acc, patience), (acc[:5], patience)
    # a curve still rising by more than min_delta every epoch never stops; a flat one does, after patience
    assert not any(cnn.stops_here(np.linspace(0.1, 0.9, e), 5, cnn.STOP_MIN_DELTA) for e in range(1, 60))
    assert cnn.stops_here(np.r_[0.2, 0.5, np.full(5, 0.5)], 5, 0.005) and not cnn.stops_here(np.r_[0.2, 0.5, np.full(4, 0.5)], 5, 0.005)


@pytest.mark.parametrize("trainer", ["fused", "plain"])
def test_training_stops_where_the_training_accuracy_stops_rising(tmp_path, trainer):
    """Both trainers stop at the first epoch the rule fires (the fused one by stops_here, model.fit
    by Keras's callback); the fused run's epochs are the uncapped run's up to there; a cap below
    that epoch is a budget; the rule joins the cache key. (model.fit is slow: its part is the stop.)"""
    if trainer == "fused":
        pytest.importorskip("numba")
    X, y = _toy()
    _, h, _ = cnn.train(X, y, seed=0, epochs=25, cache=False, progress=False, trainer=trainer, stop_patience=3)
    n = len(h["accuracy"])
    # the toy fits its training frames early, so the run stops well before the cap, at the first
    # epoch the rule fires
    assert h["stopped_early"] and n < 25
    assert cnn.stops_here(h["accuracy"], 3, cnn.STOP_MIN_DELTA) and not any(cnn.stops_here(h["accuracy"][:e], 3, cnn.STOP_MIN_DELTA)
                                                                          for e in range(1, n))
    if trainer == "plain":
        return
    _, full, _ = cnn.train(X, y, seed=0, epochs=25, cache=False, progress=False, trainer=trainer)
    assert np.allclose(h["accuracy"], full["accuracy"][:n])
    # a cap below the stopping epoch is a budget: the run ends there, not stopped early
    _, capped, _ = cnn.train(X, y, seed=0, epochs=2, cache=False, progress=False, trainer=trainer, stop_patience=3)
    assert len(capped["accuracy"]) == 2 and not capped["stopped_early"]
    # the rule joins the cache key, so a stopped run never stands in for a full one
    cnn.train(X, y, seed=0, epochs=4, cache=tmp_path, progress=False, trainer=trainer)
    cnn.train(X, y, seed=0, epochs=4, cache=tmp_path, progress=False, trainer=trainer, stop_patience=3)
    assert len([p for p in tmp_path.iterdir() if p.is_dir()]) == 2
