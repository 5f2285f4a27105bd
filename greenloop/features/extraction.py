"""The public extraction calls: ``extract`` (one backbone), ``extract_spec``, ``extract_rgbd``,
``time_per_image``; ``EXTRACTORS`` maps each backbone kind to its family's extractor (one protocol,
``registry.Options``)."""
from __future__ import annotations

import os
import warnings

import numpy as np

from greenloop.datasets import sequence
from greenloop.features import layers
from greenloop.features.cnn import clear_models, extract_cnn
from greenloop.features.frames import depth_to_uint8
from greenloop.features.pixels import extract_gradients, extract_patchnorm, extract_pixels
from greenloop.features.registry import (BACKBONES, CNN_KINDS, DEFAULT_VOCAB_SIZE, DEPTH_MAX_M,
                                         ExtractInfo, Options, get_backbone, input_size_of,
                                         split_spec)
from greenloop.features.sift import extract_sift
from greenloop.features.spot import _spot_model, extract_spot
from greenloop.features.weights import Resolved, resolve

EXTRACTORS = {**{kind: extract_cnn for kind in CNN_KINDS}, "pixels": extract_pixels,
              "pixels-patchnorm": extract_patchnorm, "gradients": extract_gradients,
              "sift_bovw": extract_sift, "spot_cnn": extract_spot, "fused": layers.extract_fused}


def extract(frames_or_folder, backbone: str, weights="auto", batch_size: int = 32,
            progress: bool = True, input_size=None, *, return_info: bool = False,
            limit: int | None = None, vocabulary=None, vocab_size: int = DEFAULT_VOCAB_SIZE,
            seed: int = 0, step: int = 1, resolved: Resolved | None = None, color: str = "rgb"):
    """Describe every frame of a sequence with one vector.

    frames_or_folder: a sequence folder (its rgb/ frames are loaded with
        greenloop.datasets.sequence.load_frames at the backbone's input size), or an array of frames: (N, H, W, 3)
        RGB (BGR with color="bgr"), (N, H, W, 1) or (N, H, W) single-channel (depth/gray: replicated
        to 3 channels for the CNNs), uint8 0..255 or float in [0, 1]; resized to the input size as
        needed, through ``sequence.preprocess_image`` for the gray descriptors.
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
    resolved: ``weights.resolve(backbone, weights)`` already computed by the caller (then not
        resolved again; ``weights`` is ignored).
    color: channel order of a 3-channel frame array: "rgb" or "bgr" (frames as ``cv2.imread``
        decodes them, the streaming detectors' input); ignored for a folder (decoded to RGB).
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
    if color not in ("rgb", "bgr"):
        raise ValueError(f"color must be 'rgb' or 'bgr', got {color!r}")
    if isinstance(frames_or_folder, (str, os.PathLike)):
        color = "rgb"                      # load_frames decodes a folder's files to RGB
    size = input_size_of(input_size, b.input_size)
    if b.fixed_input and size != b.input_size:
        why = ("its fully connected layer takes the 7x7 map of a 224x224 input" if b.top_layer
               else "the TFLite graph's; its random-init control uses the same")
        raise ValueError(f"{b.name} runs at its fixed {b.input_size[0]}x{b.input_size[1]} input "
                         f"({why}), got input_size={input_size!r}: pass input_size=None")
    label, source = resolved if resolved is not None else resolve(b.name, weights)
    if b.kind in CNN_KINDS and min(size) < 32:
        raise ValueError(f"{b.name} needs an input of at least 32x32 pixels, got {size}")
    opt = Options(int(batch_size), progress, limit, int(step), vocabulary, vocab_size, seed, color)
    X, spi, extra = EXTRACTORS[b.kind](b, frames_or_folder, source, size, opt)
    if b.kind == "spot_cnn":   # the model's own input size
        size = None
    X = np.ascontiguousarray(X, dtype=np.float32)
    if not return_info:
        return X
    return X, ExtractInfo(backbone=b.name, weights=label, dim=X.shape[1], n_images=len(X),
                          input_size=size, layer=b.layer, seconds_per_image=float(spi), extra=extra)


def extract_spec(frames_or_folder, spec: str, weights="auto", input_size=None, **kw):
    """``extract`` for a backbone-list entry (:func:`split_spec`): ``input_size`` applies to the CNN
    backbones whose input is not fixed (the TFLite MobileNets always run at 224x224); ``kw`` go to
    ``extract`` (``return_info``, ``step``, ``vocab_size``, ...). A layer descriptor
    (``"mobilenetv2@mid-grid2"``, greenloop.features.layers) goes to ``layers.extract_spec``.
    Returns what ``extract`` returns."""
    name, w = split_spec(spec, weights)
    if layers.split(name):                 # "backbone@depth-pooling": a layer descriptor
        return layers.extract_spec(frames_or_folder, name, w, **kw)
    b = BACKBONES[name]
    size = input_size if b.kind in CNN_KINDS and not b.fixed_input else None
    return extract(frames_or_folder, name, weights=w, input_size=size, **kw)


def resolve_spec(spec: str, weights="auto", warn: bool = True) -> Resolved:
    """``weights.resolve`` of a backbone-list entry (:func:`extract_spec`'s ``spec``; a layer descriptor:
    of its backbone), for a caller that describes frame by frame and hands it to :func:`extract_spec`
    as ``resolved``, so that the weights are looked up once, not at every frame."""
    name, w = split_spec(spec, weights)
    return resolve(name.partition("@")[0], w, warn)


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
    kwargs["resolved"] = kwargs.get("resolved") or resolve(b.name, weights)   # once for both passes
    Xr, ir = extract(folder, b.name, weights, batch_size, progress, input_size, return_info=True,
                     limit=limit, step=step, **kwargs)
    size = input_size_of(input_size, b.input_size) if b.kind != "spot_cnn" else None
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
        w, h = input_size_of(input_size, b.input_size) or (640, 480)
        frames = np.random.default_rng(seed).integers(0, 256, (n_images, h, w, 3), dtype=np.uint8)
    _, info = extract(frames, b.name, weights, batch_size, False, input_size, return_info=True,
                      seed=seed)
    return info.seconds_per_image




def clear_cache() -> None:
    """Forget the models built so far (frees memory; the next extract rebuilds)."""
    clear_models()
    _spot_model.cache_clear()
