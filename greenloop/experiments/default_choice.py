"""How the named default's centring windows and threshold are chosen: on tuning queries only.

The named default (``seqmatch.DEFAULT_NAME``) is one configuration for every recording, so its
knobs are chosen once, on the tuning queries of the streams the detector's targets name (notebook
13, ``experiments.leaderboard.target_protocols``): every Nordland frame at the full rate, the
two Gardens Point pairs, and the synthetic sequence's leaderboard stream (every 4th frame, notebook
13's default). The evaluation queries are never read.

1. ``center_window`` and ``cell_shift``: every candidate of GRID (one window, or two joined,
   ``seqmatch.center``) with every cell shift of SHIFTS (0: the query as it is; 1: also moved one
   cell column left and right, ``seqmatch.shift_cells``) is scored by the per-query AUC-PR on each
   stream's tuning queries; the candidate with the highest mean over the streams wins. Beside it,
   R@1 of the Nordland and Gardens Point tuning queries driven the other way
   (:func:`reversed_stream`): a short window centres a frame on the frames before it, which a
   reverse drive replaces by those after it. The grid stops at two windows, for speed: each window
   adds a part as long as the descriptor to every stored frame, and the match against every stored
   frame is what limits the frames/s at Nordland's full rate (``13_leaderboard/target_protocols``).
   It stops at a shift of one cell, although a shift of two ranks higher on these four streams (all
   forward-looking cameras): a shift tolerates a sideways move of the view, so a camera looking
   sideways, whose view pans as it drives, finds each place in its neighbours too, and its
   calibrated scores flatten. On the pan of ``tests/test_seqspeed.py``'s CLI drive a shift of two
   declares under two thirds of what a shift of one declares (most of the revisit) at the threshold
   carried from Nordland; calibrated against every candidate ("zscore") it kept every score under it,
   and a default that goes silent for a side-looking camera is not one for every recording. A shift of one also reads each stored row once for its three products
   (``util.numba_kernels.max_dot``).
2. The threshold: the "p95" rule (``seqmatch.choose_threshold``: the lowest score with >= 95 %
   closure precision) on the tuning queries of the largest stream, Nordland at its full rate, for
   the winner; ``seqmatch.DEFAULT_THRESHOLD`` is it rounded to one decimal. Every other stream then
   gets that threshold unchanged (notebook 13's threshold_carry table). The named CNN
   configuration (``seqmatch.CNN_KNOBS``: the default's knobs on another descriptor, not ranked
   here) gets its threshold by the same rule on the same stream: ``seqmatch.CNN_THRESHOLD``
   (:func:`cnn_threshold`).
3. The repeat gate's level (``repeat_cos``) is shown, not ranked: :func:`repeat_gate` gives the
   share of each stream's frames it would hold out of the trajectories. Raw gradient histograms
   share a large positive part, so a level that suits centred descriptors also holds out moving
   frames.

4. The CNN configuration's input width (``features.FUSED_WIDTH``): :func:`width_table` scores the
   named CNN configuration (its knobs as they are) with its CNN part fed frames of each of
   CNN_WIDTHS pixels wide (aspect kept) by the same per-query AUC-PR on the same tuning queries; the
   highest mean wins, as for the windows. Beside it, the CNN part's cost per frame on this machine:
   what a narrower, cheaper network costs in accuracy, the trade-off behind the 920 frames/s target
   (notebook 13's targets table). The threshold of step 2 is then picked at the width in the code.

Everything else of ``seqmatch.DEFAULT_KNOBS`` (descriptor, seq_len, velocities) is kept.
CLI: ``python -m greenloop default-choice [--nordland DIR] [--gardenspoint DIR]
[--synthetic DIR] [--out results/default_choice]`` writes ``<out>/windows``, ``<out>/repeat_gate``
and ``<out>/cnn_width`` (.md and .csv) and ``<out>/manifest.json``.
"""
from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import evaluate, features, report
from greenloop.datasets import sequence
from greenloop.experiments import leaderboard as ex
from greenloop.features.layers import extract_layers
from greenloop.methods.greenloop_seq import seqmatch, seqstream
from greenloop.similarity import l2_normalise
from greenloop.study import targets

GRID = [5, 10, 20, 30, 50] + [[a, b] for a in (3, 5, 10) for b in (15, 20, 30)]
SHIFTS = (0, 1)
SYNTHETIC_STEP = 4                       # notebook 13's frame_step on the synthetic sequence
REPEAT_LEVELS = (0.995, 0.999)
THRESHOLD_STREAM = "nordland: every frame, +- 2 frames"   # Nordland at its full rate: the largest tuning part
SYNTHETIC_STREAM = "synthetic: leaderboard"
CNN_WIDTHS = (96, 128, 160, 224)         # the CNN configuration's input widths ranked (features.FUSED_WIDTH: the winner)
TIMING_FRAMES, TIMING_REPEATS = 200, 3    # the CNN part's cost: one frame per call, median over the repeats
_PARAMS = dict(seq_lens=[5, 10, 20], fps_frames=300, weights="auto")   # what ex.prepare needs here

__all__ = ["GRID", "SHIFTS", "REPEAT_LEVELS", "CNN_WIDTHS", "streams", "stream_frames", "reversed_stream", "rank",
           "repeat_gate", "threshold", "cnn_threshold", "cnn_part", "cnn_ms_per_frame", "width_table", "main"]


def streams(nordland=None, gardenspoint=None, synthetic=None, descriptor: str = "gradients") -> dict:
    """{"<target set>: <stream>": (X (N, D) descriptors, GT (N, N) bool, exclude (frames of the stream),
    tune (N,) bool tuning queries)}: the target streams of the given dataset folders (None: left
    out), split as notebook 13 splits them (tune_fraction 0.5, exclude 150 original frames).
    descriptor: the named default's "gradients" (256-d) or the CNN configuration's (``seqmatch.CNN_KNOBS``)."""
    return {label: (seqmatch.describe(folder, descriptor, step=SYNTHETIC_STEP) if label == SYNTHETIC_STREAM
                    else d.descriptors[descriptor], d.GT, d.exclude, d.tune)
            for label, folder, d in _target_data(nordland, gardenspoint, synthetic)}


def stream_frames(nordland=None, gardenspoint=None, synthetic=None) -> dict:
    """{label: (folder, frames (N,) int)}: the dataset folder and original frame numbers of each of
    :func:`streams`' streams (the same labels, the same frames in stream order)."""
    return {label: (folder, np.asarray(d.frames)) for label, folder, d in _target_data(nordland, gardenspoint, synthetic)}


def _target_data(nordland, gardenspoint, synthetic):
    """(label, folder, Data) of each target stream of the given folders (None: left out), in order."""
    for folder in (f for f in (nordland, gardenspoint) if f is not None):
        for label, d in _protocols(str(folder)):
            yield f"{sequence.open(folder).protocol.targets}: {label}", str(folder), d
    if synthetic is not None:
        yield SYNTHETIC_STREAM, str(synthetic), _synthetic(str(synthetic))


@functools.lru_cache(maxsize=None)
def _synthetic(folder: str):
    """The synthetic sequence's leaderboard stream (notebook 13's frame_step and split) as a Data, its
    descriptors not computed, prepared once per process."""
    return ex.prepare(folder, SYNTHETIC_STEP, 0.5, 150, 0.5, None, _PARAMS)[0]


@functools.lru_cache(maxsize=None)
def _protocols(folder: str) -> tuple:
    """((label, Data), ...): notebook 13's target protocols of a Nordland or Gardens Point folder, with
    every named configuration's descriptors (``experiment.TARGET_ENTRIES``), prepared once per process
    (the default's ranking and the CNN configuration's threshold read the same streams)."""
    data, _ = ex.prepare(folder, 1, 0.5, 150, 0.5, None, _PARAMS)
    return tuple((label, d) for label, (d, _) in ex.target_protocols(data, 0.5).items())


def _scores(stream, center_window, cell_shift: int = 0) -> np.ndarray:
    X, _, exclude, _ = stream
    k = seqmatch.DEFAULT_KNOBS
    return seqstream.score_matrix(X, exclude, k["seq_len"], k["velocities"], k["contrast_window"], None,
                                  center_window=center_window, calibrate=k["calibrate"], repeat_cos=k["repeat_cos"],
                                  cell_shift=cell_shift)


def reversed_stream(stream):
    """The stream cut after its first tuning query with a partner, then those tuning queries in
    reverse order: the revisit driven the other way (target 5), tuning queries only.
    Returns (X, GT, exclude, queries) as :func:`streams`' values; queries the reversed frames.
    Only for streams whose partners all lie before their first such query (a database traversal)."""
    X, GT, exclude, tune = stream
    q = np.flatnonzero(np.asarray(tune) & np.asarray(GT).any(0))
    idx = np.r_[np.arange(q.min()), q[::-1]]
    return X[idx], np.asarray(GT)[np.ix_(idx, idx)], exclude, np.arange(len(idx)) >= q.min()


def rank(streams: dict, grid=GRID, reverse=(), shifts=SHIFTS) -> pd.DataFrame:
    """One row per candidate (center_window, cell_shift): per-query AUC-PR (%) on each stream's
    tuning queries and their mean, best first (ties: grid order, windows outer); for the streams
    named in ``reverse``, R@1 (%) of the tuning queries as they are and driven the other way
    (:func:`reversed_stream`), shown beside it, not ranked on. streams: as :func:`streams`
    returns (a cell shift needs the gradients layout, ``seqmatch.CELL_GRID``)."""
    rows = []
    for cw, cs in ((cw, cs) for cw in grid for cs in shifts):
        row = {"center_window": str(cw), "cell_shift": int(cs)}
        for label, s in streams.items():
            _, GT, exclude, tune = s
            m = evaluate.per_query(_scores(s, cw, cs), GT, exclude, tune)
            row[f"AUC-PR_tune_% {label}"] = 100 * m["AUC-PR"]
            if label in reverse:
                r = reversed_stream(s)
                row[f"R@1_tune_% {label}"] = 100 * m["R@1"]
                row[f"R@1_tune_% {label}, reversed"] = 100 * evaluate.per_query(_scores(r, cw, cs), r[1], r[2], r[3])["R@1"]
        row["mean_AUC-PR_tune_%"] = float(np.mean([v for k, v in row.items() if k.startswith("AUC-PR")]))
        rows.append(row)
    return pd.DataFrame(rows).sort_values("mean_AUC-PR_tune_%", ascending=False, kind="stable").reset_index(drop=True)


def repeat_gate(streams: dict, levels=REPEAT_LEVELS) -> pd.DataFrame:
    """Share (%) of each stream's frames the repeat gate (``seqstream.Detector``'s repeat_cos:
    cosine of the L2-normalised raw descriptor with the previous frame's) would hold out of the
    trajectories, at each level: one row per stream. A standing camera repeats itself; a moving one
    should rarely pass the gate."""
    rows = []
    for label, (X, _, _, _) in streams.items():
        Y = seqmatch.normalise(X)
        cos = (Y[1:] * Y[:-1]).sum(1)
        rows.append({"stream": label, **{f"gated_%_at_{t}": 100 * float((cos >= t).mean()) for t in levels}})
    return pd.DataFrame(rows)


def threshold(stream, center_window, cell_shift: int = 0) -> float:
    """The "p95" rule's threshold (a calibrated score) on one stream's tuning queries."""
    _, GT, exclude, tune = stream
    return seqmatch.choose_threshold(_scores(stream, center_window, cell_shift), GT, exclude, tune, rule="p95")


def cnn_threshold(nordland) -> float:
    """The "p95" rule's threshold for the named CNN configuration (``seqmatch.CNN_KNOBS``, its
    windows and cell shift as they are) on the tuning queries of Nordland at its full rate
    (THRESHOLD_STREAM of ``nordland``, a Nordland folder)."""
    k = seqmatch.CNN_KNOBS
    s = streams(nordland, descriptor=k["descriptor"])[THRESHOLD_STREAM]
    return threshold(s, k["center_window"], k["cell_shift"])


def cnn_part(frames_or_folder, width: int, resolved=None) -> np.ndarray:
    """The CNN part of the CNN configuration's descriptor fed frames ``width`` pixels wide (aspect
    kept): EfficientNet-Lite0's block-10 map pooled over 2 x 2 cells (``features.FUSED_CNN``,
    ImageNet weights; a random-init network is refused) of every frame of a folder or of an
    (N, H, W, 3) RGB array. Returns (N, 448) float32, not normalised. At ``features.FUSED_WIDTH``,
    ``[l2(gradients) | l2(this)]`` is the descriptor ``features.extract`` gives the configuration.
    resolved: ``features.resolve`` of the network, already looked up (None: looked up here)."""
    backbone, depth, pooling = features.FUSED_CNN
    resolved = features.resolve(backbone, "imagenet") if resolved is None else resolved
    feats, _ = extract_layers(frames_or_folder, backbone, depths=(depth,), poolings=(pooling,), progress=False,
                              resolved=resolved, width=int(width))
    return feats[(depth, pooling)]


def cnn_ms_per_frame(frames, width: int, repeats: int = TIMING_REPEATS) -> float:
    """Milliseconds per frame of :func:`cnn_part` fed one decoded frame per call, as a stream
    describes (frames: (N, H, W, 3) uint8 RGB; the first call, which builds the network, untimed):
    the median over ``repeats`` passes of each pass's mean, on this machine."""
    resolved = features.resolve(features.FUSED_CNN[0], "imagenet")
    cnn_part(frames[:1], width, resolved)
    per = []
    for _ in range(int(repeats)):
        t = time.perf_counter()
        for f in frames:
            cnn_part(f[None], width, resolved)
        per.append(1000 * (time.perf_counter() - t) / len(frames))
    return float(np.median(per))


def width_table(streams: dict, frames: dict, timing_frames: dict, widths=CNN_WIDTHS) -> pd.DataFrame:
    """One row per CNN input width, best first (highest mean; ties: ``widths`` order): the named CNN
    configuration (``seqmatch.CNN_KNOBS`` as they are) with its CNN part at that width, per-query AUC-PR
    (%) on each stream's tuning queries and their mean, and the CNN part's cost per frame (:func:`cnn_ms_per_frame`)
    on each of ``timing_frames`` ({name: (N, H, W, 3) uint8 RGB frames}). streams: :func:`streams` of
    the gradients (the descriptor's first part); frames: :func:`stream_frames` of the same streams."""
    k, rows = seqmatch.CNN_KNOBS, []
    for w in widths:
        row, parts = {"cnn_width": int(w)}, {}
        for label, (G, GT, exclude, tune) in streams.items():
            folder, idx = frames[label]
            if folder not in parts:
                parts[folder] = cnn_part(folder, w)
            X = np.hstack([l2_normalise(G), l2_normalise(parts[folder][idx])]).astype(np.float32)
            m = evaluate.per_query(_scores((X, GT, exclude, tune), k["center_window"], k["cell_shift"]), GT, exclude, tune)
            row[f"AUC-PR_tune_% {label}"] = 100 * m["AUC-PR"]
        row["mean_AUC-PR_tune_%"] = float(np.mean([v for c, v in row.items() if c.startswith("AUC-PR")]))
        row.update({f"cnn_ms_per_frame {name}": cnn_ms_per_frame(f, w) for name, f in timing_frames.items()})
        rows.append(row)
    return pd.DataFrame(rows).sort_values("mean_AUC-PR_tune_%", ascending=False, kind="stable").reset_index(drop=True)


def run(nordland="data/nordland", gardenspoint="data/gardenspoint", synthetic="data/synthetic-greenhouse",
        out="results/default_choice") -> list[str]:
    """Choose the named default's windows, cell shift and threshold and the CNN configuration's width
    and threshold on the target streams' tuning queries; write windows, cnn_width, repeat_gate and the
    manifest to ``out``. Returns the lines to print (the tables and the choice)."""
    for f in (nordland, gardenspoint, synthetic):
        if not Path(f).is_dir():
            raise FileNotFoundError(f"dataset folder {f} not found: build it first (make nordland gardenspoint synthetic)")
    s = streams(nordland, gardenspoint, synthetic)
    table = rank(s, reverse=[k for k in s if k != SYNTHETIC_STREAM])
    best, shift = table["center_window"][0], int(table["cell_shift"][0])
    cw = {str(c): c for c in GRID}[best]
    t = threshold(s[THRESHOLD_STREAM], cw, shift)
    t_cnn = cnn_threshold(nordland)
    out = Path(out)
    report.write_table(table, out / "windows", decimals=2,
                       title="The named default's center_window and cell_shift: per-query AUC-PR on the tuning queries of the target streams",
                       note=(f"greenloop.experiments.default_choice: the first row wins (highest mean). The 'p95' rule on "
                             f"{THRESHOLD_STREAM} picks the threshold {t:.4f} for it. In the code: "
                             f"seqmatch.DEFAULT_KNOBS center_window {list(seqmatch.center_windows(seqmatch.DEFAULT_KNOBS['center_window']))}, "
                             f"cell_shift {seqmatch.DEFAULT_KNOBS['cell_shift']}, "
                             f"seqmatch.DEFAULT_THRESHOLD {seqmatch.DEFAULT_THRESHOLD}. The same rule picks {t_cnn:.4f} "
                             f"for the named CNN configuration ({seqmatch.CNN_NAME}, not ranked here): "
                             f"seqmatch.CNN_THRESHOLD {seqmatch.CNN_THRESHOLD}."))
    widths = width_table(s, stream_frames(nordland, gardenspoint, synthetic),
                         {f"{Path(f).name} ({TIMING_FRAMES} frames)": sequence.load_frames(f, size=None, gray=False, limit=TIMING_FRAMES,
                                                                                         progress=False, dtype=np.uint8)
                          for f in (nordland, synthetic)})
    report.write_table(widths, out / "cnn_width", decimals=2,
                       title=f"The named CNN configuration ({seqmatch.CNN_NAME}) by its CNN's input width: per-query AUC-PR on the "
                             "tuning queries of the target streams, and the CNN part's cost per frame",
                       note=(f"greenloop.experiments.default_choice.width_table: the first row wins (highest mean). In the code: "
                             f"features.FUSED_WIDTH = {features.FUSED_WIDTH} pixels (aspect kept). cnn_ms_per_frame: "
                             f"EfficientNet-Lite0 to block 10 and its pooling, one decoded frame per call (TFLite graph, "
                             f"{TIMING_REPEATS} passes over the first {TIMING_FRAMES} frames, median), on this machine; the "
                             f"frame budget at {targets.FPS_TARGET:g} frames/s is {1000 / targets.FPS_TARGET:.2f} ms for everything (descriptor and search)."))
    gate = repeat_gate(s)
    report.write_table(gate, out / "repeat_gate", decimals=2,
                       title="Frames the repeat gate holds out of the trajectories, by its level (raw descriptors)",
                       note=f"greenloop.experiments.default_choice.repeat_gate; seqmatch.DEFAULT_KNOBS repeat_cos "
                            f"{seqmatch.DEFAULT_KNOBS['repeat_cos']}.")
    report.manifest(out, dict(grid=[str(c) for c in GRID], shifts=list(SHIFTS), repeat_levels=list(REPEAT_LEVELS), synthetic_step=SYNTHETIC_STEP,
                              threshold_stream=THRESHOLD_STREAM, winner=best, winner_cell_shift=shift, p95_threshold=round(t, 4),
                              cnn_configuration=seqmatch.CNN_NAME, cnn_p95_threshold=round(t_cnn, 4),
                              cnn_widths=list(CNN_WIDTHS), cnn_width_winner=int(widths["cnn_width"][0]),
                              fused_width=features.FUSED_WIDTH, timing_frames=TIMING_FRAMES,
                              timing_repeats=TIMING_REPEATS),
                    datasets=[nordland, gardenspoint, synthetic])
    return [table.round(2).to_string(index=False), gate.round(2).to_string(index=False),
            widths.round(2).to_string(index=False),
            f"winner {best}, cell_shift {shift}; p95 threshold on {THRESHOLD_STREAM}: {t:.4f}; "
            f"{seqmatch.CNN_NAME}: {t_cnn:.4f} at features.FUSED_WIDTH {features.FUSED_WIDTH} "
            f"(the width ranking's winner: {int(widths['cnn_width'][0])})"]
