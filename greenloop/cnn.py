"""The main paper's one-conv-layer CNN: build, train over seeds (cached on disk), predict.

Model (exactly the paper's): Conv2D 32 filters 3x3 ReLU -> Flatten -> Dense 68 ReLU ->
Dense n_classes softmax; Adam lr 0.001, categorical cross-entropy, batch 32, 200 epochs.
Written against the Keras 3 API only, so it runs on the TensorFlow and the JAX backends.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE_DIR = Path(os.environ.get("GREENLOOP_CACHE", ROOT / "results" / "models"))
SPLITS = ("random", "blocked")


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
                  gap: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Train/test frame indices.

    y: (N,) spot labels in capture order. seed: RNG seed.
    split="random": the paper's shuffled, non-stratified split (sklearn train_test_split);
        2260 frames give 1808 / 452.
    split="blocked": in every run of consecutive frames with one label (a spot), one contiguous
        block of round(test_size * run length) frames at a seeded random position is held out, and
        ``gap`` frames on each side of it are dropped from training, so no test frame has a
        near-duplicate neighbour in training.
    Returns (train_idx (n_train,), test_idx (n_test,)) int64, sorted for "blocked".
    """
    y = np.asarray(y)
    n = len(y)
    if not 0 < test_size < 1:
        raise ValueError(f"test_size must be in (0, 1), got {test_size}")
    if split == "random":
        from sklearn.model_selection import train_test_split
        train, test = train_test_split(np.arange(n), test_size=test_size, random_state=seed, shuffle=True)
        return np.asarray(train, np.int64), np.asarray(test, np.int64)
    if split != "blocked":
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    rng = np.random.default_rng(seed)
    starts = np.flatnonzero(np.r_[True, y[1:] != y[:-1]])
    ends = np.r_[starts[1:], n]
    is_test = np.zeros(n, bool)
    dropped = np.zeros(n, bool)
    for s, e in zip(starts, ends):
        k = int(round(test_size * (e - s)))
        if k < 1 or e - s - k < 1:
            continue
        a = s + int(rng.integers(0, e - s - k + 1))
        is_test[a:a + k] = True
        dropped[max(0, a - gap):min(n, a + k + gap)] = True
    train = np.flatnonzero(~dropped)
    test = np.flatnonzero(is_test)
    return train, test


def cache_key(X: np.ndarray, y: np.ndarray, **params) -> str:
    """Hex key of a training run: a hash of the data (X, y bytes), every parameter, and the
    Keras version and backend. Any change gives another key."""
    import keras

    h = hashlib.sha1()
    h.update(np.ascontiguousarray(X).view(np.uint8))
    h.update(np.ascontiguousarray(y, dtype=np.int64).view(np.uint8))
    meta = dict(params, shape=list(X.shape), keras=keras.__version__, backend=keras.backend.backend())
    h.update(json.dumps(meta, sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def _epoch_bar(epochs: int, desc: str):
    """A Keras callback showing one tqdm bar per training run (epochs), not per-batch output."""
    import keras
    from tqdm import tqdm  # text bars: readable in terminals and in executed notebooks

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


@contextlib.contextmanager
def _locked(path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _load_cached(folder: Path):
    import keras

    model = keras.models.load_model(folder / "model.keras")
    history = json.loads((folder / "history.json").read_text())
    split = dict(np.load(folder / "split.npz"))
    return model, history, split


def train(X: np.ndarray, y: np.ndarray, seed: int, epochs: int = 200, batch_size: int = 32,
          test_size: float = 0.2, split: str = "random", n_classes: int | None = None,
          fast: bool = True, cache: bool | str | Path = True, progress: bool = True, gap: int = 5):
    """Train the paper's CNN on frames X with spot labels y; the test split is the validation data.

    X: (N, H, W, C) float32 in [0, 1]. y: (N,) int spot labels. seed: seeds the split, the weight
    initialisation and the shuffling (same seed, same numbers on CPU).
    split: "random" (the paper's 80/20) or "blocked" (see ``split_indices``).
    n_classes: defaults to y.max() + 1.
    fast: compile the train step with XLA and run a whole epoch per call (steps_per_execution);
        the same protocol (batch 32, Adam 1e-3, shuffling) as a plain ``model.fit``.
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
    if epochs < 1 or batch_size < 1:
        raise ValueError(f"epochs and batch_size must be >= 1, got {epochs}, {batch_size}")
    n_classes = int(n_classes or y.max() + 1)
    params = dict(seed=int(seed), epochs=int(epochs), batch_size=int(batch_size),
                  test_size=float(test_size), split=split, n_classes=n_classes, fast=bool(fast),
                  gap=int(gap) if split == "blocked" else None)
    key = cache_key(X, y, **params)
    folder = None
    if cache:
        root = CACHE_DIR if cache is True else Path(cache)
        folder = root / key
        with _locked(root / f"{key}.lock"):
            if (folder / "model.keras").is_file():
                return _load_cached(folder)
            result = _fit(X, y, progress, **params)
            tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".tmp-{key}-"))
            model, history, split_ = result
            model.save(tmp / "model.keras")
            (tmp / "history.json").write_text(json.dumps(history))
            np.savez(tmp / "split.npz", **split_)
            (tmp / "params.json").write_text(json.dumps(dict(params, key=key), indent=1))
            if folder.exists():
                shutil.rmtree(folder)
            os.replace(tmp, folder)
            return result
    return _fit(X, y, progress, **params)


def _fit(X, y, progress, *, n_classes, seed, epochs, batch_size, test_size, split, fast, gap, **_):
    import keras

    train_idx, test_idx = split_indices(y, seed, test_size, split, gap or 0)
    keras.utils.set_random_seed(seed)
    steps = int(np.ceil(len(train_idx) / batch_size)) if fast else 1
    model = build(n_classes, X.shape[1:], jit_compile=bool(fast), steps_per_execution=steps)
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


def predict(model, X: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """Predicted spot labels (N,) int64 for frames X (N, H, W, C), via ``model.predict``."""
    p = model.predict(np.asarray(X, dtype=np.float32), batch_size=batch_size, verbose=0)
    return p.argmax(1).astype(np.int64)


def run_seeds(X: np.ndarray, y: np.ndarray, seeds, progress: bool = True, **train_kw) -> list[dict]:
    """Train (or load from the cache) one model per seed and score it on its own test split.

    X: (N, H, W, C) frames, y: (N,) labels, seeds: iterable of ints; train_kw go to ``train``.
    Returns one dict per seed: {'seed', 'model', 'history', 'split', 'test_accuracy',
    'test_pred' (n_test,) predicted labels of split['test']}.
    """
    from tqdm import tqdm  # text bars: readable in terminals and in executed notebooks

    out = []
    for seed in tqdm(list(seeds), desc="seeds", unit="seed", disable=not progress):
        model, history, split = train(X, y, seed, progress=progress, **train_kw)
        pred = predict(model, X[split["test"]])
        out.append({"seed": int(seed), "model": model, "history": history, "split": split,
                    "test_accuracy": float(np.mean(pred == y[split["test"]])), "test_pred": pred})
    return out
