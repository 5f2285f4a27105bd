"""A study's descriptors, once per dataset (notebooks 07, 08, 11 and 13 share them): ``extract_all``
and its on-disk descriptor cache."""
from __future__ import annotations

import contextlib
import hashlib
import json
import warnings
from pathlib import Path

import numpy as np

from greenloop.backbones import efficientnet_lite as _lite
from greenloop.backbones import ghostnet as _ghostnet
from greenloop.backbones import mobilenet_tflite as _tflite
from greenloop.backbones import shufflenet as _shufflenet
from greenloop.backbones import torch_weights as _torch_weights
from greenloop.datasets import sequence
from greenloop.features import layers
from greenloop.features.extraction import clear_cache, extract_spec
from greenloop.features.registry import (BACKBONES, CNN_KINDS, DEFAULT_VOCAB_SIZE, ExtractInfo,
                                         split_spec)
from greenloop.features.weights import resolve, source_key
from greenloop.util import cache as _cache

# the modules whose code decides a descriptor: a change to any of them gives new cache keys
_DESCRIPTOR_CODE = (*sorted(str(p) for p in Path(__file__).parent.glob("*.py")), sequence.__file__,
                    _ghostnet.__file__, _shufflenet.__file__, _tflite.__file__, _lite.__file__,
                    _torch_weights.__file__)


@contextlib.contextmanager
def random_init_reported(name: str, weights="auto", resolved=None):
    """Context for an extraction a notebook shows: where ``weights="auto"`` finds no ImageNet
    weights for backbone ``name``, print that in one line (no file paths), and keep the
    UserWarning that says the same with a path into the package out of the notebook.
    resolved: the pair's ``weights.resolve`` result when the caller has it (not resolved again)."""
    if weights == "auto" and (resolved or resolve(name, weights, warn=False)).label == "random init":
        print(f"{name}: no ImageNet weights on this machine, so its row is a RANDOM-INITIALISED "
              f"network (docs/weights.md says where the files go)")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*RANDOM-INITIALISED", category=UserWarning)
        yield


def extract_all(folder, specs, weights="auto", input_size=None, step: int = 1,
                vocab_size: int = DEFAULT_VOCAB_SIZE, spot_model=None, cache=True):
    """Descriptors of one sequence folder for every backbone-list entry, computed once per dataset.

    folder: a sequence folder. specs: backbone-list entries (:func:`split_spec`, e.g.
    ``["pixels", "mobilenetv2", "mobilenetv2:random"]``). weights, input_size: as
    :func:`extract_spec`. step: every step-th frame. vocab_size: sift_bovw's words.
    spot_model: the trained keras Model for a "spot_cnn" entry (never cached: the model is the key).
    cache: True (results/models/descriptors or $GREENLOOP_CACHE/descriptors), a folder, or False.
        Entries are keyed by the frames' names, sizes and modification times, the backbone, its
        weights file, input size, step, vocab_size and the code of the modules that compute
        descriptors, so a notebook reuses what another computed with the same settings; the
        info's seconds_per_image is the timing of the extraction that filled the cache.
    Prints one line per entry (label, D, ms/image). A missing ImageNet file is reported in one
    line (the random-init fallback of weights="auto"; docs/weights.md says where files go).
    Returns (feats {spec: (N, D) float32}, infos {spec: ExtractInfo}).
    """
    root = Path(cache) if cache not in (True, False) else _cache.CACHE_DIR / "descriptors"
    feats, infos = {}, {}
    for spec in specs:
        name, w = split_spec(spec, spot_model if spec == "spot_cnn" else weights)
        layer = layers.split(name)                # "backbone@depth-pooling": one cached pass per network
        resolved = resolve(layer[0] if layer else name, w, warn=False)   # once per entry, passed on
        kw = dict(return_info=True, progress=False, step=step, vocab_size=vocab_size,
                  resolved=resolved)

        def run(spec=spec, w=w, kw=kw):
            return extract_spec(folder, name, w, input_size, **kw)
        with random_init_reported(name, w, resolved):
            if layer:
                X, info = _layer_entry(folder, name, resolved, step, root if cache else False)
            elif spec == "spot_cnn" or not cache:
                X, info = run()
            else:
                key = _descriptor_key(folder, name, resolved.source, input_size, step, vocab_size)
                X, info = _cache.cached(key, root, run, _save_descriptors, _load_descriptors,
                                        marker="features.npy")
        feats[spec], infos[spec] = X, info
        print(f"{info.label:42s} D={info.dim:5d}  {info.seconds_per_image * 1e3:8.2f} ms/image")
    clear_cache()
    return feats, infos


def _layer_entry(folder, name: str, resolved, step: int, root):
    """(X, info) of layer descriptor ``name`` from one cached pass of its network over the folder
    that keeps every depth and pooling of ``layers.extract_layers`` (root False: not cached)."""
    backbone, _, _ = layers.split(name)
    key = "layers-" + _descriptor_key(folder, backbone, resolved.source, None, step, 0)

    def save(path: Path, result) -> None:
        feats, li = result
        np.savez(path / "layers.npz", **{f"{d}-{p}": X for (d, p), X in feats.items()})
        (path / "info.json").write_text(json.dumps(li))

    def load(path: Path):
        with np.load(path / "layers.npz") as z:
            feats = {tuple(k.split("-")): z[k] for k in z.files}
        return feats, json.loads((path / "info.json").read_text())

    feats, li = _cache.cached(key, root, lambda: layers.extract_layers(folder, backbone, progress=False, step=step,
                                                                        resolved=resolved),
                              save, load, marker="layers.npz")
    X = feats[layers.split(name)[1:]]
    return X, layers.info(name, li, X)


def _descriptor_key(folder, name, source, input_size, step, vocab_size) -> str:
    """Hex key of one extract_all() entry (see there for what it covers); source: the entry's
    ``weights.resolve(...).source``."""
    import keras

    b = BACKBONES[name]
    h = hashlib.sha1()
    for p in sequence.list_frames(folder):
        st = p.stat()
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    for path in _DESCRIPTOR_CODE:
        h.update(Path(path).read_bytes())
    size = input_size if b.kind in CNN_KINDS and not b.fixed_input else None
    meta = dict(backbone=name, source=source_key(source) if source is not None else None,
                input_size=size, step=int(step), vocab_size=int(vocab_size) if b.kind == "sift_bovw"
                else None, folder=str(Path(folder).resolve()), keras=keras.__version__)
    h.update(json.dumps(meta, sort_keys=True, default=str).encode())
    return f"{name}-{h.hexdigest()[:16]}"


def _save_descriptors(folder: Path, result) -> None:
    X, info = result
    np.save(folder / "features.npy", X)
    extra = {k: v for k, v in info.extra.items() if isinstance(v, np.ndarray)}
    if extra:
        np.savez(folder / "extra.npz", **extra)
    meta = {k: v for k, v in vars(info).items() if k != "extra"}
    meta["extra"] = {k: v for k, v in info.extra.items() if not isinstance(v, np.ndarray)}
    (folder / "info.json").write_text(json.dumps(meta, default=str))


def _load_descriptors(folder: Path):
    meta = json.loads((folder / "info.json").read_text())
    extra = dict(meta.pop("extra"))
    if (folder / "extra.npz").is_file():
        extra.update(np.load(folder / "extra.npz"))
    if meta["input_size"] is not None:
        meta["input_size"] = tuple(meta["input_size"])
    return np.load(folder / "features.npy"), ExtractInfo(**meta, extra=extra)
