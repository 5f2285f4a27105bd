"""The main paper's one-conv-layer CNN: build, train over seeds (cached on disk), predict.

Model (exactly the paper's): Conv2D 32 filters 3x3 ReLU -> Flatten -> Dense 68 ReLU ->
Dense n_classes softmax; Adam lr 0.001, categorical cross-entropy, batch 32, 200 epochs.
Written against the Keras 3 API only, so it runs on the TensorFlow and the JAX backends.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from greenloop.util import numba_kernels as kernels
from greenloop.util.cache import cache_key, cached_model
from greenloop.util.checks import positive_int
from greenloop.util.progress import bar as tqdm   # in the terminal, never in a notebook
from greenloop.util.stopping import stops_here

SPLITS = ("random", "blocked")
STOP_MIN_DELTA = 0.005   # early stopping: a rise of the training accuracy (fraction) smaller than this is none
BLOCKS = ("random", "centre")   # where split="blocked" puts each spot's test block


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
    if dropped.all():
        raise ValueError(f"the blocked split leaves no training frame: each spot's test block and its gap of {gap} "
                         f"frames on either side cover all {n} frames (spots of {int((ends - starts).max())} frames "
                         f"at most); pass a smaller gap or longer spots (frames_per_spot)")
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
          block: str = "random", train_size: int | None = None, stop_patience: int = 0):
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
        split over the cores by ``greenloop.util.numba_kernels``), the fastest on a CPU;
        "auto": "fused" when numba is installed and Keras sees no GPU, else "xla".
        Every trainer visits the frames in ``model.fit``'s order (``fit_orders``). The trainer is
        part of the cache key.
    stop_patience: 0 trains every one of ``epochs`` epochs (the paper); P > 0 stops once the training
        accuracy has not risen by ``STOP_MIN_DELTA`` over its best for P epochs (:func:`stops_here`,
        Keras's ``EarlyStopping`` rule on 'accuracy'), so ``epochs`` is a cap; the history then
        says 'stopped_early'.
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
    if stop_patience:
        params["stop_patience"] = positive_int("stop_patience", stop_patience, whole_floats=True)
        params["stop_min_delta"] = STOP_MIN_DELTA
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
         block="random", train_size=None, stop_patience=0, **_):
    if trainer == "fused":
        return _fit_fused(X, y, progress, n_classes=n_classes, seed=seed, epochs=epochs,
                          batch_size=batch_size, test_size=test_size, split=split, gap=gap,
                          block=block, train_size=train_size, stop_patience=stop_patience)
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
    if stop_patience:
        callbacks.append(keras.callbacks.EarlyStopping(monitor="accuracy", mode="max", patience=stop_patience,
                                                       min_delta=STOP_MIN_DELTA))
    t0 = time.perf_counter()
    h = model.fit(X[train_idx], Y[train_idx], epochs=epochs, batch_size=batch_size, shuffle=True,
                  validation_data=(X[test_idx], Y[test_idx]), verbose=0, callbacks=callbacks)
    history = {k: [float(v) for v in vals] for k, vals in h.history.items()}
    history["seconds"] = time.perf_counter() - t0
    history["epoch_seconds"] = epoch_seconds  # wall time per epoch (the first includes compilation)
    if stop_patience:
        history["stopped_early"] = len(history["accuracy"]) < epochs
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


def paper_weights(model) -> list | None:
    """The weights of the paper's CNN as C-contiguous float32 arrays in :func:`forward`'s order, or
    None when ``model`` has another architecture (anything but Conv2D 3x3-style valid, stride 1,
    ReLU, one input channel -> Flatten -> Dense ReLU -> Dense softmax/linear, all with biases).

    Returns [K (kh, kw, f) the conv kernel of the single input channel, bc (f,), Wd
    (positions*f, 68), bd (68,), Wo (68, C), bo (C,)].
    """
    from keras import layers

    core = [l for l in model.layers if not isinstance(l, (layers.InputLayer, layers.Dropout))]
    if [type(l).__name__ for l in core] != ["Conv2D", "Flatten", "Dense", "Dense"]:
        return None
    conv, _, dense, out = core
    cfg, dcfg, ocfg = conv.get_config(), dense.get_config(), out.get_config()
    if (cfg.get("padding") != "valid" or tuple(cfg.get("strides", (1, 1))) != (1, 1)
            or tuple(cfg.get("dilation_rate", (1, 1))) != (1, 1) or cfg.get("activation") != "relu"
            or cfg.get("data_format", "channels_last") != "channels_last" or not cfg.get("use_bias", True)
            or cfg.get("groups", 1) != 1 or conv.get_weights()[0].shape[2] != 1):
        return None
    if dcfg.get("activation") != "relu" or not dcfg.get("use_bias", True):
        return None
    if ocfg.get("activation") not in ("softmax", "linear") or not ocfg.get("use_bias", True):
        return None
    wc, bc = conv.get_weights()
    kh, kw, _, nf = wc.shape
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return [f32(wc.reshape(kh, kw, nf)), f32(bc), *map(f32, dense.get_weights()), *map(f32, out.get_weights())]


def forward(Xg: np.ndarray, params, threads: bool = True):
    """The paper's CNN in NumPy (the one forward pass of the fused trainer and of the streaming
    detector's "numpy" backend).

    Xg: (n, H, W) float32 gray frames, C-contiguous. params: :func:`paper_weights`' six arrays.
    threads: the dense layer's 28800-long inner dimension split over the worker threads
    (``kernels.matmul``, what the trainer uses) or one matmul on the calling thread (a single
    frame: handing it to the threads costs more than it saves). The conv is the numba kernel
    ``kernels.conv_relu``, or an im2col matmul where numba is not installed.
    Returns (A (n, positions*f) relu(conv) flattened as Keras's Flatten, Z2 (n, 68) the dense
    layer before its ReLU, Z3 (n, C) the logits; softmax is monotonic, so argmax(Z3) is the label).
    """
    Kc, bc, Wd, bd, Wo, bo = params
    A = kernels.conv_relu(Xg, Kc, bc) if kernels.available() else _conv_relu_im2col(Xg, Kc, bc)
    Z2 = kernels.matmul(A, Wd) if threads else A @ Wd
    Z2 += bd
    Z3 = np.maximum(Z2, 0) @ Wo
    Z3 += bo
    return A, Z2, Z3


def _conv_relu_im2col(Xg, Kc, bc):
    """``kernels.conv_relu`` without numba: a strided (n, Ho, Wo, kh, kw) view times the (kh*kw, f)
    kernel, plus bias, ReLU; (n, Ho*Wo*f) float32 ordered (row, column, filter)."""
    kh, kw, nf = Kc.shape
    win = np.lib.stride_tricks.sliding_window_view(Xg, (kh, kw), axis=(1, 2))
    a = win.reshape(-1, kh * kw) @ Kc.reshape(kh * kw, nf)
    a += bc
    np.maximum(a, 0, out=a)
    return a.reshape(len(Xg), -1)


def _softmax_loss(Z3, y):
    """Softmax cross-entropy: (probabilities (n, C), per-frame loss (n,)) from logits (n, C)."""
    Z = Z3 - Z3.max(1, keepdims=True)
    E = np.exp(Z)
    S = E.sum(1, keepdims=True)
    loss = np.log(S[:, 0]) - Z[np.arange(len(y)), y]
    return E / S, loss


def _fit_fused(X, y, progress, *, n_classes, seed, epochs, batch_size, test_size, split, gap,
               block="random", train_size=None, stop_patience=0):
    """The paper's protocol (batch 32, Adam 1e-3, softmax cross-entropy, shuffled batches, the
    test split as validation data after each epoch, early stopping by :func:`stops_here` when
    stop_patience > 0) with the gradients written out in float32,
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
    params = paper_weights(model)
    ksize = params[0].shape[:2]
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
    # one BLAS thread per call: util.threads.run_slices spreads the work over the cores itself
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
            if stop_patience and stops_here(history["accuracy"], stop_patience, STOP_MIN_DELTA):
                break
    bar.close()
    Kc, bc, Wd, bd, Wo, bo = params
    conv.set_weights([Kc[:, :, None, :], bc])
    dense.set_weights([Wd, bd])
    out.set_weights([Wo, bo])
    history["seconds"] = time.perf_counter() - t0
    history["epoch_seconds"] = epoch_seconds
    if stop_patience:
        history["stopped_early"] = len(history["accuracy"]) < epochs
    return model, history, {"train": train_idx, "test": test_idx}


def _fused_step(state: dict, Xg: np.ndarray, y: np.ndarray, idx: np.ndarray):
    """One Adam step on the batch ``idx`` (b,) of gray frames Xg (N, H, W) with labels y (N,).

    state: 'params' (the six arrays of ``paper_weights``, updated in place), 'moments' (Adam's
    first and second moments, like params), 'ksize' (kh, kw), 'step' (Adam's step count,
    incremented), 'dW' (positions*f, 68) and 'dA' (batch_size, positions*f) float32 scratch.
    Returns (correct predictions, summed loss) of the batch before the step.
    """
    params, moments = state["params"], state["moments"]
    Kc, bc, Wd, bd, Wo, bo = params
    b = len(idx)
    Xb = Xg[idx]
    A, Z2, Z3 = forward(Xb, params)
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
    of 256; params: the six arrays of ``paper_weights``."""
    val_loss = val_correct = 0.0
    for s in range(0, len(test_idx), 256):
        idx = test_idx[s:s + 256]
        Z3 = forward(Xg[idx], params)[2]
        val_loss += float(_softmax_loss(Z3, y[idx])[1].sum())
        val_correct += float((Z3.argmax(1) == y[idx]).sum())
    return val_loss, val_correct


def predict(model, X: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """Predicted spot labels (N,) int64 for frames X (N, H, W, C), via ``model.predict_on_batch``
    on batches of batch_size: the outputs of ``model.predict``, without the data pipeline it builds
    on every call, which cost the shift and control grids' many small calls more than the network.

    TensorFlow's "triggered tf.function retracing" warning (each new model or input size traces
    the predict step again, which is expected here) is silenced for the call.
    """
    import logging

    X = np.asarray(X, dtype=np.float32)
    if len(X) == 0:
        return np.zeros(0, np.int64)
    tf_log = logging.getLogger("tensorflow")
    level = tf_log.level
    tf_log.setLevel(logging.ERROR)
    try:
        p = np.concatenate([np.asarray(model.predict_on_batch(X[i:i + batch_size]))
                            for i in range(0, len(X), batch_size)])
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


