"""Notebook 06's study: the paper's speed claim (a 70-frame window of ``model.predict`` and
dictionary updates) timed as the paper ran it, beside greenloop's streaming detector on raw frames.

The timing itself is ``greenloop.speed.bench``'s (the same reference ``make bench`` times).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from greenloop.datasets import sequence
from greenloop.speed import bench
from greenloop.speed.stream import Detector

BACKENDS = ("numpy", "tflite")


def stream_comparison(model, dataset, X: np.ndarray, window: int, repeats: int):
    """The reference pipeline, each streaming backend of ``BACKENDS`` and the floor, on the first
    3 * window raw frames of the dataset (preprocessing included).

    model: the trained Keras CNN; dataset: its sequence folder; X: (N, 32, 32, 1) float32 the
    CNN's inputs of the same frames (the labels the stream must reproduce); window: frames per
    timed window; repeats: sets the rounds (repeats // 10, at least 3) and the single-frame
    samples (repeats // 4 of the reference, 5 * repeats of the stream, at least 5 and 50).
    Returns (table, timings, frame_shape): ``bench.stream_rows`` as a DataFrame; {'windows',
    'single', 'labels_equal'} the raw measurements (ms, frames/s); (H, W, 3) of a raw frame.
    """
    import cv2

    raw = [cv2.imread(str(p)) for p in sequence.list_frames(dataset)[: 3 * window]]
    dets = {b: Detector(model, None, backend=b) for b in BACKENDS}  # threshold None: count, declare nothing
    wins = bench.bench_windows(model, raw, dets, rounds=max(3, repeats // 10))
    single = bench.bench_single(model, raw, dets, n_ref=max(5, repeats // 4), n_ours=max(50, 5 * repeats))
    same = bench.raw_agreement(model, dets, raw, X)
    table = pd.DataFrame(bench.stream_rows(wins, single, same, len(raw)))
    return table, {"windows": wins, "single": single, "labels_equal": same}, raw[0].shape


def figure_window_times(times: np.ndarray, frames: int):
    """Histogram of the paper-claim window times (times: (repeats,) seconds) with the paper's
    76 ms and this run's median; frames: frames per window. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.hist(times * 1e3, bins=40)
    ax.axvline(76, color="r", ls="--", label="paper: 76 ms (i7-8750H)")
    ax.axvline(np.median(times) * 1e3, color="k", label=f"this run: median {np.median(times)*1e3:.1f} ms")
    ax.set_xlabel(f"time per {frames}-frame window (ms)"); ax.legend(); ax.set_title("model.predict + dictionary updates")
    return fig


def figure_speedups(table: pd.DataFrame, cpu: str):
    """The window speed-up over the reference of every row of :func:`stream_comparison`'s table,
    with the 10x target; cpu: the machine's name for the axis label. Returns the figure."""
    import matplotlib.pyplot as plt

    names = [p.replace("greenloop.speed.stream ", "stream ").split(":")[0] for p in table.pipeline]
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.barh(names, table["window_speed-up"], color=["0.6"] + ["C0"] * (len(names) - 2) + ["0.85"])
    ax.axvline(10, color="r", ls="--", label="target: 10x the reference")
    ax.set_xlabel(f"70-frame windows, speed-up over the reference (frames/s ratio, {cpu})")
    ax.invert_yaxis(); ax.legend(loc="lower right")
    return fig
