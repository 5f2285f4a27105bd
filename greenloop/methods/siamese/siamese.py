"""Xu et al. 2022: a Siamese CNN whose last fully connected layer is the loop-closure descriptor.

Two branches with one set of weights (the same Keras layers called on both images of a pair)
map each image to a descriptor; frames are matched by the L2 distance of their descriptors
(the paper's Eq. 5). Written against the Keras 3 public API only (``keras.layers``,
``keras.ops``, ``model.train_on_batch``), so it runs unchanged on the TensorFlow and JAX backends.

The trunk: the paper's AlexNet-like network, scaled to 64x64 inputs
--------------------------------------------------------------------
The paper feeds 227x227x3 images to AlexNet's five conv and three fully connected layers
(Table 1) and pre-trains on 2.5 M Places images. Here every network is trained from scratch on
a few hundred frames of one sequence, in about a minute on two CPU cores, so every size is
scaled down while the layer sequence, and with it Table 2's fusion points, is kept::

    layer   here (64x64 input, width=1)                  the paper (227x227 input)
    centre  x -> 2x - 1 (inputs in [0, 1] -> [-1, 1])     (mean subtraction)
    conv1   16 filters 5x5, stride 2, ReLU -> 32x32x16    96 filters 11x11, stride 4 -> 55x55
    pool1   max 3x3, stride 2              -> 16x16x16    max 3x3, stride 2 -> 27x27
    conv2   32 filters 5x5, ReLU           -> 16x16x32    256 filters 5x5
    pool2   max 3x3, stride 2              -> 8x8x32      -> 13x13
    conv3   48 filters 3x3, ReLU           -> 8x8x48      384 filters 3x3
    conv4   48 filters 3x3, ReLU           -> 8x8x48      384 filters 3x3
    conv5   32 filters 3x3, ReLU           -> 8x8x32      256 filters 3x3
    pool5   max 3x3, stride 2              -> 4x4x32      -> 6x6x256
    fc6     Dense 256, ReLU                               4096
    fc7     Dense 128, linear: THE DESCRIPTOR (D = 128)   2048 (the paper's descriptor)
    softmax Dense n_places (softmax / multi-task only)    205 Places classes

Why these sizes: 64x64 keeps the rows of plants, posts and pipes of a 640x480 frame legible, and
the whole branch costs about 8 M multiply-adds per image (AlexNet: about 700 M), which is what
lets the notebook train 13 networks over three seeds on two CPU cores within its budget. conv1 keeps AlexNet's
role (a large kernel whose stride, with pool1, quarters the resolution: 5x5 stride 2 on 64
pixels is about 11x11 stride 4 on 227), the spatial sizes after each stage are about half of
AlexNet's (32, 16, 8, 4 against 55, 27, 13, 6) and the channel counts about an eighth
(16/32/48/48/32 against 96/256/384/384/256). Every convolution and pooling uses "same" padding,
so any input size works. ``width`` scales every conv layer and fc6 (tests use small widths);
D stays ``DESCRIPTOR_DIM``. Departures from AlexNet, each for training from scratch in a few
hundred steps: no local response normalisation (Keras has no such layer) and no dropout; fc7 is
linear (with a ReLU, many of its units stayed at zero for every frame after short training, and
the L2 distance then ignores them); the inputs are centred to [-1, 1] inside the network.

Supervision (``SUPERVISIONS``; each pair k = two images with place labels l1, l2)
--------------------------------------------------------------------------------
* ``softmax``: both branches classify their image into the training part's places; per pair
  L_cls = CE(image 1) + CE(image 2) (Eq. 2 on each image).
* ``contrastive``: Eq. 3 on d = ||f1 - f2||_2: 0.5 d^2 for a pair of the same place,
  0.5 max(0, m - d)^2 otherwise. The paper does not give the margin m (it calls it a learned
  parameter, which the loss alone would drive to 0); ``MARGIN = 1.0`` is the default of Caffe's
  contrastive loss layer, the toolkit the paper used.
* ``multitask``: Eq. 4, L_cls + lambda * L_cst. The paper gives no lambda; ``LAMBDA = 1.0``.
  Eq. 4's squared-norm terms of the parameters are weight decay, applied by the optimiser.

Training (``train``): ``epochs`` passes of ``n_pairs`` freshly drawn pairs in batches of
``batch_size`` (the paper: 100). The optimiser defaults to Adam (AdamW, learning rate 1e-3,
weight decay ``WEIGHT_DECAY``): the paper's SGD (momentum 0.9, learning rate 0.01,
``optimizer="sgd"``) barely lowered the softmax loss within this budget. Given the ground truth,
a negative pair is one it calls no loop (two frames on either side of a spot border show one
place), and a ``hard_fraction`` of each epoch's negatives are hard ones (``hard_negatives``:
frames of other places the network being trained finds closest, re-mined every epoch). Each
training image can be moved and relit at random (``augment``), so that a network cannot learn the
few hundred frames of a training part by heart. The paper trains until the validation accuracy stalls for 10 epochs;
``stop_patience`` P > 0 does the same on a held-out loss: every ``VALIDATION_EVERY``-th labelled frame of each place, or
more where places are short (``validation_frames``) is kept out of every training pair, a fixed set of pairs among those frames is scored after each
epoch (no augmentation, no hard negatives), and training stops once that loss has not fallen by ``STOP_MIN_DELTA`` of
its best for P epochs (``util.stopping.stops_here`` on -log(loss)), at most ``epochs`` epochs (the cap). P = 0 trains
every one of ``epochs`` epochs. ``converged`` is the one rule the tables read. ``monitor`` records the scored
held-out AP per epoch to show whether it levelled off (watched, never used to stop).

RGB-D fusion (``FUSIONS``; RGB-D input is one (N, H, W, 4) array: RGB, then depth, in [0, 1])
------------------------------------------------------------------------------------------
* ``none``: one stream on whatever channels are given (3 = RGB, 1 = depth).
* ``early``: one stream on the 4-channel RGB+D input (Fig. 5).
* ``mid``: an RGB stream and a depth stream (separate weights) up to and including the layer
  ``fusion_layer`` (one of ``LAYERS``, Table 2's columns), where the two feature maps have the
  same size; they are joined there and one trunk continues (Fig. 6). The paper says only that
  the streams "are fused at intermediate layers with the same size of feature maps", which an
  element-wise join needs: ``merge="sum"`` (default) adds the two maps, so every layer after the
  join has the single-stream network's shape. ``merge="concat"`` stacks their channels instead;
  then fusing just before or just after a max pooling is one and the same network (pooling acts
  on each channel alone, so pool(concat(a, b)) = concat(pool(a), pool(b)), and the seeded
  weights are the same), and Table 2's conv1/pool1, conv2/pool2 and conv5/pool5 columns repeat
  each other. With a sum they are eight different networks.
* ``late``: an RGB network and a depth network trained side by side, each with its own
  supervision and no weight or loss shared (which is training them separately, on the same
  pairs); the descriptor is the average of their two fc7 descriptors (Fig. 7), so D is unchanged.

Training pairs come from a training part of the sequence only (``place_labels``,
``make_pairs``); frames labelled -1 never enter a pair (``check_pairs`` verifies it).
"""
from __future__ import annotations

import time

import numpy as np

from greenloop import evaluate, features, groundtruth
from greenloop.datasets import sequence
from greenloop.methods.dictionary import spots
from greenloop.util.cache import cache_key, cached_model, is_cached
from greenloop.util.checks import positive_int
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook
from greenloop.util.stopping import stops_here

LAYERS = ("conv1", "pool1", "conv2", "pool2", "conv3", "conv4", "conv5", "pool5")
SUPERVISIONS = ("softmax", "contrastive", "multitask")
FUSIONS = ("none", "early", "mid", "late")
MERGES = ("concat", "sum")
OPTIMIZERS = ("adam", "sgd")
INPUT_SIZE = (64, 64)          # (width, height) of every network input
DESCRIPTOR_DIM = 128           # fc7 units: the descriptor length D
MARGIN = 1.0                   # contrastive margin m (Caffe's default; the paper gives none)
LAMBDA = 1.0                   # multi-task weight of the contrastive term (the paper gives none)
WEIGHT_DECAY = 5e-4            # Eq. 4's squared-norm terms (AlexNet's value)
CACHE_VERSION = 2              # bump when training changes in a way the parameters do not show
STOP_PATIENCE = 10             # epochs: Xu 2022 stops once its validation accuracy stalls for 10 epochs
STOP_MIN_DELTA = 0.01          # a fall of the training loss by less than about 1 % of its best is none
VALIDATION_EVERY = 5           # early stopping: every 5th labelled frame of a place is a validation frame

# (name, kind, filters, kernel, stride) of the trunk at width=1; then fc6 and fc7
_TRUNK = (("conv1", "conv", 16, 5, 2), ("pool1", "pool", None, 3, 2),
          ("conv2", "conv", 32, 5, 1), ("pool2", "pool", None, 3, 2),
          ("conv3", "conv", 48, 3, 1), ("conv4", "conv", 48, 3, 1),
          ("conv5", "conv", 32, 3, 1), ("pool5", "pool", None, 3, 2))
_FC6 = 256


# --------------------------------------------------------------------------------- losses
def pair_distance(fa, fb):
    """L2 distance of two batches of descriptors (Eq. 5): (B, D), (B, D) -> (B,), keras.ops.

    The square root is taken of max(squared distance, 1e-12), so its gradient stays finite when
    the two descriptors coincide (identical inputs give 1e-6, not 0)."""
    from keras import ops

    sq = ops.sum(ops.square(fa - fb), axis=-1)
    return ops.sqrt(ops.maximum(sq, 1e-12))


def contrastive_loss(d, same, margin: float = MARGIN):
    """Eq. 3 per pair: 0.5 d^2 if same, else 0.5 max(0, margin - d)^2.

    d: (B,) L2 distances; same: (B,) 1 for a pair of the same place, 0 otherwise (bool or float).
    Returns (B,) float32 (keras.ops; NumPy arrays in, backend tensor out)."""
    from keras import ops

    d = ops.reshape(ops.cast(d, "float32"), (-1,))
    s = ops.reshape(ops.cast(same, "float32"), (-1,))
    return 0.5 * (s * ops.square(d) + (1.0 - s) * ops.square(ops.maximum(margin - d, 0.0)))


def softmax_loss(labels, logits):
    """Eq. 2 per image: -log softmax(logits)[label]. labels (B,) int, logits (B, K) -> (B,)."""
    from keras import ops

    labels = ops.reshape(ops.cast(labels, "int32"), (-1,))
    logp = ops.log_softmax(ops.cast(logits, "float32"), axis=-1)
    return -ops.take_along_axis(logp, ops.expand_dims(labels, -1), axis=-1)[:, 0]


def multitask_loss(d, same, logits_a, logits_b, labels_a, labels_b, margin: float = MARGIN,
                   lam: float = LAMBDA):
    """Eq. 4 per pair without its weight-decay terms: L_cls + lam * L_cst, where
    L_cls = softmax_loss of image a + softmax_loss of image b and L_cst = contrastive_loss.

    d, same: (B,); logits_a, logits_b: (B, K); labels_a, labels_b: (B,) int. Returns (B,)."""
    return (softmax_loss(labels_a, logits_a) + softmax_loss(labels_b, logits_b)
            + lam * contrastive_loss(d, same, margin))


def _contrastive(margin):
    def contrastive(y_true, y_pred):
        return contrastive_loss(y_pred, y_true, margin)
    return contrastive


def _softmax(y_true, y_pred):
    return softmax_loss(y_true, y_pred)


# ---------------------------------------------------------------------------------- model
def _check(supervision, fusion, fusion_layer, merge, channels):
    if supervision not in SUPERVISIONS:
        raise ValueError(f"unknown supervision {supervision!r}; choose one of {SUPERVISIONS}")
    if fusion not in FUSIONS:
        raise ValueError(f"unknown fusion {fusion!r}; choose one of {FUSIONS}")
    if fusion == "mid" and fusion_layer not in LAYERS:
        raise ValueError(f"mid-level fusion needs fusion_layer, one of {LAYERS}; got {fusion_layer!r}")
    if fusion != "mid" and fusion_layer is not None:
        raise ValueError(f"fusion_layer={fusion_layer!r} only applies to fusion='mid' (got fusion={fusion!r})")
    if merge not in MERGES:
        raise ValueError(f"unknown merge {merge!r}; choose one of {MERGES}")
    if fusion != "none" and channels != 4:
        raise ValueError(f"{fusion} fusion needs RGB-D input of 4 channels (RGB, then depth), got "
                         f"{channels}; build RGB-D frames with greenloop.methods.siamese.siamese.load_inputs, or use "
                         f"fusion='none' for RGB or depth alone")


def _layer(spec, prefix, width):
    from keras import layers

    name, kind, filters, kernel, stride = spec
    if kind == "pool":
        return layers.MaxPooling2D(kernel, stride, padding="same", name=prefix + name)
    return layers.Conv2D(max(1, round(filters * width)), kernel, strides=stride, padding="same",
                         activation="relu", name=prefix + name)


def _head(x, prefix, width):
    """pool5 output -> fc6 -> fc7 (the descriptor)."""
    from keras import layers

    x = layers.Flatten(name=prefix + "flatten")(x)
    x = layers.Dense(max(1, round(_FC6 * width)), activation="relu", name=prefix + "fc6")(x)
    return layers.Dense(DESCRIPTOR_DIM, name=prefix + "fc7")(x)


def _stream(x, prefix, width, stop=None):
    """Apply the trunk to x up to and including the layer ``stop`` (None: the whole trunk and
    fc6/fc7)."""
    from keras import layers

    x = layers.Rescaling(2.0, -1.0, name=prefix + "centre")(x)
    for spec in _TRUNK:
        x = _layer(spec, prefix, width)(x)
        if spec[0] == stop:
            return x
    return _head(x, prefix, width)


def embedding(input_shape=(64, 64, 3), fusion: str = "none", fusion_layer: str | None = None,
              width: float = 1.0, merge: str = "sum"):
    """One branch of the Siamese network: frames -> (N, DESCRIPTOR_DIM) fc7 descriptors.

    input_shape: (H, W, C); C = 4 (RGB, then depth) for every fusion other than "none".
    Returns (model, streams): ``model`` maps its inputs to the descriptor; its inputs are one
    (H, W, C) tensor for "none"/"early" and two, RGB (H, W, 3) and depth (H, W, 1), for
    "mid"/"late" (``describe`` splits a 4-channel array for it). ``streams`` lists the models
    that are supervised: [model] except for "late", where it is [rgb model, depth model] and
    ``model`` averages their descriptors.
    """
    import keras
    from keras import layers

    H, W, C = (int(v) for v in input_shape)
    _check("softmax", fusion, fusion_layer, merge, C)
    if fusion in ("none", "early"):
        x = keras.Input((H, W, C), name="frames")
        model = keras.Model(x, _stream(x, "", width), name=f"scnn_{fusion}")
        return model, [model]
    rgb, dep = keras.Input((H, W, 3), name="rgb"), keras.Input((H, W, 1), name="depth")
    if fusion == "late":
        r = keras.Model(rgb, _stream(rgb, "rgb_", width), name="scnn_late_rgb")
        d = keras.Model(dep, _stream(dep, "depth_", width), name="scnn_late_depth")
        avg = layers.Average(name="average")([r(rgb), d(dep)])
        return keras.Model([rgb, dep], avg, name="scnn_late"), [r, d]
    a = _stream(rgb, "rgb_", width, fusion_layer)
    b = _stream(dep, "depth_", width, fusion_layer)
    join = layers.Concatenate(name=f"fuse_{fusion_layer}") if merge == "concat" else layers.Add(
        name=f"fuse_{fusion_layer}")
    x = join([a, b])
    rest = _TRUNK[LAYERS.index(fusion_layer) + 1:]
    for spec in rest:
        x = _layer(spec, "", width)(x)
    model = keras.Model([rgb, dep], _head(x, "", width), name=f"scnn_mid_{fusion_layer}")
    return model, [model]


def build(n_classes: int | None, input_shape=(64, 64, 3), supervision: str = "multitask",
          fusion: str = "none", fusion_layer: str | None = None, margin: float = MARGIN,
          lam: float = LAMBDA, width: float = 1.0, merge: str = "sum",
          optimizer: str = "adam", learning_rate: float | None = None,
          weight_decay: float = WEIGHT_DECAY):
    """The Siamese network, compiled, and its descriptor branch.

    n_classes: places of the softmax head (softmax and multitask; ignored for contrastive).
    input_shape, fusion, fusion_layer, width, merge: see ``embedding``. supervision: one of
    ``SUPERVISIONS``. margin: contrastive m (> 0). lam: multi-task lambda (>= 0).
    optimizer: "adam" (AdamW, learning rate 1e-3 unless given) or "sgd" (the paper's: momentum
    0.9, learning rate 0.01 unless given); both with decoupled ``weight_decay``.
    Returns (siamese, descriptor). ``siamese`` takes the inputs of both images of a pair (a's
    inputs, then b's) and outputs a dict with, per supervised stream s ("" or "rgb_"/"depth_"):
    ``{s}distance`` (B,) and ``{s}logits_a``/``{s}logits_b`` (B, n_classes), compiled with the
    supervision's losses and weights. ``descriptor`` is the branch, sharing
    its weights: frames -> (N, DESCRIPTOR_DIM).
    """
    import keras
    from keras import layers

    _check(supervision, fusion, fusion_layer, merge, int(input_shape[-1]))
    if optimizer not in OPTIMIZERS:
        raise ValueError(f"unknown optimizer {optimizer!r}; choose one of {OPTIMIZERS}")
    if margin <= 0 or lam < 0:
        raise ValueError(f"margin must be > 0 and lam >= 0, got margin={margin}, lam={lam}")
    cls = supervision != "contrastive"
    if cls and (n_classes is None or n_classes < 2):
        raise ValueError(f"{supervision} supervision needs n_classes >= 2 places, got {n_classes}")
    descriptor, streams = embedding(input_shape, fusion, fusion_layer, width, merge)
    ins_a = [keras.Input(t.shape[1:], name=f"a_{t.name}") for t in descriptor.inputs]
    ins_b = [keras.Input(t.shape[1:], name=f"b_{t.name}") for t in descriptor.inputs]
    outputs, losses, weights = {}, {}, {}
    for k, stream in enumerate(streams):
        s = "" if len(streams) == 1 else ("rgb_", "depth_")[k]
        pick = (lambda ins: ins if len(ins) > 1 else ins[0]) if len(streams) == 1 else (
            lambda ins, k=k: ins[k])
        fa, fb = stream(pick(ins_a)), stream(pick(ins_b))
        if supervision != "softmax":
            outputs[s + "distance"] = pair_distance(fa, fb)
            losses[s + "distance"] = _contrastive(float(margin))
            weights[s + "distance"] = 1.0 if supervision == "contrastive" else float(lam)
        if cls:
            head = layers.Dense(int(n_classes), name=s + "softmax")   # logits; one head, both images
            outputs[s + "logits_a"], outputs[s + "logits_b"] = head(fa), head(fb)
            losses[s + "logits_a"] = losses[s + "logits_b"] = _softmax
            weights[s + "logits_a"] = weights[s + "logits_b"] = 1.0
    siamese = keras.Model(ins_a + ins_b, outputs, name=f"siamese_{supervision}_{descriptor.name}")
    siamese.compile(optimizer=_optimizer(optimizer, learning_rate, weight_decay), loss=losses,
                    loss_weights=weights)
    return siamese, descriptor


def _optimizer(name, learning_rate, weight_decay):
    import keras

    if name == "sgd":
        return keras.optimizers.SGD(learning_rate or 0.01, momentum=0.9, weight_decay=weight_decay)
    return keras.optimizers.AdamW(learning_rate or 1e-3, weight_decay=weight_decay)


# ----------------------------------------------------------------------------- descriptors
def _inputs(model, frames):
    """Frames (N, H, W, C) -> the list of arrays ``model`` takes (splits RGB-D for two inputs)."""
    X = np.asarray(frames, dtype=np.float32)
    need = [int(t.shape[-1]) for t in model.inputs]
    if X.ndim != 4 or X.shape[-1] != sum(need):
        raise ValueError(f"{model.name} takes frames (N, H, W, {sum(need)}), got {X.shape}")
    if len(need) == 1:
        return [X]
    return [X[..., :need[0]], X[..., need[0]:]]


def describe(model, frames, batch_size: int = 256, stream: str | None = None,
             return_info: bool = False, weights: str = "trained here"):
    """Descriptors of frames: (N, D) float32, D = DESCRIPTOR_DIM.

    model: a descriptor model from ``build``/``train``/``embedding``. frames: (N, H, W, C)
    float32 in [0, 1] with the channels the model takes (4 = RGB then depth for the fusions).
    stream: for a late-fusion model, "rgb" or "depth" describes with that stream alone (its fc7).
    return_info: also return a ``greenloop.features.ExtractInfo`` whose seconds_per_image is the
    wall time of the batched forward pass per frame, after one untimed warm-up batch (network
    only: the frames are already at the input size); ``weights`` labels it.
    """
    import keras

    if stream is not None:
        name = f"scnn_late_{stream}"
        if stream not in ("rgb", "depth") or name not in [l.name for l in model.layers]:
            raise ValueError(f"stream={stream!r} needs a late-fusion model and 'rgb' or 'depth'")
        sub = model.get_layer(name)
        model = keras.Model(model.inputs, sub(model.inputs[("rgb", "depth").index(stream)]))
    ins = _inputs(model, frames)
    n = len(ins[0])
    spans = [(i, min(i + batch_size, n)) for i in range(0, n, batch_size)]
    def run(i, j):
        batch = [a[i:j] for a in ins]
        return np.asarray(model.predict_on_batch(batch if len(batch) > 1 else batch[0]), np.float32)

    run(*spans[0])                                                        # warm-up, untimed
    t0 = time.perf_counter()
    out = [run(i, j) for i, j in spans]
    dt = (time.perf_counter() - t0) / n
    X = np.concatenate(out).reshape(n, -1)
    if not return_info:
        return X
    h, w = ins[0].shape[1:3]
    return X, features.ExtractInfo(backbone=model.name, weights=weights, dim=X.shape[1], n_images=n,
                                   input_size=(int(w), int(h)), layer=f"fc7 (Dense {DESCRIPTOR_DIM}, linear)",
                                   seconds_per_image=float(dt))


def load_inputs(folder, size=INPUT_SIZE, step: int = 1, depth: bool = True,
                max_depth: float | None = None) -> np.ndarray:
    """Network inputs of a sequence: (N, H, W, 3) RGB, or (N, H, W, 4) RGB then depth, float32
    in [0, 1].

    RGB: ``greenloop.datasets.sequence.load_frames`` at ``size`` (width, height). Depth (depth=True; the folder
    must have depth/): ``sequence.load_depth`` at the same size, mapped to 0..1 over 0..max_depth
    metres by ``features.depth_to_uint8`` (default ``features.DEPTH_MAX_M``).
    step: every step-th frame.
    """
    X = sequence.load_frames(folder, size=size, gray=False, step=step, progress=False)
    if not depth:
        return X
    D = sequence.load_depth(folder, size=size, step=step)
    if len(D) != len(X):
        raise ValueError(f"{folder}: {len(X)} rgb frames but {len(D)} depth frames")
    D = features.depth_to_uint8(D, max_depth or features.DEPTH_MAX_M).astype(np.float32) / 255.0
    return np.concatenate([X, D[..., None]], axis=-1)


# ---------------------------------------------------------------------------------- pairs
def training_split(n: int, fraction: float, gt, gap: int, frames_per_spot: int, frames=None):
    """The training and held-out frames of a Siamese run, kept ``gap`` frames apart.

    n: frames. fraction: share of the revisit frames before the cut (``evaluate.split_mask``).
    gt: (n, n) bool ground truth. gap: frames after the training part in neither part.
    frames_per_spot: L, the place length; all in frames of this array. frames: optional (n,)
    original frame numbers of these frames (``np.arange(0, N, step)``), to name them in the note.
    Returns (train (n,) bool, held (n,) bool, note): first ``evaluate.split_mask(n, fraction,
    gt, gap)`` (revisit frames on both sides) with note None. Where that raises
    ``evaluate.NoHonestSplit`` (every revisit frame within ``gap`` of the others, e.g. one short
    loop at the end of a sequence), training needs no revisit frame, so the training part is
    every frame before (first revisit frame - gap) and the held-out part every frame from the
    first revisit frame on: every revisit is held out, the places are spots only (no positive
    pair across time), no training frame lies within ``gap`` of a held-out one, and note (one
    Markdown sentence) says so. Raises ``evaluate.NoHonestSplit`` where that training part would
    hold fewer than two places (first revisit frame - gap <= frames_per_spot).
    """
    try:
        train, held = evaluate.split_mask(n, fraction, gt=gt, gap=gap)
        return train, held, None
    except evaluate.NoHonestSplit as e:
        first = int(np.flatnonzero(groundtruth.revisit_frames(gt))[0])
        cut = first - int(gap)
        if cut <= int(frames_per_spot):
            raise evaluate.NoHonestSplit(
                f"{e}; nor does a training part before the first revisit frame {first} less the gap "
                f"of {gap} frames hold two places of {frames_per_spot} frames",
                n=e.n, gap=e.gap, revisits=e.revisits, first=e.first, last=e.last) from e
        idx = np.arange(n)
        f = idx if frames is None else np.asarray(frames)
        unit = "frames" if frames is None else "steps"
        note = (f"**Training part without revisits:** the {e.revisits} revisit frames (frames "
                f"{f[e.first]}..{f[e.last]}) all lie within {e.span} {unit}, no more than the gap of "
                f"{gap} {unit}, so no cut leaves revisits on both sides; the networks are trained on "
                f"frames {f[0]}..{f[cut - 1]} (before the first revisit frame less the gap), whose "
                f"places are spots only, and every frame from {f[first]} on, every revisit, is held "
                f"out and scored.")
        return idx < cut, idx >= first, note


def place_labels(train, gt, frames_per_spot: int) -> np.ndarray:
    """The place of every training frame: (N,) int64 in 0 .. K-1, and -1 for every other frame.

    train: (N,) bool, the frames pairs may be drawn from (e.g. the tuning part of
    ``evaluate.split_mask``). gt: (N, N) bool ground-truth loops of the same frames.
    frames_per_spot: L, in frames of this array.
    Places are spots of L consecutive training frames, and a training frame with a ground-truth
    loop partner among earlier training frames takes that partner's place
    (``spots.by_place`` on the training frames alone), so a revisit inside the training part gives
    positive pairs across time. Frames outside ``train`` get -1 and never enter a pair.
    """
    train = np.asarray(train, dtype=bool)
    gt = np.asarray(gt, dtype=bool)
    if train.ndim != 1 or gt.shape != (len(train), len(train)):
        raise ValueError(f"train must be (N,) bool and gt (N, N), got {train.shape} and {gt.shape}")
    idx = np.flatnonzero(train)
    if len(idx) < 2:
        raise ValueError(f"the training part has {len(idx)} frame(s); pairs need at least 2")
    labels = np.full(len(train), -1, dtype=np.int64)
    labels[idx] = spots.by_place(frames_per_spot, gt[np.ix_(idx, idx)])
    return labels


def make_pairs(labels, n_pairs: int, seed=0, positive_fraction: float = 0.5, gt=None):
    """Training pairs drawn from the frames with a place label (labels >= 0) only.

    labels: (N,) int place labels, -1 = never in a pair (held-out frames and their neighbours).
    n_pairs: P. seed: int or numpy Generator. positive_fraction: share of pairs of the same place
    (default 0.5: one positive per negative). gt: optional (N, N) bool ground truth; a negative
    pair is then also one the ground truth calls no loop (two frames at the border of two spots
    show one place and never make a negative).
    Positives: an anchor drawn uniformly among frames whose place has >= 2 frames, and another
    frame of its place. Negatives: two frames drawn uniformly with different places.
    Returns (pairs (P, 2) int64 frame indices, same (P,) bool), in random order.
    """
    labels = np.asarray(labels, dtype=np.int64)
    rng = np.random.default_rng(seed)
    if not 0 <= positive_fraction <= 1 or int(n_pairs) < 1:
        raise ValueError(f"need n_pairs >= 1 and 0 <= positive_fraction <= 1, got {n_pairs}, "
                         f"{positive_fraction}")
    valid = np.flatnonzero(labels >= 0)
    n_pos = int(round(positive_fraction * int(n_pairs)))
    n_neg = int(n_pairs) - n_pos
    order = valid[np.argsort(labels[valid], kind="stable")]       # frames grouped by place
    places, start, count = np.unique(labels[order], return_index=True, return_counts=True)
    if n_neg and len(places) < 2:
        raise ValueError(f"negative pairs need >= 2 places among the labelled frames, got {len(places)}")
    multi = np.flatnonzero(count >= 2)
    if n_pos and not len(multi):
        raise ValueError("positive pairs need a place with >= 2 labelled frames; none has")
    # positives: anchor position p in its group, partner any other member of the group
    in_multi = np.flatnonzero(np.repeat(count >= 2, count))       # positions in `order`
    p = rng.choice(in_multi, n_pos) if n_pos else np.zeros(0, np.int64)
    g = np.searchsorted(start, p, side="right") - 1                # p's place
    r = rng.integers(0, count[g] - 1) if n_pos else np.zeros(0, np.int64)
    q = start[g] + r + (start[g] + r >= p)                         # another member, never p
    pos = np.stack([order[p], order[q]], 1)
    a, b = rng.choice(valid, n_neg), rng.choice(valid, n_neg)
    for _ in range(1000):
        clash = labels[a] == labels[b]
        if gt is not None:
            clash |= np.asarray(gt, dtype=bool)[a, b]
        if not clash.any():
            break
        b[clash] = rng.choice(valid, int(clash.sum()))
    else:
        raise ValueError("no negative pair found in 1000 draws: the ground truth calls almost every "
                         "pair of labelled frames a loop")
    pairs = np.concatenate([pos, np.stack([a, b], 1)]).astype(np.int64)
    same = np.r_[np.ones(n_pos, bool), np.zeros(n_neg, bool)]
    perm = rng.permutation(len(pairs))
    return pairs[perm], same[perm]


def hard_negatives(F, labels, gt, n: int, seed=0, k: int = 10) -> np.ndarray:
    """Negative pairs of frames that look alike: for each of n anchors, one of its k nearest frames
    (by L2 distance of the descriptors F) among those of another place that the ground truth calls
    no loop.

    F: (N, D) descriptors of every frame (the network being trained); labels: (N,) int place
    labels (-1: never in a pair); gt: (N, N) bool ground truth; n: pairs; seed: int or Generator;
    k: the nearest candidates one is drawn from (uniformly). Returns (n, 2) int64 frame indices.
    """
    labels = np.asarray(labels, dtype=np.int64)
    rng = np.random.default_rng(seed)
    valid = np.flatnonzero(labels >= 0)
    Fv = np.asarray(F, dtype=np.float32)[valid]
    sq = (Fv * Fv).sum(1)
    D = sq[:, None] + sq[None, :] - 2 * Fv @ Fv.T                 # squared L2, (V, V)
    bad = (labels[valid][:, None] == labels[valid][None, :]) | np.asarray(gt, dtype=bool)[np.ix_(valid, valid)]
    D[bad] = np.inf
    ok = np.flatnonzero(np.isfinite(D).any(1))
    if not len(ok):
        raise ValueError("no frame has a negative partner: every labelled pair is one place or a loop")
    a = rng.choice(ok, int(n))
    kk = min(int(k), D.shape[1])
    near = np.argpartition(D[a], kk - 1, axis=1)[:, :kk]           # the k nearest of each anchor
    finite = np.isfinite(np.take_along_axis(D[a], near, 1))
    pick = np.array([rng.choice(np.flatnonzero(f)) for f in finite])
    b = near[np.arange(len(a)), pick]
    return np.stack([valid[a], valid[b]], 1).astype(np.int64)


def near_heldout(heldout, gap: int = 0) -> np.ndarray:
    """(N,) bool: the held-out frames and every frame within ``gap`` frames of one.

    heldout: (N,) bool mask of the held-out frames; gap: frames (>= 0) on either side.
    """
    heldout = np.asarray(heldout, dtype=bool)
    return np.convolve(heldout.astype(np.int64), np.ones(2 * int(gap) + 1, np.int64), "same") > 0


def check_pairs(pairs, heldout, gap: int = 0) -> None:
    """Raise ValueError if any frame of ``pairs`` is a held-out frame or within ``gap`` frames of
    one. pairs: (P, 2) int frame indices; heldout: (N,) bool; gap: frames (>= 0)."""
    near = near_heldout(heldout, gap)
    bad = np.unique(np.asarray(pairs).ravel()[near[np.asarray(pairs).ravel()]])
    if bad.size:
        raise ValueError(f"{bad.size} frame(s) of the training pairs are held out or within {gap} "
                         f"frames of a held-out frame (first: {bad[:5].tolist()}); label them -1")


# ------------------------------------------------------------------------------- training
def _output_keys(supervision, fusion):
    prefixes = ("rgb_", "depth_") if fusion == "late" else ("",)
    names = {"softmax": ("logits_a", "logits_b"), "contrastive": ("distance",),
             "multitask": ("distance", "logits_a", "logits_b")}[supervision]
    return [p + n for p in prefixes for n in names]


def augment(frames, rng, shift: float = 0.125, photometric: float = 0.2) -> np.ndarray:
    """Each frame moved and relit at random (training only), so a network cannot learn the
    training part's frames by heart.

    frames: (B, H, W, C) float32 in [0, 1], RGB first (a 4th channel, depth, is moved with them
    and never relit). shift: the largest move, a fraction of the height and of the width (edge
    pixels repeated). photometric: RGB scaled by a gain in [1 - p, 1 + p] and offset by one in
    [-p/2, p/2], per frame, clipped to [0, 1]. rng: numpy Generator. Returns (B, H, W, C) float32.
    """
    X = np.asarray(frames, dtype=np.float32)
    B, H, W, C = X.shape
    dy = rng.integers(-int(shift * H), int(shift * H) + 1, B)
    dx = rng.integers(-int(shift * W), int(shift * W) + 1, B)
    rows = np.clip(np.arange(H)[None, :] - dy[:, None], 0, H - 1)              # (B, H)
    cols = np.clip(np.arange(W)[None, :] - dx[:, None], 0, W - 1)              # (B, W)
    out = X[np.arange(B)[:, None, None], rows[:, :, None], cols[:, None, :]]
    gain = rng.uniform(1 - photometric, 1 + photometric, (B, 1, 1, 1))
    offset = rng.uniform(-photometric / 2, photometric / 2, (B, 1, 1, 1))
    out[..., :3] = np.clip(out[..., :3] * gain + offset, 0, 1)
    return out.astype(np.float32)


def _epoch_pairs(labels, n, rng, positive_fraction, gt, hard_fraction, hard_k, descriptor, X):
    """One epoch's pairs: ``make_pairs``, then a ``hard_fraction`` of its negatives replaced by
    ``hard_negatives`` mined with the network as it stands (every labelled frame described)."""
    pairs, same = make_pairs(labels, n, rng, positive_fraction, gt)
    n_hard = int(round(hard_fraction * (~same).sum()))
    if n_hard:
        F = np.zeros((len(X), DESCRIPTOR_DIM), np.float32)
        lab = np.flatnonzero(labels >= 0)
        F[lab] = describe(descriptor, X[lab])
        pairs[np.flatnonzero(~same)[:n_hard]] = hard_negatives(F, labels, gt, n_hard, rng, hard_k)
    return pairs, same


def validation_frames(labels, every: int = VALIDATION_EVERY) -> np.ndarray:
    """Early stopping's validation frames: (N,) bool, every k-th labelled frame of each place in frame
    order, from its (k // 2)-th, with k = ``every``, or fewer where the places are short (half the median
    place's frames, at least 2) so that a place keeps two of them; they never enter a training pair.
    labels: (N,) int, -1 = unlabelled. Raises ValueError where no place keeps two (no positive pair)."""
    labels = np.asarray(labels, dtype=np.int64)
    places, counts = np.unique(labels[labels >= 0], return_counts=True)
    k = int(max(2, min(every, np.median(counts) // 2))) if len(counts) else every
    val = np.zeros(len(labels), bool)
    for c in places:
        idx = np.flatnonzero(labels == c)
        val[idx[k // 2::k]] = True
    if not len(counts) or not np.any(np.bincount(labels[val]) >= 2):
        raise ValueError(f"early stopping needs a place with at least 4 labelled frames (two validation frames): "
                         f"use longer places (frames_per_spot) or stop_patience=0")
    return val


def _batches(siamese, descriptor, X, labels, pairs, same, keys, batch_size, rng=None, shift=0.0, light=0.0, train=True):
    """One pass over ``pairs`` (P, 2) / ``same`` (P,) in batches: trained on (``train``, augmented by
    shift, light with rng) or only scored. Returns the mean loss (float)."""
    losses = []
    for s in range(0, len(pairs), batch_size):
        i, j = pairs[s:s + batch_size, 0], pairs[s:s + batch_size, 1]
        target = {"distance": same[s:s + batch_size].astype(np.float32),
                  "logits_a": labels[i].astype(np.int32), "logits_b": labels[j].astype(np.int32)}
        y = {k: target[k.split("_", 1)[1] if k.startswith(("rgb_", "depth_")) else k] for k in keys}
        Xa, Xb = X[i], X[j]
        if train and (shift or light):
            Xa, Xb = augment(Xa, rng, shift, light), augment(Xb, rng, shift, light)
        step = siamese.train_on_batch if train else siamese.test_on_batch
        losses.append(float(step(_inputs(descriptor, Xa) + _inputs(descriptor, Xb), y, return_dict=True)["loss"]))
    return float(np.mean(losses))


def _fit(X, labels, progress, gt=None, monitor=None, *, seed, supervision, fusion, fusion_layer, epochs,
         n_pairs, batch_size, positive_fraction, hard_fraction, hard_k, augment_shift, augment_light, margin, lam,
         width, merge, optimizer, learning_rate, weight_decay, stop_patience=0, **_):
    import keras

    keras.utils.set_random_seed(seed)
    n_classes = int(labels.max()) + 1
    siamese, descriptor = build(n_classes, X.shape[1:], supervision, fusion, fusion_layer, margin,
                                lam, width, merge or "sum", optimizer, learning_rate, weight_decay)
    keys = _output_keys(supervision, fusion)
    rng = np.random.default_rng(seed)
    steps = -(-int(n_pairs) // batch_size)
    history = {"loss": [], "val_loss": [], "epoch_seconds": [], "monitor": [], "stopped": False,
               "stop_patience": int(stop_patience)}
    full = labels
    if stop_patience:                           # validation frames out of every training pair, fixed pairs among them
        val = validation_frames(full)
        val_pairs = make_pairs(np.where(val, full, -1), max(batch_size, steps * batch_size // 4), seed + 1,
                               positive_fraction, gt)
        labels = np.where(val, -1, full)
    all_pairs, all_same = [], []
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in tqdm(range(epochs), desc=descriptor.name, unit="epoch", leave=False, disable=not progress):
        t_epoch = time.perf_counter()
        pairs, same = _epoch_pairs(labels, steps * batch_size, rng, positive_fraction, gt, hard_fraction, hard_k,
                                   descriptor, X)
        all_pairs.append(pairs)
        all_same.append(same)
        history["loss"].append(_batches(siamese, descriptor, X, labels, pairs, same, keys, batch_size, rng,
                                        augment_shift, augment_light))
        history["epoch_seconds"].append(time.perf_counter() - t_epoch)
        if monitor is not None:                 # watched, never acted on
            history["monitor"].append(float(monitor(descriptor)))
        if stop_patience:
            history["val_loss"].append(_batches(siamese, descriptor, X, full, *val_pairs, keys, batch_size, train=False))
            if stops_here(-np.log(np.maximum(history["val_loss"], 1e-12)), stop_patience, STOP_MIN_DELTA):
                history["stopped"] = True      # the held-out loss stopped falling within the cap
                break
    history["seconds"] = time.perf_counter() - t0
    history["cpu_seconds"] = time.process_time() - c0     # all threads of this process
    history["n_classes"] = n_classes
    history["n_train_frames"] = int((labels >= 0).sum())
    return descriptor, history, {"pairs": np.concatenate(all_pairs), "same": np.concatenate(all_same)}


def plateaued(loss, patience: int = STOP_PATIENCE, min_delta: float = STOP_MIN_DELTA) -> bool:
    """Did the training loss stop falling within its epochs: the early-stopping rule
    (``util.stopping.stops_here``, Keras's ``EarlyStopping``, on the training part) fires after some epoch of
    -log(loss), so a fall by less than about ``min_delta`` of the best loss (a fraction, whatever
    the loss's scale) counts as none for ``patience`` epochs. loss: per-epoch training losses
    (``history["loss"]``). False: the loss still fell within every ``patience`` epochs, and the
    network ended on its budget (``epochs``) before its training stopped improving."""
    r = -np.log(np.maximum(np.asarray(loss, dtype=float), 1e-12))
    return any(stops_here(r[:e], patience, min_delta) for e in range(2, len(r) + 1))


def converged(history: dict) -> bool:
    """The one convergence rule of a Siamese network: under early stopping (``history["val_loss"]``
    recorded, ``stop_patience`` > 0) its held-out loss stopped falling within the epoch cap
    (``history["stopped"]``); with a fixed budget its training loss stopped falling within its
    epochs (:func:`plateaued`). False: it ended on its budget while its loss still fell."""
    if history.get("val_loss"):
        return bool(history.get("stopped", False))
    return plateaued(history["loss"])


def train(X, labels, seed: int = 0, supervision: str = "multitask", fusion: str = "none",
          fusion_layer: str | None = None, epochs: int = 10, n_pairs: int = 1000,
          batch_size: int = 100, positive_fraction: float = 0.5, margin: float = MARGIN,
          lam: float = LAMBDA, width: float = 1.0, merge: str = "sum",
          optimizer: str = "adam", learning_rate: float | None = None,
          weight_decay: float = WEIGHT_DECAY, gt=None, hard_fraction: float = 0.0, hard_k: int = 10,
          augment_shift: float = 0.0, augment_light: float = 0.0, monitor=None, cache=True, progress: bool = False, was_cached=None,
          stop_patience: int = 0):
    """Train a Siamese network on pairs of the labelled frames (cached on disk).

    X: (N, H, W, C) float32 in [0, 1], every frame of the sequence (C = 3 RGB, 1 depth, 4 RGB-D).
    labels: (N,) int place labels from ``place_labels``; frames labelled -1 never enter a pair.
    seed: seeds the initial weights and the pairs. supervision, fusion, fusion_layer, margin,
    lam, width, merge, optimizer, learning_rate, weight_decay: see ``build``.
    epochs: passes; each draws n_pairs new pairs (``make_pairs``, rounded up to whole batches of
    ``batch_size`` pairs). gt: optional (N, N) bool ground truth: negatives are then pairs it calls
    no loop, and a ``hard_fraction`` (0..1) of each epoch's negatives are mined among the
    ``hard_k`` nearest such frames by the network as it stands (``hard_negatives``; needs gt).
    augment_shift, augment_light: ``augment``'s shift and photometric range for every training
    image (0, 0: the frames as they are).
    stop_patience: 0 trains every one of ``epochs`` epochs; P > 0 stops once the held-out loss (pairs
    of ``validation_frames``, kept out of training) has not fallen by ``STOP_MIN_DELTA`` of its best for
    P epochs, ``epochs`` then being the cap (:func:`converged` reads it).
    monitor: optional (key, fn): fn(descriptor model) -> float is recorded after every epoch in
    history["monitor"] (e.g. the held-out AP, watched and never used to stop or choose); key (a
    string) names what fn measures in the cache key. cache: as ``greenloop.methods.dictionary.cnn.train``
    (results/models/ or $GREENLOOP_CACHE, keyed by ``util.cache.cache_key`` of the data, labels,
    ground truth and every parameter). progress: a tqdm bar on stderr. was_cached: optional list;
    True is appended when the network is read from the cache, False when it is trained here.
    Returns (descriptor, history, pairs): the descriptor model (frames -> (N, DESCRIPTOR_DIM));
    history with per-epoch 'loss', 'val_loss' (under early stopping, else empty), 'epoch_seconds' and
    'monitor', 'stopped' (the held-out loss stopped falling within the cap), 'seconds' (training wall time),
    'cpu_seconds' (CPU time of all threads), 'n_classes', 'n_train_frames'; pairs =
    {'pairs': (epochs*P, 2) int64, 'same': bool}, every pair trained on.
    """
    X = np.asarray(X, dtype=np.float32)
    labels = np.asarray(labels, dtype=np.int64)
    if X.ndim != 4 or labels.shape != (len(X),):
        raise ValueError(f"X must be (N, H, W, C) and labels (N,), got {X.shape} and {labels.shape}")
    positive_int("epochs", epochs, whole_floats=True)
    positive_int("batch_size", batch_size, whole_floats=True)
    if int(stop_patience) < 0:
        raise ValueError(f"stop_patience must be 0 (a fixed budget) or a positive number of epochs, got {stop_patience}")
    _check(supervision, fusion, fusion_layer, merge, X.shape[-1])
    if not 0 <= hard_fraction <= 1 or (hard_fraction and gt is None):
        raise ValueError(f"hard_fraction must be in [0, 1] and needs gt, got {hard_fraction} (gt given: {gt is not None})")
    gt = None if gt is None else np.asarray(gt, dtype=bool)
    params = dict(model="xu2022_siamese", version=CACHE_VERSION, seed=int(seed),
                  supervision=supervision, fusion=fusion, fusion_layer=fusion_layer,
                  epochs=int(epochs), n_pairs=int(n_pairs), batch_size=int(batch_size),
                  positive_fraction=float(positive_fraction), margin=float(margin), lam=float(lam),
                  width=float(width), merge=merge if fusion == "mid" else None,
                  optimizer=optimizer, learning_rate=learning_rate, weight_decay=float(weight_decay),
                  hard_fraction=float(hard_fraction), hard_k=int(hard_k), augment_shift=float(augment_shift),
                  augment_light=float(augment_light),
                  gt_key=None if gt is None else cache_key(gt, labels),
                  monitor_key=None if monitor is None else monitor[0],
                  **({"stop_patience": int(stop_patience), "validation_every": VALIDATION_EVERY} if stop_patience else {}))
    key = cache_key(X, labels, **params)
    if was_cached is not None:
        was_cached.append(is_cached(key, cache))
    fn = None if monitor is None else monitor[1]
    return cached_model(key, cache, lambda: _fit(X, labels, progress, gt, fn, **params), params, "pairs.npz",
                        compile=False)
