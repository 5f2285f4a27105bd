"""The on-disk cache of everything expensive: trained models and extracted descriptors.

One folder per key under ``CACHE_DIR`` (``results/models/``, or ``$GREENLOOP_CACHE``), written
under a temporary name and renamed, under a file lock, so reruns and parallel ``make -j`` jobs
compute each key once and never read a half-written folder.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from greenloop.util.files import publish_folder

ROOT = Path(__file__).resolve().parents[2]
CACHE_DIR = Path(os.environ.get("GREENLOOP_CACHE", ROOT / "results" / "models"))


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


@contextlib.contextmanager
def _locked(path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def cached(key: str, cache, fit, save, load, marker: str = "model.keras"):
    """Compute ``fit()`` once per ``key`` and keep it on disk.

    key: e.g. ``cache_key(...)``. cache: True (``CACHE_DIR``), a folder, or False (just return
    fit()). save(folder, result) writes fit()'s result into an empty folder; load(folder) reads it
    back; a key counts as cached when ``<root>/<key>/<marker>`` exists. The folder is written under
    a temporary name and renamed, all under a file lock on ``<root>/<key>.lock``. Returns fit()'s
    result, or load(folder) when the key was cached.
    """
    if not cache:
        return fit()
    root = CACHE_DIR if cache is True else Path(cache)
    folder = root / key
    with _locked(root / f"{key}.lock"):
        if (folder / marker).is_file():
            return load(folder)
        result = fit()
        tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".tmp-{key}-"))
        save(tmp, result)
        publish_folder(tmp, folder)
        return result


def is_cached(key: str, cache, marker: str = "model.keras") -> bool:
    """Whether :func:`cached` would load ``key`` instead of fitting it (``<root>/<key>/<marker>``
    exists; cache as in :func:`cached`, False: never)."""
    if not cache:
        return False
    root = CACHE_DIR if cache is True else Path(cache)
    return (root / key / marker).is_file()


def cached_model(key: str, cache, fit, params: dict, arrays: str, compile: bool = True):
    """:func:`cached` for a trained Keras model (``cnn.train``, ``siamese.train``).

    fit() returns (model, history, extras): a Keras model, its JSON-able training history and a
    dict of named arrays (the split's frame indices, the training pairs). They are kept as
    ``model.keras``, ``history.json``, ``<arrays>`` (an .npz file name) and ``params.json`` (params
    and the key, for a reader of the cache). compile: load the model compiled (False for models
    whose loss Keras cannot rebuild; cached models only predict). Returns (model, history, extras).
    """
    def save(folder: Path, result) -> None:
        model, history, extras = result
        model.save(folder / "model.keras")
        (folder / "history.json").write_text(json.dumps(history))
        np.savez(folder / arrays, **extras)
        (folder / "params.json").write_text(json.dumps(dict(params, key=key), indent=1, default=str))

    def load(folder: Path):
        import warnings

        import keras

        with warnings.catch_warnings():  # the optimizer state is not saved: cached models only predict
            warnings.filterwarnings("ignore", message="Skipping variable loading for optimizer",
                                    category=UserWarning)
            model = keras.models.load_model(folder / "model.keras", compile=compile)
        history = json.loads((folder / "history.json").read_text())
        return model, history, dict(np.load(folder / arrays))

    return cached(key, cache, fit, save, load)
