"""The one exclusion rule: how many frames before a query are never its loop candidates.

A query frame j is compared only with frames i < j - exclude: the frames just before it show the
same place because the camera has not left it yet, not because it came back. ``make`` (every
notebook's ``exclude``, through ``greenloop.study.params``) and ``python -m greenloop detect`` read
the value from :func:`exclusion`, which takes the first of:

1. ``sequence.yaml``'s ``exclude`` (the folder says it);
2. the ground truth, when the folder has one (:func:`from_ground_truth`): the frames until the
   camera has left the place (for every frame, the run of following frames the ground truth calls
   the same place; the longest run), then the paper's DEFAULT_EXCLUDE frames (Qi 2024, Eq. 5:
   "the neighbouring 150 images are disregarded") where that window still leaves at least half of
   the frames of revisit pairs (either end) a partner, else half the distance of the closest
   revisit, so that revisits count;
3. capture time, when ``sequence.yaml`` gives ``frame_rate`` (a bag's or a video's time stamps:
   :func:`of_recording`): EXCLUDE_SECONDS of recording;
4. else EXCLUDE_FRACTION of the recording, between MIN_EXCLUDE and DEFAULT_EXCLUDE frames.

Every value is in ORIGINAL frames (a stream of every k-th frame excludes ``exclude // k`` of its
own). :func:`candidate_share` says what share of the frames it leaves any candidate.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from greenloop import groundtruth
from greenloop.datasets import recording, sequence
from greenloop.groundtruth import DEFAULT_EXCLUDE

EXCLUDE_SECONDS = 10.0       # seconds of recording: a walking or driving camera has left a place by then
EXCLUDE_FRACTION = 0.1       # of the recording, when neither ground truth nor frame times are known
MIN_EXCLUDE = 20             # frames: two sequences of the named detectors (seq_len 10) never overlap
KEEP_SHARE = 0.5             # the paper's window is kept while it leaves this share of the revisit frames


class Exclusion(NamedTuple):
    """frames: the exclusion in original frames (>= 0); source: "sequence.yaml", "ground truth",
    "frame rate" or "fraction"; rule: one sentence saying how it was chosen, for printouts."""
    frames: int
    source: str
    rule: str


def exclusion(folder, loop_threshold: float = 0.5) -> Exclusion:
    """The exclusion of a sequence folder by the module's rule (first that applies).

    folder: a sequence folder (greenloop.datasets.sequence), a Sequence or a folder of frames
        (opened once: ``sequence.open``).
    loop_threshold: Qi 2024 Eq. 5's threshold for a folder with poses (as ``groundtruth.for_sequence``).
    """
    seq = sequence.open(folder)
    d = seq.description
    if seq.exclude is not None:
        return Exclusion(int(seq.exclude), sequence.DESCRIPTION_NAME,
                         f"exclude {seq.exclude} frames, from {seq.path / sequence.DESCRIPTION_NAME}")
    if seq.ground_truth is not None:
        return from_ground_truth(seq, loop_threshold)
    return _by_time(seq.n_frames, d["frame_rate"], sequence.DESCRIPTION_NAME,
                    f"no frame_rate in {sequence.DESCRIPTION_NAME}; write `exclude: N` or `frame_rate: FPS` there")


def of_recording(source, loop_threshold: float = 0.5) -> Exclusion:
    """The exclusion of any recording (greenloop.datasets.recording): a folder's by :func:`exclusion`;
    a bag's or a video's, which carry no ground truth and no sequence.yaml, by rule 3 at the frame
    rate of its time stamps, else rule 4. source: a FrameSource, or what ``open_frames`` opens."""
    source = recording.open_frames(source)
    if source.sequence is not None:
        return exclusion(source.sequence, loop_threshold)
    return _by_time(len(source), source.frame_rate, f"the time stamps of {source}",
                    f"the {source.kind} has no frame times; pass --exclude N")


def _by_time(n: int, frame_rate, where: str, fix: str) -> Exclusion:
    """Rules 3 and 4: EXCLUDE_SECONDS at ``frame_rate`` (frames/s, from ``where``), else
    EXCLUDE_FRACTION of the ``n`` frames within MIN_EXCLUDE..DEFAULT_EXCLUDE (``fix`` says how to choose)."""
    if frame_rate is not None:
        frames = int(round(EXCLUDE_SECONDS * float(frame_rate)))
        return Exclusion(frames, "frame rate", f"exclude {frames} frames: {EXCLUDE_SECONDS:g} s at the "
                         f"{frame_rate:g} frames/s of {where} (no ground truth)")
    frames = int(min(max(round(EXCLUDE_FRACTION * n), MIN_EXCLUDE), DEFAULT_EXCLUDE))
    return Exclusion(frames, "fraction", f"exclude {frames} frames: {EXCLUDE_FRACTION:.0%} of the {n} frames, "
                     f"within {MIN_EXCLUDE}..{DEFAULT_EXCLUDE} (no ground truth, {fix} to choose)")


def partner_offsets(folder, loop_threshold: float = 0.5) -> tuple[np.ndarray, np.ndarray, int]:
    """Every ground-truth partner of a folder before any exclusion, as (a, d, n): a (P,) frames,
    d (P,) offsets >= 1 (frame a + d is a partner of a), n frames in the folder.

    Poses: Qi 2024 Eq. 5 (``groundtruth.pose_error`` < loop_threshold); loop pairs (any source of
    ``sequence.ground_truth_source``): each row (i, j, tolerance) pairs i with j - tol .. j + tol.
    folder: a sequence folder or Sequence."""
    seq = sequence.open(folder)
    n = seq.n_frames
    if seq.ground_truth is not None and seq.ground_truth.kind == "poses":
        _, poses = seq.poses()
        a, b = np.nonzero(np.triu(groundtruth.pose_error(poses) < loop_threshold, 1))
    else:
        p = seq.loop_pairs()
        lo, hi = np.maximum(p[:, 1] - p[:, 2], 0), np.minimum(p[:, 1] + p[:, 2], n - 1)
        i = np.repeat(p[:, 0], np.maximum(hi - lo + 1, 0))
        j = np.concatenate([np.arange(s, e + 1) for s, e in zip(lo, hi)] + [np.zeros(0, np.int64)])
        ab = np.unique(np.stack([np.minimum(i, j), np.maximum(i, j)], 1)[i != j], axis=0).reshape(-1, 2)
        a, b = ab[:, 0], ab[:, 1]
    return a.astype(np.int64), (b - a).astype(np.int64), n


def same_place_runs(a: np.ndarray, d: np.ndarray, n: int) -> np.ndarray:
    """For every frame, how many following frames the ground truth calls the same place without a
    break (frame a and a + 1 .. a + run are all partners): the frames until the camera has left.

    a, d: (P,) partner frames and offsets (:func:`partner_offsets`). Returns (n,) int64."""
    run = np.zeros(n, np.int64)
    if not len(a):
        return run
    order = np.lexsort((d, a))
    a, d = a[order], d[order]
    starts = np.flatnonzero(np.r_[True, a[1:] != a[:-1]])
    for s, e in zip(starts, np.r_[starts[1:], len(a)]):
        ds = d[s:e]
        broken = np.flatnonzero(ds != np.arange(1, len(ds) + 1))
        run[a[s]] = broken[0] if len(broken) else len(ds)
    return run


def from_ground_truth(folder, loop_threshold: float = 0.5) -> Exclusion:
    """Rule 2 of the module doc: the exclusion a folder's ground truth implies."""
    a, d, n = partner_offsets(folder, loop_threshold)
    runs = same_place_runs(a, d, n)
    reach = int(runs.max()) if n else 0
    revisit = d > runs[a]                    # partners beyond their frame's same-place run
    ra, rd = a[revisit], d[revisit]
    if not len(rd):
        frames = max(reach, MIN_EXCLUDE) if reach else DEFAULT_EXCLUDE
        return Exclusion(frames, "ground truth", f"exclude {frames} frames: the ground truth has no revisit "
                         f"(the camera leaves a place within {reach} frames)")
    frames_with = np.unique(np.r_[ra, ra + rd])
    far = np.unique(np.r_[ra[rd > DEFAULT_EXCLUDE], (ra + rd)[rd > DEFAULT_EXCLUDE]])
    left = f"the camera leaves a place within {reach} frames; revisits {int(rd.min())}..{int(rd.max())} frames apart"
    if reach <= DEFAULT_EXCLUDE and len(far) >= KEEP_SHARE * len(frames_with):
        return Exclusion(DEFAULT_EXCLUDE, "ground truth", f"exclude {DEFAULT_EXCLUDE} frames (the paper's window): "
                         f"{left}, {len(far)} of {len(frames_with)} frames of revisit pairs beyond it")
    frames = max(reach, int(rd.min()) // 2)
    return Exclusion(frames, "ground truth", f"exclude {frames} frames (the longer of the camera's stay and half "
                     f"the closest revisit): {left}; the paper's {DEFAULT_EXCLUDE} would leave "
                     f"{len(far)} of {len(frames_with)} frames of revisit pairs (either end)")


def candidate_share(n_frames: int, exclude: int) -> float:
    """Share of n_frames frames that have any candidate (frame j > exclude), in [0, 1]."""
    return max(n_frames - exclude - 1, 0) / max(n_frames, 1)
