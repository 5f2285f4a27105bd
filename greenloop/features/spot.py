"""The spot_cnn extractor: the penultimate layer of the main paper's trained CNN (greenloop.methods.dictionary.cnn.build).

``extract_spot`` follows the extractor protocol (``registry.Options``); the input size is the
model's own, whatever ``size`` says.
"""
from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from greenloop.datasets import sequence
from greenloop.features.cnn import run_model
from greenloop.features.frames import gray_batch, load, rgb_batch
from greenloop.features.registry import Backbone, Options


@functools.lru_cache(maxsize=2)
def _spot_model(path: str, mtime):
    import keras
    if not path.endswith(".keras"):
        raise ValueError(f"spot_cnn weights must be a .keras model file saved from "
                         f"greenloop.methods.dictionary.cnn.build (got {path})")
    try:
        return keras.models.load_model(path, compile=False)
    except Exception as e:
        raise ValueError(f"cannot load the spot_cnn model {path}: {e}") from e


def spot_feature_model(model):
    """The sub-model of a main-paper CNN that outputs its penultimate layer.

    model: a keras Model of greenloop.methods.dictionary.cnn.build (Conv2D -> Flatten -> Dense(68, relu) ->
    Dense(n, softmax)). Returns a Model from the same inputs to the input of the last Dense layer,
    i.e. the (N, 68) Dense-68 ReLU activations. Raises ValueError if the model has no Dense layer
    or was never built.
    """
    import keras
    dense = [l for l in model.layers if isinstance(l, keras.layers.Dense)]
    if not dense:
        raise ValueError(f"model {model.name} has no Dense layer: spot_cnn expects the main paper's "
                         f"CNN (Conv2D -> Flatten -> Dense(68) -> Dense(n, softmax))")
    try:
        inputs = model.inputs
        inputs = inputs[0] if len(inputs) == 1 else inputs
        feat = dense[-1].input
    except (AttributeError, ValueError) as e:
        raise ValueError(f"model {model.name} has not been built (call it on data or give it an "
                         f"Input) so its penultimate layer is undefined: {e}") from e
    return keras.Model(inputs, feat, name=f"{model.name}_penultimate")


def extract_spot(b: Backbone, frames_or_folder, source, size, opt: Options):
    """The spot_cnn extractor: frames -> (features (N, 68) float32, s/image, {})."""
    limit, step = opt.limit, opt.step
    model = source if not isinstance(source, Path) else _spot_model(
        str(source.resolve()), source.stat().st_mtime_ns)
    feat_model = spot_feature_model(model)
    shape = tuple(model.inputs[0].shape[1:])
    if len(shape) != 3 or shape[-1] not in (1, 3) or None in shape[:2]:
        raise ValueError(f"spot_cnn model input must be (H, W, 1) or (H, W, 3), got {shape}")
    size, channels = (shape[1], shape[0]), shape[-1]
    if isinstance(frames_or_folder, (str, os.PathLike)):
        a = sequence.load_frames(frames_or_folder, size=size, gray=channels == 1, limit=limit,
                                 dtype=np.uint8, progress=opt.progress, step=step)
    else:
        a = load(frames_or_folder, size, True, limit, step)

    def batch(x):
        if channels == 1:
            return gray_batch(x, size, as_float=True, color=opt.color)[..., None]
        return rgb_batch(x, size, opt.color) / np.float32(255.0)

    return (*run_model(feat_model.predict_on_batch, a, batch, opt.batch_size, opt.progress,
                        "spot_cnn features"), {})


def spot_dim(source) -> int:
    """D of spot_cnn for its resolved source (a keras Model or the Path of a .keras file): the
    units of the model's penultimate layer (68 for greenloop.methods.dictionary.cnn.build)."""
    model = source if not isinstance(source, Path) else _spot_model(str(source.resolve()), source.stat().st_mtime_ns)
    return int(spot_feature_model(model).outputs[0].shape[-1])
