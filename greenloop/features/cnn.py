"""The CNN extractor family: Keras applications, the Keras ports and the TFLite MobileNets.

``extract_cnn`` follows the extractor protocol of ``features.descriptor.EXTRACTORS`` (see
``registry.Options``). Models are built once per process (``clear_models`` forgets them).
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib
import io
import random
import re
import time
import warnings
import weakref
from pathlib import Path

import numpy as np

from greenloop.datasets.synthetic import build_scene, render_frame, route_world
from greenloop.backbones import efficientnet_lite as _lite, ghostnet as _ghostnet, mobilenet_tflite as _tflite, shufflenet as _shufflenet
from greenloop.features.frames import load, rgb_batch
from greenloop.features.registry import Backbone, BACKBONES, Options, RANDOM_INIT_SEED
from greenloop.features.weights import _missing_weights_message, source_key, WeightsNotFoundError
from greenloop.util import cache, devices
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

# the Keras ports: build (input_shape -> headless pooled model), native weights suffix, its loader
_PORTS = {
    "ghostnet": (lambda shape: _ghostnet.build_ghostnet(input_shape=shape, include_top=False,
                                                        pooling="avg"),
                 ".safetensors", _ghostnet.load_timm_weights),
    "efficientnet_lite": (lambda shape: _lite.build_efficientnet_lite0(input_shape=shape),
                          ".pth", _lite.load_weights),
    "shufflenet": (lambda shape: _shufflenet.build_shufflenet_v2(input_shape=shape), None, None),
}

def _seeded(fn, seed=RANDOM_INIT_SEED):
    """Run fn() with Keras's global seed set (deterministic initialisers); Python's and NumPy's global
    random states are restored afterwards so callers' streams are not disturbed."""
    import keras
    py_state, np_state = random.getstate(), np.random.get_state()
    keras.utils.set_random_seed(seed)
    try:
        return fn()
    finally:
        random.setstate(py_state)
        np.random.set_state(np_state)

@functools.lru_cache(maxsize=4)
def _cnn_model(name: str, source_key, size: tuple[int, int]):
    """Keras model (N, h, w, 3) -> (N, D) for a CNN backbone. source_key: None, 'download' or
    (path string, mtime) (the mtime keys the cache to the file's content)."""
    import keras
    b = BACKBONES[name]
    shape = (size[1], size[0], 3)
    source = source_key[0] if isinstance(source_key, tuple) else source_key
    if b.kind in _PORTS:
        build, suffix, load_native = _PORTS[b.kind]
        model = _seeded(lambda: build(shape))
        if source is not None:
            path = Path(source)
            if suffix is not None and path.suffix == suffix:
                load_native(model, path)  # ValueError on a wrong architecture
            else:
                try:
                    model.load_weights(str(path))
                except Exception as e:
                    raise ValueError(f"weights file {path} does not fit {b.name} (expected its "
                                     f"{suffix} file {b.weights_file} or Keras weights of the "
                                     f"same port): {_short(e)}") from e
        return model
    ctor = getattr(keras.applications, b.app)
    kwargs = dict(include_top=b.top_layer is not None, input_shape=shape)
    if b.top_layer is None:
        kwargs["pooling"] = "avg"
    if source is None:
        model = _seeded(lambda: ctor(weights=None, **kwargs))
    elif source == "download":
        try:
            model = ctor(weights="imagenet", **kwargs)
        except Exception as e:
            raise WeightsNotFoundError(f"{_missing_weights_message(b)}. Keras could not download "
                                       f"{b.weights_file}: {e}") from e
    else:
        try:
            model = _seeded(lambda: ctor(weights=str(source), **kwargs))
        except Exception as e:
            raise ValueError(f"weights file {source} does not fit {b.name} ({b.app}, include_top="
                             f"{kwargs['include_top']}): {type(e).__name__}: {_short(e)}") from e
    if b.top_layer is None:
        return model
    return keras.Model(model.inputs, model.get_layer(b.top_layer).output, name=b.name)

@functools.lru_cache(maxsize=8)
def _tflite_interpreter(name: str, source_key, batch: int):
    """(interpreter, frames per invoke) for a TFLite backbone's graph file, resized to ``batch``
    frames where the graph allows it; checked to be that backbone's graph."""
    path = source_key[0]
    interp, used = _tflite.load_interpreter(path, batch)
    _tflite.check_graph(interp, name, path)
    return interp, used

def _short(e: Exception, n: int = 300) -> str:
    text = " ".join(str(e).split())
    return text if len(text) <= n else text[:n] + " ..."

def _preprocess_fn(b: Backbone):
    if b.kind == "ghostnet":
        return _ghostnet.preprocess_input
    if b.kind == "efficientnet_lite":
        return _lite.preprocess_input
    if b.kind == "shufflenet":
        return _shufflenet.preprocess_input
    module = importlib.import_module(f"keras.applications.{b.module}")
    return module.preprocess_input

def _batches(n, batch_size):
    return [(i, min(i + batch_size, n)) for i in range(0, n, batch_size)]



def _progress(total, desc, progress):
    return tqdm(total=total, desc=desc, unit="img", disable=not progress)


# Keras model -> {calibration key (None: float32): its TFLite interpreter} (keras_predict), forgotten with the model
_LITE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
# The int8 graphs' fixed calibration set (int8_calibration_frames): CALIBRATION_VIEWS frames of the synthetic
# generator (seed 0, evenly along its route, CALIBRATION_SIZE pixels), each also under the photometric changes
# of CALIBRATION_GAMMAS, CALIBRATION_DIM (brightness scaled) and CALIBRATION_CONTRAST and mirrored, so that its
# activation ranges cover bright, dark and washed-out real frames without any data of the user's. Chosen on
# R@1 of Nordland's and Gardens Point's target streams against sets without the dark views and sets of those
# datasets' own frames (tools/int8_measure.py): none kept every night-time query of Gardens Point.
CALIBRATION_VIEWS, CALIBRATION_SIZE, CALIBRATION_GAMMAS, CALIBRATION_DIM, CALIBRATION_CONTRAST = \
    24, (160, 120), (0.5, 2.0, 3.0), 0.3, 1.8
# what a cached int8 descriptor's key records of its calibration set (features.descriptor)
CALIBRATION_KEY = (f"synthetic seed 0, {CALIBRATION_VIEWS} views at {CALIBRATION_SIZE}, gammas {CALIBRATION_GAMMAS}, "
                   f"dimmed {CALIBRATION_DIM}, contrast {CALIBRATION_CONTRAST}, mirrored")
# the int8 graph's outputs must keep this cosine with the float model's on the calibration frames
INT8_MIN_COSINE = 0.9
# backbone kinds whose Keras networks run as TFLite graphs (keras_predict): the EfficientNet-Lite port,
# a family made for that runtime. The converter's graphs of Keras applications (VGG19, MobileNet v3)
# gave inf / nan here, so those keep predict_on_batch.
LITE_KINDS = ("efficientnet_lite",)


def predictor(b: Backbone, model, calibration=None):
    """The predict function of backbone ``b``'s Keras ``model``: :func:`keras_predict` for
    ``LITE_KINDS`` (with ``calibration``: its full-integer int8 graph), ``model.predict_on_batch``
    for the others (which refuse a calibration: ValueError)."""
    if b.kind in LITE_KINDS:
        return keras_predict(model, calibration)
    if calibration is not None:
        raise ValueError(f"{b.name} has no int8 TFLite graph: only {LITE_KINDS} networks run as TFLite graphs here")
    return model.predict_on_batch


@functools.lru_cache(maxsize=1)
def int8_calibration_frames() -> np.ndarray:
    """The fixed calibration set of every int8 graph (:func:`keras_predict`): (7 * CALIBRATION_VIEWS,
    h, w, 3) uint8 RGB, CALIBRATION_SIZE (w, h): the synthetic generator's frames (seed 0, noiseless
    renders evenly along a 200-frame route), then the same under gamma 0.5, 2 and 3, dimmed to 0.3,
    contrast x1.8 about mid-grey and mirrored. The same bytes on every machine, and no data of the user's."""
    scene, (poses, _) = build_scene(0), route_world(200, 0)
    F = np.stack([render_frame(scene, poses[i], CALIBRATION_SIZE)[0]
                  for i in np.linspace(0, len(poses) - 1, CALIBRATION_VIEWS).round().astype(int)]).astype(np.float32)
    views = [F] + [255 * (F / 255) ** np.float32(g) for g in CALIBRATION_GAMMAS] + [F * np.float32(CALIBRATION_DIM)]
    views += [np.clip((F - 128) * np.float32(CALIBRATION_CONTRAST) + 128, 0, 255), F[:, :, ::-1]]
    return np.rint(np.concatenate(views)).astype(np.uint8)


def keras_predict(model, calibration=None):
    """``predict(x)`` of a Keras model: x (N, h, w, c) float32, its preprocessed input -> the model's
    outputs as ``model.predict_on_batch`` gives them (an array, or a list in the model's output order).

    With the tensorflow backend the model runs as a float32 TFLite graph converted from it once per
    model (XNNPACK kernels, one thread per core: the runtime of the ImageNet MobileNet graphs), checked
    on a probe batch to give the Keras model's outputs to float32 rounding. With another backend
    (jax on a GPU) it is ``predict_on_batch``. Raises RuntimeError when the graph's outputs differ.
    calibration: None, or (K, h, w, c) float32 preprocessed inputs: the model runs as a full-integer
    int8 graph (post-training quantisation, every activation range measured on them; float32 in and
    out), converted once per model and calibration set (``util.cache.cached_graph``) and checked to
    keep INT8_MIN_COSINE with the model's outputs on the first of them; needs the tensorflow
    backend (ValueError otherwise)."""
    import keras
    if keras.backend.backend() != "tensorflow":
        if calibration is not None:
            raise ValueError("an int8 TFLite graph needs Keras's tensorflow backend (KERAS_BACKEND=tensorflow)")
        return model.predict_on_batch
    calib = None if calibration is None else np.ascontiguousarray(calibration, dtype=np.float32)
    ckey = None if calib is None else hashlib.sha1(calib.view(np.uint8)).hexdigest()[:16]
    graphs = _LITE.setdefault(model, {})
    if ckey not in graphs:
        graphs[ckey] = _lite_graph(model, calib, ckey)
    interp, inp, outs = graphs[ckey]

    def predict(x):
        x = np.ascontiguousarray(x, dtype=np.float32)
        if tuple(interp.get_input_details()[0]["shape"]) != x.shape:
            interp.resize_tensor_input(inp, x.shape)
            interp.allocate_tensors()
        interp.set_tensor(inp, x)
        interp.invoke()
        got = [interp.get_tensor(o) for o in outs]
        return got[0] if len(model.outputs) == 1 else got
    return predict


def _lite_graph(model, calib=None, ckey=None):
    """(interpreter, input index, output indices in the model's order) of a Keras model converted to a
    TFLite graph with a free batch dimension (once per network: util.cache.cached_graph): float32, after
    a probe batch gave the model's outputs; or, with calib (K, h, w, c) float32 inputs (ckey: their
    hash), full-integer int8 calibrated on them (:func:`_check_int8`)."""
    import tensorflow as tf
    # the model's own tf.function: from_keras_model (dictionary.stream's converter) fails on the Lite port's
    # several-output models under Keras 3
    def convert() -> bytes:
        spec = tf.TensorSpec((None, *model.inputs[0].shape[1:]), tf.float32)
        fn = tf.function(lambda x: model(x, training=False), input_signature=[spec])
        conv = tf.lite.TFLiteConverter.from_concrete_functions([fn.get_concrete_function()], model)
        if calib is not None:   # post-training full-integer: int8 weights and activations, float32 in and out
            conv.optimizations = [tf.lite.Optimize.DEFAULT]
            conv.representative_dataset = lambda: ([x[None]] for x in calib)
            conv.target_spec.supported_ops = [tf.lite.OpsSet.TFLITE_BUILTINS_INT8]
        with contextlib.redirect_stdout(io.StringIO()), devices.without_backend_notices(), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r"Statistics for quantized inputs")
            return conv.convert()

    settings = dict(converter=f"from_concrete_functions {tf.__version__}")
    if calib is not None:
        settings.update(quantisation="full-integer int8", calibration=ckey)
    flat = cache.cached_graph(cache.model_key(model, **settings), convert)
    with warnings.catch_warnings():  # the interpreter's deprecation notice
        warnings.filterwarnings("ignore", message=r"(?s).*deprecated", category=UserWarning)
        interp = tf.lite.Interpreter(model_content=flat, num_threads=_tflite._threads())
    # outputs are named Identity, Identity_1, ... in the order the function returns them
    details = sorted(interp.get_output_details(),
                     key=lambda d: int((re.findall(r"_(\d+)$", d["name"]) or [0])[0]))
    if calib is not None:
        return _check_int8(model, interp, details, calib[:4])
    probe = np.random.default_rng(0).uniform(-1, 1, (2, *model.inputs[0].shape[1:])).astype(np.float32)
    for w, got in _probe_outputs(model, interp, details, probe):
        if got.shape != w.shape or not np.allclose(got, w, rtol=1e-3, atol=1e-4 * max(np.abs(w).max(), 1e-12)):
            raise RuntimeError(f"the TFLite graph of {model.name} does not give its outputs on a probe batch")
    return interp, interp.get_input_details()[0]["index"], [d["index"] for d in details]


def _probe_outputs(model, interp, details, probe) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(the Keras model's output, the TFLite graph's), ...] per output (``details``' order) on the probe
    batch (k, h, w, c) float32: the check of a converted graph against its model."""
    interp.resize_tensor_input(interp.get_input_details()[0]["index"], probe.shape)
    interp.allocate_tensors()
    interp.set_tensor(interp.get_input_details()[0]["index"], probe)
    interp.invoke()
    want = model.predict_on_batch(probe)
    return [(np.asarray(w), interp.get_tensor(d["index"]))
            for d, w in zip(details, want if isinstance(want, (list, tuple)) else [want])]


def _check_int8(model, interp, details, probe):
    """(interpreter, input index, output indices) of an int8 graph whose every output keeps
    INT8_MIN_COSINE (per frame, flattened) with the model's on probe (k, h, w, c) float32 inputs;
    RuntimeError otherwise (a graph quantised out of its calibration's range)."""
    for w, got in _probe_outputs(model, interp, details, probe):
        w, got = w.reshape(len(probe), -1), got.reshape(len(probe), -1)
        cos = (w * got).sum(1) / np.maximum(np.linalg.norm(w, axis=1) * np.linalg.norm(got, axis=1), 1e-12)
        if got.shape != w.shape or not np.all(cos >= INT8_MIN_COSINE):
            raise RuntimeError(f"the int8 TFLite graph of {model.name} does not keep a cosine of {INT8_MIN_COSINE} "
                               f"with its float outputs on its calibration frames")
    return interp, interp.get_input_details()[0]["index"], [d["index"] for d in details]


# (warm_key, batch length) pairs run_model has warmed up in this process (cleared with the models)
_WARMED: set = set()


def run_model(predict, frames, batch_fn, batch_size, progress, desc, warm_key=None):
    """Batched ``predict(batch_fn(frames[i:j]))`` (:func:`predictor`'s or a TFLite runner)
    with an untimed warm-up batch per batch length; returns (features (N, D) float32, seconds per image).
    warm_key: what identifies the traced model and its input size (None: warm up on every call). With
    it, only the first call of each batch length warms up, so that a stream that describes one frame
    per call runs the network once per frame, not twice."""
    n = len(frames)
    spans = _batches(n, batch_size)
    # warm-up, untimed: traces the graph for the full batch shape and, if different, the last one
    first, last = spans[0], spans[-1]
    for i, j in [first] + ([last] if last[1] - last[0] != first[1] - first[0] else []):
        if warm_key is not None and (warm_key, j - i) in _WARMED:
            continue
        predict(batch_fn(frames[i:j]))
        if warm_key is not None:
            _WARMED.add((warm_key, j - i))
    out = []
    with _progress(n, desc, progress) as bar:
        t0 = time.perf_counter()
        for i, j in spans:
            out.append(np.asarray(predict(batch_fn(frames[i:j])), dtype=np.float32))
            bar.update(j - i)
        dt = time.perf_counter() - t0
    return np.concatenate(out).reshape(n, -1), dt / n


def extract_cnn(b: Backbone, frames_or_folder, source, size, opt: Options):
    """The extractor of the CNN kinds: frames -> (features (N, D) float32, s/image, {})."""
    frames = load(frames_or_folder, size, gray=False, limit=opt.limit, step=opt.step)
    key = source_key(source)
    if b.kind == "tflite" and isinstance(source, Path) and source.suffix == ".tflite":
        def predict(rgb):  # RGB 0..255 -> the graph's uint8 input: mobilenet_tflite.quantise_input
            interp, used = _tflite_interpreter(b.name, key, len(rgb))
            return _tflite.describe(interp, used, b.name, rgb)
        return (*run_model(predict, frames, lambda a: rgb_batch(a, size, opt.color), opt.batch_size, opt.progress,
                            f"{b.name} features", ("tflite", b.name, key)), {})
    model = _cnn_model(b.name, key, size)
    pre = _preprocess_fn(b)
    return (*run_model(predictor(b, model), frames, lambda a: pre(rgb_batch(a, size, opt.color)),
                        opt.batch_size, opt.progress, f"{b.name} features", ("keras", id(model))), {})


def clear_models() -> None:
    """Forget the CNN models and TFLite interpreters built so far."""
    _cnn_model.cache_clear()
    _tflite_interpreter.cache_clear()
    _LITE.clear()
    _WARMED.clear()
