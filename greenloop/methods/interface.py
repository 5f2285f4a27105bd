"""What a detector provides and what it is given: two records, no class hierarchy.

A detector family is an :class:`Entry` of functions over a :class:`Data` (the described frames
of one dataset, its ground truth and its tuning/evaluation split). Knob records are plain dicts
(JSON-serialisable: they go to summary.json and the manifest), one per leaderboard row
("method"); a family may give several rows (greenloop-seq and greenloop-seq-fast).

Shapes: M described frames; descriptors (M, D) float32 in stream order; score matrices (M, M)
float32, row = earlier (database) frame, column = query, higher = more similar; ``exclude`` in
described frames (steps of ``frame_step``).
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np


class Data(NamedTuple):
    """What every detector is described, tuned and scored on.

    dataset: the sequence folder: its ``datasets.sequence.Sequence`` (``experiments.leaderboard.prepare``
        opens it once; os.PathLike, so code that takes a folder takes it) or a path.
        frame_step: every frame_step-th frame is described.
    frames: (M,) int original frame numbers of the described frames. GT: (M, M) bool ground truth.
    exclude: candidates of query j are frames i with j - i > exclude (described frames).
    tune: (M,) bool tuning queries, or None where no honest split exists (untuned defaults then).
    evalq: (M,) bool evaluation queries (every query without a split).
    params: the knob grids and options (notebook 13's parameters: seq_lens, contrast_windows,
        velocities, weights, input_size, ...; each family reads the keys it documents).
    descriptors: {descriptor name: (M, D)}; infos: {descriptor name: features.ExtractInfo}: what
        the families' ``describe`` returned, merged in registry order (a later family may reuse an
        earlier one's). cache: scratch shared by a family's functions (e.g. fitted projections).
    """
    dataset: object      # a datasets.sequence.Sequence or a path (str | os.PathLike)
    frame_step: int
    frames: np.ndarray
    GT: np.ndarray
    exclude: int
    tune: np.ndarray | None
    evalq: np.ndarray
    params: dict
    descriptors: dict
    infos: dict
    cache: dict


class Entry(NamedTuple):
    """One detector family: what the leaderboard, the CLI and the tests call.

    name: the registry key and ``detect --method NAME``.
    describe: (Data) -> ({descriptor name: (M, D)}, {name: ExtractInfo}): what it needs that
        ``data.descriptors`` lacks (evaluation input).
    tune: (Data) -> (tuning rows, {method: knob record}, {method: tuning AUC-PR %}): its knob grid
        scored by the ONE budget (per-query AUC-PR on ``data.tune``), the best record per method;
        without a tuning part (``data.tune`` None) its untuned records and no rows.
    score: (knob record, Data) -> (M, M) float32 score matrix (evaluation), or None for a detector
        that only decides (the dictionary: ``decide`` gives its row instead).
    stream: (knob record, threshold float | None, Data) -> a streaming detector: ``reset()``,
        ``update_descriptor(x)`` -> event {'frame', 'match', 'score'} | None, ``events``,
        ``frame_index``, ``threshold``, ``exclude``, ``bytes_per_frame`` (after a frame).
    describer: (knob record, Data) -> f(one decoded BGR frame (H, W, 3) uint8) -> (D,) descriptor,
        the stream's input: frame -> describer -> stream is the CLI's path and the timed one
        (``speed.timing.detector_method``).
    knob_text: (knob record) -> one line for the table.
    checked: its rows get the stream-vs-matrix check over the whole stream (summary.json).
    cli_knobs: the knob record ``detect --method NAME`` streams without ``--tuned`` (its keys are the
        knobs ``detect``'s flags may set; ``fixed_threshold``: the threshold it streams at).
    cli_threshold: (knob record) -> the default threshold where it follows the knobs (the
        dictionary's tau = L + margin); None: ``fixed_threshold`` or a threshold given.
    cli_variant: the summary.json row ``detect --tuned`` streams without ``--variant`` (None: it must
        be named).
    decide: for score=None: (Data) -> dict(row=leaderboard row fields, detector=its streaming detector,
        preload=what its start takes); None otherwise.
    """
    name: str
    describe: Callable
    tune: Callable
    score: Callable | None
    stream: Callable | None
    describer: Callable | None
    knob_text: Callable
    checked: bool = False
    cli_knobs: dict | None = None
    cli_threshold: Callable | None = None
    cli_variant: str | None = None
    decide: Callable | None = None


class IndexOptions(NamedTuple):
    """The candidate index a streaming detector may search instead of every stored frame
    (``detect --index``). kinds: the index names (``methods.lsh.retrieval``); dim: the dims the
    index holds (a PCA of the stored descriptors); fit: the candidate frames that PCA is fitted on;
    null_sample: the stored frames sampled for the calibration's null in candidate mode."""
    kinds: tuple
    dim: int
    fit: int
    null_sample: int


class Closure(NamedTuple):
    """One declared loop closure, as ``greenloop.detect.run`` returns it (``Run.closures``).

    query, match: streamed frame numbers (match -1 for a detector that names no frame, the
    dictionary); score: the detector's score (NaN where it has none). verified: True where the
    geometric verifier accepted the pair, None where it was not checked (no verifier, or frames too
    small for local features: model "too-small"); a rejected candidate is never a Closure.
    inliers: the verifier's inlier count (0 unchecked); model: "essential", "homography", "pnp",
    "too-small" or "none" (unchecked). R: (3, 3) float rotation of the match's camera relative to
    the query's, None without a pose; t: (3,) float translation, in metres where ``metric`` (a pose
    from depth, PnP) else a unit direction; None without a pose.
    """
    query: int
    match: int
    score: float
    verified: bool | None
    inliers: int
    model: str
    R: np.ndarray | None
    t: np.ndarray | None
    metric: bool


def no_descriptors(data: Data) -> tuple[dict, dict]:
    """``describe`` of a family that needs no descriptor beyond those already in ``data``."""
    return {}, {}
