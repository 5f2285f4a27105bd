"""Notebook 13's experiment: every registered detector on the same frames, ground truth, split,
tuning budget and timing (``greenloop.methods.registry``); its rows, spreads and paired comparisons are
``leaderboard.rows``: one leaderboard, one folder.

The calls, in the notebook's order (each returns what one table or figure shows):

    step = choose_step(dataset, frame_step, loop_threshold, exclude, tune_fraction, params, min_revisit_queries)
    data, split = prepare(dataset, step.step, loop_threshold, exclude, tune_fraction, reference_frames, params)
    tuned = tune(data)                  # describe + tune every entry (one budget), score matrices
    decisions = decide(data)            # entries without a score (the dictionary): trained, declared
    timed = stream_and_time(data, tuned, decisions)   # thresholds, stream = matrix check, timing
    result = board(data, split, tuned, timed, decisions)
    splits = days.day_splits(data, tuned, timed)      # a render of the greenhouse over days only, else None

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

from greenloop import evaluate, groundtruth, report
from greenloop.datasets import sequence
from greenloop.datasets.sequence import list_frames
from greenloop.experiments.leaderboard import days, rows as lb
from greenloop.methods.greenloop_seq import seqmatch
from greenloop.methods.interface import Data
from greenloop.methods.registry import REGISTRY
from greenloop.methods.single_frame import entry as single_frame
from greenloop.speed import timing
from greenloop.study import verdict, wording

NAMED = tuple(seqmatch.NAMED)      # the named configurations (untuned, fixed thresholds)
SEQ_ROWS = ("greenloop-seq", "greenloop-seq-fast", *NAMED)   # the rows the targets judge
TARGET_ENTRIES = NAMED + ("seqslam",)    # what a target protocol runs: the named configurations and SeqSLAM's rows
TARGET_TOLERANCE = sequence.TARGET_TOLERANCE   # frames: a target stream's ground truth (sequence.yaml's default)
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
    stream_check: {method: ``methods.greenloop_seq.seqstream.stream_check``}; speed: timing rows indexed by method (with
    decode_ms); decode: ``timing.decode_ms``."""
    thresholds: dict
    dets: dict
    stream_check: dict
    speed: pd.DataFrame
    decode: dict


class Board(NamedTuple):
    """board: the leaderboard (``rows.COLUMNS``, unrounded; ``rows.rounded`` is
    its written form); target: ``rows.targets``; targets: the targets table; statement:
    the printed sentences (these three judge the written, rounded numbers, and read "above",
    "higher" and "highest" from comparisons only); comparisons: the paired comparisons as written
    (``rows.comparisons``: each greenloop-seq row against every other scored row, loop closure)."""
    board: pd.DataFrame
    target: dict
    targets: pd.DataFrame
    statement: str
    comparisons: pd.DataFrame


MIN_REVISIT_QUERIES = 50    # evaluation revisit queries a leaderboard must rest on where the recording has them


class Step(NamedTuple):
    """The frame step notebook 13 describes: step (used), requested, minimum (evaluation revisit
    queries wanted), revisits ({step tried: its evaluation revisit queries}), why (the printed line)."""
    step: int
    requested: int
    minimum: int
    revisits: dict
    why: str


def evaluation_revisits(GT, exclude_steps: int, tune_fraction: float, gap: int) -> int:
    """The revisit queries (``lb.query_counts``, loop closure) among the evaluation queries that
    :func:`prepare` would score on this ground truth: the honest split's evaluation part (a gap of
    ``gap`` steps), every query without one. GT: (M, M) bool; 0 when it has no revisit at all."""
    G = np.asarray(GT, dtype=bool)
    if len(G) < 2 or not groundtruth.revisit_frames(G).any():
        return 0
    _, evalq, no_split = evaluate.honest_split(len(G), tune_fraction, G, gap)
    return lb.query_counts(G, exclude_steps, evalq if no_split is None else None)["revisit_queries"]


def largest_step(requested: int, revisits_at, minimum: int = MIN_REVISIT_QUERIES) -> tuple[int, dict]:
    """The largest step s <= requested with revisits_at(s) >= minimum, trying requested, requested - 1,
    ... down to 1 (so only as far as needed); 1 when none does. revisits_at: step -> evaluation
    revisit queries. Returns (step, {step tried: revisits_at(step)})."""
    seen = {}
    for s in range(int(requested), 0, -1):
        seen[s] = int(revisits_at(s))
        if seen[s] >= minimum:
            return s, seen
    return 1, seen


def step_text(step: int, requested: int, revisits: dict, minimum: int) -> str:
    """The line that says which frame step the leaderboard uses and why (:func:`choose_step`)."""
    if step == requested:
        more = "" if revisits[step] >= minimum else f"; fewer than {minimum}, and no finer step exists"
        return f"frame_step {step} as requested: its evaluation part holds {revisits[step]} revisit queries{more}"
    if revisits[step] >= minimum:
        return (f"frame_step {step}, not the requested {requested}: step {requested} would leave "
                f"{revisits[requested]} evaluation revisit queries (< {minimum}); {step} is the largest step that "
                f"leaves at least {minimum} ({revisits[step]})")
    return (f"frame_step 1, not the requested {requested}: no step leaves {minimum} evaluation revisit queries "
            f"(step {requested}: {revisits[requested]}, step 1: {revisits[1]}), so every frame is described")


def choose_step(dataset, requested: int, loop_threshold: float, exclude: int, tune_fraction: float, params: dict,
                minimum: int = MIN_REVISIT_QUERIES) -> Step:
    """The frame step for :func:`prepare`: the largest step <= ``requested`` whose described frames
    leave at least ``minimum`` revisit queries in the evaluation part (:func:`evaluation_revisits`,
    the split :func:`prepare` makes: a gap of the longest of ``params["seq_lens"]``), step 1 when none
    does. A coarse ``frame_step`` meant for notebooks 07-09 must not leave the leaderboard resting on a
    handful of queries. dataset: a sequence folder or Sequence (opened once). exclude: ORIGINAL frames."""
    gap, seq = max(params["seq_lens"]), sequence.open(dataset)

    def at(s):
        _, exclude_steps, GT, _ = groundtruth.described_frames(seq, s, loop_threshold, exclude)
        return evaluation_revisits(GT, exclude_steps, tune_fraction, gap)

    step, seen = largest_step(requested, at, minimum)
    return Step(step, int(requested), int(minimum), seen, step_text(step, int(requested), seen, minimum))


def prepare(dataset, frame_step: int, loop_threshold: float, exclude: int, tune_fraction: float,
            reference_frames, params: dict) -> tuple[Data, Split]:
    """The described frames, ground truth and honest split (``evaluate.honest_split``, a gap of the
    longest of ``params["seq_lens"]``), and the timed window (the first ``params["fps_frames"]``
    evaluation frames). dataset: a sequence folder or Sequence, opened once (``sequence.open``): Data.dataset
    is its Sequence. exclude: ORIGINAL frames. Returns (Data, Split); without an honest split
    Data.tune is None and every query is an evaluation query."""
    seq = sequence.open(dataset)
    frames, exclude_steps, GT, summary = groundtruth.described_frames(seq, frame_step, loop_threshold, exclude)
    return _with_split(Data(seq, frame_step, frames, GT, exclude_steps, None, None, dict(params, exclude=exclude),
                            {}, {}, {}), tune_fraction, lb.reference_mask(frames, reference_frames), summary)


def _with_split(data: Data, tune_fraction: float, reference, summary: str) -> tuple[Data, Split]:
    """``data`` (its tune and evalq not yet set) with the honest split of its ground truth (a gap of
    the longest of ``params["seq_lens"]``) and the timed window; its Split (reference as given)."""
    M, gap = len(data.frames), max(data.params["seq_lens"])
    tune_q, evalq, no_split = evaluate.honest_split(M, tune_fraction, data.GT, gap, data.frames, NO_SPLIT_DROPPED,
                                                    NO_SPLIT_KEPT)
    if no_split is None:
        scored_on = "evaluation queries; " + evaluate.split_summary(tune_q, evalq, data.GT, gap)
    else:
        evalq, scored_on = np.ones(M, dtype=bool), f"every query (frames 0..{M - 1} of {M}; no honest split)"
    window = lb.timing_window(evalq, data.params["fps_frames"])
    data = data._replace(tune=tune_q, evalq=evalq, params=dict(data.params, timing_window=window))
    return data, Split(reference, gap, no_split, scored_on, summary)


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


def streams(data: Data, tuned: Tuned, registry=None) -> tuple[dict, dict]:
    """Each tuned method's threshold, picked on the tuning queries by ``params["threshold_rule"]``
    (a record's ``fixed_threshold`` kept; NaN without a tuning part), and its streaming detector at
    it: ({method: threshold}, {method: detector}); what :func:`stream_and_time` checks and times and
    ``experiments.loop_closing`` streams for its closures."""
    reg = REGISTRY if registry is None else registry
    fixed = {m: k["fixed_threshold"] for m, k in tuned.knobs.items() if "fixed_threshold" in k}
    thr = lb.thresholds(tuned.S, data.GT, data.exclude, data.tune, data.params["threshold_rule"], fixed)
    return thr, {m: reg[tuned.owner[m]].stream(k, thr.get(m), data) for m, k in tuned.knobs.items()}


def stream_and_time(data: Data, tuned: Tuned, decisions=(), registry=None, only=None) -> Timed:
    """Thresholds on the tuning queries (rule ``params["threshold_rule"]``; a record's
    ``fixed_threshold`` kept), each method's streaming detector, the stream-vs-matrix check of the
    ``checked`` entries over the whole stream, and the one timing definition (``speed.timing``)
    over the timed window, every method (the decisions' too) interleaved. only: the methods to
    check and time where given (the others get no timing row); None: every method."""
    reg, p = (REGISTRY if registry is None else registry), data.params
    thr, dets = streams(data, tuned, reg)
    checked = [m for m in tuned.knobs if reg[tuned.owner[m]].checked and (only is None or m in only)]
    agree = lb.stream_checks(checked, dets, tuned.knobs, data.descriptors, tuned.S, data.GT)
    describers = {m: reg[tuned.owner[m]].describer(k, data) for m, k in tuned.knobs.items()}
    start, stop = p["timing_window"]
    raw, paths = lb.decode_window(list_frames(data.dataset), data.frames, start, stop)
    knobs = {m: k for m, k in tuned.knobs.items() if only is None or m in only}
    methods, preload = lb.timing_methods(knobs, dets, describers, data.descriptors, start)
    methods += [timing.dictionary_method(d["name"], d["detector"]) for d in decisions]
    preload.update({d["name"]: d["preload"] for d in decisions})
    speed = pd.DataFrame(timing.time_methods(methods, raw, preload, p["timing_repeats"])).set_index("method")
    decode = timing.decode_ms(paths, p["timing_repeats"])
    speed["decode_ms"] = decode["decode_ms_median"]
    return Timed(thr, dets, agree, speed, decode)


def board(data: Data, split: Split, tuned: Tuned, timed: Timed, decisions=()) -> Board:
    """The leaderboard (evaluation queries only): every method's rows, chance, the decisions' rows;
    the paired comparisons of the greenloop-seq rows (SEQ_ROWS) with every other scored row (in the
    bootstrap runs of the rows' intervals, ``split.gap`` queries); their targets, the named
    configurations' targets table and the statement, judged from those comparisons."""
    meta = lb.meta(tuned.knobs, timed.dets, data.infos, tuned.texts)
    rows = lb.method_rows(tuned.S, meta, data.GT, data.exclude, data.evalq, split.reference, timed.thresholds,
                          timed.speed.to_dict("index"), data.frame_step, split.scored_on, split.gap)
    rows += lb.chance_rows(data.GT, data.exclude, data.evalq, split.reference, split.scored_on)
    counts = lb.query_counts(data.GT, data.exclude, data.evalq)
    rows += [lb.dictionary_row(d["name"], d["tau"], d["n_train"], d["closures"], d["op"],
                               timed.speed.loc[d["name"]].to_dict(), data.frame_step, split.scored_on, counts)
             for d in decisions]
    table = lb.table(rows)
    written = lb.rounded(table)
    comp = lb.comparisons(tuned.S, lb.comparison_pairs(written, SEQ_ROWS), data.GT, data.exclude, data.evalq, split.gap)
    targets = sequence.open(data.dataset).protocol.targets        # the dataset's target set (sequence.yaml)
    return Board(table, lb.targets(written, list(SEQ_ROWS), comp), lb.targets_table(written, targets,
                 data.frame_step, comp), lb.statement(written, comp, SEQ_ROWS), comp)


def _every_frame(data: Data, registry: dict) -> Data:
    """``data`` at frame_step 1 (every frame of the dataset) with the descriptors the registry's
    entries need: data itself when it already describes every frame, else described here."""
    n = sequence.open(data.dataset).n_frames
    full = data if data.frame_step == 1 and len(data.frames) == n else data._replace(
        frame_step=1, frames=np.arange(n), descriptors={}, infos={}, cache={})
    for e in registry.values():
        X, info = e.describe(full)
        full.descriptors.update(X)
        full.infos.update(info)
    return full


def _protocol(full: Data, stream: sequence.TargetStream, tune_fraction: float) -> tuple[Data, Split]:
    """The stream of the given traversals of ``full`` (``stream.traversals``, in stream order), their
    frames aligned +- ``stream.tolerance``, the first traversal the place-recognition database."""
    traversals, tol = stream.traversals, stream.tolerance
    idx = np.concatenate([np.arange(t.start, t.stop) for t in traversals])
    bounds = np.cumsum([0] + [t.stop - t.start for t in traversals])
    ex = int(full.params["exclude"])                       # frame_step 1: steps are original frames
    GT = groundtruth.pair_matrix(sequence.aligned_pairs(list(zip(bounds[:-1], bounds[1:])), tol),
                                 len(idx), None, ex)
    d = Data(full.dataset, 1, idx, GT, ex, None, None, dict(full.params), {k: v[idx] for k, v in full.descriptors.items()},
             dict(full.infos), {})
    names = " then ".join(f"{t.name} (frames {t.start}..{t.stop - 1})" for t in traversals)
    summary = (f"{len(idx)} frames (every frame) of {names}; ground truth: frame k of each traversal is frame k of the "
               f"others +- {tol} frames, pairs within {ex} frames excluded: {int(GT.sum()) // 2} loop pairs")
    return _with_split(d, tune_fraction, np.arange(len(idx)) < bounds[1], summary)


def target_protocols(data: Data, tune_fraction: float) -> dict:
    """{label: (Data, Split)}: the streams on which the detector's targets are defined where this
    leaderboard's own differ, for the named default and SeqSLAM (TARGET_ENTRIES): the target streams of
    the dataset's sequence.yaml (``Sequence.protocol.streams``, labelled by their names), each every frame
    of its traversals (frame_step 1), in its order, the first traversal the database, frame k of each
    the same place +- its tolerance (default TARGET_TOLERANCE frames). Nordland's builder names all its
    frames, summer then winter, +- 2 (the leaderboard: every frame_step-th frame, the dataset's own
    tolerance); Gardens Point's the pairs day_right -> night_right and day_left -> night_right (the
    leaderboard: day_left the database of both later walks). A dataset without streams: {} (its
    targets are judged on the leaderboard itself). Each is split as the leaderboard is
    (``tune_fraction``, a gap of the longest sequence)."""
    streams = sequence.open(data.dataset).protocol.streams
    if not streams:
        return {}
    full = _every_frame(data, {k: REGISTRY[k] for k in TARGET_ENTRIES})
    return {s.name: _protocol(full, s, tune_fraction) for s in streams}


def threshold_check(data: Data, tuned: Tuned) -> list[dict]:
    """Does each named configuration's one threshold carry to this stream? Its closures on the
    evaluation queries (loop closure) at its fixed threshold (the record's ``fixed_threshold``),
    beside those at the threshold the "p95" rule (the lowest score with >= 95 % closure precision,
    ``seqmatch.choose_threshold``) picks on this stream's own tuning queries.
    Returns one row (dict) per named configuration (NAMED) scored here: its name ("configuration"),
    the evaluation queries and revisit queries the closures are counted on (``lb.query_counts``),
    the thresholds (calibrated scores; the tuning part's NaN without an honest split), closures
    declared and their precision (%, NaN when none) at each."""
    GT, ex, rows = data.GT, data.exclude, []
    for m in (m for m in NAMED if m in tuned.S):
        S = tuned.S[m]
        own = np.nan if data.tune is None else seqmatch.choose_threshold(S, GT, ex, data.tune, rule="p95")
        row = {"configuration": m, **lb.query_counts(GT, ex, data.evalq)}
        for name, thr in (("fixed", tuned.knobs[m]["fixed_threshold"]), ("tuning_p95", own)):
            row.update({f"threshold_{name}": round(float(thr), 4), f"declared_at_{name}": np.nan,
                        f"precision_at_{name}_%": np.nan})
            if not np.isfinite(thr):           # no tuning part (no honest split): nothing to pick on
                continue
            c = seqmatch.closures(S, GT, thr, ex, data.evalq)
            row[f"declared_at_{name}"] = c["declared"]
            if c["declared"]:
                row[f"precision_at_{name}_%"] = round(100 * c["precision"], 2)
        rows.append(row)
    return rows


def false_closures(data: Data, tuned: Tuned) -> list[dict]:
    """Where each named configuration (NAMED) scored here declares its false closures: the runs of
    ``evaluate.false_closure_runs`` on its score matrix at its fixed threshold, evaluation queries,
    frames numbered as the dataset numbers them (``data.frames``), with the distance between camera
    centres (metres) and the angle between optical axes (degrees) where the sequence has poses.
    Returns one row (dict) per run, its configuration first; [] where every closure is right."""
    seq = sequence.open(data.dataset)
    poses = seq.poses()[1][data.frames] if seq.has_trajectory else None     # one pose per frame, by frame number
    rows = []
    for m in (m for m in NAMED if m in tuned.S):
        runs = evaluate.false_closure_runs(tuned.S[m], data.GT, tuned.knobs[m]["fixed_threshold"], data.exclude,
                                           data.evalq, data.frames, poses)
        rows += [dict(configuration=m, **r) for r in runs]
    return rows


FALSE_COLUMNS = ["protocol", "configuration", "first_query", "last_query", "first_match", "last_match", "closures",
                 "with_partner", "offset_frames", "max_score"]


def false_table(data: Data, tuned: Tuned, runs: dict) -> pd.DataFrame:
    """:func:`false_closures` of the leaderboard (protocol "leaderboard") and of each target protocol
    run ({label: ProtocolRun}) as one table, FALSE_COLUMNS first, then distance_m and angle_deg where
    some run has poses; no row where every closure is right."""
    rows = ([dict(protocol="leaderboard", **f) for f in false_closures(data, tuned)]
            + [dict(protocol=label, **f) for label, r in runs.items() for f in r.false_closures])
    return pd.DataFrame(rows, columns=FALSE_COLUMNS + [c for c in ("distance_m", "angle_deg") if any(c in r for r in rows)])


class ProtocolRun(NamedTuple):
    """One target protocol's run (:func:`run_protocol`): its Board, the stream-vs-matrix check {method:
    ``seqstream.stream_check``}, :func:`threshold_check`'s rows and :func:`false_closures`' rows."""
    board: Board
    stream_check: dict
    carry: list
    false_closures: list


def run_protocol(data: Data, split: Split) -> ProtocolRun:
    """The named configurations and SeqSLAM (TARGET_ENTRIES) on one target protocol, as the leaderboard's
    rows are: tuned (SeqSLAM's grid on its tuning queries) and thresholded; the stream-vs-matrix
    check and the timing for the named configurations only: the leaderboard checks and times SeqSLAM,
    and at Nordland's full rate each timing repeat would first stream every earlier frame through
    each SeqSLAM row, one SAD against every stored frame each. Returns (Board, the stream check {method:
    ``seqstream.stream_check``}, :func:`threshold_check`'s rows, :func:`false_closures`' rows) as a ProtocolRun."""
    reg = {k: REGISTRY[k] for k in TARGET_ENTRIES}
    tuned = tune(data, reg)
    timed = stream_and_time(data, tuned, (), reg, only=NAMED)
    return ProtocolRun(board(data, split, tuned, timed), timed.stream_check, threshold_check(data, tuned),
                       false_closures(data, tuned))


def protocol_tables(result: Board, runs: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(targets, rows): the targets table of the leaderboard and of every protocol run ({label:
    Board}), with a ``protocol`` column ("leaderboard" for this run's own rows), and the protocol
    runs' rounded leaderboard rows with the same column. runs: {label: Board} (the first item of
    :func:`run_protocol`)."""
    targets = pd.concat([t.assign(protocol=label) for label, t in
                         [("leaderboard", result.targets)] + [(k, b.targets) for k, b in runs.items()]], ignore_index=True)
    rows = [lb.rounded(b.board).assign(protocol=k) for k, b in runs.items()]
    cols = ["protocol"] + list(lb.COLUMNS)
    return (targets[["protocol"] + [c for c in targets.columns if c != "protocol"]],
            pd.concat(rows, ignore_index=True)[cols] if rows else pd.DataFrame(columns=cols))


COMPARISONS_NOTE = ("leaderboard.comparisons: a minus b (percentage points) on the evaluation queries both are scored "
                    "on (queries), loop closure; lo, hi: the 95 % paired block bootstrap, both methods scored on the "
                    "same resamples as the leaderboard's *_lo_% / *_hi_% intervals (leaderboard.resamples: the same "
                    f"runs of consecutive queries, {lb.N_BOOT} resamples, seed {lb.SEED}), each resample's R@1 and "
                    "AUC-PR recomputed by evaluate.query_metrics; resolved: the written [lo, hi] excludes 0. The "
                    "statement and the targets call a row higher, above or highest only where these rows are "
                    "resolved. protocol: the leaderboard or the stream a target names.")


def write_comparisons(result: Board, runs: dict, out_dir):
    """``comparisons.csv`` and ``.md`` in ``out_dir``: the leaderboard's paired comparisons and every
    protocol run's ({label: Board}, :func:`run_protocol`), with a ``protocol`` column first
    ("leaderboard" for this run's own). Returns (csv path, md path)."""
    table = pd.concat([c.comparisons.assign(protocol=k) for k, c in [("leaderboard", result), *runs.items()]],
                      ignore_index=True)
    return lb.write_comparisons(table[["protocol"] + lb.COMPARISON_COLUMNS], out_dir, COMPARISONS_NOTE)


def method_colours(methods) -> dict:
    """{method: RGBA colour}: one colour per distinct name, in sorted order (``report.palette``:
    up to 60 distinct), so that a board's figures (PR curves, R@1 bars) draw each method in the
    same colour."""
    return report.palette(sorted(set(methods)))


def figure_pr(data: Data, tuned: Tuned, board: pd.DataFrame):
    """Per-query PR curves of every scored method (loop closure, evaluation queries), coloured as
    in :func:`figure_r1` for ``board`` (the leaderboard table), the legend beside the axes: a Figure.
    Sequence methods are thick, each with its own dash pattern, so that a curve lying on another
    (two configurations both at precision 1) still shows; single-frame curves are thin, drawn on top."""
    curves = lb.pr_curves(tuned.S, data.GT, data.exclude, data.evalq)
    colours = method_colours(board.method)     # figure_r1's mapping; a curve the board lacks is grey
    dashes = iter([(None, None), (6, 3), (2, 2), (8, 3, 2, 3), (1, 3), (10, 4)] * 4)
    fig, ax = plt.subplots(figsize=(10, 6))
    for name, (p, r) in curves.items():
        seq = name.startswith(("greenloop-seq", "SeqSLAM"))
        line, = ax.step(r, p, where="post", lw=2.4 if seq else 1.1, color=colours.get(name, "0.5"), label=name,
                        zorder=2 if seq else 3)
        if seq and (d := next(dashes)) != (None, None):
            line.set_dashes(d)
    ax.set_xlabel("recall (queries with a partner)"); ax.set_ylabel("precision (declared queries)")
    ax.set_xlim(0, 1); ax.set_ylim(0, 1.02)
    ax.set_title(f"{Path(data.dataset).name}: per-query PR over each query's best match, loop closure, "
                 "evaluation queries", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), title="thick: sequence methods (dashed apart)",
              title_fontsize=7)
    fig.tight_layout()
    return fig


def ties_with_top(order: pd.DataFrame, comparisons: pd.DataFrame | None, metric: str = "R@1") -> dict:
    """{method: "top" | "tie" | "below" | "above" | "not compared"}: each row of ``order`` (the bars, best
    first) against the first by their paired comparison of ``metric`` (``lb.comparisons``' table, either
    direction): "tie" where its interval holds 0, "not compared" where the table has no such pair (or no
    table is given)."""
    top = order.method.iloc[0]
    out = {top: "top"}
    c = pd.DataFrame(columns=lb.COMPARISON_COLUMNS) if comparisons is None else comparisons
    c = c[c.metric == metric]
    for m in order.method.iloc[1:]:
        rows = c[((c.a == top) & (c.b == m)) | ((c.a == m) & (c.b == top))]
        if not len(rows):
            out[m] = "not compared"
            continue
        r = rows.iloc[0]
        lead = r.difference if r.a == top else -r.difference          # top minus m
        out[m] = "tie" if not r.resolved else ("below" if lead > 0 else "above")
    return out


def figure_r1(table: pd.DataFrame, comparisons: pd.DataFrame | None = None):
    """R@1 of every scored loop-closure row, best first, each bar with its 95 % interval over the
    evaluation queries (``R@1_lo_%``..``R@1_hi_%``; none drawn where the table has none) and
    chance's R@1 as a line; colours as in :func:`figure_pr`. The sorted order is not a ranking: every
    bar whose paired R@1 difference with the top bar (``comparisons``, :func:`ties_with_top`) holds 0
    is hatched and marked "tied with the top", one never compared with it dotted, so only an
    unhatched bar below the top is resolved below it. Returns a Figure."""
    order = table[(table["mode"] == "loop closure")].dropna(subset=["R@1_%"]).sort_values("R@1_%", ascending=False)
    chance_r1 = table[(table.method == "chance (random scores)") & (table["mode"] == "loop closure")]["R@1_%"].iloc[0]
    colours = method_colours(table.method)
    r1 = order["R@1_%"].to_numpy(float)
    err = np.nan_to_num(np.vstack([r1 - order["R@1_lo_%"].to_numpy(float), order["R@1_hi_%"].to_numpy(float) - r1]))
    fig, ax = plt.subplots(figsize=(9, 4.8))
    bars = ax.barh(order.method, r1, color=[colours[m] for m in order.method],
                   xerr=err, error_kw=dict(ecolor="k", lw=1, capsize=2), label="R@1, whisker: 95 % interval")
    status = ties_with_top(order, comparisons)
    marks = {"top": ("", "top bar"), "tie": ("///", "tied with the top (paired R@1 interval holds 0)"),
             "not compared": ("..", "not compared with the top (no paired comparison)")}
    for bar, m in zip(bars.patches, order.method):
        if status[m] in marks:
            bar.set_hatch(marks[status[m]][0]); bar.set_edgecolor("k")
            ax.annotate(marks[status[m]][1].split(" (")[0], (bar.get_width(), bar.get_y() + bar.get_height() / 2),
                        xytext=(4, 0), textcoords="offset points", va="center", fontsize=6)
    ax.axvline(chance_r1, color="C3", ls="--", lw=1, label=f"chance R@1 {chance_r1:.2f} %")
    n_tie = sum(v == "tie" for v in status.values())
    ax.set_title(f"sorted by R@1, not ranked: {n_tie} of {len(order) - 1} bars tied with the top "
                 f"({order.method.iloc[0]}) by their paired interval", fontsize=8)
    ax.invert_yaxis(); ax.set_xlabel("R@1 on the evaluation queries (%), loop closure")
    ax.set_xlim(0, 100); ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
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
            f"the queries (runs of {split.gap} consecutive queries resampled, leaderboard.spread); a row is called "
            "higher than another only where their paired difference is resolved (comparisons.csv); pair_AP_% = the "
            "pair AP (one sample per pair of frames), a secondary column; chance = evaluate.query_chance (pair AP: "
            f"evaluate.chance_level). Knobs picked by per-query AUC-PR on the tuning queries ({split.scored_on}); "
            f"thresholds by rule '{p['threshold_rule']}' on the tuning queries. Frames/s (greenloop.speed.timing): decoded "
            "frame in memory -> decision (describe, match against every stored frame, store), over described frames "
            f"{start}..{stop - 1} with frames 0..{start - 1} stored, median [min, max] of {p['timing_repeats']} "
            f"interleaved repeats on {report.cpu_model()}; decode_ms = cv2.imread of the same frames, apart. "
            "bytes_per_stored_frame = stored descriptor + 4 x seq_len column buffer (the dictionary stores none, only "
            f"counters). Targets: {target}.")


def summary(data: Data, split: Split, tuned: Tuned, timed: Timed, result: Board, decisions=(),
            step: Step | None = None) -> dict:
    """summary.json's content (the keys the CLI's --tuned, the tests and the README read); step: the
    :func:`choose_step` that gave ``data.frame_step`` (its requested step and why), when given."""
    return {"leaderboard": lb.rounded(result.board).to_dict("records"), "target": result.target,
            "detector_targets": result.targets.to_dict("records"), "knobs": tuned.knobs,
            "thresholds": {k: timed.thresholds[k] for k in tuned.knobs}, "stream_matches_matrix": timed.stream_check,
            "frames": len(data.frames), "frame_step": data.frame_step, "exclude_steps": data.exclude,
            "timing_window": list(data.params["timing_window"]), "decode": timed.decode,
            "dictionary_trained_on_frames": decisions[0]["n_train"] if decisions else None,
            "split": {"honest": split.no_split is None, "not_available": split.no_split},
            **({} if step is None else {"frame_step_requested": step.requested, "frame_step_rule": step.why,
                                        "min_revisit_queries": step.minimum})}


def _standing(lc: pd.DataFrame, comp: pd.DataFrame | None, name: str) -> str:
    """One greenloop-seq row's R@1 (%, 95 % interval) and how many other rows its paired R@1 difference
    is resolved above / below (comparisons.csv); "" where the board has no such scored row."""
    if name not in lc.index or pd.isna(lc.loc[name, "R@1_%"]):
        return ""
    r = lc.loc[name]
    text = f"{name} R@1 {wording.num(r['R@1_%'])} % {wording.span(r['R@1_lo_%'], r['R@1_hi_%'])}"
    if comp is None:
        return text + " (no paired comparisons in this folder: no order is called)"
    c = comp[(comp.a == name) & (comp.metric == "R@1")]
    up, down = int((c.resolved & (c.lo > 0)).sum()), int((c.resolved & (c.hi < 0)).sum())
    return text + f", paired R@1 resolved above {up} and below {down} of the {len(c)} other rows, not resolved against {len(c) - up - down}"


def _targets_sentence(targets: pd.DataFrame, name: str) -> str:
    """How many of the named configuration ``name``'s targets are met on each protocol (targets.csv),
    naming those not met; targets not measured (met empty) are counted apart."""
    parts = []
    for protocol, t in targets[targets.configuration == name].groupby("protocol", sort=False):
        judged = t[t.met.notna() & (t.met.astype(str) != "")]
        met = judged.met.astype(str).str.lower() == "true"
        missed = "; ".join(judged[~met].target.str.split(": ").str[0])
        where = "the leaderboard" if protocol == "leaderboard" else f"the stream {protocol}"
        parts.append(f"{int(met.sum())} of its {len(judged)} targets judged on {where}" + (f" (not met: {missed})" if missed else "")
                     + (f", {len(t) - len(judged)} not measured there" if len(t) > len(judged) else ""))
    return f"The named default {name} meets " + "; ".join(parts) + "." if parts else ""


def conclusion(out_dir) -> str:
    """Notebook 13's last cell, in Markdown: the verdict on the main paper's dictionary as a detector for
    this dataset (``study.verdict``), then where greenloop-seq (tuned here) and the named default stand on
    the leaderboard (R@1 % with its 95 % interval; above / below only where comparisons.csv's paired
    difference is resolved) and which of the named default's targets are met (leaderboard.csv,
    comparisons.csv, targets.csv under ``out_dir``)."""
    out_dir = Path(out_dir)
    board = pd.read_csv(out_dir / "leaderboard.csv")
    lc = board[board["mode"] == "loop closure"].set_index("method")
    comp = pd.read_csv(out_dir / "comparisons.csv") if (out_dir / "comparisons.csv").is_file() else None
    if comp is not None and "protocol" in comp:
        comp = comp[comp.protocol == "leaderboard"]
    rows = [x for x in (_standing(lc, comp, n) for n in ("greenloop-seq", seqmatch.DEFAULT_NAME)) if x]
    n = lc.iloc[0]
    counts = f"{int(n.queries)} evaluation queries, {int(n.revisit_queries)} with a partner"
    lines = [f"On {verdict.dataset_name(out_dir.parent)} ({counts}; loop closure): "
             + ("; ".join(rows) if rows else "no greenloop-seq row was scored") + ".",
             _targets_sentence(pd.read_csv(out_dir / "targets.csv"), seqmatch.DEFAULT_NAME),
             _false_sentence(out_dir / "false_closures.csv", seqmatch.DEFAULT_NAME)]
    return wording.heading(Path(out_dir).parent, "13_leaderboard") + "\n\n" + " ".join(x for x in lines if x)


def _false_sentence(path: Path, name: str) -> str:
    """Where the named configuration ``name``'s false closures on the leaderboard lie (false_closures.csv,
    :func:`false_table`): how many, in how many runs, and the longest run; "" without the table."""
    if not path.is_file():
        return ""
    t = pd.read_csv(path)
    t = t[(t.protocol == "leaderboard") & (t.configuration == name)]
    if not len(t):
        return f"Every closure {name} declares on the leaderboard's evaluation queries is right."
    r = t.loc[t.closures.idxmax()]
    where = (f"{r.distance_m:.2f} m from the query's camera, optical axes {r.angle_deg:.0f} degrees apart (medians)"
             if "distance_m" in t and pd.notna(r.distance_m) else
             f"{r.offset_frames:g} frames from the query's nearest partner (median)" if pd.notna(r.offset_frames) else
             "queries without a partner")
    return (f"Its {int(t.closures.sum())} false closures at the fixed threshold lie in {len(t)} run(s) of consecutive "
            f"queries; the longest, queries {int(r.first_query)}-{int(r.last_query)} matched to frames "
            f"{int(r.first_match)}-{int(r.last_match)} ({int(r.closures)} closures), at {where} (false_closures.csv).")


def manifest_extra(data: Data, tuned: Tuned) -> dict:
    """The manifest's run-dependent entries: the knobs used, the CPU and the weights of each
    single-frame descriptor (``methods.single_frame.entry.specs``)."""
    return {"knobs": tuned.knobs, "cpu": report.cpu_model(),
            "weights_used": {b: data.infos[b].weights for b in single_frame.specs(data.params)}}
