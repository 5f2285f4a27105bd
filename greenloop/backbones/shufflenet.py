"""ShuffleNet v2 (Ma et al., ECCV 2018, Table 5) in Keras 3, randomly initialised.

Qi et al. 2024 (Tables 2-4) compare ShuffleNet v2 with other light backbones as loop-closure feature
extractors. Keras ships no ShuffleNet, and **no ImageNet weights are available offline** (Keras has
none to download, and this study has no copy of torchvision's), so greenloop uses this network only
as a *random-init* row of those tables: it measures the architecture's cost and what its untrained
features are worth, not what the published pretrained network does. Only the Keras 3 public API is
used (``keras.layers``, ``keras.ops``, functional ``keras.Model``), so it runs on the TensorFlow, JAX
or PyTorch backend.

Architecture (paper Table 5, torchvision's ``shufflenet_v2_x{0_5,1_0,1_5,2_0}``), for an
``(h, w, 3)`` input; ``c2, c3, c4`` and ``c5`` depend on ``width`` (``STAGE_CHANNELS``):

=========  ===========================================  =================  ==========
layer      operation                                    output shape       repeats
=========  ===========================================  =================  ==========
conv1      3x3 conv stride 2 (24), BN, ReLU             (h/2,  w/2,  24)   1
maxpool    3x3 max-pool stride 2                        (h/4,  w/4,  24)   1
stage2     downsampling unit, then basic units          (h/8,  w/8,  c2)   1 + 3
stage3     downsampling unit, then basic units          (h/16, w/16, c3)   1 + 7
stage4     downsampling unit, then basic units          (h/32, w/32, c4)   1 + 3
conv5      1x1 conv (c5), BN, ReLU                      (h/32, w/32, c5)   1
pool       global average pooling                       (c5,)              1
fc         Dense ``classes`` + softmax (include_top)    (classes,)         1
=========  ===========================================  =================  ==========

width 0.5: (c2, c3, c4, c5) = (48, 96, 192, 1024); 1.0: (116, 232, 464, 1024);
1.5: (176, 352, 704, 1024); 2.0: (244, 488, 976, 2048).  (``h/2`` etc. round as a torch conv with
padding 1 does: ``floor((n - 1) / 2) + 1``; any input of at least 32x32 works, square or not.)

Units, for a unit with ``out`` output channels and ``b = out / 2`` channels per branch:

* basic unit (stride 1, paper Fig. 3(c)): split the input channels in two halves; the first half is
  the identity, the second goes through 1x1 conv (b) - BN - ReLU, 3x3 depthwise conv - BN (no ReLU),
  1x1 conv (b) - BN - ReLU; concatenate ``[identity, branch]``; channel shuffle with 2 groups.
* downsampling unit (stride 2, Fig. 3(d)): no split; both branches see the whole input.
  ``branch1``: 3x3 depthwise conv stride 2 - BN, 1x1 conv (b) - BN - ReLU. ``branch2``: 1x1 conv (b)
  - BN - ReLU, 3x3 depthwise conv stride 2 - BN, 1x1 conv (b) - BN - ReLU. Concatenate
  ``[branch1, branch2]``, channel shuffle with 2 groups.

Choices that follow torchvision exactly (so the parameter counts are torchvision's, see
``N_TORCHVISION_PARAMS``): convolutions have no bias, every BatchNorm has a scale and an offset
(eps 1e-5, torch's), the classifier is a Dense layer with bias; convolutions and the max-pool pad 1
pixel on every side like torch (explicit ``ZeroPadding2D`` + ``'valid'``; Keras ``'same'`` pads
stride-2 layers asymmetrically). Zero padding before the max-pool equals torch's -inf padding
because the pool follows a ReLU. Layer names are torchvision's module paths with ``.`` written
``__`` (``stage2.0.branch1.0`` -> ``stage2__0__branch1__0``, as in ``greenloop.backbones.torch_weights``), so
``torch_weights.export_state_dict`` gives torchvision's key names; numerical agreement with
torchvision has not been checked (no torch here).

Channel shuffle (``channel_shuffle``) is ``Reshape (h, w, 2, c/2) -> Permute -> Reshape (h, w, c)``
built from the symbolic shape at model-build time, so the model serialises with plain Keras layers
(no ``Lambda``); only a model with unknown spatial size (``input_shape=(None, None, 3)``) uses the
small registered ``ChannelShuffle`` layer instead. The channel split is a plain slice
``x[..., :c/2]`` / ``x[..., c/2:]``, which Keras 3 records and serialises as an operation.

Descriptor for loop closure: the global-average-pooled conv5 output, **1024** values at widths 0.5 to
1.5 (``NUM_FEATURES``; 2048 at width 2.0). Input: RGB 0..255 through ``preprocess_input`` (torchvision's
ImageNet normalisation).
"""
from __future__ import annotations

import numpy as np

from greenloop.backbones import torch_weights as _tw

NUM_FEATURES = 1024      # pooled descriptor length at width 1.0 (conv5 channels)
BN_EPS = 1e-5            # torch BatchNorm2d default
STAGE_REPEATS = (4, 8, 4)
# width -> (conv1, stage2, stage3, stage4, conv5) output channels, paper Table 5 / torchvision
STAGE_CHANNELS = {
    0.5: (24, 48, 96, 192, 1024),
    1.0: (24, 116, 232, 464, 1024),
    1.5: (24, 176, 352, 704, 1024),
    2.0: (24, 244, 488, 976, 2048),
}
# trainable parameters with the 1000-class top: torchvision's shufflenet_v2_x*_* (BatchNorm running
# statistics excluded; Keras counts them as non-trainable weights in ``count_params``)
N_TORCHVISION_PARAMS = {0.5: 1_366_792, 1.0: 2_278_604, 1.5: 3_503_624, 2.0: 7_393_996}
IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)


def preprocess_input(x):
    """torchvision's ShuffleNet v2 preprocessing.

    x: RGB images, float or uint8 in 0..255, shape (..., 3) channels-last.
    Returns float32 ``(x / 255 - mean) / std`` with the ImageNet mean (0.485, 0.456, 0.406) and std
    (0.229, 0.224, 0.225), same shape.
    """
    x = np.asarray(x, dtype=np.float32)
    return (x / np.float32(255.0) - IMAGENET_MEAN) / IMAGENET_STD


_k = _tw.keras_layer_name


def _layers():
    import keras  # deferred: importing greenloop must not start a backend
    return keras.layers


_CHANNEL_SHUFFLE_CLS = None


def _channel_shuffle_layer_cls():
    """The ``ChannelShuffle`` layer class (defined on first use so importing greenloop does not
    import keras), registered for serialisation as ``greenloop>ChannelShuffle``."""
    global _CHANNEL_SHUFFLE_CLS
    if _CHANNEL_SHUFFLE_CLS is None:
        import keras

        @keras.saving.register_keras_serializable(package="greenloop")
        class ChannelShuffle(keras.layers.Layer):
            """Channel shuffle for inputs of unknown spatial size: (batch, h, w, c) -> same shape,
            channel ``g * (c / groups) + i`` moved to position ``i * groups + g``."""

            def __init__(self, groups=2, **kwargs):
                super().__init__(**kwargs)
                self.groups = int(groups)

            def call(self, x):
                ops = keras.ops
                s = ops.shape(x)
                c = x.shape[-1]
                y = ops.reshape(x, (s[0], s[1], s[2], self.groups, c // self.groups))
                y = ops.transpose(y, (0, 1, 2, 4, 3))
                return ops.reshape(y, (s[0], s[1], s[2], c))

            def compute_output_shape(self, input_shape):
                return input_shape

            def get_config(self):
                return {**super().get_config(), "groups": self.groups}

        _CHANNEL_SHUFFLE_CLS = ChannelShuffle
    return _CHANNEL_SHUFFLE_CLS


def channel_shuffle(x, groups: int = 2, name: str = "shuffle"):
    """Channel shuffle (paper Sec. 3, torchvision ``channel_shuffle``) of a symbolic tensor.

    x: KerasTensor (batch, h, w, c), c divisible by ``groups``. Returns (batch, h, w, c) where
    output channel ``i * groups + g`` is input channel ``g * (c / groups) + i``: with 2 groups,
    channels [0, 1, 2, 3, 4, 5] come out as [0, 3, 1, 4, 2, 5].
    Built as ``Reshape (h, w, groups, c/groups)`` -> ``Permute`` (swap the last two axes) ->
    ``Reshape (h, w, c)`` with h, w read from the symbolic shape; a tensor whose h or w is unknown
    (None) goes through the registered ``ChannelShuffle`` layer instead.
    """
    L = _layers()
    _, h, w, c = x.shape
    if c % groups:
        raise ValueError(f"channel_shuffle: {c} channels are not divisible by {groups} groups")
    if h is None or w is None:
        return _channel_shuffle_layer_cls()(groups, name=name)(x)
    x = L.Reshape((h, w, groups, c // groups), name=f"{name}_split")(x)
    x = L.Permute((1, 2, 4, 3), name=f"{name}_permute")(x)
    return L.Reshape((h, w, c), name=f"{name}_merge")(x)


def _bn(name):
    return _layers().BatchNormalization(epsilon=BN_EPS, momentum=0.9, name=_k(name))


def _pad(x, name):
    return _layers().ZeroPadding2D(1, name=_k(f"{name}_pad"))(x)


def _dw(x, stride, name):
    """3x3 depthwise conv, torch padding 1 on every side, no bias."""
    return _layers().DepthwiseConv2D(3, strides=stride, padding="valid", use_bias=False,
                                     name=_k(name))(_pad(x, name))


def _pw(x, chs, name):
    """1x1 conv without bias."""
    return _layers().Conv2D(chs, 1, use_bias=False, name=_k(name))(x)


def _branch2(x, chs, stride, prefix):
    """1x1 conv - BN - ReLU, 3x3 depthwise (stride) - BN, 1x1 conv - BN - ReLU; (b, h, w, *) ->
    (b, h/stride, w/stride, chs). Indices are torchvision's ``branch2`` Sequential."""
    L = _layers()
    x = _pw(x, chs, f"{prefix}.0")
    x = _bn(f"{prefix}.1")(x)
    x = L.ReLU(name=_k(f"{prefix}.2"))(x)
    x = _dw(x, stride, f"{prefix}.3")
    x = _bn(f"{prefix}.4")(x)
    x = _pw(x, chs, f"{prefix}.5")
    x = _bn(f"{prefix}.6")(x)
    return L.ReLU(name=_k(f"{prefix}.7"))(x)


def _inverted_residual(x, out_chs, stride, prefix):
    """One ShuffleNet v2 unit (torchvision ``InvertedResidual``).

    x: (b, h, w, c_in). stride 1 (basic unit, needs c_in == out_chs): split, branch on the second
    half, concat, shuffle -> (b, h, w, out_chs). stride 2 (downsampling unit): both branches on the
    whole input -> (b, h/2, w/2, out_chs).
    """
    L = _layers()
    b = out_chs // 2
    if stride == 1:
        c_in = x.shape[-1]
        if c_in != out_chs:
            raise ValueError(f"basic unit {prefix}: {c_in} input channels != {out_chs} output")
        left = x[..., :b]
        right = _branch2(x[..., b:], b, 1, f"{prefix}.branch2")
    else:
        left = _dw(x, stride, f"{prefix}.branch1.0")
        left = _bn(f"{prefix}.branch1.1")(left)
        left = _pw(left, b, f"{prefix}.branch1.2")
        left = _bn(f"{prefix}.branch1.3")(left)
        left = L.ReLU(name=_k(f"{prefix}.branch1.4"))(left)
        right = _branch2(x, b, stride, f"{prefix}.branch2")
    out = L.Concatenate(axis=-1, name=_k(f"{prefix}.cat"))([left, right])
    return channel_shuffle(out, 2, name=_k(f"{prefix}.shuffle"))


def build_shufflenet_v2(input_shape=(224, 224, 3), width: float = 1.0, include_top: bool = False,
                        pooling: str | None = "avg", classes: int = 1000, name: str | None = None):
    """Build ShuffleNet v2 at ``width`` (0.5, 1.0, 1.5 or 2.0) as a Keras functional model,
    randomly initialised (no pretrained weights exist for it here).

    input_shape: (height, width, 3) channels-last, each side >= 32 (square or not); the study feeds
        128x128 and 224x224. ``(None, None, 3)`` also works (shuffle then uses ``ChannelShuffle``).
        Feed it ``preprocess_input(rgb_0_255)``.
    include_top: True -> global average pool then ``fc`` (Dense ``classes``, softmax): output
        (batch, classes). Trainable parameters with 1000 classes equal torchvision's
        (``N_TORCHVISION_PARAMS``: 2,278,604 at width 1.0).
    pooling: only for include_top=False. ``'avg'`` -> (batch, c5) pooled descriptor (layer
        ``global_pool``; c5 = NUM_FEATURES = 1024, 2048 at width 2.0); None -> the conv5 map
        (batch, h/32, w/32, c5).
    name: model name, default ``shufflenet_v2_x{width}`` (e.g. ``shufflenet_v2_x1_0``).
    """
    import keras
    L = keras.layers
    width = float(width)
    if width not in STAGE_CHANNELS:
        raise ValueError(f"width must be one of {sorted(STAGE_CHANNELS)}, got {width}")
    if pooling not in ("avg", None):
        raise ValueError(f"pooling must be 'avg' or None, got {pooling!r}")
    h, w = tuple(input_shape)[:2]
    if (h is not None and h < 32) or (w is not None and w < 32):
        raise ValueError(f"input must be at least 32x32, got {h}x{w}")
    if name is None:
        name = "shufflenet_v2_x" + f"{width:.1f}".replace(".", "_")
    c1, *stage_chs, c5 = STAGE_CHANNELS[width]

    inputs = keras.Input(shape=tuple(input_shape), name="input")
    x = _pad(inputs, "conv1.0")
    x = L.Conv2D(c1, 3, strides=2, padding="valid", use_bias=False, name=_k("conv1.0"))(x)
    x = _bn("conv1.1")(x)
    x = L.ReLU(name=_k("conv1.2"))(x)
    x = _pad(x, "maxpool")
    x = L.MaxPooling2D(3, strides=2, padding="valid", name="maxpool")(x)
    for stage, (repeats, chs) in enumerate(zip(STAGE_REPEATS, stage_chs), start=2):
        for i in range(repeats):
            x = _inverted_residual(x, chs, 2 if i == 0 else 1, f"stage{stage}.{i}")
    x = _pw(x, c5, "conv5.0")
    x = _bn("conv5.1")(x)
    x = L.ReLU(name=_k("conv5.2"))(x)
    if include_top:
        x = L.GlobalAveragePooling2D(name="global_pool")(x)
        x = L.Dense(classes, activation="softmax", name="fc")(x)
    elif pooling == "avg":
        x = L.GlobalAveragePooling2D(name="global_pool")(x)
    return keras.Model(inputs, x, name=name)


def trainable_params(model) -> int:
    """Number of trainable parameters (what torch counts; excludes BatchNorm moving statistics)."""
    return int(sum(int(np.prod(v.shape)) for v in model.trainable_weights))
