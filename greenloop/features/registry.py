"""The one descriptor registry: one record per descriptor name, and the names' grammar, read here
and nowhere else (:func:`parse`).

Every descriptor greenloop computes is a key of ``BACKBONES`` or a layer descriptor of one
(``"backbone@depth-pooling"``), optionally with a weights suffix (``":random"``, ``":imagenet"``);
``features.get(name)`` turns a name into a ``Descriptor``. The notebooks, the leaderboard, the CLI
and greenloop-seq read this registry (``SEQUENCE_DESCRIPTORS`` names the ones greenloop-seq
streams). A new descriptor is one module and one line here (docs/ARCHITECTURE.md, "Adding a
descriptor"). Imports nothing of the other features modules (they all import this one).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from greenloop.backbones import efficientnet_lite as _lite, ghostnet as _ghostnet, mobilenet_tflite as _tflite, shufflenet as _shufflenet

DEFAULT_VOCAB_SIZE = 500       # SIFT bag-of-words vocabulary (visual words)
DEPTH_MAX_M = 10.0             # depth -> uint8 mapping: 0 m -> 0, >= DEPTH_MAX_M -> 255 (linear)
PIXELS_SIZE = (32, 32)         # (width, height) of the main paper's preprocessing
RANDOM_INIT_SEED = 0           # seed of the weights=None / "auto"-fallback random networks
PATCH = 8                      # SeqSLAM patch-normalisation size (pixels), pixels-patchnorm
GRADIENT_SIZE = (128, 64)      # "gradients": gray frame (width, height), 2:1 like SeqSLAM
GRADIENT_CELL, GRADIENT_BINS = 16, 8   # 16x16-pixel cells (4 x 8 of them), 8 unsigned bins -> 256-d
GRADIENT_DIM = (GRADIENT_SIZE[0] // GRADIENT_CELL) * (GRADIENT_SIZE[1] // GRADIENT_CELL) * GRADIENT_BINS
# "gradients+efficientnetlite0": the gradients beside EfficientNet-Lite0's block-10 map (112 channels)
# pooled over 2 x 2 cells (``features.layers``), the network fed frames FUSED_WIDTH pixels wide with
# their aspect ratio kept (``layers.aspect_size``): Nordland's 64 x 32 frames become 128 x 64. The width
# is the one ``greenloop.experiments.default_choice`` ranks first on tuning queries (results/default_choice/cnn_width.md).
FUSED_CNN = ("efficientnetlite0", "mid", "grid2")
FUSED_WIDTH = 128
FUSED_DIM = GRADIENT_DIM + 4 * 112
# the same descriptor with its CNN part run as a full-integer int8 TFLite graph (post-training quantisation,
# calibrated on the fixed synthetic set features.cnn.int8_calibration_frames): the CNN configuration's
# cheaper backend (``--descriptor gradients+efficientnetlite0-int8``)
FUSED_INT8 = "gradients+efficientnetlite0-int8"
# layer descriptors "backbone@depth-pooling" (greenloop.features.layers): the channels C of each depth's map
# (a descriptor is C long, 4 C for grid2), the same for the ImageNet graph and the random-init control
DEPTHS = ("early", "mid", "last")
POOLINGS = ("avg", "grid2", "gem")
LAYER_CHANNELS = {"mobilenetv1": {"early": 256, "mid": 512, "last": 1024},
                  "mobilenetv2": {"early": 32, "mid": 96, "last": 1280},
                  "efficientnetlite0": {"early": 40, "mid": 112, "last": 1280}}
WEIGHT_TAGS = {"": None, "random": None, "imagenet": "imagenet"}   # name suffix -> weights ("": the caller's)


@dataclass(frozen=True)
class Backbone:
    """One registry line: what ``features.get`` knows about a descriptor.

    name: the key in BACKBONES. kind: 'keras' | 'ghostnet' | 'efficientnet_lite' | 'tflite' |
    'sift_bovw' | 'pixels' | 'spot_cnn' | 'pixels-patchnorm' | 'gradients' | 'fused' (gradients beside a
    CNN layer, ``layers.extract_fused``) | 'function' (a registered function of frames, ``fn``). dim: descriptor length D (None: depends on the vocabulary or
    the model). input_size: default (width, height) fed to the extractor (None: native frame size).
    layer: which layer/feature the descriptor is. weights_file: name of the ImageNet weights file
    looked for by ``weights_search_path`` (None for weight-free backbones). app / module: the
    keras.applications constructor (for 'tflite': the same architecture's random-init control) and
    the submodule holding its preprocess_input. fixed_input: the input size cannot be changed.
    fn: kind 'function' only: "module:function" of a function frames (N, H, W, 3) uint8 RGB ->
    (N, D) float32 (imported when first used). leaderboard: the leaderboard's single-frame matcher
    gives it a row (``methods.single_frame``), beside the notebook's CNNs, SIFT-BoVW and pixels.
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
    fn: str | None = None          # 'function' only: "module:function", frames -> descriptors
    leaderboard: bool = False      # a row of the leaderboard's single-frame matcher


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
    Backbone("pixels-patchnorm", "pixels-patchnorm", PIXELS_SIZE[0] * PIXELS_SIZE[1], PIXELS_SIZE,
             f"32x32 grayscale frame in [0, 1], SeqSLAM patch-normalised ({PATCH}x{PATCH} blocks "
             f"to zero mean, unit std), flattened"),
    Backbone("gradients", "gradients", GRADIENT_DIM,
             GRADIENT_SIZE, f"{GRADIENT_CELL}x{GRADIENT_CELL}-cell orientation histograms"),
    Backbone("gradients+efficientnetlite0", "fused", FUSED_DIM, None,
             f"[gradients | efficientnetlite0@mid-grid2 at {FUSED_WIDTH} pixels wide, aspect kept], each part "
             f"L2-normalised; ImageNet weights only"),
    Backbone(FUSED_INT8, "fused", FUSED_DIM, None,
             "gradients+efficientnetlite0 with its CNN part a full-integer int8 TFLite graph (post-training, "
             "calibrated on a fixed set of synthetic frames); ImageNet weights only"),
)}
CNN_KINDS = ("keras", "ghostnet", "efficientnet_lite", "tflite", "shufflenet")
CNN_BACKBONES = tuple(n for n, b in BACKBONES.items() if b.kind in CNN_KINDS)
# greenloop-seq's per-frame descriptors (seqmatch.DESCRIPTORS), in its order; each a BACKBONES key
SEQUENCE_DESCRIPTORS = ("pixels", "pixels-patchnorm", "mobilenetv2", "gradients", "gradients+efficientnetlite0", FUSED_INT8)


@dataclass
class ExtractInfo:
    """What a ``Descriptor.extract`` / ``describe`` call did; use ``label`` in every table row and legend.

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


class Options(NamedTuple):
    """The per-call settings every extractor takes (a Descriptor's and its call's, checked there).

    The extractor protocol: ``fn(b: Backbone, frames_or_folder, source, size, opt: Options)`` ->
    (features (N, D) float32, seconds per image, extra dict); frames_or_folder is a sequence folder
    or an (N, H, W[, 1 | 3]) uint8 / [0, 1] float array, source the ``weights.Resolved`` source,
    size the (width, height) input (None: native). ``descriptor.EXTRACTORS`` maps each kind to its fn.
    color: the channel order of a 3-channel array, "rgb" or "bgr" (as ``cv2.imread`` decodes);
    always "rgb" for a folder, which ``sequence.load_frames`` decodes to RGB.
    """
    batch_size: int = 32
    progress: bool = True
    limit: int | None = None
    step: int = 1
    vocabulary: Any = None     # sift_bovw: (k, 128) centres, or None to fit on the input
    vocab_size: int = DEFAULT_VOCAB_SIZE
    seed: int = 0
    color: str = "rgb"


def get_backbone(name: str) -> Backbone:
    """BACKBONES[name], or ValueError listing the valid names."""
    if not isinstance(name, str) or name.lower() not in BACKBONES:
        raise ValueError(f"unknown backbone {name!r}; valid names: {', '.join(BACKBONES)}")
    return BACKBONES[name.lower()]


def input_size_of(input_size, default):
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


class Name(NamedTuple):
    """A descriptor name read by :func:`parse`. backbone: its BACKBONES key. depth, pooling: a layer
    descriptor's map and pooling (None otherwise). tag: the weights suffix, "", "random" or "imagenet"."""
    backbone: str
    depth: str | None
    pooling: str | None
    tag: str

    @property
    def base(self) -> str:
        """The name without its weights suffix: "mobilenetv2", "efficientnetlite0@mid-grid2"."""
        return self.backbone if self.depth is None else layer_name(self.backbone, self.depth, self.pooling)


def _unknown(name) -> ValueError:
    return ValueError(f"unknown descriptor {name!r}; valid names: {', '.join(BACKBONES)}; or a layer "
                      f"descriptor <backbone>@<depth>-<pooling> with backbone in {sorted(LAYER_CHANNELS)}, depth "
                      f"in {DEPTHS}, pooling in {POOLINGS}; each with an optional ':random' or ':imagenet' suffix")


def parse(name: str) -> Name:
    """Read a descriptor name, the one place the grammar is read:
    ``<backbone>[@<depth>-<pooling>][:random | :imagenet]``.

    ``":random"`` forces random initialisation (the untrained control of the same architecture),
    ``":imagenet"`` the ImageNet weights; without a suffix the caller's weights apply.
    ``"backbone@depth-pooling"`` is a layer descriptor (greenloop.features.layers). Raises
    ValueError listing the valid names for an unknown backbone, layer or suffix.
    """
    if not isinstance(name, str):
        raise _unknown(name)
    base, _, tag = name.partition(":")
    if tag not in WEIGHT_TAGS or (not tag and name.endswith(":")):
        raise ValueError(f"descriptor {name!r}: the suffix must be ':random' or ':imagenet'")
    backbone, at, layer = base.partition("@")
    if backbone.lower() not in BACKBONES:
        raise _unknown(name)
    if not at:
        return Name(backbone.lower(), None, None, tag)
    depth, _, pooling = layer.partition("-")
    if backbone not in LAYER_CHANNELS or depth not in DEPTHS or pooling not in POOLINGS:
        raise ValueError(f"layer descriptor {base!r}: write <backbone>@<depth>-<pooling> with backbone in "
                         f"{sorted(LAYER_CHANNELS)}, depth in {DEPTHS}, pooling in {POOLINGS}")
    return Name(backbone, depth, pooling, tag)


def layer_name(backbone: str, depth: str, pooling: str) -> str:
    """The name of one layer descriptor, e.g. ``"mobilenetv2@mid-grid2"``."""
    return f"{backbone}@{depth}-{pooling}"


def names() -> list[str]:
    """Every descriptor name of the registry: the BACKBONES keys, then every layer descriptor
    (each may take a ``:random`` / ``:imagenet`` suffix, :func:`parse`)."""
    return list(BACKBONES) + [layer_name(b, d, p) for b in LAYER_CHANNELS for d in DEPTHS for p in POOLINGS]


def split_spec(spec: str, weights="auto"):
    """A notebook's descriptor-list entry -> (name without the weights suffix, weights): ``"name"``
    takes ``weights``, ``"name:random"`` None, ``"name:imagenet"`` "imagenet" (:func:`parse`)."""
    n = parse(spec)
    return n.base, weights if not n.tag else WEIGHT_TAGS[n.tag]
