"""The one on-disk cache of everything expensive: trained models and extracted descriptors.

One folder per key under ``CACHE_DIR`` (``results/models/``, or ``$GREENLOOP_CACHE``; descriptors
in its ``descriptors/`` folder), written under a temporary name and renamed, under a file lock, so
reruns and parallel ``make -j`` jobs compute each key once and never read a half-written folder.

Keys: a model's (:func:`cache_key`) hashes its training data and parameters; a descriptor's
(:func:`descriptor_key`) the frames' names, sizes and modification times, the descriptor code's
version (:data:`DESCRIPTOR_CODE_VERSION`) and the settings. Formats: a model folder holds
``model.keras`` (:func:`cached_model`); a descriptor folder ``features.npy`` (:func:`cached_descriptor`)
or, for one pass of a network at every depth, ``layers.npz`` (:func:`cached_layers`); a converted
network's (:func:`model_key`: its configuration and weights) ``graph.tflite`` (:func:`cached_graph`).
"""
from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import json
import lzma
import os
import tempfile
from pathlib import Path

import numpy as np

from greenloop.util.files import publish_folder

ROOT = Path(__file__).resolve().parents[2]
CACHE_DIR = Path(os.environ.get("GREENLOOP_CACHE", ROOT / "results" / "models"))
DESCRIPTORS = "descriptors"    # the descriptor entries' folder under CACHE_DIR
GRAPHS = "graphs"              # the converted networks' folder under CACHE_DIR (cached_graph)

# Descriptor keys once hashed the live source of greenloop/features/*.py, datasets/sequence.py and
# the backbone ports, so that any edit (a docstring, a move) re-extracted every cached descriptor.
# They now hash a frozen stamp of the code version instead: version 1 is exactly those files' bytes
# at commit e5611eb (their sha1 below), so every key, and the warm cache, stays what it was.
# A change to what a descriptor computes must bump the version (then the stamp is the version
# string); tests/test_descriptor_objects.py holds checksums of every family that fail until then.
DESCRIPTOR_CODE_VERSION = 1
_STAMP_V1 = (Path(__file__).with_name("descriptor_code_v1.xz"), "0ec05641e7b0e72e7dead994bfae7e8812308a83")


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


@functools.lru_cache(maxsize=1)
def code_stamp() -> bytes:
    """The bytes every descriptor key hashes for the code version (:data:`DESCRIPTOR_CODE_VERSION`)."""
    if DESCRIPTOR_CODE_VERSION != 1:
        return f"greenloop descriptor code v{DESCRIPTOR_CODE_VERSION}".encode()
    path, digest = _STAMP_V1
    data = lzma.decompress(path.read_bytes())
    if hashlib.sha1(data).hexdigest() != digest:
        raise RuntimeError(f"{path} is damaged: its content is not the code stamp of descriptor keys v1")
    return data


def descriptor_key(name: str, frames, meta: dict) -> str:
    """Key "<name>-<16 hex>" of a descriptor of the frame files ``frames`` (Paths, in order): a sha1
    of each file's name, size and modification time, :func:`code_stamp` and the JSON of ``meta``
    (the settings: sorted keys, ``str`` for what JSON lacks)."""
    h = hashlib.sha1()
    for p in frames:
        st = p.stat()
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    h.update(code_stamp())
    h.update(json.dumps(meta, sort_keys=True, default=str).encode())
    return f"{name}-{h.hexdigest()[:16]}"


def descriptor_root(cache) -> Path | bool:
    """The folder of descriptor entries: cache True -> ``CACHE_DIR/descriptors``, a folder -> it,
    False -> False (not cached)."""
    if cache is True:
        return CACHE_DIR / DESCRIPTORS
    return Path(cache) if cache else False


def cached_descriptor(key: str, cache, fit):
    """:func:`cached` for one descriptor: fit() -> (X (N, D) float32, info dict, extra dict). Kept
    as ``features.npy``, ``info.json`` (info with the JSON-able extras under "extra") and
    ``extra.npz`` (the array extras, when any). cache: as :func:`descriptor_root`.
    Returns (X, info dict, extra dict)."""
    def save(folder: Path, result) -> None:
        X, info, extra = result
        np.save(folder / "features.npy", X)
        arrays = {k: v for k, v in extra.items() if isinstance(v, np.ndarray)}
        if arrays:
            np.savez(folder / "extra.npz", **arrays)
        meta = dict(info, extra={k: v for k, v in extra.items() if not isinstance(v, np.ndarray)})
        (folder / "info.json").write_text(json.dumps(meta, default=str))

    def load(folder: Path):
        info = json.loads((folder / "info.json").read_text())
        extra = dict(info.pop("extra"))
        if (folder / "extra.npz").is_file():
            extra.update(np.load(folder / "extra.npz"))
        return np.load(folder / "features.npy"), info, extra

    return cached(key, descriptor_root(cache), fit, save, load, marker="features.npy")


def cached_layers(key: str, cache, fit):
    """:func:`cached` for one pass of a network kept at several depths and poolings: fit() ->
    ({(depth, pooling): (N, D) float32}, info dict), kept as ``layers.npz`` (arrays named
    "depth-pooling") and ``info.json``. Returns what fit() returns."""
    def save(folder: Path, result) -> None:
        feats, info = result
        np.savez(folder / "layers.npz", **{f"{d}-{p}": X for (d, p), X in feats.items()})
        (folder / "info.json").write_text(json.dumps(info))

    def load(folder: Path):
        with np.load(folder / "layers.npz") as z:
            feats = {tuple(k.split("-")): z[k] for k in z.files}
        return feats, json.loads((folder / "info.json").read_text())

    return cached(key, descriptor_root(cache), fit, save, load, marker="layers.npz")


def model_key(model, **settings) -> str:
    """Hex key of a built Keras model: a sha1 of its configuration (layers and wiring, each name,
    which Keras numbers per process, replaced by its order of appearance), every weight's shape and
    bytes, its input shapes and ``settings`` (what else the cached result depends on: the converter's
    version and options). The same network built in another process gets the same key; any other
    weight or layer gets another."""
    config = model.get_config()
    text = json.dumps(config, sort_keys=True, default=str)
    for i, name in sorted(enumerate(_names(config)), key=lambda p: -len(p[1])):    # longest first
        text = text.replace(f'"{name}"', f'"#{i}"')
    h = hashlib.sha1(text.encode())
    for w in model.get_weights():
        h.update(str(w.shape).encode())
        h.update(np.ascontiguousarray(w).view(np.uint8))
    inputs = [[str(d) for d in t.shape] for t in model.inputs]
    h.update(json.dumps(dict(settings, inputs=inputs), sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def _names(config) -> list[str]:
    """The values of every "name" key in a nested Keras configuration, each once, in order."""
    out = []
    if isinstance(config, dict):
        if isinstance(config.get("name"), str):
            out.append(config["name"])
        for v in config.values():
            out += _names(v)
    elif isinstance(config, (list, tuple)):
        for v in config:
            out += _names(v)
    return list(dict.fromkeys(out))


def cached_graph(key: str, convert) -> bytes:
    """:func:`cached` for a converted network (a TFLite flatbuffer): convert() -> bytes, kept as
    ``graph.tflite`` under ``CACHE_DIR/graphs`` (key: :func:`model_key`), so that each network
    is converted once, not once per process. Returns the bytes."""
    return cached(key, CACHE_DIR / GRAPHS, convert, lambda folder, flat: (folder / "graph.tflite").write_bytes(flat),
                  lambda folder: (folder / "graph.tflite").read_bytes(), marker="graph.tflite")
