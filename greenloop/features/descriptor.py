"""Descriptors as objects: ``get(name, ...)`` -> a :class:`Descriptor`, the one way to describe frames.

A Descriptor knows its name, label, dimension D and weights, and maps frames to rows::

    d = features.get("mobilenetv2:random")            # or get("mobilenetv2", weights=None)
    X = d(frames)                                     # (N, H, W, 3) uint8 RGB -> (N, D) float32
    X = d(bgr_frames, color="bgr")                    # frames as cv2.imread decodes them
    X, info = d.describe("data/nordland", step=4)     # a sequence folder, cached on disk

Names are read by ``registry.parse`` (the grammar: ``<backbone>[@<depth>-<pooling>][:random|:imagenet]``),
weights by ``weights.resolve``, once, when the Descriptor is made; ``EXTRACTORS`` maps each
registry kind to its family's extractor (one protocol, ``registry.Options``).
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from greenloop.datasets import sequence
from greenloop.features import layers
from greenloop.features.cnn import CALIBRATION_KEY, extract_cnn
from greenloop.features.function import code_digest, extract_function
from greenloop.features.pixels import extract_gradients, extract_patchnorm, extract_pixels
from greenloop.features.registry import (BACKBONES, CNN_KINDS, DEFAULT_VOCAB_SIZE, FUSED_INT8, GRADIENT_BINS, GRADIENT_CELL,
                                         LAYER_CHANNELS, WEIGHT_TAGS, Backbone, ExtractInfo, Name, Options,
                                         input_size_of, layer_name, parse)
from greenloop.features.sift import extract_sift
from greenloop.features.spot import extract_spot, spot_dim
from greenloop.features.weights import resolve, Resolved, source_key
from greenloop.util import cache as _cache

EXTRACTORS = {**{kind: extract_cnn for kind in CNN_KINDS}, "pixels": extract_pixels,
              "pixels-patchnorm": extract_patchnorm, "gradients": extract_gradients,
              "sift_bovw": extract_sift, "spot_cnn": extract_spot, "fused": layers.extract_fused,
              "function": extract_function}


@dataclass(frozen=True, eq=False)
class Descriptor:
    """One whole-image descriptor, ready to describe frames (make it with :func:`get`).

    name: the name asked for ("mobilenetv2:random"). parsed: its ``registry.Name``. backbone: its
    registry record. weights: the weights asked for ('auto', 'imagenet', None, a path, a model).
    resolved: what they resolved to (label, source). input_size: (width, height) fed to it, None
    for the native size (sift_bovw, a function's) or the model's own (spot_cnn, layer descriptors
    choose theirs, ``layers.aspect_size``). vocabulary, vocab_size, seed: sift_bovw's (a fixed (k, 128)
    vocabulary, else one of vocab_size words fitted on the frames described, k-means seeded by seed).
    key_size: the input size as the cache keys write it.
    """
    name: str
    parsed: Name
    backbone: Backbone
    weights: Any
    resolved: Resolved
    input_size: tuple[int, int] | None
    vocabulary: np.ndarray | None = None
    vocab_size: int = DEFAULT_VOCAB_SIZE
    seed: int = 0
    key_size: Any = None

    @property
    def label(self) -> str:
        """"<name without suffix> (<weights label>)", e.g. "mobilenetv2 (random init)": for tables and legends."""
        return f"{self.parsed.base} ({self.resolved.label})"

    @property
    def dim(self) -> int:
        """D, the length of a row (sift_bovw: its vocabulary's words, fewer only when the frames hold
        fewer SIFT descriptors than vocab_size)."""
        b, n = self.backbone, self.parsed
        if n.depth is not None:
            return LAYER_CHANNELS[n.backbone][n.depth] * (4 if n.pooling == "grid2" else 1)
        if b.kind == "sift_bovw":
            return len(self.vocabulary) if self.vocabulary is not None else int(self.vocab_size)
        if b.kind == "spot_cnn":
            return spot_dim(self.resolved.source)
        if b.kind in ("pixels", "pixels-patchnorm"):
            return self.input_size[0] * self.input_size[1]
        if b.kind == "gradients":
            return (self.input_size[0] // GRADIENT_CELL) * (self.input_size[1] // GRADIENT_CELL) * GRADIENT_BINS
        return b.dim

    def __call__(self, frames, color: str = "rgb", batch_size: int = 32, progress: bool = False) -> np.ndarray:
        """Describe frames: (N, H, W, 3) uint8 RGB (color="bgr": BGR, as ``cv2.imread`` decodes),
        also (N, H, W[, 1]) single-channel or float in [0, 1]; or a sequence folder (decoded to RGB).
        Returns (N, D) float32, row i describing frame i."""
        return self.extract(frames, color=color, batch_size=batch_size, progress=progress)[0]

    def extract(self, frames_or_folder, step: int = 1, limit: int | None = None, batch_size: int = 32,
                progress: bool = False, color: str = "rgb") -> tuple[np.ndarray, ExtractInfo]:
        """:meth:`__call__` with every step-th frame (applied first), at most ``limit``, and what was
        done: (X (N, D) float32, ExtractInfo with the label, D, the input size and the seconds per
        frame of the timed pass, after an untimed warm-up batch)."""
        _check_run(batch_size, limit, step, color)
        if isinstance(frames_or_folder, (str, os.PathLike)):
            color = "rgb"                      # load_frames decodes a folder's files to RGB
        if self.parsed.depth is not None:
            return self._extract_layer(frames_or_folder, step, limit, batch_size, progress, color)
        b = self.backbone
        opt = Options(int(batch_size), progress, limit, int(step), self.vocabulary, self.vocab_size, self.seed, color)
        X, spi, extra = EXTRACTORS[b.kind](b, frames_or_folder, self.resolved.source, self.input_size, opt)
        X = np.ascontiguousarray(X, dtype=np.float32)
        return X, ExtractInfo(backbone=b.name, weights=self.resolved.label, dim=X.shape[1], n_images=len(X),
                              input_size=None if b.kind == "spot_cnn" else self.input_size, layer=b.layer,
                              seconds_per_image=float(spi), extra=extra)

    def _extract_layer(self, frames_or_folder, step, limit, batch_size, progress, color):
        """A layer descriptor: one depth and pooling of ``layers.extract_layers``."""
        n = self.parsed
        feats, li = layers.extract_layers(frames_or_folder, n.backbone, depths=(n.depth,), poolings=(n.pooling,),
                                          batch_size=batch_size, progress=progress, step=step, limit=limit,
                                          resolved=self.resolved, color=color)
        return self._layer_info(feats[(n.depth, n.pooling)], li)

    def _layer_info(self, X: np.ndarray, li: dict) -> tuple[np.ndarray, ExtractInfo]:
        """(X, ExtractInfo) of this layer descriptor from its rows X (N, D) and ``extract_layers``' info."""
        n = self.parsed
        w, h = map(int, li["input"].split("x"))
        return X, ExtractInfo(backbone=n.base, weights=li["weights"], dim=int(X.shape[1]), n_images=len(X),
                              input_size=(w, h), layer=f"{li['layers'][n.depth]}, {n.pooling} pooling",
                              seconds_per_image=float(li["seconds_per_image"]))

    def describe(self, folder, step: int = 1, cache=True, progress: bool = False) -> tuple[np.ndarray, ExtractInfo]:
        """Every step-th frame of a sequence folder, computed once per settings and kept on disk.

        cache: True (``$GREENLOOP_CACHE/descriptors``, default results/models/descriptors), a folder,
        or False. Entries are keyed (``util.cache.descriptor_key``) by the frames' names, sizes and
        modification times, the backbone, its weights file, input size, step, vocab_size and the
        descriptor code's version; a layer descriptor reads one cached pass of its network that keeps
        every depth and pooling; spot_cnn (the model is its key) is never cached. The info's
        seconds_per_image is the timing of the extraction that filled the cache.
        Returns (X (N, D) float32, ExtractInfo)."""
        if not cache or self.backbone.kind == "spot_cnn":
            return self.extract(folder, step=step, progress=progress)
        if self.parsed.depth is not None:
            return self._describe_layer(folder, step, cache)
        key = _cache.descriptor_key(self.backbone.name, sequence.list_frames(folder), self._key_meta(folder, step))

        def fit():
            X, info = self.extract(folder, step=step, progress=progress)
            return X, {k: v for k, v in vars(info).items() if k != "extra"}, info.extra
        X, info, extra = _cache.cached_descriptor(key, cache, fit)
        if info["input_size"] is not None:
            info["input_size"] = tuple(info["input_size"])
        return X, ExtractInfo(**info, extra=extra)

    def _describe_layer(self, folder, step: int, cache):
        """:meth:`describe` of a layer descriptor: one cached pass of its network at every depth and pooling."""
        name = self.parsed.backbone
        meta = _legacy_meta(BACKBONES[name], self.resolved.source, None, step, 0, folder)
        key = "layers-" + _cache.descriptor_key(name, sequence.list_frames(folder), meta)
        fit = lambda: layers.extract_layers(folder, name, progress=False, step=step, resolved=self.resolved)  # noqa: E731
        feats, li = _cache.cached_layers(key, cache, fit)
        return self._layer_info(feats[(self.parsed.depth, self.parsed.pooling)], li)

    def _key_meta(self, folder, step: int) -> dict:
        """The settings a cache key hashes: those keys always held, and only where a setting differs
        from what they always described, the size of a non-CNN, the SIFT vocabulary or seed, a
        registered function's code and the int8 graph's calibration set (so existing keys stay as they were)."""
        b = self.backbone
        meta = _legacy_meta(b, self.resolved.source, self.key_size, step, self.vocab_size, folder)
        if b.kind not in CNN_KINDS and self.input_size != b.input_size:
            meta["size"] = list(self.input_size)
        if b.kind == "sift_bovw" and self.vocabulary is not None:
            meta["vocabulary"] = hashlib.sha1(np.ascontiguousarray(self.vocabulary, np.float32)).hexdigest()
        if b.kind == "sift_bovw" and self.seed != 0:
            meta["seed"] = int(self.seed)
        if b.kind == "function":
            meta["code"] = code_digest(b.fn)
        if b.name == FUSED_INT8:
            meta["int8_calibration"] = CALIBRATION_KEY
        return meta


def _legacy_meta(b: Backbone, source, size, step: int, vocab_size: int, folder) -> dict:
    """The settings every descriptor key has hashed (in this form, so that the keys stay put)."""
    import keras
    size = size if b.kind in CNN_KINDS and not b.fixed_input else None
    return dict(backbone=b.name, source=source_key(source) if source is not None else None, input_size=size,
                step=int(step), vocab_size=int(vocab_size) if b.kind == "sift_bovw" else None,
                folder=str(Path(folder).resolve()), keras=keras.__version__)


def _check_run(batch_size, limit, step, color) -> None:
    """ValueError for a bad batch size, limit, step or channel order."""
    if int(batch_size) < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    if limit is not None and limit < 1:
        raise ValueError(f"limit must be >= 1, got {limit}")
    if int(step) != step or step < 1:
        raise ValueError(f"step must be an integer >= 1, got {step}")
    if color not in ("rgb", "bgr"):
        raise ValueError(f"color must be 'rgb' or 'bgr', got {color!r}")


def get(name: str, weights="auto", *, input_size=None, cnn_input_size=None, layer: str | None = None,
        pooling: str | None = None, vocabulary=None, vocab_size: int = DEFAULT_VOCAB_SIZE, seed: int = 0,
        warn: bool = True) -> Descriptor:
    """The descriptor called ``name``: the one way to get one.

    name: a registry name (``registry.names()``): a BACKBONES key ("pixels", "sift_bovw",
        "mobilenetv2", "gradients+efficientnetlite0", ...) or a layer descriptor
        "backbone@depth-pooling", with an optional ":random" (weights None) or ":imagenet" suffix.
    weights: 'auto' | 'imagenet' | None | a file path (CNNs, see the package doc); spot_cnn: the
        trained keras Model or its .keras path; the weight-free descriptors take 'auto' or None.
    input_size: int S (S x S) or (width, height) fed to it; None: the registry's default (224x224
        for the CNNs, 32x32 pixels, 128x64 gradients, native for sift_bovw). The fixed-input networks
        (mobilenetv1/v2, vgg19_fc1) and the layer descriptors refuse another.
    cnn_input_size: a study-wide CNN input (the notebooks' ``input_size``): applied to the CNNs whose
        input is not fixed, ignored by every other descriptor.
    layer, pooling: a layer descriptor by keywords: get("mobilenetv2", layer="mid", pooling="grid2")
        is get("mobilenetv2@mid-grid2").
    vocabulary, vocab_size, seed: sift_bovw only (:class:`Descriptor`).
    warn: a UserWarning when weights='auto' finds no ImageNet file and falls back to a random-init network.
    Raises ValueError for an unknown name (listing the valid ones) or settings it cannot take,
    FileNotFoundError / WeightsNotFoundError for missing weights.
    """
    n = parse(name)
    if layer is not None or pooling is not None:
        if n.depth is not None:
            raise ValueError(f"{name!r} already names its layer: leave layer= and pooling= out")
        n = parse(layer_name(n.backbone, layer, pooling or "avg") + (":" + n.tag if n.tag else ""))
    w = weights if not n.tag else WEIGHT_TAGS[n.tag]
    b = BACKBONES[n.backbone]
    size_arg = input_size if input_size is not None else (
        cnn_input_size if b.kind in CNN_KINDS and not b.fixed_input and n.depth is None else None)
    size = _input_size(b, n, size_arg)
    resolved = resolve(b.name, w, warn)
    if vocabulary is not None:
        vocabulary = np.asarray(vocabulary, dtype=np.float32)
    return Descriptor(name, n, b, w, resolved, size, vocabulary, vocab_size, seed, size_arg)


def _input_size(b: Backbone, n: Name, size_arg):
    """The (width, height) a descriptor is fed (None: native / its own), checked against what it takes."""
    if n.depth is not None:
        if size_arg is not None:
            raise ValueError(f"{n.base} chooses its own input (224 pixels wide, aspect kept where the network "
                             f"allows it: greenloop.features.layers): pass input_size=None")
        return None
    size = input_size_of(size_arg, b.input_size)
    if b.fixed_input and size != b.input_size:
        why = ("its fully connected layer takes the 7x7 map of a 224x224 input" if b.top_layer
               else "the TFLite graph's; its random-init control uses the same")
        raise ValueError(f"{b.name} runs at its fixed {b.input_size[0]}x{b.input_size[1]} input "
                         f"({why}), got input_size={size_arg!r}: pass input_size=None")
    if b.kind in CNN_KINDS and min(size) < 32:
        raise ValueError(f"{b.name} needs an input of at least 32x32 pixels, got {size}")
    return size
