"""Notebook 06's study: the paper's speed claim (a 70-frame window of ``model.predict`` and
dictionary updates) timed as the paper ran it, beside greenloop's streaming detector on raw frames.

The timing itself is ``greenloop.speed.bench``'s (the same reference ``make bench`` times).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from greenloop.datasets import sequence
from greenloop.methods.dictionary.stream import Detector
from greenloop.speed import bench
from greenloop.study import wording

BACKENDS = ("numpy", "tflite")
PAPER_FPS, PAPER_WINDOW_S = 920, 0.076     # the paper: 70 frames in 0.076 s on an i7-8750H
TARGETS = {"window_speed-up": 10, "single_median_ms": 0.3, "single_p99_ms": 1.0}   # the streaming detector's


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
    raw = [sequence.read_image(p) for p in sequence.list_frames(dataset)[: 3 * window]]
    dets = {b: Detector(model, None, backend=b) for b in BACKENDS}  # threshold None: count, declare nothing
    wins = bench.bench_windows(model, raw, dets, rounds=max(3, repeats // 10))
    single = bench.bench_single(model, raw, dets, n_ref=max(5, repeats // 4), n_ours=max(50, 5 * repeats))
    same = bench.raw_agreement(model, dets, raw, X)
    table = pd.DataFrame(bench.stream_rows(wins, single, same, len(raw)))
    return table, {"windows": wins, "single": single, "labels_equal": same}, raw[0].shape


def figure_window_times(times: np.ndarray, frames: int):
    """Histogram of the paper-claim window times (times: (repeats,) seconds) with the paper's
    76 ms (920 frames/s) dashed and this run's median; frames: frames per window. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.5, 3.5))
    ax.hist(times * 1e3, bins=40)
    ax.axvline(PAPER_WINDOW_S * 1e3, color="r", ls="--",
               label=f"paper: {PAPER_WINDOW_S * 1e3:.0f} ms = {PAPER_FPS} frames/s (i7-8750H)")
    ax.axvline(np.median(times) * 1e3, color="k", label=f"this run: median {np.median(times)*1e3:.1f} ms")
    ax.set_xlabel(f"time per {frames}-frame window (ms)"); ax.set_ylabel("windows (count)")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1)); ax.set_title("model.predict + dictionary updates")
    fig.tight_layout()
    return fig


def _window_key(pipeline: str) -> str:
    """The key of :func:`stream_comparison`'s timings['windows'] that a table row's pipeline names."""
    if pipeline.startswith("reference"):
        return "reference"
    if pipeline.startswith("floor"):
        return "gray_pass_floor"
    return pipeline[pipeline.index("(") + 1:pipeline.index(")")]


def figure_speedups(table: pd.DataFrame, cpu: str, windows: dict | None = None):
    """Frames per second of 70-frame windows, raw frames in, for every row of :func:`stream_comparison`'s
    table (median window), with a whisker down to the p99 window where ``windows`` (its timings'
    'windows') is given, the paper's 920 frames/s dashed and the 10x target dotted; cpu: the machine's
    name for the axis label. Returns the figure."""
    import matplotlib.pyplot as plt

    names = [p.replace("greenloop.methods.dictionary.stream ", "stream ").split(":")[0] for p in table.pipeline]
    fps = table["window_frames_per_s"].to_numpy(float)
    err = None
    if windows is not None:
        w = [windows[_window_key(p)] for p in table.pipeline]
        err = [fps - np.array([x["frames_per_s"] * x["median_ms"] / x["p99_ms"] for x in w]), np.zeros(len(w))]
    fig, ax = plt.subplots(figsize=(9, 3.4))
    ax.barh(names, fps, xerr=err, capsize=3, color=["0.6"] + ["C0"] * (len(names) - 2) + ["0.85"],
            label="median window" + (" (whisker: p99 window)" if err is not None else ""))
    ax.axvline(PAPER_FPS, color="r", ls="--", label=f"paper: {PAPER_FPS} frames/s (i7-8750H, preprocessed frames)")
    ax.axvline(TARGETS["window_speed-up"] * fps[0], color="k", ls=":",
               label=f"target: {TARGETS['window_speed-up']}x the reference")
    ax.set_xscale("log"); ax.set_xlabel(f"frames per second, 70-frame windows of raw frames ({cpu})")
    ax.set_ylabel("pipeline"); ax.invert_yaxis()
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    return fig


def _claim(s: dict, name: str, cpu: str) -> str:
    """The paper's window timed here: frames/s at the median and at the p95 window against 920."""
    fps, fps95 = s["frames_per_s"], s["window_frames"] / s["p95_window_s"]
    if fps95 >= PAPER_FPS:
        where = "both lie above the paper's figure"
    elif fps < PAPER_FPS:
        where = "both lie below the paper's figure"
    else:
        where = f"the paper's figure lies between them: {wording.UNRESOLVED}"
    return (f"On the {name} frames and {cpu}, a {s['window_frames']}-frame window of model.predict and dictionary "
            f"updates takes {wording.num(1e3 * s['median_window_s'], 1)} ms (median of {s['repeats']}; p95 "
            f"{wording.num(1e3 * s['p95_window_s'], 1)} ms): {wording.num(fps, 0)} frames/s at the median window and "
            f"{wording.num(fps95, 0)} at the p95 one against the paper's {PAPER_FPS} on an i7-8750H, so {where} "
            f"(different machines: this compares them as much as the code).")


def _target_word(low: float, mid: float, target: float) -> str:
    """A speed-up target is met when even the slow-side ratio ``low`` reaches it, not met when the
    median ratio ``mid`` does not, and not resolved between."""
    return "met" if low >= target else "not met" if mid < target else f"{wording.UNRESOLVED} (met at the medians only)"


def _stream(table: pd.DataFrame, windows: dict) -> str:
    """Each streaming backend's window speed-up (median, and against its p99 window) and single-frame
    latencies, against the targets."""
    ref = windows["reference"]["median_ms"]
    parts = []
    for _, r in table[table.pipeline.str.startswith("greenloop")].iterrows():
        w = windows[_window_key(r.pipeline)]
        low = ref / w["p99_ms"]
        single = ("met" if r.single_median_ms <= TARGETS["single_median_ms"] and r.single_p99_ms <= TARGETS["single_p99_ms"]
                  else "not met")
        parts.append(f"{_window_key(r.pipeline)}: {wording.num(r['window_speed-up'], 1)}x at the medians, "
                     f"{wording.num(low, 1)}x against its p99 window (target {TARGETS['window_speed-up']}x: "
                     f"{_target_word(low, r['window_speed-up'], TARGETS['window_speed-up'])}), single frames "
                     f"{wording.num(r.single_median_ms, 3)} ms median and {wording.num(r.single_p99_ms, 3)} ms p99 "
                     f"(targets {TARGETS['single_median_ms']} and {TARGETS['single_p99_ms']:g} ms: {single})")
    return f"The streaming detector on raw frames, against the reference pipeline: {'; '.join(parts)}." if parts else ""


def conclusion(out_dir) -> str:
    """Notebook 06's last cell: the verdict on the paper's 920 frames/s for its dataset, then the
    paper's window at its median and p95 time, and the streaming detector against its targets.
    out_dir: the notebook's folder (``<results_dir>/06_speed``) holding summary.json, stream.csv and
    stream.json. Returns Markdown."""
    out_dir = Path(out_dir)
    s = json.loads((out_dir / "summary.json").read_text())
    name = wording.verdict.dataset_name(out_dir.parent)
    sentences = [_claim(s, name, s.get("cpu", "this CPU"))]
    if (out_dir / "stream.csv").is_file():
        sentences.append(_stream(pd.read_csv(out_dir / "stream.csv"),
                                 json.loads((out_dir / "stream.json").read_text())["windows"]))
    return wording.compose(out_dir.parent, "06_speed", sentences)
