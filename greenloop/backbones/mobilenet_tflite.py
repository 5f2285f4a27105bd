"""MobileNet v1 / v2 ImageNet descriptors from Google's uint8-quantised TFLite graphs.

The only ImageNet-trained MobileNets that can be had offline here are the quantised TensorFlow Lite
graphs of github.com/google-coral/test_data (Apache-2.0). They run with TensorFlow's own
interpreter (``tf.lite.Interpreter``); no other runtime is needed.

Descriptors (``GRAPHS``; the backbones ``mobilenetv1`` / ``mobilenetv2`` of greenloop.features)::

    backbone     D     graph file                                              feature map (7x7xD)
    mobilenetv1  1024  mobilenet_v1_1.0_224_quant_embedding_extractor.tflite  Conv2d_13_pointwise/Relu6
    mobilenetv2  1280  mobilenet_v2_1.0_224_quant.tflite                      Conv_1/Relu6 (1x1 320->1280)

The descriptor is the last feature map before the graph's own average pool (the classifier's input),
read from the interpreter (``experimental_preserve_all_tensors``), dequantised with the tensor's
scale and zero point and averaged over the 7x7 positions in float32; the graph's ``AvgPool`` output
is that mean rounded to its uint8 grid. Both graphs take a fixed 224x224x3 uint8 input.

Input (``quantise_input``): RGB 0..255 is preprocessed as MobileNet was trained (``x / 127.5 - 1``,
Keras's ``mobilenet.preprocess_input``) and quantised with the input tensor's own scale and zero
point (round half up, clipped to the dtype's range); for these graphs (scale 1/128, zero point 128)
that is the pixel value itself below 128 and one level above it from 128 on.

Interpreter settings: the interpreter's defaults (its XNNPACK delegate for the quantised
convolutions), one thread per usable core, and ``experimental_preserve_all_tensors`` so that the
feature map is not overwritten by later tensors once ``invoke`` returns. XNNPACK leaves the graphs'
average pools to the built-in kernels, so the feature map is a delegate output and is written out;
tests/test_pretrained.py checks that its mean equals the graph's own AvgPool output. (The built-in
kernels alone, ``BUILTIN_WITHOUT_DEFAULT_DELEGATES``, round some layers differently: descriptors
shift slightly, and with several threads they ran per-frame graphs far slower on a busy machine.)
Frames are batched with ``resize_tensor_input`` where the graph allows it (v1); the v2 classifier
reshapes to a fixed (1, 1001), so it runs one frame per ``invoke``.

Getting the files: ``https://github.com/google-coral/test_data/raw/master/<file>`` (``SOURCE_URL``);
put them in one folder and point ``GREENLOOP_WEIGHTS`` at it (or place them in
``$KERAS_HOME/models/``), see greenloop.features.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SOURCE_URL = "https://github.com/google-coral/test_data/raw/master/"
INPUT_SIZE = (224, 224)          # (width, height) of both descriptor graphs


@dataclass(frozen=True)
class Graph:
    """A descriptor graph: its file, the feature-map tensor (first ';'-separated part of its TFLite
    name), the graph's own pooled tensor (same mean, rounded to uint8) and the descriptor length."""
    file: str
    feature_tensor: str
    pooled_tensor: str
    dim: int


GRAPHS = {
    "mobilenetv1": Graph("mobilenet_v1_1.0_224_quant_embedding_extractor.tflite",
                         "MobilenetV1/MobilenetV1/Conv2d_13_pointwise/Relu6",
                         "MobilenetV1/Logits/AvgPool_1a/AvgPool", 1024),
    "mobilenetv2": Graph("mobilenet_v2_1.0_224_quant.tflite", "MobilenetV2/Conv_1/Relu6",
                         "MobilenetV2/Logits/AvgPool", 1280),
}
# ImageNet classifiers of the same source (1001 classes, 0 = background): used to check the graphs
CLASSIFIERS = ("mobilenet_v1_0.25_128_quant.tflite", "mobilenet_v1_0.5_160_quant.tflite",
               "mobilenet_v1_0.75_192_quant.tflite", "mobilenet_v2_1.0_224_quant.tflite",
               "tf2_mobilenet_v2_1.0_224_ptq.tflite")
LABELS_FILE = "imagenet_labels.txt"


def preprocess_input(x):
    """MobileNet's training preprocessing. x: RGB 0..255 (..., 3). Returns float32 x / 127.5 - 1."""
    return np.asarray(x, dtype=np.float32) / np.float32(127.5) - np.float32(1.0)


def _threads() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def load_interpreter(path, batch: int = 1):
    """A ready ``tf.lite.Interpreter`` for a graph file, its input resized to ``batch`` frames.

    Default kernels (XNNPACK), every tensor preserved, one thread per core (see module doc). Returns
    ``(interpreter, batch_used)``: batch_used is 1 when the graph cannot be resized (fixed reshapes).
    Raises FileNotFoundError for a missing file and ValueError for a file that is not a TFLite graph.
    """
    import tensorflow as tf
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"TFLite graph {path} not found; download it from "
                                f"{SOURCE_URL}{path.name}")

    def make():
        with warnings.catch_warnings():  # deprecation notice and "for debugging" notice
            warnings.filterwarnings("ignore", message=r"(?s).*(deprecated|preserve_all_tensors)",
                                    category=UserWarning)
            return tf.lite.Interpreter(model_path=str(path), num_threads=_threads(),
                                       experimental_preserve_all_tensors=True)

    try:
        interp = make()
    except (ValueError, RuntimeError) as e:
        raise ValueError(f"{path} is not a readable TFLite graph: {e}") from e
    if batch > 1:
        try:
            inp = interp.get_input_details()[0]
            interp.resize_tensor_input(inp["index"], [batch, *inp["shape"][1:]], strict=False)
            interp.allocate_tensors()
            return interp, batch
        except (ValueError, RuntimeError):
            interp = make()   # a failed allocation leaves the interpreter unusable
    interp.allocate_tensors()
    return interp, 1


def tensor_detail(interp, name: str) -> dict:
    """The one tensor whose TFLite name starts with ``name`` (its first ';'-separated part), as
    ``get_tensor_details`` gives it. Raises ValueError when the graph has no such tensor or several
    (fused names can share a first part, e.g. a bias and the layer output)."""
    found = [d for d in interp.get_tensor_details() if d["name"].split(";")[0] == name]
    if len(found) != 1:
        raise ValueError(f"the graph has {len(found) or 'no'} tensors named {name!r}"
                         f"{' (ambiguous)' if found else ''}")
    return found[0]


def dequantise(q: np.ndarray, detail: dict) -> np.ndarray:
    """Real values of a quantised tensor: ``(q - zero_point) * scale`` (per-tensor quantisation),
    float32; a float tensor is returned as float32."""
    scale, zero = detail["quantization"]
    if scale == 0:
        return np.asarray(q, dtype=np.float32)
    return (np.asarray(q, dtype=np.float32) - np.float32(zero)) * np.float32(scale)


def quantise_input(rgb, detail: dict) -> np.ndarray:
    """RGB 0..255 frames (b, h, w, 3) -> the graph's input values: ``preprocess_input``, quantised
    with the input tensor's scale/zero point (round half up), clipped to its integer dtype."""
    dtype = np.dtype(detail["dtype"])
    real = preprocess_input(rgb)
    scale, zero = detail["quantization"]
    if scale == 0:                       # float graph
        return real.astype(dtype)
    info = np.iinfo(dtype)
    q = np.floor(real / np.float32(scale) + np.float32(zero) + np.float32(0.5))
    return np.clip(q, info.min, info.max).astype(dtype)


def run(interp, batch: int, rgb, names) -> dict[str, np.ndarray]:
    """Run frames through an interpreter and return the named tensors, dequantised.

    interp, batch: from ``load_interpreter``. rgb: (N, 224, 224, 3) RGB 0..255 (uint8 or float),
    N a multiple of ``batch`` or less than it. names: tensor names (``tensor_detail``), or
    ``"output"`` for the graph's output. Returns name -> float32 array (N, ...).
    """
    inp = interp.get_input_details()[0]
    if tuple(rgb.shape[1:]) != tuple(inp["shape"][1:]):
        raise ValueError(f"the graph takes frames of shape {tuple(inp['shape'][1:])}, got "
                         f"{tuple(rgb.shape[1:])}")
    details = {n: interp.get_output_details()[0] if n == "output" else tensor_detail(interp, n)
               for n in names}
    out = {n: [] for n in names}
    q = quantise_input(rgb, inp)
    for i in range(0, len(q), batch):
        chunk = q[i:i + batch]
        if len(chunk) != batch:
            raise ValueError(f"{len(rgb)} frames do not split into batches of {batch}")
        interp.set_tensor(inp["index"], chunk)
        interp.invoke()
        for n, d in details.items():
            out[n].append(dequantise(interp.get_tensor(d["index"]), d))
    return {n: np.concatenate(v) for n, v in out.items()}


def check_graph(interp, backbone: str, path) -> None:
    """ValueError unless the interpreter holds ``backbone``'s graph: a 224x224x3 input and the
    feature map of GRAPHS[backbone] with D channels (another network's .tflite fails here)."""
    g = GRAPHS[backbone]
    shape = tuple(interp.get_input_details()[0]["shape"][1:])
    try:
        fshape = tuple(tensor_detail(interp, g.feature_tensor)["shape"][1:])
    except ValueError:
        fshape = None
    if shape != (INPUT_SIZE[1], INPUT_SIZE[0], 3) or fshape is None or fshape[-1] != g.dim:
        raise ValueError(f"{path} does not fit {backbone}: it needs {g.file} (input 224x224x3 and "
                         f"the {g.dim}-channel tensor {g.feature_tensor}); got input {shape}, "
                         f"feature map {fshape}")


def describe(interp, batch: int, backbone: str, rgb) -> np.ndarray:
    """(N, D) float32 descriptors of frames (N, 224, 224, 3) RGB 0..255: the dequantised feature map
    of GRAPHS[backbone], averaged over its spatial positions in float32."""
    name = GRAPHS[backbone].feature_tensor
    return run(interp, batch, rgb, [name])[name].mean(axis=(1, 2), dtype=np.float32)
