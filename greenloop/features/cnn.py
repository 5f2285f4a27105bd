"""The CNN extractor family: Keras applications, the Keras ports and the TFLite MobileNets.

``extract_cnn`` follows the extractor protocol of ``features.descriptor.EXTRACTORS`` (see
``registry.Options``). Models are built once per process (``clear_models`` forgets them).
"""
from __future__ import annotations

import contextlib
import functools
import importlib
import io
import random
import re
import time
import warnings
import weakref
from pathlib import Path

import numpy as np

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


# Keras model -> its TFLite interpreter (keras_predict), forgotten with the model
_LITE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
# backbone kinds whose Keras networks run as TFLite graphs (keras_predict): the EfficientNet-Lite port,
# a family made for that runtime. The converter's graphs of Keras applications (VGG19, MobileNet v3)
# gave inf / nan here, so those keep predict_on_batch.
LITE_KINDS = ("efficientnet_lite",)


def predictor(b: Backbone, model):
    """The predict function of backbone ``b``'s Keras ``model``: :func:`keras_predict` for
    ``LITE_KINDS``, ``model.predict_on_batch`` for the others."""
    return keras_predict(model) if b.kind in LITE_KINDS else model.predict_on_batch


def keras_predict(model):
    """``predict(x)`` of a Keras model: x (N, h, w, c) float32, its preprocessed input -> the model's
    outputs as ``model.predict_on_batch`` gives them (an array, or a list in the model's output order).

    With the tensorflow backend the model runs as a float32 TFLite graph converted from it once per
    model (XNNPACK kernels, one thread per core: the runtime of the ImageNet MobileNet graphs), checked
    on a probe batch to give the Keras model's outputs to float32 rounding. With another backend
    (jax on a GPU) it is ``predict_on_batch``. Raises RuntimeError when the graph's outputs differ."""
    import keras
    if keras.backend.backend() != "tensorflow":
        return model.predict_on_batch
    if model not in _LITE:
        _LITE[model] = _lite_graph(model)
    interp, inp, outs = _LITE[model]

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


def _lite_graph(model):
    """(interpreter, input index, output indices in the model's order) of a Keras model converted to a
    float32 TFLite graph with a free batch dimension (once per network: util.cache.cached_graph),
    after a probe batch gave the model's outputs."""
    import tensorflow as tf
    # the model's own tf.function: from_keras_model (dictionary.stream's converter) fails on the Lite port's
    # several-output models under Keras 3
    def convert() -> bytes:
        spec = tf.TensorSpec((None, *model.inputs[0].shape[1:]), tf.float32)
        fn = tf.function(lambda x: model(x, training=False), input_signature=[spec])
        with contextlib.redirect_stdout(io.StringIO()), devices.without_backend_notices():
            return tf.lite.TFLiteConverter.from_concrete_functions([fn.get_concrete_function()], model).convert()

    flat = cache.cached_graph(cache.model_key(model, converter=f"from_concrete_functions {tf.__version__}"), convert)
    with warnings.catch_warnings():  # the interpreter's deprecation notice
        warnings.filterwarnings("ignore", message=r"(?s).*deprecated", category=UserWarning)
        interp = tf.lite.Interpreter(model_content=flat, num_threads=_tflite._threads())
    # outputs are named Identity, Identity_1, ... in the order the function returns them
    details = sorted(interp.get_output_details(),
                     key=lambda d: int((re.findall(r"_(\d+)$", d["name"]) or [0])[0]))
    probe = np.random.default_rng(0).uniform(-1, 1, (2, *model.inputs[0].shape[1:])).astype(np.float32)
    interp.resize_tensor_input(interp.get_input_details()[0]["index"], probe.shape)
    interp.allocate_tensors()
    interp.set_tensor(interp.get_input_details()[0]["index"], probe)
    interp.invoke()
    want = model.predict_on_batch(probe)
    for d, w in zip(details, want if isinstance(want, (list, tuple)) else [want]):
        w, got = np.asarray(w), interp.get_tensor(d["index"])
        if got.shape != w.shape or not np.allclose(got, w, rtol=1e-3, atol=1e-4 * max(np.abs(w).max(), 1e-12)):
            raise RuntimeError(f"the TFLite graph of {model.name} does not give its outputs on a probe batch")
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
