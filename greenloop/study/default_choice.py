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
   keeps every score under the threshold carried from Nordland, where a shift of one declares most
   of the revisit; a default that goes silent for a side-looking camera is not one for every
   recording. A shift of one also reads each stored row once for its three products
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

Everything else of ``seqmatch.DEFAULT_KNOBS`` (descriptor, seq_len, velocities) is kept.
CLI: ``python -m greenloop.study.default_choice [--nordland DIR] [--gardenspoint DIR]
[--synthetic DIR] [--out results/default_choice]`` writes ``<out>/windows`` and ``<out>/repeat_gate``
(.md and .csv) and ``<out>/manifest.json``.
"""
from __future__ import annotations

import argparse
import functools
from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import evaluate, seqmatch
from greenloop.experiments import leaderboard as ex
from greenloop.speed import seqstream
from greenloop.study import report, targets

GRID = [5, 10, 20, 30, 50] + [[a, b] for a in (3, 5, 10) for b in (15, 20, 30)]
SHIFTS = (0, 1)
SYNTHETIC_STEP = 4                       # notebook 13's frame_step on the synthetic sequence
REPEAT_LEVELS = (0.995, 0.999)
THRESHOLD_STREAM = "nordland: every frame, +- 2 frames"   # Nordland at its full rate: the largest tuning part
SYNTHETIC_STREAM = "synthetic: leaderboard"
_PARAMS = dict(seq_lens=[5, 10, 20], fps_frames=300, weights="auto")   # what ex.prepare needs here

__all__ = ["GRID", "SHIFTS", "REPEAT_LEVELS", "streams", "reversed_stream", "rank", "repeat_gate", "threshold",
           "cnn_threshold", "main"]


def streams(nordland=None, gardenspoint=None, synthetic=None, descriptor: str = "gradients") -> dict:
    """{"<dataset kind>: <protocol>": (X (N, D) descriptors, GT (N, N) bool, exclude (frames of the stream),
    tune (N,) bool tuning queries)}: the target streams of the given dataset folders (None: left
    out), split as notebook 13 splits them (tune_fraction 0.5, exclude 150 original frames).
    descriptor: the named default's "gradients" (256-d) or the CNN configuration's (``seqmatch.CNN_KNOBS``)."""
    out = {}
    for folder in (f for f in (nordland, gardenspoint) if f is not None):
        for label, d in _protocols(str(folder)):
            out[f"{targets.dataset_kind(folder)}: {label}"] = (d.descriptors[descriptor], d.GT, d.exclude, d.tune)
    if synthetic is not None:
        d, _ = ex.prepare(str(synthetic), SYNTHETIC_STEP, 0.5, 150, 0.5, None, _PARAMS)
        X = seqmatch.describe(str(synthetic), descriptor, step=SYNTHETIC_STEP)
        out[SYNTHETIC_STREAM] = (X, d.GT, d.exclude, d.tune)
    return out


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


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m greenloop.study.default_choice", description=__doc__.splitlines()[0])
    p.add_argument("--nordland", default="data/nordland")
    p.add_argument("--gardenspoint", default="data/gardenspoint")
    p.add_argument("--synthetic", default="data/synthetic-greenhouse")
    p.add_argument("--out", default="results/default_choice")
    a = p.parse_args(argv)
    for f in (a.nordland, a.gardenspoint, a.synthetic):
        if not Path(f).is_dir():
            raise SystemExit(f"dataset folder {f} not found: build it first (make nordland gardenspoint synthetic)")
    s = streams(a.nordland, a.gardenspoint, a.synthetic)
    table = rank(s, reverse=[k for k in s if k != SYNTHETIC_STREAM])
    best, shift = table["center_window"][0], int(table["cell_shift"][0])
    cw = {str(c): c for c in GRID}[best]
    t = threshold(s[THRESHOLD_STREAM], cw, shift)
    t_cnn = cnn_threshold(a.nordland)
    out = Path(a.out)
    report.write_table(table, out / "windows", decimals=2,
                       title="The named default's center_window and cell_shift: per-query AUC-PR on the tuning queries of the target streams",
                       note=(f"greenloop.study.default_choice: the first row wins (highest mean). The 'p95' rule on "
                             f"{THRESHOLD_STREAM} picks the threshold {t:.4f} for it. In the code: "
                             f"seqmatch.DEFAULT_KNOBS center_window {list(seqmatch.center_windows(seqmatch.DEFAULT_KNOBS['center_window']))}, "
                             f"cell_shift {seqmatch.DEFAULT_KNOBS['cell_shift']}, "
                             f"seqmatch.DEFAULT_THRESHOLD {seqmatch.DEFAULT_THRESHOLD}. The same rule picks {t_cnn:.4f} "
                             f"for the named CNN configuration ({seqmatch.CNN_NAME}, not ranked here): "
                             f"seqmatch.CNN_THRESHOLD {seqmatch.CNN_THRESHOLD}."))
    gate = repeat_gate(s)
    report.write_table(gate, out / "repeat_gate", decimals=2,
                       title="Frames the repeat gate holds out of the trajectories, by its level (raw descriptors)",
                       note=f"greenloop.study.default_choice.repeat_gate; seqmatch.DEFAULT_KNOBS repeat_cos "
                            f"{seqmatch.DEFAULT_KNOBS['repeat_cos']}.")
    report.manifest(out, dict(grid=[str(c) for c in GRID], shifts=list(SHIFTS), repeat_levels=list(REPEAT_LEVELS), synthetic_step=SYNTHETIC_STEP,
                              threshold_stream=THRESHOLD_STREAM, winner=best, winner_cell_shift=shift, p95_threshold=round(t, 4),
                              cnn_configuration=seqmatch.CNN_NAME, cnn_p95_threshold=round(t_cnn, 4)),
                    datasets=[a.nordland, a.gardenspoint, a.synthetic])
    print(table.round(2).to_string(index=False))
    print(gate.round(2).to_string(index=False))
    print(f"winner {best}, cell_shift {shift}; p95 threshold on {THRESHOLD_STREAM}: {t:.4f}; "
          f"{seqmatch.CNN_NAME}: {t_cnn:.4f}")


if __name__ == "__main__":
    main()
