"""Notebook 13's experiment: every registered detector on the same frames, ground truth, split,
tuning budget and timing (``greenloop.detectors.registry``; the rows are ``study.leaderboard``'s).

The calls, in the notebook's order (each returns what one table or figure shows):

    data, split = prepare(dataset, frame_step, loop_threshold, exclude, tune_fraction, reference_frames, params)
    tuned = tune(data)                  # describe + tune every entry (one budget), score matrices
    decisions = decide(data)            # entries without a score (the dictionary): trained, declared
    timed = stream_and_time(data, tuned, decisions)   # thresholds, stream = matrix check, timing
    result = board(data, split, tuned, timed, decisions)

A detector added to the registry (docs/ARCHITECTURE.md, "Adding a detector") is described, tuned,
scored, checked and timed here with the others: no notebook changes. ``registry`` arguments
default to ``registry.REGISTRY``.
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from greenloop import evaluate, groundtruth, seqmatch
from greenloop.datasets.sequence import list_frames
from greenloop.detectors import single_frame
from greenloop.detectors.interface import Data
from greenloop.detectors.registry import REGISTRY
from greenloop.speed import timing
from greenloop.study import leaderboard as lb
from greenloop.study import report

SEQ_ROWS = ("greenloop-seq", "greenloop-seq-fast", seqmatch.DEFAULT_NAME)   # the rows the targets judge
NO_SPLIT_DROPPED = "greenloop-seq, the tuned SeqSLAM, every tuned knob and threshold and so every closure count"
NO_SPLIT_KEPT = ("the single-frame methods (untuned), SeqSLAM at its published parameters and the "
                 "dictionary at its fixed τ are scored on every query instead")


class Split(NamedTuple):
    """reference: (M,) bool place-recognition database or None; gap: frames kept between the
    parts (the longest sequence); no_split: the Markdown note when no honest split exists, else
    None; scored_on: the rows' scored_on text; summary: the ground truth's one line."""
    reference: np.ndarray | None
    gap: int
    no_split: str | None
    scored_on: str
    summary: str


class Tuned(NamedTuple):
    """rows: every knob combination offered and its tuning score (the tuning table); knobs:
    {method: knob record}; score: {method: tuning AUC-PR %}; owner: {method: registry name};
    texts: {method: knob text}; S: {method: (M, M) score matrix}."""
    rows: pd.DataFrame
    knobs: dict
    score: dict
    owner: dict
    texts: dict
    S: dict


class Timed(NamedTuple):
    """thresholds: {method: float (NaN: none)}; dets: {method: streaming detector};
    stream_check: {method: ``speed.seqstream.stream_check``}; speed: timing rows indexed by method (with
    decode_ms); decode: ``timing.decode_ms``."""
    thresholds: dict
    dets: dict
    stream_check: dict
    speed: pd.DataFrame
    decode: dict


class Board(NamedTuple):
    """board: the leaderboard (``study.leaderboard.COLUMNS``, unrounded; ``leaderboard.rounded`` is
    its written form); target: ``leaderboard.targets``; targets: the targets table; statement:
    the printed sentences (these three judge the written, rounded numbers)."""
    board: pd.DataFrame
    target: dict
    targets: pd.DataFrame
    statement: str


def prepare(dataset, frame_step: int, loop_threshold: float, exclude: int, tune_fraction: float,
            reference_frames, params: dict) -> tuple[Data, Split]:
    """The described frames, ground truth and honest split (``evaluate.honest_split``, a gap of the
    longest of ``params["seq_lens"]``), and the timed window (the first ``params["fps_frames"]``
    evaluation frames). exclude: ORIGINAL frames. Returns (Data, Split); without an honest split
    Data.tune is None and every query is an evaluation query."""
    frames, exclude_steps, GT, summary = groundtruth.described_frames(dataset, frame_step, loop_threshold, exclude)
    M, gap = len(frames), max(params["seq_lens"])
    ref = lb.reference_mask(frames, reference_frames)
    tune_q, evalq, no_split = evaluate.honest_split(M, tune_fraction, GT, gap, frames, NO_SPLIT_DROPPED, NO_SPLIT_KEPT)
    if no_split is None:
        scored_on = "evaluation queries; " + evaluate.split_summary(tune_q, evalq, GT, gap)
    else:
        evalq, scored_on = np.ones(M, dtype=bool), f"every query (frames 0..{M - 1} of {M}; no honest split)"
    window = lb.timing_window(evalq, params["fps_frames"])
    data = Data(dataset, frame_step, frames, GT, exclude_steps, tune_q, evalq,
                dict(params, exclude=exclude, timing_window=window), {}, {}, {})
    return data, Split(ref, gap, no_split, scored_on, summary)


def tune(data: Data, registry=None) -> Tuned:
    """Describe the frames for every entry (in registry order, filling ``data.descriptors`` and
    ``data.infos``), tune every scored entry on the tuning queries (its untuned records without a
    split) and compute each method's score matrix on every described frame."""
    reg = REGISTRY if registry is None else registry
    for e in reg.values():
        X, info = e.describe(data)
        data.descriptors.update(X)
        data.infos.update(info)
    rows, knobs, score, owner = [], {}, {}, {}
    for e in (e for e in reg.values() if e.score is not None):
        r, k, s = e.tune(data)
        rows, owner = rows + list(r), {**owner, **dict.fromkeys(k, e.name)}
        knobs.update(k)
        score.update(s)
    table = pd.DataFrame(rows if data.tune is not None else
                         [{"status": "not available: no honest tuning/evaluation split"}])
    texts = {m: reg[owner[m]].knob_text(k) for m, k in knobs.items()}
    S = {m: reg[owner[m]].score(k, data) for m, k in knobs.items()}
    return Tuned(table, knobs, score, owner, texts, S)


def decide(data: Data, registry=None) -> list[dict]:
    """``Entry.decide`` of every entry without a score (the dictionary), in registry order."""
    reg = REGISTRY if registry is None else registry
    return [e.decide(data) for e in reg.values() if e.score is None]


def stream_and_time(data: Data, tuned: Tuned, decisions=(), registry=None) -> Timed:
    """Thresholds on the tuning queries (rule ``params["threshold_rule"]``; a record's
    ``fixed_threshold`` kept), each method's streaming detector, the stream-vs-matrix check of the
    ``checked`` entries over the whole stream, and the one timing definition (``speed.timing``)
    over the timed window, every method (the decisions' too) interleaved."""
    reg, p = (REGISTRY if registry is None else registry), data.params
    fixed = {m: k["fixed_threshold"] for m, k in tuned.knobs.items() if "fixed_threshold" in k}
    thr = lb.thresholds(tuned.S, data.GT, data.exclude, data.tune, p["threshold_rule"], fixed)
    dets = {m: reg[tuned.owner[m]].stream(k, thr.get(m), data) for m, k in tuned.knobs.items()}
    checked = [m for m in tuned.knobs if reg[tuned.owner[m]].checked]
    agree = lb.stream_checks(checked, dets, tuned.knobs, data.descriptors, tuned.S, data.GT)
    describers = {m: reg[tuned.owner[m]].describer(k, data) for m, k in tuned.knobs.items()}
    start, stop = p["timing_window"]
    raw, paths = lb.decode_window(list_frames(data.dataset), data.frames, start, stop)
    methods, preload = lb.timing_methods(tuned.knobs, dets, describers, data.descriptors, start)
    methods += [d["method"] for d in decisions]
    preload.update({d["name"]: d["preload"] for d in decisions})
    speed = pd.DataFrame(timing.time_methods(methods, raw, preload, p["timing_repeats"])).set_index("method")
    decode = timing.decode_ms(paths, p["timing_repeats"])
    speed["decode_ms"] = decode["decode_ms_median"]
    return Timed(thr, dets, agree, speed, decode)


def board(data: Data, split: Split, tuned: Tuned, timed: Timed, decisions=()) -> Board:
    """The leaderboard (evaluation queries only): every method's rows, chance, the decisions' rows;
    the targets of the greenloop-seq rows and the named default's targets table; the statement."""
    meta = lb.meta(tuned.knobs, timed.dets, data.infos, tuned.texts)
    rows = lb.method_rows(tuned.S, meta, data.GT, data.exclude, data.evalq, split.reference, timed.thresholds,
                          timed.speed.to_dict("index"), data.frame_step, split.scored_on, split.gap)
    rows += lb.chance_rows(data.GT, data.exclude, data.evalq, split.reference, split.scored_on)
    rows += [lb.dictionary_row(d["name"], d["tau"], d["n_train"], d["closures"], d["op"],
                               timed.speed.loc[d["name"]].to_dict(), data.frame_step, split.scored_on)
             for d in decisions]
    table = lb.table(rows)
    written = lb.rounded(table)
    return Board(table, lb.targets(written, list(SEQ_ROWS)), lb.targets_table(written, data.dataset, data.frame_step),
                 lb.statement(written))


def figure_pr(data: Data, tuned: Tuned):
    """Per-query PR curves of every scored method (loop closure, evaluation queries): a Figure."""
    curves = lb.pr_curves(tuned.S, data.GT, data.exclude, data.evalq)
    fig, ax = plt.subplots(figsize=(8, 6))
    for n_, (name, (p, r)) in enumerate(curves.items()):
        seq = name.startswith(("greenloop-seq", "SeqSLAM"))
        ax.step(r, p, where="post", lw=2.2 if seq else 1.1, color=None if seq else plt.get_cmap("tab20")(n_ % 20),
                label=name)
    ax.set_xlabel("recall (queries with a partner)"); ax.set_ylabel("precision (declared queries)")
    ax.set_xlim(0, 1); ax.set_ylim(0, 1.02)
    ax.set_title(f"{Path(data.dataset).name}: per-query PR over each query's best match, loop closure, "
                 "evaluation queries", fontsize=9)
    ax.legend(fontsize=6, loc="lower left")
    return fig


def figure_r1(table: pd.DataFrame):
    """R@1 of every scored loop-closure row, best first, with chance's R@1 as a line: a Figure."""
    order = table[(table["mode"] == "loop closure")].dropna(subset=["R@1_%"]).sort_values("R@1_%", ascending=False)
    chance_r1 = table[(table.method == "chance (random scores)") & (table["mode"] == "loop closure")]["R@1_%"].iloc[0]
    fig, ax = plt.subplots(figsize=(9, 4.5))
    ax.barh(order.method, order["R@1_%"],
            color=["k" if m.startswith(("greenloop-seq", "SeqSLAM")) else "C0" for m in order.method])
    ax.axvline(chance_r1, color="C3", ls="--", lw=1, label=f"chance R@1 {chance_r1:.2f} %")
    ax.invert_yaxis(); ax.set_xlabel("R@1 on the evaluation queries (%), loop closure"); ax.legend(fontsize=8)
    ax.tick_params(axis="y", labelsize=7)
    fig.tight_layout()
    return fig


def note(data: Data, split: Split, target: dict, loop_threshold: float, reference_frames) -> str:
    """The leaderboard's note: frames, ground truth, metrics, budget, timing, targets."""
    p, exclude_steps, (start, stop) = data.params, data.exclude, data.params["timing_window"]
    return (f"{len(data.frames)} frames (frame_step {data.frame_step}) of {data.dataset}; ground truth: "
            f"{groundtruth.definition(data.dataset, loop_threshold, p['exclude'])}; "
            f"candidates more than {exclude_steps} steps ({exclude_steps * data.frame_step} original frames) back (loop closure"
            + ("" if split.reference is None else f"; place recognition: the reference = original frames < {reference_frames}")
            + "). Per-query metrics (evaluate.per_query) in %: R@1, R@5, AUC-PR (step-wise area of the PR curve over each "
            "query's best match), R@100P, R@95P; *_lo_% / *_hi_% = 95 % block-bootstrap interval of R@1 and AUC-PR over "
            f"the queries (runs of {split.gap} consecutive queries resampled, leaderboard.spread); pair_AP_% = the pair AP "
            "(one sample per pair of frames), a secondary column; chance = evaluate.query_chance (pair AP: "
            f"evaluate.chance_level). Knobs picked by per-query AUC-PR on the tuning queries ({split.scored_on}); "
            f"thresholds by rule '{p['threshold_rule']}' on the tuning queries. Frames/s (greenloop.speed.timing): decoded "
            "frame in memory -> decision (describe, match against every stored frame, store), over described frames "
            f"{start}..{stop - 1} with frames 0..{start - 1} stored, median [min, max] of {p['timing_repeats']} "
            f"interleaved repeats on {report.cpu_model()}; decode_ms = cv2.imread of the same frames, apart. "
            "bytes_per_stored_frame = stored descriptor + 4 x seq_len column buffer (the dictionary stores none, only "
            f"counters). Targets: {target}.")


def summary(data: Data, split: Split, tuned: Tuned, timed: Timed, result: Board, decisions=()) -> dict:
    """summary.json's content (the keys the CLI's --tuned, the tests and the README read)."""
    return {"leaderboard": lb.rounded(result.board).to_dict("records"), "target": result.target,
            "detector_targets": result.targets.to_dict("records"), "knobs": tuned.knobs,
            "thresholds": {k: timed.thresholds[k] for k in tuned.knobs}, "stream_matches_matrix": timed.stream_check,
            "frames": len(data.frames), "frame_step": data.frame_step, "exclude_steps": data.exclude,
            "timing_window": list(data.params["timing_window"]), "decode": timed.decode,
            "dictionary_trained_on_frames": decisions[0]["n_train"] if decisions else None,
            "split": {"honest": split.no_split is None, "not_available": split.no_split}}


def manifest_extra(data: Data, tuned: Tuned) -> dict:
    """The manifest's run-dependent entries: the knobs used, the CPU and the weights of each
    single-frame descriptor (``detectors.single_frame.specs``)."""
    return {"knobs": tuned.knobs, "cpu": report.cpu_model(),
            "weights_used": {b: data.infos[b].weights for b in single_frame.specs(data.params)}}
