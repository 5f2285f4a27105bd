"""One timing definition for every method of the leaderboard: a decoded frame in memory -> its decision.

What is timed, for every method alike (:func:`time_methods`)
    * from a frame already decoded in memory ((H, W, 3) uint8 BGR, as ``cv2.imread`` returns it)
      to the method's decision on it: describe the frame (preprocessing and network included),
      match it against every frame stored at that point, store it, decide;
    * over the frames of a window of the stream (the leaderboard: the first frames of its
      evaluation part), with the database already holding every frame before the window, so the
      stored count is the real one and the revisit is in it. Those stored frames are preloaded
      from their descriptors (the notebooks' descriptor cache), untimed;
    * ``repeats`` times (at least 3), the methods interleaved in one process (repeat r starts at
      method r, so none always runs first on a warm or cold cache), each after one untimed
      warm-up frame; frames/s reported as median and min-max over the repeats;
    * with the CPU named (``greenloop.report.cpu_model``);
    * each network on the runtime its family has here: the ImageNet MobileNets and EfficientNet-Lite0 as
      TFLite graphs (XNNPACK, ``features.cnn.predictor``), the networks trained here (the main paper's
      spot CNN, the Siamese networks) through Keras's ``predict_on_batch``, whose per-call cost makes
      their frames/s a lower bound.
    Decoding (``cv2.imread`` of the same files) is timed apart (:func:`decode_ms`): it is a column of
    its own, the same for every method that reads the same files.

One more quantity, not per frame: the wall time of one whole computation (notebook 07's M x M
cosine matrix), the best of ``repeats`` calls (:func:`best_of`).

Every time greenloop reports is read by one clock, ``timed`` (``greenloop.util.clock``: one call,
wall seconds on ``time.perf_counter``; re-exported here): this module's functions, notebook 06's
paper windows and stream comparison (``speed.bench``), the scaling benchmark (``speed.scale``) and
a user's ``detect`` run all call it.

A method is a :class:`Method`: ``start(preload)`` builds its database from the preloaded data
(untimed) and returns a state, ``step(state, frame)`` is the timed path. :func:`detector_method`
wraps a streaming detector that takes descriptors (``seqstream.Detector``, ``seqslam_stream.Detector``,
and the single-frame methods as a ``seqstream.Detector`` with seq_len 1), :func:`dictionary_method`
the main paper's ``methods.dictionary.stream.Detector`` (its database is its spot counters).
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from greenloop import report
from greenloop.datasets import sequence
from greenloop.util.checks import positive_int
from greenloop.util.clock import timed   # the one clock (greenloop.util.clock), re-exported for speed/

__all__ = ["Method", "timed", "detector_method", "dictionary_method", "time_methods", "decode_ms", "best_of"]


class Method(NamedTuple):
    """One method to time. name: its row label. start: preload -> state (untimed; builds the
    database of the frames before the window). step: (state, decoded frame) -> decision (timed)."""
    name: str
    start: Callable
    step: Callable


def detector_method(name: str, detector, describe) -> Method:
    """A descriptor-fed streaming detector as a :class:`Method`.

    detector: has ``reset()`` and ``update_descriptor(x)`` (``seqstream`` / ``seqslam_stream`` Detector).
    describe: one decoded frame (H, W, 3) uint8 BGR -> its descriptor (D,), the detector's input.
    preload of ``start``: (n0, D) descriptors of the frames before the window, fed in order.
    """
    def start(X):
        detector.reset()
        for x in np.asarray(X):
            detector.update_descriptor(x)
        return detector

    def step(det, frame):
        return det.update_descriptor(describe(frame))
    return Method(name, start, step)


def dictionary_method(name: str, detector) -> Method:
    """The main paper's detector (``greenloop.methods.dictionary.stream.Detector``) as a :class:`Method`.

    preload of ``start``: (n0,) int spot labels of the frames before the window (counted into the
    dictionary, no event). step: ``detector.update(frame)`` (preprocess, classify, count, decide).
    """
    def start(labels):
        labels = np.asarray(labels, dtype=np.int64)
        detector.reset()
        if len(labels):
            detector.dictionary.add_many(labels)
        detector.frame_index, detector.labels = len(labels), labels.tolist()
        return detector

    def step(det, frame):
        return det.update(frame)
    return Method(name, start, step)


def _steps(m: Method, state, frames) -> None:
    for f in frames:
        m.step(state, f)


def _run_once(m: Method, preload, frames) -> float:
    state = m.start(preload)
    return timed(_steps, m, state, frames)[1]


def time_methods(methods, frames, preload: dict, repeats: int = 3) -> list[dict]:
    """Frames per second of every method on the same decoded frames, interleaved (module doc).

    methods: list of :class:`Method`. frames: list of decoded frames (H, W, 3) uint8 BGR, the
    timed window in stream order. preload: {method name: what its ``start`` takes}.
    repeats: >= 3 timed passes per method. Returns one dict per method, in the given order:
    method, fps_median, fps_min, fps_max (frames/s over the repeats), ms_per_frame_median,
    frames_timed, stored_at_start (len of the preload), repeats, cpu.
    """
    repeats = positive_int("repeats", repeats, 3)
    frames = list(frames)
    if not frames:
        raise ValueError("frames is empty: give the decoded frames of the timed window")
    missing = [m.name for m in methods if m.name not in preload]
    if missing:
        raise ValueError(f"no preload for {missing}: give each method the data of the frames before the window")
    for m in methods:                                   # warm-up: models built, caches filled
        m.step(m.start(preload[m.name]), frames[0])
    secs = {m.name: [] for m in methods}
    for r in range(repeats):
        for m in methods[r % len(methods):] + methods[:r % len(methods)]:
            secs[m.name].append(_run_once(m, preload[m.name], frames))
    cpu, rows = report.cpu_model(), []
    for m in methods:
        fps = len(frames) / np.asarray(secs[m.name])
        rows.append({"method": m.name, "fps_median": float(np.median(fps)), "fps_min": float(fps.min()),
                     "fps_max": float(fps.max()), "ms_per_frame_median": float(1e3 / np.median(fps)),
                     "frames_timed": len(frames), "stored_at_start": int(len(preload[m.name])),
                     "repeats": repeats, "cpu": cpu})
    return rows


def decode_ms(paths, repeats: int = 3) -> dict:
    """Milliseconds per frame of decoding the given files (``sequence.read_image``, the one decoder:
    ``cv2.imread(path, IMREAD_COLOR)``).
    Returns {"decode_ms_median", "decode_ms_min", "decode_ms_max"} over ``repeats`` (>= 3) passes."""
    repeats = positive_int("repeats", repeats, 3)
    paths = [str(p) for p in paths]
    if not paths:
        raise ValueError("paths is empty: give the files of the timed window")
    ts = [1e3 * timed(_decode_all, paths)[1] / len(paths) for _ in range(repeats)]
    return {"decode_ms_median": float(np.median(ts)), "decode_ms_min": float(min(ts)),
            "decode_ms_max": float(max(ts))}


def _decode_all(paths) -> None:
    for p in paths:
        sequence.read_image(p)


def best_of(fn, *args, repeats: int = 3):
    """The wall time of one call ``fn(*args)``, the best (shortest) of ``repeats`` >= 1 calls.

    Returns (result, seconds): the last call's result and the shortest wall time in seconds
    (``time.perf_counter``; the minimum is the least disturbed by other load on the machine).
    """
    repeats = positive_int("repeats", repeats, 1)
    best, out = float("inf"), None
    for _ in range(repeats):
        out, secs = timed(fn, *args)
        best = min(best, secs)
    return out, best

