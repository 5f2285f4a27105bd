"""The main paper's one-conv-layer CNN: build, train over seeds (cached on disk), predict.

Model (exactly the paper's): Conv2D 32 filters 3x3 ReLU -> Flatten -> Dense 68 ReLU ->
Dense n_classes softmax; Adam lr 0.001, categorical cross-entropy, batch 32, 200 epochs.
Written against the Keras 3 API only, so it runs on the TensorFlow and the JAX backends.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from greenloop.util import kernels
from greenloop.util.cache import cache_key, cached_model
from greenloop.util.checks import positive_int
from greenloop.util.progress import bar as tqdm   # in the terminal, never in a notebook

SPLITS = ("random", "blocked")
BLOCKS = ("random", "centre")   # where split="blocked" puts each spot's test block
# the runs of ``leakage_controls``: a blocked split, a random split with its number of training
# frames, and a blocked split with the test block centred in its spot
LEAKAGE_CONTROLS = ("blocked", "random, same n_train", "blocked, centred")


def build(n_classes: int, input_shape=(32, 32, 1), jit_compile="auto", steps_per_execution: int = 1):
    """The paper's CNN, compiled (Adam 1e-3, categorical cross-entropy, accuracy).

    n_classes: number of spots. input_shape: (H, W, C) of the preprocessed frames.
    jit_compile, steps_per_execution: passed to ``model.compile`` (speed only, same maths).
    Returns a compiled ``keras.Sequential``; output (N, n_classes) softmax probabilities.
    """
    import keras
    from keras import layers

    if n_classes < 2:
        raise ValueError(f"n_classes must be >= 2 to train a classifier, got {n_classes}")
    model = keras.Sequential([
        keras.Input(shape=tuple(input_shape)),
        layers.Conv2D(32, (3, 3), activation="relu", name="conv"),
        layers.Flatten(name="flatten"),
        layers.Dense(68, activation="relu", name="dense"),
        layers.Dense(n_classes, activation="softmax", name="output"),
    ], name="spot_cnn")
    model.compile(optimizer=keras.optimizers.Adam(learning_rate=1e-3),
                  loss="categorical_crossentropy", metrics=["accuracy"], jit_compile=jit_compile,
                  steps_per_execution=steps_per_execution)
    return model


def split_indices(y: np.ndarray, seed: int, test_size: float = 0.2, split: str = "random",
                  gap: int = 5, block: str = "random",
                  train_size: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Train/test frame indices.

    y: (N,) spot labels in capture order. seed: RNG seed.
    split="random": the paper's shuffled, non-stratified split (sklearn train_test_split);
        2260 frames give 1808 / 452.
    split="blocked": in every run of consecutive frames with one label (a spot), one contiguous
        block of round(test_size * run length) frames is held out, and ``gap`` frames (>= 0) on
        each side of it are dropped from training, so no test frame has a near-duplicate
        neighbour in training. block="random": the block sits at a seeded random position and
        its gap may reach into the neighbouring spots; block="centre": the block sits in the
        middle of its spot (the seed then only shuffles training), so block and gap stay inside
        the spot when the spot is long enough.
    train_size: keep only this many training frames (a seeded random subset), to compare splits
        at one training-set size; None keeps them all.
    Returns (train_idx (n_train,), test_idx (n_test,)) int64, sorted for "blocked" and for a
    subsampled split.
    """
    y = np.asarray(y)
    n = len(y)
    if not 0 < test_size < 1:
        raise ValueError(f"test_size must be in (0, 1), got {test_size}")
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if block not in BLOCKS:
        raise ValueError(f"block must be one of {BLOCKS}, got {block!r}")
    gap = _count(gap, "gap")
    if split == "random":
        from sklearn.model_selection import train_test_split
        train, test = train_test_split(np.arange(n), test_size=test_size, random_state=seed, shuffle=True)
        train, test = np.asarray(train, np.int64), np.asarray(test, np.int64)
    else:
        train, test = _blocked(y, np.random.default_rng(seed), test_size, gap, block)
    if train_size is None:
        return train, test
    train_size = _count(train_size, "train_size")
    if not 1 <= train_size <= len(train):
        raise ValueError(f"train_size must be in [1, {len(train)}] (the split's training frames), "
                         f"got {train_size}")
    keep = np.random.default_rng([seed, 1]).choice(len(train), train_size, replace=False)
    return np.sort(train[keep]), test


def _count(v, name: str) -> int:
    """v as an int >= 0, or ValueError naming ``name``."""
    return positive_int(name, v, 0)


def _blocked(y, rng, test_size: float, gap: int, block: str):
    """split_indices' blocked split: (train_idx, test_idx) sorted int64 (see there)."""
    n = len(y)
    starts = np.flatnonzero(np.r_[True, y[1:] != y[:-1]])
    ends = np.r_[starts[1:], n]
    is_test = np.zeros(n, bool)
    dropped = np.zeros(n, bool)
    for s, e in zip(starts, ends):
        k = int(round(test_size * (e - s)))
        if k < 1 or e - s - k < 1:
            continue
        offset = int(rng.integers(0, e - s - k + 1)) if block == "random" else (e - s - k) // 2
        a = s + offset
        is_test[a:a + k] = True
        dropped[max(0, a - gap):min(n, a + k + gap)] = True
    return np.flatnonzero(~dropped), np.flatnonzero(is_test)


def _epoch_bar(epochs: int, desc: str):
    """A Keras callback showing one tqdm bar per training run (epochs), not per-batch output."""
    import keras

    class EpochBar(keras.callbacks.Callback):
        def on_train_begin(self, logs=None):
            self.bar = tqdm(total=epochs, desc=desc, unit="epoch", leave=False)

        def on_epoch_end(self, epoch, logs=None):
            self.bar.update(1)
            if logs and "val_accuracy" in logs:
                self.bar.set_postfix(val_acc=f"{logs['val_accuracy']:.3f}", refresh=False)

        def on_train_end(self, logs=None):
            self.bar.close()
    return EpochBar()


def train(X: np.ndarray, y: np.ndarray, seed: int, epochs: int = 200, batch_size: int = 32,
          test_size: float = 0.2, split: str = "random", n_classes: int | None = None,
          trainer: str = "auto", cache: bool | str | Path = True, progress: bool = True, gap: int = 5,
          block: str = "random", train_size: int | None = None):
    """Train the paper's CNN on frames X with spot labels y; the test split is the validation data.

    X: (N, H, W, C) float32 in [0, 1]. y: (N,) int spot labels. seed: seeds the split, the weight
    initialisation and the shuffling (same seed, same numbers on CPU).
    split: "random" (the paper's 80/20) or "blocked"; gap, block, train_size: see ``split_indices``.
    n_classes: defaults to y.max() + 1.
    trainer: which trainer runs the same protocol (batch 32, Adam 1e-3, categorical cross-entropy,
        ``model.fit``'s shuffled batches, the same seeded Keras initial weights):
        "plain": ``model.fit`` as the paper's code would call it (the reference);
        "xla": ``model.fit`` with the train step compiled by XLA and one call per epoch
        (steps_per_execution), the fast path on an accelerator or without numba;
        "fused": gradients written out (``_fit_fused``: numba kernels and single-threaded BLAS
        split over the cores by ``greenloop.util.kernels``), the fastest on a CPU;
        "auto": "fused" when numba is installed and Keras sees no GPU, else "xla".
        Every trainer visits the frames in ``model.fit``'s order (``fit_orders``). The trainer is
        part of the cache key.
    cache: True (results/models/ or $GREENLOOP_CACHE), a folder, or False. Runs are keyed by
        ``cache_key`` and written atomically under a file lock, so reruns and parallel ``make -j``
        jobs reuse a model instead of training it again.
    Returns (model, history, split): history maps 'accuracy', 'loss', 'val_accuracy', 'val_loss'
    and 'epoch_seconds' to per-epoch lists, plus 'seconds' (training wall time);
    split = {'train': idx, 'test': idx}.
    """
    X = np.asarray(X, dtype=np.float32)
    y = np.asarray(y, dtype=np.int64)
    if X.ndim != 4 or len(X) != len(y):
        raise ValueError(f"X must be (N, H, W, C) and y (N,), got {X.shape} and {y.shape}")
    positive_int("epochs", epochs, whole_floats=True)
    positive_int("batch_size", batch_size, whole_floats=True)
    n_classes = int(n_classes or y.max() + 1)
    trainer = resolve_trainer(trainer)
    if trainer == "fused" and X.shape[3] != 1:
        raise ValueError(f"the fused trainer needs gray frames (N, H, W, 1), got {X.shape}; "
                         f"use trainer='xla' or trainer='plain'")
    params = dict(seed=int(seed), epochs=int(epochs), batch_size=int(batch_size),
                  test_size=float(test_size), split=split, n_classes=n_classes, trainer=trainer,
                  gap=int(gap) if split == "blocked" else None)
    if split == "blocked" and block != "random":  # only non-default split knobs join the key,
        params["block"] = block                  # so models trained before they existed stay cached
    if train_size is not None:
        params["train_size"] = int(train_size)
    if trainer == "fused":  # keys fused runs apart from those of the first fused trainer (NumPy's order)
        params["batch_order"] = "model.fit"
    # the key calls the trainer "fast" (train's argument before it was named trainer), so models
    # trained before the rename stay cached
    key = cache_key(X, y, **{"fast" if k == "trainer" else k: v for k, v in params.items()})

    return cached_model(key, cache, lambda: _fit(X, y, progress, **params), params, "split.npz")


TRAINERS = ("auto", "plain", "xla", "fused")


def resolve_trainer(trainer: str = "auto") -> str:
    """The trainer ``train(trainer=...)`` runs: "plain", "xla" or "fused" (see ``train``)."""
    if trainer not in TRAINERS:
        raise ValueError(f"trainer must be one of {TRAINERS}, got {trainer!r}")
    if trainer == "auto":
        return "fused" if kernels.available() and not _accelerator() else "xla"
    return trainer


def _accelerator() -> bool:
    """True when the Keras backend computes on a GPU/TPU (then XLA beats the CPU kernels).

    Handles the TensorFlow backend (the one installed and tested) and JAX; any other backend
    counts as no accelerator."""
    import keras

    backend = keras.backend.backend()
    if backend == "jax":
        import jax
        return jax.default_backend() != "cpu"
    if backend == "tensorflow":
        import tensorflow as tf
        return bool(tf.config.list_physical_devices("GPU"))
    return False


def _fit(X, y, progress, *, n_classes, seed, epochs, batch_size, test_size, split, trainer, gap,
         block="random", train_size=None, **_):
    if trainer == "fused":
        return _fit_fused(X, y, progress, n_classes=n_classes, seed=seed, epochs=epochs,
                          batch_size=batch_size, test_size=test_size, split=split, gap=gap,
                          block=block, train_size=train_size)
    import keras

    train_idx, test_idx = split_indices(y, seed, test_size, split, gap or 0, block, train_size)
    keras.utils.set_random_seed(seed)
    xla = trainer == "xla"
    steps = int(np.ceil(len(train_idx) / batch_size)) if xla else 1
    model = build(n_classes, X.shape[1:], jit_compile=xla, steps_per_execution=steps)
    Y = keras.utils.to_categorical(y, n_classes).astype(np.float32)
    epoch_seconds = []
    clock = keras.callbacks.LambdaCallback(
        on_epoch_begin=lambda e, logs: epoch_seconds.append(-time.perf_counter()),
        on_epoch_end=lambda e, logs: epoch_seconds.__setitem__(-1, epoch_seconds[-1] + time.perf_counter()))
    callbacks = [clock] + ([_epoch_bar(epochs, f"train seed {seed} ({split})")] if progress else [])
    t0 = time.perf_counter()
    h = model.fit(X[train_idx], Y[train_idx], epochs=epochs, batch_size=batch_size, shuffle=True,
                  validation_data=(X[test_idx], Y[test_idx]), verbose=0, callbacks=callbacks)
    history = {k: [float(v) for v in vals] for k, vals in h.history.items()}
    history["seconds"] = time.perf_counter() - t0
    history["epoch_seconds"] = epoch_seconds  # wall time per epoch (the first includes compilation)
    return model, history, {"train": train_idx, "test": test_idx}


def fit_orders(n: int, batch_size: int):
    """The order in which ``model.fit(x, y, batch_size, shuffle=True)`` visits n training frames,
    epoch after epoch: an endless iterator of (n,) int64 index arrays, the batches being
    consecutive runs of ``batch_size`` (the last one partial).

    The orders come from Keras's own array data adapter for the active backend, so call this where
    ``model.fit`` would start: after ``keras.utils.set_random_seed`` and ``build``. On the
    TensorFlow backend the shuffle is a seeded ``tf.random.shuffle`` that is re-seeded each time
    the epoch's dataset is iterated, so a seeded ``model.fit`` (Keras 3.15, TF 2.21) visits the
    frames in the same order in every epoch (unseeded, a new one each epoch); on the JAX backend
    it draws a new ``np.random.permutation`` each epoch (followed from Keras's source; only the
    TensorFlow backend is tested here). tests/test_kernels.py checks the orders against
    ``model.fit`` itself."""
    import keras

    adapter = _array_data_adapter()(np.arange(n), batch_size=batch_size, shuffle=True)
    if keras.backend.backend() == "tensorflow":
        dataset = adapter.get_tf_dataset()  # created once per fit, iterated once per epoch
        while True:
            yield np.concatenate([np.asarray(b) for b in dataset])
    while True:
        yield np.concatenate(list(adapter.get_numpy_iterator()))


def _array_data_adapter():
    """Keras's private ``ArrayDataAdapter`` class, the one place greenloop imports ``keras.src``.

    ``model.fit(x, y, shuffle=True)`` on NumPy arrays draws its batch order through this adapter,
    and Keras 3 has no public API that exposes that order (``keras.utils`` offers no data adapter;
    a hand-written ``tf.random.shuffle`` would not follow Keras's seeding). ``fit_orders`` needs the
    very same order so that the fused trainer takes model.fit's steps. The module path is private
    and may move in a Keras upgrade: tests/test_cnn.py imports it through this function and
    fails with a message naming it."""
    from keras.src.trainers.data_adapters.array_data_adapter import ArrayDataAdapter

    return ArrayDataAdapter


def _logits(Xg, Kc, bc, Wd, bd, Wo, bo):
    """Forward pass on gray frames Xg (n, H, W): (A (n, positions*f), Z2 (n, 68), Z3 (n, C))."""
    A = kernels.conv_relu(Xg, Kc, bc)
    Z2 = kernels.matmul(A, Wd)
    Z2 += bd
    Z3 = np.maximum(Z2, 0) @ Wo
    Z3 += bo
    return A, Z2, Z3


def _softmax_loss(Z3, y):
    """Softmax cross-entropy: (probabilities (n, C), per-frame loss (n,)) from logits (n, C)."""
    Z = Z3 - Z3.max(1, keepdims=True)
    E = np.exp(Z)
    S = E.sum(1, keepdims=True)
    loss = np.log(S[:, 0]) - Z[np.arange(len(y)), y]
    return E / S, loss


def _fit_fused(X, y, progress, *, n_classes, seed, epochs, batch_size, test_size, split, gap,
               block="random", train_size=None):
    """The paper's protocol (batch 32, Adam 1e-3, softmax cross-entropy, shuffled batches, the
    test split as validation data after each epoch) with the gradients written out in float32,
    like Keras computes them:
    conv + ReLU (``kernels.conv_relu``) -> dense (BLAS, split over the cores) -> output layer and
    softmax (NumPy); backward: the dense layer's two products and Adam's update of its 2 M
    weights, split over the cores by rows (``kernels.dense_backward_adam``), then the conv's
    gradients (``kernels.conv_grad``) and Adam on the small arrays (``kernels.adam``).
    The weights start from the seeded ``build`` model (Keras's own initialisers) and are written
    back into it at the end, so the model returned and cached is the ordinary Keras model.
    The batches are those ``model.fit`` would draw (``fit_orders``), so each seed takes the same
    steps as under ``model.fit``, up to float rounding; tests/test_kernels.py checks the weights
    against ``model.fit``'s. Same history keys as ``model.fit``."""
    import keras
    from threadpoolctl import threadpool_limits

    train_idx, test_idx = split_indices(y, seed, test_size, split, gap or 0, block, train_size)
    keras.utils.set_random_seed(seed)
    model = build(n_classes, X.shape[1:], jit_compile=False)
    conv, dense, out = (model.get_layer(n) for n in ("conv", "dense", "output"))
    params, ksize = _fused_params(conv, dense, out)
    state = {"params": params, "moments": [(np.zeros_like(p), np.zeros_like(p)) for p in params],
             "ksize": ksize, "step": 0, "dW": np.empty_like(params[2]),
             "dA": np.empty((batch_size, params[2].shape[0]), np.float32)}
    Xg = np.ascontiguousarray(X[..., 0], dtype=np.float32)
    y = np.asarray(y, np.int64)
    orders = fit_orders(len(train_idx), batch_size)
    history = {k: [] for k in ("accuracy", "loss", "val_accuracy", "val_loss")}
    epoch_seconds = []
    t0 = time.perf_counter()
    bar = tqdm(total=epochs, desc=f"train seed {seed} ({split})", unit="epoch", leave=False, disable=not progress)
    # one BLAS thread per call: kernels.run_slices spreads the work over the cores itself
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(epochs):
            t_epoch = time.perf_counter()
            order = train_idx[next(orders)]
            correct = loss_sum = 0.0
            for s in range(0, len(order), batch_size):
                c, l_ = _fused_step(state, Xg, y, order[s:s + batch_size])
                correct += c
                loss_sum += l_
            val_loss, val_correct = _fused_validate(params, Xg, y, test_idx)
            history["accuracy"].append(correct / len(order))
            history["loss"].append(loss_sum / len(order))
            history["val_accuracy"].append(val_correct / max(1, len(test_idx)))
            history["val_loss"].append(val_loss / max(1, len(test_idx)))
            epoch_seconds.append(time.perf_counter() - t_epoch)
            bar.update(1)
            bar.set_postfix(val_acc=f"{history['val_accuracy'][-1]:.3f}", refresh=False)
    bar.close()
    Kc, bc, Wd, bd, Wo, bo = params
    conv.set_weights([Kc[:, :, None, :], bc])
    dense.set_weights([Wd, bd])
    out.set_weights([Wo, bo])
    history["seconds"] = time.perf_counter() - t0
    history["epoch_seconds"] = epoch_seconds
    return model, history, {"train": train_idx, "test": test_idx}


def _fused_params(conv, dense, out):
    """The Keras layers' weights as C-contiguous float32 arrays, in ``_logits``'s order.

    Returns ([Kc (kh, kw, f) conv kernel of the single input channel, bc (f,), Wd (positions*f, 68),
    bd (68,), Wo (68, C), bo (C,)], (kh, kw) kernel size in pixels).
    """
    wc, bc = conv.get_weights()
    kh, kw, _, nf = wc.shape
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return [f32(wc.reshape(kh, kw, nf)), f32(bc), *map(f32, dense.get_weights()),
            *map(f32, out.get_weights())], (kh, kw)


def _fused_step(state: dict, Xg: np.ndarray, y: np.ndarray, idx: np.ndarray):
    """One Adam step on the batch ``idx`` (b,) of gray frames Xg (N, H, W) with labels y (N,).

    state: 'params' (the six arrays of ``_fused_params``, updated in place), 'moments' (Adam's
    first and second moments, like params), 'ksize' (kh, kw), 'step' (Adam's step count,
    incremented), 'dW' (positions*f, 68) and 'dA' (batch_size, positions*f) float32 scratch.
    Returns (correct predictions, summed loss) of the batch before the step.
    """
    params, moments = state["params"], state["moments"]
    Kc, bc, Wd, bd, Wo, bo = params
    b = len(idx)
    Xb = Xg[idx]
    A, Z2, Z3 = _logits(Xb, Kc, bc, Wd, bd, Wo, bo)
    prob, loss = _softmax_loss(Z3, y[idx])
    correct = float((Z3.argmax(1) == y[idx]).sum())
    loss_sum = float(loss.sum())
    dZ3 = prob
    dZ3[np.arange(b), y[idx]] -= 1.0
    dZ3 /= np.float32(b)
    H = np.maximum(Z2, 0)
    dZ2 = (dZ3 @ Wo.T) * (Z2 > 0)
    grads = {3: dZ2.sum(0), 4: H.T @ dZ3, 5: dZ3.sum(0)}
    state["step"] += 1
    t = np.float32(state["step"])
    alpha = np.float32(1e-3) * np.sqrt(np.float32(1) - np.float32(0.999) ** t) / (np.float32(1) - np.float32(0.9) ** t)
    dA = state["dA"]
    kernels.dense_backward_adam(A, dZ2, Wd, *moments[2], alpha, state["dW"], dA[:b])  # Wd updated
    grads[0], grads[1] = kernels.conv_grad(Xb, dA[:b], A, state["ksize"])
    for i, g in grads.items():
        kernels.adam(params[i], np.ascontiguousarray(g, np.float32), *moments[i], alpha)
    return correct, loss_sum


def _fused_validate(params, Xg: np.ndarray, y: np.ndarray, test_idx: np.ndarray):
    """(summed loss, correct predictions) on the frames ``test_idx`` of Xg (N, H, W), in batches
    of 256; params: the six arrays of ``_fused_params``."""
    val_loss = val_correct = 0.0
    for s in range(0, len(test_idx), 256):
        idx = test_idx[s:s + 256]
        Z3 = _logits(Xg[idx], *params)[2]
        val_loss += float(_softmax_loss(Z3, y[idx])[1].sum())
        val_correct += float((Z3.argmax(1) == y[idx]).sum())
    return val_loss, val_correct


def predict(model, X: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """Predicted spot labels (N,) int64 for frames X (N, H, W, C), via ``model.predict``.

    TensorFlow's "triggered tf.function retracing" warning (each new model or input size traces
    the predict step again, which is expected here) is silenced for the call.
    """
    import logging

    tf_log = logging.getLogger("tensorflow")
    level = tf_log.level
    tf_log.setLevel(logging.ERROR)
    try:
        p = model.predict(np.asarray(X, dtype=np.float32), batch_size=batch_size, verbose=0)
    finally:
        tf_log.setLevel(level)
    return p.argmax(1).astype(np.int64)


def run_seeds(X: np.ndarray, y: np.ndarray, seeds, progress: bool = True, **train_kw) -> list[dict]:
    """Train (or load from the cache) one model per seed and score it on its own test split.

    X: (N, H, W, C) frames, y: (N,) labels, seeds: iterable of ints; train_kw go to ``train``.
    Returns one dict per seed: {'seed', 'model', 'history', 'split', 'test_accuracy',
    'test_pred' (n_test,) predicted labels of split['test']}.
    """
    out = []
    for seed in tqdm(list(seeds), desc="seeds", unit="seed", disable=not progress):
        model, history, split = train(X, y, seed, progress=progress, **train_kw)
        pred = predict(model, X[split["test"]])
        out.append({"seed": int(seed), "model": model, "history": history, "split": split,
                    "test_accuracy": float(np.mean(pred == y[split["test"]])), "test_pred": pred})
    return out


def leakage_controls(X: np.ndarray, y: np.ndarray, seeds, gaps=(0, 5, 10, 20, 40),
                     centre_gap: int = 5, converged_at: float = 0.95, progress: bool = True,
                     **train_kw) -> list[dict]:
    """How much of the random split's accuracy is memory: the blocked split at every gap, beside a
    random split with the same number of training frames, and a block centred in its spot.

    X: (N, H, W, C) frames, y: (N,) spot labels, seeds: ints; gaps: frames dropped on each side of
    a test block (``split_indices``); centre_gap: the gap of the centred-block run.
    converged_at: a seed whose final training accuracy is below this fraction did not fit its own
    training frames ("converged" False). train_kw go to ``train`` (epochs, batch_size, ...).
    The matched random run keeps as many training frames as the blocked run, or all of the random
    split's where the blocked split keeps more (a frame or so at gap 0, from per-spot rounding).
    Returns one dict per run: control ("blocked", "random, same n_train", "blocked, centred"),
    gap (frames; the matched random run carries the gap of the blocked run it matches), seed,
    n_train, n_test, test_acc_% and final_train_acc_% (in %), converged (bool).
    """
    def row(control, gap, r):
        final = 100 * r["history"]["accuracy"][-1]
        return {"control": control, "gap": int(gap), "seed": r["seed"],
                "n_train": len(r["split"]["train"]), "n_test": len(r["split"]["test"]),
                "test_acc_%": round(100 * r["test_accuracy"], 2), "final_train_acc_%": round(final, 2),
                "converged": converged(r["history"], converged_at)}

    rows = []
    for gap in gaps:
        for r in run_seeds(X, y, seeds, progress, split="blocked", gap=gap, **train_kw):
            rows.append(row(LEAKAGE_CONTROLS[0], gap, r))
            # the blocked split can keep one frame more than the random 80/20 split has (per-spot
            # rounding of the test blocks at gap 0): then the control keeps all of the random split's
            n_random = len(split_indices(y, r["seed"], train_kw.get("test_size", 0.2))[0])
            m = run_seeds(X, y, [r["seed"]], progress, split="random",
                          train_size=min(len(r["split"]["train"]), n_random), **train_kw)[0]
            rows.append(row(LEAKAGE_CONTROLS[1], gap, m))
    for r in run_seeds(X, y, seeds, progress, split="blocked", gap=centre_gap, block="centre",
                       **train_kw):
        rows.append(row(LEAKAGE_CONTROLS[2], centre_gap, r))
    return rows


def controls_by_grouping(X: np.ndarray, labels: dict, seeds, gap: int, converged_at: float = 0.95,
                         progress: bool = True, **train_kw) -> list[dict]:
    """Table 1 under the leakage control: ``leakage_controls`` at one gap for every grouping.

    X: (N, H, W, C) frames; labels: {L: (N,) spot labels of L frames per spot}; seeds: ints;
    gap: frames dropped on each side of a test block, for the blocked and the centred runs alike.
    converged_at, train_kw: as in ``leakage_controls``. Returns its rows, L after L, each with
    'frames_per_spot': L added last.
    """
    return [dict(row, frames_per_spot=L) for L, y in labels.items()
            for row in leakage_controls(X, y, seeds, gaps=[gap], centre_gap=gap, converged_at=converged_at,
                                        progress=progress, **train_kw)]


# ------------------------------------------------------- summaries of runs over seeds
def converged(history: dict, converged_at: float = 0.95) -> bool:
    """Did a run fit its training frames: its final training accuracy (a fraction in [0, 1],
    ``history['accuracy'][-1]``) is at least converged_at (a fraction)."""
    return bool(history["accuracy"][-1] >= converged_at)


def first_epoch(history: dict, target: float):
    """The first epoch (1-based) whose validation accuracy (fraction) reaches target (fraction),
    or None when no epoch does."""
    hit = np.flatnonzero(np.asarray(history["val_accuracy"]) >= target)
    return int(hit[0]) + 1 if len(hit) else None


def accuracy_over_seeds(runs: list[dict], converged_at: float = 0.95) -> dict:
    """Test accuracy of one grouping over seeds (Table 1's columns).

    runs: ``run_seeds``' dicts of one grouping (at least one). Returns {'seeds', 'acc_mean_%',
    'acc_std_%' (0 with one seed), 'acc_median_%', 'acc_min_%', 'acc_max_%',
    'final_train_acc_min_%' (the worst seed's final training accuracy), 'converged_seeds'
    (``converged``), 'acc_median_converged_%' (NaN when none converged)}: accuracies in %,
    rounded to 2 decimals.
    """
    acc = np.array([r["test_accuracy"] for r in runs]) * 100
    conv = np.array([converged(r["history"], converged_at) for r in runs])
    return {"seeds": len(acc), "acc_mean_%": acc.mean().round(2),
            "acc_std_%": acc.std(ddof=1).round(2) if len(acc) > 1 else 0.0,
            "acc_median_%": np.median(acc).round(2), "acc_min_%": acc.min().round(2), "acc_max_%": acc.max().round(2),
            "final_train_acc_min_%": round(100 * min(r["history"]["accuracy"][-1] for r in runs), 2),
            "converged_seeds": int(conv.sum()),
            "acc_median_converged_%": np.median(acc[conv]).round(2) if conv.any() else np.nan}


def per_seed_rows(runs_by_split: dict, target_accuracy: float = 0.98, converged_at: float = 0.95,
                  after_epoch: int = 45) -> list[dict]:
    """One row per run: the figures the paper gives for its learning curves (Figures 3 and 4).

    runs_by_split: {split name: ``run_seeds``' dicts}. target_accuracy, converged_at: fractions.
    Returns dicts (split, seed, n_train, n_test, test_acc_%, epoch_to_<target in %>% (first
    epoch whose validation accuracy reaches the target, None if none), min_val_acc_after_ep<after_epoch>_%
    (lowest validation accuracy from epoch after_epoch + 1 on, or of the last epoch in a shorter
    run), final_train_acc_%, converged, train_seconds): accuracies in %, rounded to 2 decimals.
    """
    rows = []
    for split, rs in runs_by_split.items():
        for r in rs:
            h = r["history"]; va = np.asarray(h["val_accuracy"])
            rows.append({"split": split, "seed": r["seed"], "n_train": len(r["split"]["train"]),
                         "n_test": len(r["split"]["test"]), "test_acc_%": round(100 * r["test_accuracy"], 2),
                         f"epoch_to_{int(target_accuracy * 100)}%": first_epoch(h, target_accuracy),
                         f"min_val_acc_after_ep{after_epoch}_%": round(100 * va[min(after_epoch, len(va) - 1):].min(), 2),
                         "final_train_acc_%": round(100 * h["accuracy"][-1], 2),
                         "converged": converged(h, converged_at),
                         "train_seconds": round(h["seconds"], 1)})
    return rows


def seed_summary(per_seed):
    """Test accuracy over seeds per split, from ``per_seed_rows`` as a DataFrame.

    Returns a DataFrame, one row per split (sorted by name): split, seeds, converged_seeds,
    mean, std, median, worst, best (of test_acc_%, rounded to 2 decimals) and median_of_converged
    (median test_acc_% of the converged seeds, NaN when none).
    """
    summ = per_seed.groupby("split").agg(seeds=("seed", "count"), converged_seeds=("converged", "sum"),
                                         mean=("test_acc_%", "mean"), std=("test_acc_%", "std"),
                                         median=("test_acc_%", "median"), worst=("test_acc_%", "min"),
                                         best=("test_acc_%", "max")).round(2).reset_index()
    summ["median_of_converged"] = [per_seed[(per_seed.split == s) & per_seed.converged]["test_acc_%"].median()
                                   for s in summ.split]
    return summ


_ACC_STATS = {"mean": lambda a: a.mean(), "std": lambda a: a.std(ddof=1) if len(a) > 1 else 0.0,
              "median": lambda a: a.median(), "min": lambda a: a.min(), "max": lambda a: a.max()}


def summarise_controls(runs, by, stats=("median", "min", "max")):
    """Leakage-control runs summarised per group.

    runs: DataFrame of ``leakage_controls`` rows (or ``controls_by_grouping``'s); by: the columns
    that make a group (e.g. ["control", "gap"]); stats: which of mean, std (0 for one run),
    median, min, max of test_acc_% to give, in that order. Returns a DataFrame, one row per group
    in order of appearance: the by columns, seeds, converged_seeds, n_train_median, acc_<stat>_%
    per stat, acc_median_converged_% (NaN when none converged); rounded to 2 decimals.
    """
    import pandas as pd

    unknown = [s for s in stats if s not in _ACC_STATS]
    if unknown:
        raise ValueError(f"unknown stats {unknown}: choose from {list(_ACC_STATS)}")

    def summarise(d):
        acc, conv = d["test_acc_%"], d[d.converged]["test_acc_%"]
        return pd.Series({"seeds": len(d), "converged_seeds": int(d.converged.sum()),
                          "n_train_median": int(d.n_train.median()),
                          **{f"acc_{s}_%": _ACC_STATS[s](acc) for s in stats},
                          "acc_median_converged_%": conv.median() if len(conv) else np.nan})

    return runs.groupby(list(by), sort=False).apply(summarise, include_groups=False).round(2).reset_index()


def memory_points(runs):
    """What memory of neighbours buys: per seed and gap, the random split with the blocked
    split's number of training frames minus the blocked (and the centred-block) run.

    runs: DataFrame of ``leakage_controls`` rows. Returns a DataFrame indexed by (control, gap),
    control in "blocked", "blocked, centred" (those present), with columns memory_points_median,
    memory_points_min, memory_points_max over seeds (points of test accuracy, rounded to 2
    decimals); pairs missing either run are left out.
    """
    import pandas as pd

    pair = runs.pivot_table(index=["gap", "seed"], columns="control", values="test_acc_%")
    matched = pair[LEAKAGE_CONTROLS[1]]
    memory = pd.concat({c: (matched - pair[c]).dropna().groupby("gap").agg(["median", "min", "max"])
                        for c in (LEAKAGE_CONTROLS[0], LEAKAGE_CONTROLS[2]) if c in pair},
                       names=["control"]).round(2)
    memory.columns = [f"memory_points_{c}" for c in memory.columns]
    return memory
