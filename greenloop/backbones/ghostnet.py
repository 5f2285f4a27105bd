"""GhostNet 1.0x (Han et al., CVPR 2020) in Keras 3, weight-compatible with timm's ``ghostnet_100``.

The Qi et al. 2024 greenhouse study found GhostNet the best feature extractor for loop closure
detection, but Keras ships no GhostNet. This module rebuilds timm's ``ghostnet_100`` layer for layer
(Keras 3 API only: it runs on the TensorFlow, JAX or PyTorch backend) so that timm's ImageNet weights
load into it without torch at run time.

Layer names are timm's module paths with ``.`` written ``__`` (Keras's torch backend forbids dots):
the Keras layer ``blocks__3__0__se__conv_reduce`` holds timm's ``blocks.3.0.se.conv_reduce.weight``
and ``.bias`` (``keras_layer_name`` / ``timm_module_path`` convert). The mapping is systematic, and
``export_timm_state_dict`` / ``load_timm_weights`` are exact inverses. Differences from Keras
defaults that matter for exactness, all handled here: BatchNorm eps is 1e-5 (torch) not 1e-3;
convolutions pad ``(k - 1) // 2`` on every side like torch (explicit ``ZeroPadding2D`` + ``'valid'``,
since Keras ``'same'`` pads stride-2 layers asymmetrically); SE gates are hard sigmoids
(``relu6(x + 3) / 6``) with ``make_divisible(channels * 0.25, 4)`` reduced channels; a Ghost module
keeps the first ``out`` channels of ``concat(primary, cheap)``.

Descriptor for loop closure (what ``greenloop.features`` uses): the output of ``blocks.9`` (the 1x1
ConvBnAct 160 -> 960 with ReLU, the last feature map, 7x7 at 224x224 input), global-average-pooled
to **960** values. That is timm's ``forward_features`` + pooling (``num_features == 960``), i.e. the
pooled features *before* ``conv_head`` (960 -> 1280) and the classifier.

Getting the ImageNet weights (about 21 MB), on any machine with internet::

    huggingface-cli download timm/ghostnet_100.in1k model.safetensors --local-dir .
    mv model.safetensors ~/.keras/models/ghostnet_100.in1k.safetensors

i.e. place the file as ``$KERAS_HOME/models/ghostnet_100.in1k.safetensors`` (``KERAS_HOME``
defaults to ``~/.keras``), the same folder Keras caches its own ImageNet weights in
(``default_weights_path()`` gives the exact path). Input preprocessing is timm's: RGB scaled to
[0, 1], then ImageNet mean/std normalisation (``preprocess_input``).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from greenloop.backbones import torch_weights as _tw

TIMM_NAME = "ghostnet_100"
WEIGHTS_FILENAME = "ghostnet_100.in1k.safetensors"
NUM_FEATURES = 960       # pooled descriptor width (blocks.9 output)
HEAD_FEATURES = 1280     # conv_head width (only with include_top=True)
N_TIMM_TENSORS = 512     # tensors in timm's state_dict (incl. BatchNorm num_batches_tracked)
N_TIMM_PARAMS = 5_182_508  # trainable parameters of the full model with a 1000-class classifier
BN_EPS = 1e-5            # torch BatchNorm2d default
IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)

# timm's _create_ghostnet table, one list per stage: (kernel, expansion (mid) chs, out chs, SE ratio,
# stride). Stage i becomes timm's ``blocks.i``; ``blocks.9`` is the final 1x1 ConvBnAct.
CFGS = (
    ((3, 16, 16, 0.0, 1),),
    ((3, 48, 24, 0.0, 2),),
    ((3, 72, 24, 0.0, 1),),
    ((5, 72, 40, 0.25, 2),),
    ((5, 120, 40, 0.25, 1),),
    ((3, 240, 80, 0.0, 2),),
    ((3, 200, 80, 0.0, 1), (3, 184, 80, 0.0, 1), (3, 184, 80, 0.0, 1),
     (3, 480, 112, 0.25, 1), (3, 672, 112, 0.25, 1)),
    ((5, 672, 160, 0.25, 2),),
    ((5, 960, 160, 0.0, 1), (5, 960, 160, 0.25, 1), (5, 960, 160, 0.0, 1), (5, 960, 160, 0.25, 1)),
)


def make_divisible(v: float, divisor: int = 4, min_value: int | None = None,
                   round_limit: float = 0.9) -> int:
    """timm's channel rounding: nearest multiple of ``divisor``, never below ``round_limit * v``."""
    min_value = min_value or divisor
    new_v = max(min_value, int(v + divisor / 2) // divisor * divisor)
    if new_v < round_limit * v:
        new_v += divisor
    return new_v


def keras_models_dir() -> Path:
    """Folder where Keras caches downloaded weights: ``$KERAS_HOME/models`` (default ``~/.keras/models``;
    ``/tmp/.keras/models`` when the home folder is not writable, as Keras itself does)."""
    if "KERAS_HOME" in os.environ:
        return Path(os.environ["KERAS_HOME"]).expanduser() / "models"
    home = os.path.expanduser("~")
    base = home if os.access(home, os.W_OK) else "/tmp"
    return Path(base) / ".keras" / "models"


def default_weights_path() -> Path:
    """Where greenloop looks for timm's ImageNet GhostNet weights:
    ``$KERAS_HOME/models/ghostnet_100.in1k.safetensors``."""
    return keras_models_dir() / WEIGHTS_FILENAME


def preprocess_input(x):
    """timm's preprocessing for ghostnet_100.

    x: RGB images, float or uint8 in 0..255, shape (..., 3) channels-last.
    Returns float32 ``(x / 255 - mean) / std`` with the ImageNet mean/std, same shape.
    """
    x = np.asarray(x, dtype=np.float32)
    return (x / np.float32(255.0) - IMAGENET_MEAN) / IMAGENET_STD


# --------------------------------------------------------------------------------------------
# model
# --------------------------------------------------------------------------------------------

def keras_layer_name(timm_path: str) -> str:
    """Keras layer name of a timm module path: dots become double underscores
    (``blocks.3.0.se.conv_reduce`` -> ``blocks__3__0__se__conv_reduce``). Keras's torch backend
    forbids dots in names, and timm paths never contain ``__``, so the mapping is reversible
    (``greenloop.backbones.torch_weights.keras_layer_name``)."""
    return _tw.keras_layer_name(timm_path)


def timm_module_path(keras_name: str) -> str:
    """Inverse of ``keras_layer_name``."""
    return _tw.torch_module_path(keras_name)


_k = keras_layer_name


def _layers():
    import keras  # deferred: importing greenloop must not start a backend
    return keras.layers


def _bn(name):
    return _layers().BatchNormalization(epsilon=BN_EPS, momentum=0.9, name=_k(name))


def _dw(x, kernel, stride, name):
    """Depthwise conv with torch's symmetric padding (k - 1) // 2."""
    L = _layers()
    pad = (kernel - 1) // 2
    if pad:
        x = L.ZeroPadding2D(pad, name=_k(f"{name}_pad"))(x)
    return L.DepthwiseConv2D(kernel, strides=stride, padding="valid", use_bias=False,
                              name=_k(name))(x)


def _ghost_module(x, out_chs, relu, prefix):
    """timm GhostModule (ratio 2, 1x1 primary conv, 3x3 depthwise cheap op)."""
    L = _layers()
    init_chs = math.ceil(out_chs / 2)
    x1 = L.Conv2D(init_chs, 1, use_bias=False, name=_k(f"{prefix}.primary_conv.0"))(x)
    x1 = _bn(f"{prefix}.primary_conv.1")(x1)
    if relu:
        x1 = L.ReLU(name=_k(f"{prefix}.primary_conv.2"))(x1)
    x2 = _dw(x1, 3, 1, f"{prefix}.cheap_operation.0")
    x2 = _bn(f"{prefix}.cheap_operation.1")(x2)
    if relu:
        x2 = L.ReLU(name=_k(f"{prefix}.cheap_operation.2"))(x2)
    out = L.Concatenate(axis=-1, name=_k(f"{prefix}.cat"))([x1, x2])
    if 2 * init_chs > out_chs:  # odd out_chs (never at width 1.0): keep the first out_chs channels
        out = out[..., :out_chs]
    return out


def _squeeze_excite(x, chs, se_ratio, prefix):
    """timm SqueezeExcite with a hard-sigmoid gate and make_divisible(chs * ratio, 4) channels."""
    L = _layers()
    rd = make_divisible(chs * se_ratio, 4)
    s = L.GlobalAveragePooling2D(keepdims=True, name=_k(f"{prefix}.pool"))(x)
    s = L.Conv2D(rd, 1, use_bias=True, name=_k(f"{prefix}.conv_reduce"))(s)
    s = L.ReLU(name=_k(f"{prefix}.act1"))(s)
    s = L.Conv2D(chs, 1, use_bias=True, name=_k(f"{prefix}.conv_expand"))(s)
    s = L.Activation("hard_sigmoid", name=_k(f"{prefix}.gate"))(s)  # relu6(x + 3) / 6, as torch
    return L.Multiply(name=_k(f"{prefix}.mul"))([x, s])


def _bottleneck(x, in_chs, mid_chs, out_chs, kernel, stride, se_ratio, prefix):
    """timm GhostBottleneck (version 1, mode 'original')."""
    L = _layers()
    y = _ghost_module(x, mid_chs, True, f"{prefix}.ghost1")
    if stride > 1:
        y = _dw(y, kernel, stride, f"{prefix}.conv_dw")
        y = _bn(f"{prefix}.bn_dw")(y)
    if se_ratio:
        y = _squeeze_excite(y, mid_chs, se_ratio, f"{prefix}.se")
    y = _ghost_module(y, out_chs, False, f"{prefix}.ghost2")
    if in_chs == out_chs and stride == 1:
        shortcut = x
    else:
        shortcut = _dw(x, kernel, stride, f"{prefix}.shortcut.0")
        shortcut = _bn(f"{prefix}.shortcut.1")(shortcut)
        shortcut = L.Conv2D(out_chs, 1, use_bias=False, name=_k(f"{prefix}.shortcut.2"))(shortcut)
        shortcut = _bn(f"{prefix}.shortcut.3")(shortcut)
    return L.Add(name=_k(f"{prefix}.add"))([y, shortcut])


def build_ghostnet(input_shape=(224, 224, 3), include_top: bool = False, pooling: str | None = "avg",
                   num_classes: int = 1000, drop_rate: float = 0.2, name: str = TIMM_NAME):
    """Build GhostNet 1.0x (timm ``ghostnet_100``) as a Keras functional model, randomly initialised.

    input_shape: (height, width, 3) channels-last; ``(None, None, 3)`` accepts any size >= 32.
        Feed it ``preprocess_input(rgb_0_255)``.
    include_top: False -> features only. True -> timm's full head: global average pool, ``conv_head``
        (1x1 conv 960 -> 1280 with bias), ReLU, dropout ``drop_rate``, ``classifier`` (Dense
        ``num_classes``); outputs logits (no softmax), as timm does. This full model has
        N_TIMM_PARAMS = 5,182,508 trainable parameters for 1000 classes.
    pooling: only for include_top=False. ``'avg'`` -> (batch, 960) global-average-pooled descriptor
        (layer ``global_pool``); None -> the (batch, h/32, w/32, 960) map output by ``blocks.9``.
    Use ``load_timm_weights(model, path)`` to load timm's (ImageNet) weights.
    """
    import keras
    L = keras.layers
    if pooling not in ("avg", None):
        raise ValueError(f"pooling must be 'avg' or None, got {pooling!r}")
    inputs = keras.Input(shape=tuple(input_shape), name=_k("input"))
    x = L.ZeroPadding2D(1, name=_k("conv_stem_pad"))(inputs)
    x = L.Conv2D(16, 3, strides=2, padding="valid", use_bias=False, name=_k("conv_stem"))(x)
    x = _bn("bn1")(x)
    x = L.ReLU(name=_k("act1"))(x)
    prev = 16
    exp_size = None
    for stage, cfg in enumerate(CFGS):
        for i, (k, exp_size, c, se_ratio, s) in enumerate(cfg):
            out_chs, mid_chs = make_divisible(c, 4), make_divisible(exp_size, 4)
            x = _bottleneck(x, prev, mid_chs, out_chs, k, s, se_ratio, f"blocks.{stage}.{i}")
            prev = out_chs
    final = len(CFGS)  # blocks.9: ConvBnAct 160 -> 960
    x = L.Conv2D(make_divisible(exp_size, 4), 1, use_bias=False,
                 name=_k(f"blocks.{final}.0.conv"))(x)
    x = _bn(f"blocks.{final}.0.bn1")(x)
    x = L.ReLU(name=_k(f"blocks.{final}.0.act"))(x)
    if include_top:
        x = L.GlobalAveragePooling2D(keepdims=True, name=_k("global_pool"))(x)
        x = L.Conv2D(HEAD_FEATURES, 1, use_bias=True, name=_k("conv_head"))(x)
        x = L.ReLU(name=_k("act2"))(x)
        x = L.Flatten(name=_k("flatten"))(x)
        if drop_rate > 0:
            x = L.Dropout(drop_rate, name=_k("dropout"))(x)
        x = L.Dense(num_classes, name=_k("classifier"))(x)
    elif pooling == "avg":
        x = L.GlobalAveragePooling2D(name=_k("global_pool"))(x)
    return keras.Model(inputs, x, name=name)


# --------------------------------------------------------------------------------------------
# timm <-> keras weights
# --------------------------------------------------------------------------------------------

def export_timm_state_dict(model) -> dict[str, np.ndarray]:
    """The weights of a model from ``build_ghostnet`` as timm's ``state_dict`` (numpy, torch layouts).

    Keys and shapes are exactly timm's (``conv_stem.weight`` (16, 3, 3, 3), ...), including each
    BatchNorm's ``num_batches_tracked`` (int64 scalar 0), so the full model gives N_TIMM_TENSORS = 512
    entries. Save it with ``safetensors.numpy.save_file`` to get a file timm can load.
    """
    return _tw.export_state_dict(model)


def load_timm_state_dict(model, state: dict) -> None:
    """Load a timm ``ghostnet_100`` state dict (name -> numpy array, torch layouts) into ``model``.

    Every weight of the model must be present with timm's shape. ``num_batches_tracked`` entries are
    ignored, and so are ``conv_head.*`` / ``classifier.*`` when the model was built without its top.
    Raises ValueError naming missing, unexpected or mis-shaped tensors (a state dict of another
    architecture, e.g. ghostnetv2 or ghostnet_130, fails here rather than loading garbage).
    """
    _tw.load_state_dict(model, state, arch=f"timm's {TIMM_NAME}",
                        hint="use timm/ghostnet_100.in1k model.safetensors (see greenloop.backbones.ghostnet "
                             "docs)", head_prefixes=("conv_head.", "classifier."))


def load_timm_weights(model, path) -> None:
    """Load timm ghostnet_100 weights from a ``.safetensors`` file into a ``build_ghostnet`` model.

    path: e.g. timm/ghostnet_100.in1k ``model.safetensors`` (read with ``safetensors.numpy``; torch
    is not needed). Raises FileNotFoundError if the file does not exist and ValueError if it is not a
    safetensors file or not ghostnet_100 weights.
    """
    from safetensors.numpy import load_file
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(
            f"GhostNet weights {path} not found; get timm's with `huggingface-cli download "
            f"timm/ghostnet_100.in1k model.safetensors` and place the file at {default_weights_path()}")
    try:
        state = load_file(str(path))
    except Exception as e:  # safetensors raises its own error types for a bad header
        raise ValueError(f"{path} is not a readable safetensors file ({e}); GhostNet needs "
                         f"timm's ghostnet_100 model.safetensors") from e
    load_timm_state_dict(model, state)
