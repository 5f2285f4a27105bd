"""Streaming loop-closure detection: raw camera frames in, closure events out (the speed path).

``Detector`` takes raw frames one at a time (``update``) or in windows (``update_many``), applies
the main paper's preprocessing (gray, 32x32, [0, 1]), classifies them with the paper's CNN and
updates the frequency-count dictionary (``greenloop.methods.dictionary.dictionary.LoopDetector``: a closure is declared
the first time a spot's count reaches tau, exactly like ``dictionary.closure_events``).

Frames
    H x W x 3 uint8 **BGR** (what ``cv2.imread`` and ``cv2.VideoCapture`` return; pass
    ``color="rgb"`` for RGB frames), or H x W / H x W x 1 uint8 gray. Any H, W: frames are
    resized to the model's input size (32 x 32) with ``cv2.INTER_AREA`` when shrinking and
    ``cv2.INTER_LINEAR`` when enlarging, as ``greenloop.datasets.sequence.load_frames`` does.

Preprocessing and training data
    One path: ``greenloop.datasets.sequence.preprocess_image`` (cvtColor BGR->gray, then INTER_AREA resize),
    which ``load_frames`` also applies to every frame it decodes in colour. A frame from disk and
    the same frame from a live camera give bit-identical model inputs (tests/test_stream.py).

Backends (all give the labels of ``argmax(model.predict(x))``; checked by tests/test_stream.py
and by ``python -m greenloop bench`` on every frame of the dataset)
    "numpy":  the paper's CNN written out in NumPy with the weights pulled from the Keras model
              (``greenloop.methods.dictionary.cnn.forward``, the fused trainer's own forward pass): conv 3x3 + ReLU
              (numba's ``kernels.conv_relu``, or im2col without numba), the 28800 x 68 dense layer
              as float32 matmuls (split over the worker threads for a window), argmax of the logits
              (softmax is monotonic). No extra dependency, instant to build.
    "tflite": TensorFlow's own TFLite interpreter (XNNPACK delegate), converted in memory from the
              Keras model or loaded from a ``.tflite`` file; one interpreter for single frames (2
              threads: the 7.8 MB dense layer is read from memory for every frame, and two cores
              share that memory traffic), one multi-thread interpreter for windows.
    "keras":  ``model.predict`` (the reference; slow, for comparison only).
    "auto":   "tflite" when TensorFlow has tf.lite, else "numpy" (paper's architecture only).

Why "auto" picks TFLite: in ``python -m greenloop bench`` (reference and candidates interleaved in
one process; the figures are in results/bench/bench.md) TFLite has the lowest window and
single-frame times of the backends that give Keras's labels on every frame; NumPy is the
dependency-free fallback. A numba forward pass (the training kernels of ``greenloop.util.numba_kernels``, with
the dense layer skipping the ReLU's zero rows) was no faster than TFLite and is not offered. Costs no
backend removes: the 28800 x 68 dense layer means reading a 7.8 MB weight matrix per forward pass
(2.2 MFLOP/frame), and the exact preprocessing of a 640x480 BGR frame must read its 921,600 bytes
(cvtColor). The 20x15 area shrink after it runs in ``greenloop.util.numba_kernels.area_shrink`` (the same bytes
as OpenCV, whose loop for this factor is scalar). The bench's floor row (one cvtColor pass over the window's frames on
all cores) bounds the window speed-up of any pipeline that converts colour with OpenCV. NumPy's
BLAS runs on one thread inside these calls (``kernels.one_blas_thread``): on a loaded 2-core machine a
two-thread matmul stalls whenever one thread is pre-empted.
"""
from __future__ import annotations

import contextlib
import io
import os
import warnings
from pathlib import Path

import numpy as np

from greenloop.datasets.sequence import preprocess_image
from greenloop.methods.dictionary import cnn
from greenloop.methods.dictionary.dictionary import LoopDetector
from greenloop.util import cache, devices
from greenloop.util.checks import positive_int
from greenloop.util.files import write_atomic
from greenloop.util.threads import one_blas_thread, run_chunked

BACKENDS = ("auto", "numpy", "tflite", "keras")
COLORS = ("bgr", "rgb")


# ---------------------------------------------------------------------------------------------
# preprocessing
# ---------------------------------------------------------------------------------------------
def _check_frame(frame, index=None) -> np.ndarray:
    where = "" if index is None else f" {index}"
    if not isinstance(frame, np.ndarray):
        raise ValueError(f"frame{where} must be a numpy array (H, W, 3) uint8 BGR or (H, W) gray, "
                         f"got {type(frame).__name__}")
    if frame.dtype != np.uint8:
        raise ValueError(f"frame{where} must be uint8 (0..255, as cv2.imread returns), got "
                         f"{frame.dtype}; convert with frame.astype(np.uint8) or "
                         f"(frame * 255).round().astype(np.uint8) for [0, 1] floats")
    if not (frame.ndim == 2 or (frame.ndim == 3 and frame.shape[2] in (1, 3))):
        raise ValueError(f"frame{where} must be (H, W, 3) colour or (H, W) / (H, W, 1) gray, got shape "
                         f"{frame.shape}; for a window of frames use update_many")
    if frame.shape[0] < 1 or frame.shape[1] < 1:
        raise ValueError(f"frame{where} is empty: shape {frame.shape}")
    return frame


def preprocess_u8(frame: np.ndarray, size=(32, 32), color: str = "bgr") -> np.ndarray:
    """The paper's preprocessing without the final scaling: gray, resized, uint8.

    frame: (H, W, 3) uint8 BGR (``color="rgb"`` for RGB) or (H, W) / (H, W, 1) uint8 gray.
    size: (width, height) in pixels.
    Returns (height, width) uint8: cvtColor to gray, then resize with INTER_AREA when the frame is
    wider than ``size`` and INTER_LINEAR otherwise (no resize when the size already matches),
    exactly as ``greenloop.datasets.sequence.load_frames`` treats a frame it decoded.
    """
    if color not in COLORS:
        raise ValueError(f"color must be one of {COLORS}, got {color!r}")
    return preprocess_image(_check_frame(frame), size, gray=True, color=color)


def preprocess(frame: np.ndarray, size=(32, 32), color: str = "bgr") -> np.ndarray:
    """One raw frame -> the model input, as ``load_frames`` produces it.

    frame: (H, W, 3) uint8 BGR (or RGB with ``color="rgb"``) or (H, W) / (H, W, 1) uint8 gray.
    size: (width, height). Returns (height, width) float32 in [0, 1] (gray / 255).
    """
    return preprocess_u8(frame, size, color).astype(np.float32) / np.float32(255.0)


# ---------------------------------------------------------------------------------------------
# models and backends
# ---------------------------------------------------------------------------------------------
def _load_model(model):
    """A Keras model, or a path to a .keras / .tflite file -> (keras model or None, tflite bytes or None)."""
    if isinstance(model, (str, os.PathLike)):
        path = Path(model)
        if not path.is_file():
            raise FileNotFoundError(f"model file {path} not found: pass a trained .keras model "
                                    f"(greenloop.methods.dictionary.cnn.train saves them under results/models/<key>/"
                                    f"model.keras) or a .tflite file from greenloop.methods.dictionary.stream.export_tflite")
        suffix = path.suffix.lower()
        if suffix == ".keras":
            import keras
            return keras.models.load_model(path, compile=False), None
        if suffix == ".tflite":
            return None, path.read_bytes()
        raise ValueError(f"model file {path} must end in .keras or .tflite, got {suffix!r}")
    if hasattr(model, "predict") and hasattr(model, "layers"):
        return model, None
    raise ValueError(f"model must be a keras Model or a path to a .keras/.tflite file, "
                     f"got {type(model).__name__}")


class _NumpyNet:
    """The paper's CNN in NumPy (``greenloop.methods.dictionary.cnn.forward``, the fused trainer's forward pass) on
    one BLAS thread. params: ``cnn.paper_weights``' arrays; hw: (H, W) of the input.
    labels(X (N, H, W) float32) -> (N,) int64."""

    def __init__(self, params: list, hw):
        self.params = params
        kh, kw, nf = params[0].shape
        n_in = (hw[0] - kh + 1) * (hw[1] - kw + 1) * nf
        if n_in != params[2].shape[0]:
            raise ValueError(f"dense layer expects {params[2].shape[0]} inputs, conv gives {n_in}")

    def labels(self, X: np.ndarray) -> np.ndarray:
        X = np.ascontiguousarray(X, dtype=np.float32)
        with one_blas_thread():
            return cnn.forward(X, self.params, threads=len(X) > 1)[2].argmax(1).astype(np.int64)


class _TFLiteNet:
    """TFLite interpreters (XNNPACK): one for single frames (min(2, cores) threads), a
    multi-thread one for windows (resized to the window length on demand).
    labels(X (N, H, W) float32) -> (N,) int64."""

    def __init__(self, content: bytes, num_threads: int | None = None):
        tf = _tensorflow_lite()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.one = tf.lite.Interpreter(model_content=content, num_threads=min(2, os.cpu_count() or 1))
            self.many = tf.lite.Interpreter(model_content=content,
                                            num_threads=num_threads or min(4, os.cpu_count() or 1))
        inp = self.one.get_input_details()[0]
        self.in_shape = tuple(int(s) for s in inp["shape"][1:])
        if len(self.in_shape) != 3 or self.in_shape[2] != 1:
            raise ValueError(f"the .tflite model must take (N, H, W, 1) gray frames, got input "
                             f"shape {inp['shape']}")
        self.n_classes = int(self.one.get_output_details()[0]["shape"][-1])
        self.one.resize_tensor_input(inp["index"], [1, *self.in_shape])
        self.one.allocate_tensors()
        self._in = inp["index"]
        self._out = self.one.get_output_details()[0]["index"]
        self._n = 0

    def labels(self, X: np.ndarray) -> np.ndarray:
        X = X.reshape(X.shape[0], *self.in_shape)
        if X.shape[0] == 1:
            it = self.one
        else:
            it = self.many
            if self._n != X.shape[0]:
                it.resize_tensor_input(self._in, [X.shape[0], *self.in_shape])
                it.allocate_tensors()
                self._n = X.shape[0]
        it.set_tensor(self._in, np.ascontiguousarray(X, dtype=np.float32))
        it.invoke()
        return it.get_tensor(self._out).argmax(1).astype(np.int64)


class _KerasNet:
    """The reference: ``model.predict``. labels(X (N, H, W) float32) -> (N,) int64."""

    def __init__(self, model):
        self.model = model

    def labels(self, X: np.ndarray) -> np.ndarray:
        p = self.model.predict(X[..., None], batch_size=max(1, len(X)), verbose=0)
        return np.asarray(p).argmax(1).astype(np.int64)


def _has_tflite() -> bool:
    try:
        _tensorflow_lite()
        return True
    except ImportError:
        return False


def _tensorflow_lite():
    try:
        import tensorflow as tf
        tf.lite.Interpreter  # noqa: B018  (attribute check)
    except (ImportError, AttributeError) as e:  # pragma: no cover - depends on the install
        raise ImportError(f"the tflite backend needs TensorFlow with tf.lite ({e}); use "
                          f"backend='numpy' or install tensorflow") from e
    return tf


def _convert(model, quantize: bool = False) -> bytes:
    """Keras model -> TFLite flatbuffer bytes (TensorFlow's converter; quiet; once per network and
    option: util.cache.cached_graph)."""
    tf = _tensorflow_lite()

    def convert() -> bytes:
        conv = tf.lite.TFLiteConverter.from_keras_model(model)
        if quantize:
            conv.optimizations = [tf.lite.Optimize.DEFAULT]  # dynamic-range: int8 weights, float maths
        with contextlib.redirect_stdout(io.StringIO()), devices.without_backend_notices():
            return conv.convert()
    return cache.cached_graph(cache.model_key(model, converter=f"from_keras_model {tf.__version__}",
                                              quantize=quantize), convert)


def export_tflite(model, path, quantize: bool = False) -> Path:
    """Convert the paper's CNN to a TFLite file with TensorFlow's converter.

    model: a keras Model or a path to a .keras file. path: the .tflite file to write (atomically).
    quantize: False for a float32 model (7.8 MB for 38 classes, same labels as Keras); True for
        dynamic-range quantisation (int8 weights, ~2 MB; labels may differ: see bench.json for the
        accuracy change measured on a test split).
    The model takes (N, H, W, 1) float32 in [0, 1] and returns (N, n_classes) probabilities.
    Returns the Path written.
    """
    keras_model, content = _load_model(model)
    if keras_model is None:
        raise ValueError(f"{model} is already a .tflite file; export_tflite needs a Keras model")
    path = Path(path)
    if path.suffix.lower() != ".tflite":
        raise ValueError(f"path must end in .tflite, got {path}")
    return write_atomic(path, _convert(keras_model, quantize))


# ---------------------------------------------------------------------------------------------
# the detector
# ---------------------------------------------------------------------------------------------
class Detector:
    """Raw frames -> spot labels -> frequency-count dictionary -> closure events.

    model: a keras Model of the paper's CNN (input (32, 32, 1)), or a path to a .keras or .tflite
        file.
    threshold: tau >= 1; a closure of spot c is declared at the frame where its count reaches tau
        (once per spot, like ``greenloop.methods.dictionary.dictionary.closure_events``; the dictionary never decays).
        None: count every frame but declare no closure (``events`` stays empty; for timing).
    n_classes: size of the dictionary; defaults to the model's number of outputs.
    backend: "auto", "numpy", "tflite" or "keras" (see the module docstring).
    color: channel order of 3-channel frames: "bgr" (OpenCV, the default) or "rgb". Gray frames
        ((H, W) or (H, W, 1)) are always accepted.
    num_threads: threads of the tflite window interpreter (default min(4, cores)).

    Attributes: ``labels`` (list of int, the predicted spot of every frame seen), ``events`` (list of
    every closure event dict), ``dictionary`` (the ``LoopDetector``; ``dictionary.counts`` (n_classes,)
    int32), ``frame_index`` (frames seen), ``backend`` (the one in use), ``size`` (width, height).
    """

    event_columns = ("spot", "count")   # an event: {frame, spot, count} (the detect table's columns)

    def __init__(self, model, threshold: int | None, n_classes: int | None = None, backend: str = "auto",
                 color: str = "bgr", num_threads: int | None = None):
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
        if color not in COLORS:
            raise ValueError(f"color must be one of {COLORS}, got {color!r}")
        if threshold is not None:
            positive_int("threshold tau", threshold, whole_floats=True)
        keras_model, content = _load_model(model)
        self.color = color
        if keras_model is not None:
            shape = tuple(keras_model.input_shape[1:])
            if len(shape) != 3 or shape[2] != 1 or None in shape:
                raise ValueError(f"the model must take (N, H, W, 1) gray frames, got input shape "
                                 f"{keras_model.input_shape}")
            hw = shape[:2]
            out_classes = int(keras_model.output_shape[-1])
            if backend in ("auto", "numpy"):
                w = cnn.paper_weights(keras_model)
                if w is None and backend == "numpy":
                    raise ValueError("backend='numpy' needs the paper's CNN (Conv2D 3x3 ReLU -> Flatten -> "
                                     "Dense ReLU -> Dense); use backend='tflite' or 'keras' for this model")
                if backend == "auto" and _has_tflite():
                    backend = "tflite"
                elif w is not None:
                    self._net, self.backend = _NumpyNet(w, hw), "numpy"
                else:
                    backend = "tflite"
            if backend == "tflite":
                self._net, self.backend = _TFLiteNet(_convert(keras_model), num_threads), "tflite"
            elif backend == "keras":
                self._net, self.backend = _KerasNet(keras_model), "keras"
        else:
            if backend not in ("auto", "tflite"):
                raise ValueError(f"a .tflite model runs only on backend='tflite', got {backend!r}")
            self._net, self.backend = _TFLiteNet(content, num_threads), "tflite"
            hw, out_classes = self._net.in_shape[:2], self._net.n_classes
        self.size = (int(hw[1]), int(hw[0]))  # (width, height) for cv2
        n_classes = out_classes if n_classes is None else int(n_classes)
        if n_classes < out_classes:
            raise ValueError(f"n_classes={n_classes} is smaller than the model's {out_classes} outputs")
        self.threshold = None if threshold is None else int(threshold)
        self.dictionary = LoopDetector(n_classes, self.threshold)
        self.n_classes = n_classes
        self.reset()

    def reset(self) -> None:
        """Forget every frame: counters to zero, frame index to 0, labels and events cleared."""
        self.dictionary.reset()
        self.frame_index = 0
        self.labels: list[int] = []
        self.events: list[dict] = []

    # -- classification -------------------------------------------------------------------------
    def preprocess_many(self, frames) -> np.ndarray:
        """Frames -> model inputs (N, height, width) float32 in [0, 1].

        frames: a sequence of frames (each any size; see ``preprocess``) or an (N, H, W, 3) /
        (N, H, W) uint8 array.
        """
        if isinstance(frames, np.ndarray):
            if frames.ndim == 3 and frames.shape[-1] in (1, 3):
                raise ValueError(f"a window must be (N, H, W, 3) colour or (N, H, W) gray frames; got "
                                 f"shape {frames.shape}, which looks like one frame: use update(frame)")
            if frames.ndim not in (3, 4):
                raise ValueError(f"a window must be (N, H, W, 3) colour or (N, H, W) gray frames, got "
                                 f"shape {frames.shape}")
        seq = list(frames)
        out = np.empty((len(seq), self.size[1], self.size[0]), np.uint8)

        def work(idx):
            for i in idx:
                try:
                    out[i] = preprocess_u8(seq[i], self.size, self.color)
                except ValueError as e:
                    raise ValueError(f"frame {i} of the window: {e}") from None

        run_chunked(work, len(seq))
        return out.astype(np.float32) / np.float32(255.0)

    def predict(self, frames) -> np.ndarray:
        """Spot labels (N,) int64 of raw frames (see ``preprocess_many``); the dictionary is not
        touched."""
        X = self.preprocess_many(frames)
        if len(X) == 0:
            return np.zeros(0, np.int64)
        return self._net.labels(X)

    # -- streaming ------------------------------------------------------------------------------
    def update(self, frame: np.ndarray) -> dict | None:
        """Classify one raw frame and count it.

        frame: (H, W, 3) uint8 BGR (RGB if ``color="rgb"``) or (H, W) / (H, W, 1) uint8 gray.
        Returns the closure event {'frame': index of this frame in the stream, 'spot': label,
        'count': its count (= tau)} when this frame's spot reaches tau now, else None. The label is
        appended to ``labels`` either way. An EVENT (count == tau, once per spot), unlike
        ``dictionary.LoopDetector.update(label)``, which returns the closure STATE (count >= tau)
        at every later frame of the spot too; both count by ``LoopDetector.add``.
        """
        x = preprocess_u8(frame, self.size, self.color).astype(np.float32) / np.float32(255.0)
        label = int(self._net.labels(x[None])[0])
        return self._count(label)

    def _count(self, label: int) -> dict | None:
        d = self.dictionary
        if not 0 <= label < d.n_classes:
            raise ValueError(f"model predicted label {label} outside the dictionary's 0..{d.n_classes - 1}")
        count = d.add(label)                         # the dictionary's one counting rule
        t = self.frame_index
        self.frame_index += 1
        self.labels.append(label)
        if count == d.threshold:                     # an EVENT: the count becomes tau (once per spot)
            event = {"frame": t, "spot": label, "count": count}
            self.events.append(event)
            return event
        return None

    def update_many(self, frames) -> list[dict]:
        """Classify a window of raw frames (one batched forward pass) and count them in order.

        frames: a sequence of frames (any sizes) or an (N, H, W, 3) / (N, H, W) uint8 array.
        Returns the closure events declared inside the window, in frame order (the same events as
        calling ``update`` on each frame).
        """
        if isinstance(frames, np.ndarray) and frames.ndim == 2:
            raise ValueError(f"update_many takes a window (N, H, W[, C]); got one 2-D frame of shape "
                             f"{frames.shape}: use update(frame)")
        labels = self.predict(frames)
        if len(labels) == 0:
            return []
        d = self.dictionary
        if labels.min() < 0 or labels.max() >= d.n_classes:
            raise ValueError(f"model predicted labels outside the dictionary's 0..{d.n_classes - 1}")
        running = d.add_many(labels)                 # count before the window + occurrences so far
        t0 = self.frame_index
        events = [{"frame": t0 + int(i), "spot": int(labels[i]), "count": int(running[i])}
                  for i in (np.flatnonzero(running == d.threshold) if d.threshold is not None else ())]
        self.frame_index += len(labels)
        self.labels.extend(labels.tolist())
        self.events.extend(events)
        return events
