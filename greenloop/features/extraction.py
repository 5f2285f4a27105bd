"""Shortcuts over :class:`~greenloop.features.descriptor.Descriptor`, for callers that describe once:
``extract`` (frames by name), ``extract_all`` (a notebook's descriptor list on one sequence, cached),
``extract_rgbd`` (RGB beside depth), ``time_per_image``; and the notebooks' random-init report."""
from __future__ import annotations

import contextlib
import warnings

import numpy as np

from greenloop.datasets import sequence
from greenloop.features.cnn import clear_models
from greenloop.features.descriptor import Descriptor, get
from greenloop.features.frames import depth_to_uint8
from greenloop.features.registry import DEFAULT_VOCAB_SIZE, DEPTH_MAX_M, ExtractInfo
from greenloop.features.spot import _spot_model


def extract(frames_or_folder, backbone: str, weights="auto", batch_size: int = 32, progress: bool = True,
            input_size=None, *, return_info: bool = False, limit: int | None = None, vocabulary=None,
            vocab_size: int = DEFAULT_VOCAB_SIZE, seed: int = 0, step: int = 1, color: str = "rgb"):
    """``get(backbone, weights, input_size=..., vocabulary=..., vocab_size=..., seed=...)`` applied to
    frames_or_folder (its :meth:`~Descriptor.extract`: step, limit, batch_size, progress, color).
    Returns features (N, D) float32, or (features, ExtractInfo) with return_info. Raises as ``get``."""
    d = get(backbone, weights, input_size=input_size, vocabulary=vocabulary, vocab_size=vocab_size, seed=seed)
    X, info = d.extract(frames_or_folder, step=step, limit=limit, batch_size=batch_size, progress=progress, color=color)
    return (X, info) if return_info else X


@contextlib.contextmanager
def random_init_reported(d: Descriptor):
    """Context for an extraction a notebook shows: where ``weights="auto"`` found no ImageNet weights
    for ``d``, print that in one line (no file paths), and keep the UserWarning that says the same
    with a path into the package out of the notebook."""
    if isinstance(d.weights, str) and d.weights == "auto" and d.resolved.label == "random init":
        print(f"{d.parsed.base}: no ImageNet weights on this machine, so its row is a RANDOM-INITIALISED "
              f"network (docs/weights.md says where the files go)")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*RANDOM-INITIALISED", category=UserWarning)
        yield


def extract_all(folder, specs, weights="auto", input_size=None, step: int = 1,
                vocab_size: int = DEFAULT_VOCAB_SIZE, spot_model=None, cache=True):
    """Descriptors of one sequence folder for every name of a notebook's list, each computed once
    per dataset and settings (:meth:`Descriptor.describe`, the descriptor cache).

    specs: descriptor names (``registry.parse``; e.g. ``["pixels", "mobilenetv2", "mobilenetv2:random"]``).
    weights: the CNNs' (a ":random" / ":imagenet" suffix overrides it). input_size: the study's
    CNN input (``get``'s cnn_input_size). step: every step-th frame. vocab_size: sift_bovw's words.
    spot_model: the trained keras Model for a "spot_cnn" entry. cache: as ``Descriptor.describe``.
    Prints one line per entry (label, D, ms/image) and, where weights="auto" fell back to a
    random-init network, one line saying so. Returns (feats {spec: (N, D) float32}, infos {spec: ExtractInfo}).
    """
    feats, infos = {}, {}
    for spec in specs:
        d = get(spec, spot_model if spec == "spot_cnn" else weights, cnn_input_size=input_size,
                vocab_size=vocab_size, warn=False)
        with random_init_reported(d):
            feats[spec], infos[spec] = d.describe(folder, step=step, cache=cache)
        info = infos[spec]
        print(f"{info.label:42s} D={info.dim:5d}  {info.seconds_per_image * 1e3:8.2f} ms/image")
    clear_cache()
    return feats, infos


def extract_rgbd(folder, d, weights="auto", batch_size: int = 32, progress: bool = True, input_size=None, *,
                 max_depth: float = DEPTH_MAX_M, return_info: bool = False, limit: int | None = None,
                 step: int = 1):
    """RGB-D descriptors as in Qi et al. 2024: RGB features and depth features, concatenated.

    folder: a sequence folder with rgb/ and depth/ (uint16, metres = value / 5000). d: a Descriptor,
        or a name for ``get(d, weights, input_size=input_size)``. Depth is read with
        ``sequence.load_depth``, mapped to 0..255 by ``depth_to_uint8`` (fixed range 0..max_depth
        metres, default 10 m), replicated to 3 channels and described by the same descriptor.
    Returns (N, 2D) float32 ``[rgb features | depth features]`` (or with return_info, an ExtractInfo
    whose seconds_per_image is the sum for one RGB frame and one depth frame). Raises
    FileNotFoundError when there is no depth/ folder and ValueError when the counts differ.
    A sift_bovw without a vocabulary fits one per modality, on its frames.
    """
    d = d if isinstance(d, Descriptor) else get(d, weights, input_size=input_size)
    Xr, ir = d.extract(folder, step=step, limit=limit, batch_size=batch_size, progress=progress)
    size = d.input_size if d.backbone.kind != "spot_cnn" else None
    depth = sequence.load_depth(folder, size=size, limit=limit, step=step)
    if len(depth) != len(Xr):
        raise ValueError(f"{folder}: {len(Xr)} rgb frames but {len(depth)} depth frames; an RGB-D "
                         f"sequence needs one depth/N.png per rgb/N.png")
    Xd, idp = d.extract(depth_to_uint8(depth, max_depth), batch_size=batch_size, progress=progress)
    X = np.concatenate([Xr, Xd], axis=1)
    if not return_info:
        return X
    return X, ExtractInfo(backbone=ir.backbone, weights=ir.weights, dim=X.shape[1], n_images=len(X),
                          input_size=ir.input_size, layer=f"[rgb | depth] {ir.layer}",
                          seconds_per_image=ir.seconds_per_image + idp.seconds_per_image,
                          extra={"rgb": ir.extra, "depth": idp.extra, "max_depth_m": max_depth})


def time_per_image(name: str, weights="auto", input_size=None, n_images: int = 64,
                   batch_size: int = 32, seed: int = 0, frames=None) -> float:
    """Extraction seconds per image of a descriptor (``get(name, weights, input_size=...)``), after
    a warm-up batch. A Keras network costs the same with any weights, but mobilenetv1/v2 with their
    ImageNet files run the uint8 TFLite graph and with weights=None the float Keras control: two
    different programs with different times. frames: the frames to time on (array or folder);
    default ``n_images`` random RGB uint8 frames at the input size (a fair timing for CNNs, whose
    cost does not depend on content; for sift_bovw pass real frames)."""
    d = get(name, weights, input_size=input_size, seed=seed)
    if frames is None:
        w, h = d.input_size or (640, 480)
        frames = np.random.default_rng(seed).integers(0, 256, (n_images, h, w, 3), dtype=np.uint8)
    return d.extract(frames, batch_size=batch_size)[1].seconds_per_image


def clear_cache() -> None:
    """Forget the models built so far (frees memory; the next extraction rebuilds)."""
    clear_models()
    _spot_model.cache_clear()
