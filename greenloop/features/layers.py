"""CNN descriptors layer by layer: an early, a mid-level and the last feature map of a network,
each pooled globally or over a spatial grid.

Sünderhauf et al. (2015) found mid-level convolutional layers, which keep the image's layout, the
most robust to appearance change for place recognition; ``features.get(network)`` reads only the last
map, averaged over the whole image. ``extract_layers`` reads three depths of one forward pass
(``LAYERS``) and pools each map (N, h, w, C) in three ways (``POOLINGS``):

    avg     global average pooling                                   D = C
    grid2   2 x 2 cells, each averaged and L2-normalised, concatenated D = 4 C
    gem     generalised mean, p = 3 (Radenović et al. 2018), of the   D = C
            values clipped at 1e-6 (the linear bottleneck outputs of
            MobileNet v2 and EfficientNet-Lite0 can be negative)

Depths (``LAYERS``: TFLite tensor for the ImageNet graphs, Keras layer for the random-init control
and the Keras ports), at a 224 x 224 input::

    backbone           early                    mid                       last
    mobilenetv1        Conv2d_5_pointwise       Conv2d_11_pointwise       Conv2d_13_pointwise
                       28 x 28 x 256            14 x 14 x 512             7 x 7 x 1024
    mobilenetv2        expanded_conv_5 (add)    expanded_conv_12 (add)    Conv_1
                       28 x 28 x 32             14 x 14 x 96              7 x 7 x 1280
    efficientnetlite0  block 4 (add)            block 10 (add)            head (1x1 conv, ReLU6)
                       28 x 28 x 40             14 x 14 x 112             7 x 7 x 1280

Input: the TFLite MobileNets take only 224 x 224, so their frames are stretched to it (as in
``features.extract``). EfficientNet-Lite0 takes any size: with ``aspect=True`` frames keep their
aspect ratio, 224 pixels wide and a multiple of 16 high (:func:`aspect_size`; Nordland's 64 x 32
frames become 224 x 112, not 224 x 224).

``extract_fused`` is the descriptor of greenloop-seq's named CNN configuration,
"gradients+efficientnetlite0": the gradient histograms beside EfficientNet-Lite0's mid map pooled
over the 2 x 2 grid, from frames ``registry.FUSED_WIDTH`` pixels wide (aspect kept).
"""
from __future__ import annotations

import functools
import time

import numpy as np

from greenloop.backbones import mobilenet_tflite as _tflite
from greenloop.datasets import sequence
from greenloop.features.cnn import _cnn_model, _preprocess_fn, _tflite_interpreter, int8_calibration_frames, predictor, run_model
from greenloop.features.frames import load, rgb_batch
from greenloop.features.pixels import extract_gradients
from greenloop.features.registry import (BACKBONES, DEPTHS, FUSED_CNN, FUSED_INT8, FUSED_WIDTH, GRADIENT_SIZE, POOLINGS, Options,
                                         get_backbone, layer_name, parse)
from greenloop.features.weights import resolve, Resolved, source_key
from greenloop.similarity import l2_normalise

GEM_P = 3.0
_V1, _V2 = "MobilenetV1/MobilenetV1/", "MobilenetV2/"
# backbone -> depth -> (TFLite tensor of the ImageNet graph, Keras layer of the same depth)
LAYERS = {
    "mobilenetv1": {"early": (_V1 + "Conv2d_5_pointwise/Relu6", "conv_pw_5_relu"),
                    "mid": (_V1 + "Conv2d_11_pointwise/Relu6", "conv_pw_11_relu"),
                    "last": (_V1 + "Conv2d_13_pointwise/Relu6", "conv_pw_13_relu")},
    "mobilenetv2": {"early": (_V2 + "expanded_conv_5/add", "block_5_add"),
                    "mid": (_V2 + "expanded_conv_12/add", "block_12_add"),
                    "last": (_V2 + "Conv_1/Relu6", "out_relu")},
    "efficientnetlite0": {"early": (None, "_blocks__4___add"), "mid": (None, "_blocks__10___add"),
                          "last": (None, "_bn1_relu6")},
}


def specs(backbones, depths=DEPTHS, poolings=POOLINGS) -> list[str]:
    """Every layer descriptor name of the descriptor-list entries ``backbones`` (a ``:random`` /
    ``:imagenet`` suffix carries over), depth by depth: ``specs(["mobilenetv2"], ["mid"])`` is
    ["mobilenetv2@mid-avg", "mobilenetv2@mid-grid2", "mobilenetv2@mid-gem"]."""
    out = []
    for b in backbones:
        n = parse(b)
        out += [layer_name(n.backbone, d, p) + (":" + n.tag if n.tag else "") for d in depths for p in poolings]
    return out


def aspect_size(width: int, height: int, target: int = 224, multiple: int = 16) -> tuple[int, int]:
    """(target, h): a frame width x height (pixels) scaled to ``target`` pixels wide, its height
    rounded (half up) to a multiple of ``multiple`` (at least one)."""
    h = max(multiple, int(target * height / width / multiple + 0.5) * multiple)
    return target, h


def pool(fmap: np.ndarray, how: str) -> np.ndarray:
    """Pool feature maps fmap (N, h, w, C) float32 into descriptors (N, D) float32, D as
    ``POOLINGS`` says (grid2 needs h, w >= 2)."""
    fmap = np.asarray(fmap, dtype=np.float32)
    if how == "avg":
        return fmap.mean(axis=(1, 2), dtype=np.float32)
    if how == "gem":
        x = np.maximum(fmap, np.float32(1e-6)) ** np.float32(GEM_P)
        return x.mean(axis=(1, 2), dtype=np.float32) ** np.float32(1.0 / GEM_P)
    if how == "grid2":
        n, h, w, _ = fmap.shape
        if h < 2 or w < 2:
            raise ValueError(f"grid2 pooling needs a map of at least 2 x 2, got {h} x {w}")
        cells = [fmap[:, r, c].mean(axis=(1, 2), dtype=np.float32)
                 for r in (slice(0, h // 2), slice(h // 2, h)) for c in (slice(0, w // 2), slice(w // 2, w))]
        cells = [v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), np.float32(1e-12)) for v in cells]
        return np.concatenate(cells, axis=1).astype(np.float32)
    raise ValueError(f"pooling must be one of {POOLINGS}, got {how!r}")


@functools.lru_cache(maxsize=4)
def _keras_layers(name: str, key, size: tuple[int, int], layers: tuple[str, ...]):
    """A Keras model frames (N, h, w, 3) -> [maps of ``layers``] of backbone ``name``."""
    import keras
    model = _cnn_model(name, key, size)
    return keras.Model(model.inputs, [model.get_layer(n).output for n in layers])


def _pooled(maps: list, poolings) -> np.ndarray:
    """Every map pooled every way, concatenated (N, sum of D) float32 (split again by the caller)."""
    return np.concatenate([pool(m, p) for m in maps for p in poolings], axis=1)


def extract_layers(frames_or_folder, backbone: str, weights="auto", depths=DEPTHS, poolings=POOLINGS,
                   aspect: bool = True, batch_size: int = 32, progress: bool = True, step: int = 1,
                   limit: int | None = None, resolved=None, width: int = 224, color: str = "rgb",
                   int8: bool = False) -> tuple[dict, dict]:
    """Descriptors of every frame at several depths of one network, one forward pass.

    frames_or_folder: a sequence folder or (N, H, W, 3) RGB frames (as ``Descriptor.extract``).
    backbone: a key of ``LAYERS``; weights: as ``features.get`` (the TFLite graphs for the
    ImageNet MobileNets, their Keras architecture with weights=None). depths: keys of
    LAYERS[backbone]; poolings: of ``POOLINGS``. aspect: keep the frames' aspect ratio where the
    network allows it (:func:`aspect_size`, ``width`` pixels wide). step, limit, resolved, color (of a
    frame array: "rgb", or "bgr" as ``cv2.imread`` decodes): as ``Descriptor.extract``. int8: run a
    Keras-built network (EfficientNet-Lite0) as its full-integer int8 TFLite graph, calibrated on
    ``cnn.int8_calibration_frames`` (``cnn.keras_predict``); ValueError for the TFLite MobileNets.
    Returns (feats, info): feats {(depth, pooling): (N, D) float32}; info {'weights': label,
    'input': 'WxH', 'layers': {depth: layer name}, 'seconds_per_image': wall s per frame of the
    whole forward pass and pooling}.
    """
    if backbone not in LAYERS:
        raise ValueError(f"layer descriptors exist for {sorted(LAYERS)}, not {backbone!r}")
    bad = [d for d in depths if d not in LAYERS[backbone]] + [p for p in poolings if p not in POOLINGS]
    if bad or not depths or not poolings:
        raise ValueError(f"depths must be of {DEPTHS} and poolings of {POOLINGS}, got {depths}, {poolings}")
    b = get_backbone(backbone)
    label, source = resolved if resolved is not None else resolve(b.name, weights)
    key = source_key(source)
    tflite = b.kind == "tflite" and source is not None
    size = b.input_size
    if aspect and not b.fixed_input:
        if isinstance(frames_or_folder, (str, bytes)) or hasattr(frames_or_folder, "__fspath__"):
            meta = sequence.folder_info(frames_or_folder)
            w, h = meta["width"], meta["height"]
        else:
            h, w = np.asarray(frames_or_folder).shape[1:3]
        size = aspect_size(w, h, width)
    frames = load(frames_or_folder, size, gray=False, limit=limit, step=step)
    names = [LAYERS[backbone][d][0 if tflite else 1] for d in depths]
    if int8 and tflite:
        raise ValueError(f"int8 runs a Keras-built network as an int8 graph; {b.name}'s ImageNet graph is a uint8 TFLite file already")
    predict, batch_fn, warm_key = _predictor(b, key, size, tflite, names, poolings, color, int8)
    X, spi = run_model(predict, frames, batch_fn, batch_size, progress, f"{b.name} layers", warm_key)
    feats, at = {}, 0
    for d, c in zip(depths, _channels(b.name, key, size, tflite, names)):
        for p in poolings:
            D = c * (4 if p == "grid2" else 1)
            feats[(d, p)] = np.ascontiguousarray(X[:, at:at + D])
            at += D
    return feats, {"weights": label, "input": f"{size[0]}x{size[1]}", "seconds_per_image": spi,
                   "layers": dict(zip(depths, names))}


def _predictor(b, key, size, tflite: bool, names, poolings, color: str = "rgb", int8: bool = False):
    """(predict, batch_fn, warm_key) for ``cnn.run_model``: a batch of frames -> every named map pooled
    every way, concatenated (N, sum of D); the TFLite graph's interpreter or the Keras model's outputs
    (``cnn.predictor``: EfficientNet-Lite's runs as a TFLite graph converted from it, int8: its full-integer
    int8 graph calibrated on ``cnn.int8_calibration_frames`` at this input size);
    warm_key names the traced graph (run_model warms each batch length of it up once)."""
    if tflite:
        def predict(rgb):
            interp, used = _tflite_interpreter(b.name, key, len(rgb))
            out = _tflite.run(interp, used, rgb, names)
            return _pooled([out[n] for n in names], poolings)
        return predict, lambda a: rgb_batch(a, size, color), ("tflite", b.name, key)
    model, pre = _keras_layers(b.name, key, size, tuple(names)), _preprocess_fn(b)
    run = _int8_runner(b.name, key, size, tuple(names)) if int8 else predictor(b, model)

    def predict(x):
        maps = run(x)
        return _pooled([np.asarray(m) for m in (maps if isinstance(maps, (list, tuple)) else [maps])], poolings)
    return predict, lambda a: pre(rgb_batch(a, size, color)), ("keras", id(model), int8)


@functools.lru_cache(maxsize=4)
def _int8_runner(name: str, key, size: tuple[int, int], layers: tuple[str, ...]):
    """``cnn.predictor`` of :func:`_keras_layers`' model as its int8 graph, calibrated on
    ``cnn.int8_calibration_frames`` at ``size``: made once per model, so that a stream describing one
    frame per call neither prepares nor hashes the calibration set again."""
    b = BACKBONES[name]
    return predictor(b, _keras_layers(name, key, size, layers), _preprocess_fn(b)(rgb_batch(int8_calibration_frames(), size)))


def _channels(name, key, size, tflite: bool, names) -> list[int]:
    """The channel count C of each named map (TFLite tensor or Keras layer)."""
    if tflite:
        interp, _ = _tflite_interpreter(name, key, 1)
        return [int(_tflite.tensor_detail(interp, n)["shape"][-1]) for n in names]
    return [int(o.shape[-1]) for o in _keras_layers(name, key, size, tuple(names)).outputs]


def extract_fused(b, frames_or_folder, source, size, opt: Options):
    """'gradients+efficientnetlite0' and its int8 form ``FUSED_INT8`` (the CNN part from the full-integer
    int8 graph, ``extract_layers(int8=True)``) (the extractor protocol, ``registry.Options``): each frame's
    gradients (``pixels.gradient_histograms``, 256-d) beside EfficientNet-Lite0's block-10 map pooled
    over 2 x 2 cells (:func:`extract_layers` at ``FUSED_WIDTH`` pixels wide, aspect kept, 448-d),
    each part L2-normalised: (N, 704) float32, so that the cosine of two frames weighs both parts
    alike, and ``seqmatch.shift_cells`` finds the gradient grid in the first 256 dims.
    source: the CNN part's ImageNet weights (``weights.resolve`` refuses a random-init fallback).
    Returns (X, seconds per image of both parts, {})."""
    if source is None:
        raise ValueError(f"{b.name} needs ImageNet weights for its CNN part, not a random-init network")
    t0 = time.perf_counter()
    G, _, _ = extract_gradients(BACKBONES["gradients"], frames_or_folder, None, GRADIENT_SIZE, opt)
    backbone, depth, pooling = FUSED_CNN
    feats, _ = extract_layers(frames_or_folder, backbone, depths=(depth,), poolings=(pooling,), batch_size=opt.batch_size,
                              progress=opt.progress, step=opt.step, limit=opt.limit,
                              resolved=Resolved("imagenet", source), width=FUSED_WIDTH, color=opt.color,
                              int8=b.name == FUSED_INT8)
    X = np.hstack([l2_normalise(G), l2_normalise(feats[(depth, pooling)])]).astype(np.float32)
    return X, (time.perf_counter() - t0) / max(len(X), 1), {}
