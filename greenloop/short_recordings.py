"""Short recordings: cuts of 60-300 frames from a sequence folder, scored with
``detect``'s named configurations as a user runs them (``greenloop.detect.plan`` / ``run``, no flags
but the method and verification on or off), against the cut's ground truth.

A cut (:class:`Cut`) is a list of frame ranges of the source, in stream order, written as a sequence
folder by :func:`build_cut`: rgb/ (and depth/) symlinks to the source's frames numbered 0.., the
camera file copied, and the source's ground truth re-indexed: its poses (CameraTrajectory.txt, the
cut's rows) where it has poses, else its loop pairs among the cut's frames (ground_truth.csv, one
row per pair, tolerance already applied); a sequence.yaml naming the source and ranges and setting
``exclude`` to ``greenloop.exclusion``'s rule for a folder without ground truth (a share of its
frames), the exclusion a user's recording gets at run time: the ground truth's own rule would give
a short drive without revisit the paper's 150 frames and leave it no candidate to be wrong about.

Which cuts a dataset gives (:func:`cuts_for`):

* a folder with traversals (Gardens Point's layout, Nordland's protocol stream): the same ``n`` places
  of each traversal then of the next ("revisit", day-time unless a traversal's name says night or
  winter: the recall of night pairs and of Nordland's seasons is stated, not targeted);
* a folder with poses (the synthetic greenhouse): the first revisit, both visits ("revisit");
  the longest stretch without any loop ("no-revisit"); the two most alike straight legs that are
  no loop, driven one after the other ("neighbour": the neighbouring aisle); and the legs that do
  not revisit each other, concatenated ("aisles once": a repetitive recording without revisit).

Scoring (:func:`score_closures`): a closure (query, match) is right when its pair is a loop of the
cut's ground truth at any distance in time (loop pairs within their tolerance, Eq. 5 on poses), or,
where the cut has poses, when its relative pose is within POSE_TARGETS (:func:`pose_errors`).
Recall counts the cut's revisit frames (those with a loop farther than the run's exclusion) that a
right closure declares. :func:`short_recordings` writes the table (one row per cut x configuration x
verification) and the targets check (:func:`targets`) as CSV and Markdown.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from greenloop import detect, exclusion, groundtruth, report
from greenloop.datasets import sequence
from greenloop.methods import registry

CONFIGURATIONS = (registry.DEFAULT, "greenloop-seq-cnn")   # the named configurations the targets decide between
POSE_TARGETS = dict(rot_deg=2.0, dir_deg=10.0, metric_m=0.3)  # degrees, degrees, metres (the targets' pose errors)
MIN_PRECISION = 0.99       # of declared closures, on every cut
MIN_RECALL = 0.5           # of revisit frames, on cuts with a day-time revisit
CUT_FRAMES = (60, 300)     # a short recording's length, frames
LEG_TURN_DEG = 20.0        # a straight leg: heading within this of its first frame's
STATED_ONLY = ("night", "winter")   # a traversal pair so named: its recall is stated, not a target
NEIGHBOUR_MIN_M = 0.5      # metres across the heading: a neighbouring line, not the same aisle's next stretch
MIN_LEG = 20               # frames: shorter straight runs are corners, not legs


class Cut(NamedTuple):
    """A short recording: name (a folder name), ranges ((start, stop) source frames, increasing and
    disjoint, in stream order), kind ('revisit', 'no-revisit' or 'neighbour': two legs side by side,
    no revisit, where a closure is right by its relative pose) and day (False for a night or a winter
    revisit: the recall target applies to day-time revisits only, :data:`STATED_ONLY`)."""
    name: str
    ranges: tuple
    kind: str
    day: bool = True

    @property
    def frames(self) -> np.ndarray:
        """(M,) int64 source frame numbers of the cut, in stream order."""
        return np.concatenate([np.arange(a, b, dtype=np.int64) for a, b in self.ranges])


def _check_cut(cut: Cut, n_source: int) -> np.ndarray:
    """The cut's source frames, or ValueError naming a range outside the source or out of order."""
    for a, b in cut.ranges:
        if not 0 <= a < b <= n_source:
            raise ValueError(f"cut {cut.name}: range ({a}, {b}) is not within the source's frames 0..{n_source}")
    f = cut.frames
    if np.any(np.diff(f) <= 0):
        raise ValueError(f"cut {cut.name}: ranges {cut.ranges} must be increasing and disjoint (stream order)")
    return f


def _link(src: Path, dst: Path) -> None:
    """dst a symlink to src (a copy where the file system has no symlinks)."""
    try:
        os.symlink(src.resolve(), dst)
    except OSError:
        shutil.copy2(src, dst)


def build_cut(source, cut: Cut, out) -> Path:
    """Write ``cut`` of the sequence folder ``source`` as the sequence folder ``out/cut.name``
    (module doc: rgb/ and depth/ links, camera file, ground truth re-indexed, sequence.yaml).
    Returns the folder. ValueError for a bad range, NoGroundTruthError for a source without one."""
    seq = sequence.open(source)
    f = _check_cut(cut, seq.n_frames)
    folder = Path(out) / cut.name
    if folder.exists():
        shutil.rmtree(folder)
    for sub, paths in (("rgb", seq.frame_paths), ("depth", seq.depth_paths)):
        if paths is None:
            continue
        (folder / sub).mkdir(parents=True)
        for k, i in enumerate(f):
            _link(paths[i], folder / sub / f"{k}{paths[i].suffix}")
    for name in sequence.CAMERA_NAMES:
        if (seq.path / name).is_file():
            shutil.copy2(seq.path / name, folder / name)
    ex = exclusion.exclusion(folder / "rgb")         # the rule without ground truth: what detect sees at run time
    _write_ground_truth(seq, f, folder)
    ranges = ", ".join(f"{a}-{b - 1}" for a, b in cut.ranges)
    (folder / sequence.DESCRIPTION_NAME).write_text(
        f"# {cut.kind} cut of {seq.path}: source frames {ranges}\n# {ex.rule}\nexclude: {ex.frames}\n")
    return folder


def _write_ground_truth(seq: sequence.Sequence, f: np.ndarray, folder: Path) -> None:
    """The source's ground truth over frames ``f`` (M,), re-indexed 0..M-1: poses or loop pairs."""
    if seq.ground_truth is not None and seq.ground_truth.kind == "poses":
        _, poses = seq.poses()
        sequence.write_trajectory(folder / sequence.TRAJECTORY_NAMES[0], np.arange(len(f)), poses[f])
        return
    gt = groundtruth.for_sequence(seq, f, exclude=0)
    sequence.write_loop_pairs(folder / sequence.GROUND_TRUTH_NAME, groundtruth.loop_pairs(gt))


def pose_errors(R, t, metric: bool, T_true) -> dict:
    """A closure's relative pose against the true one T_true = T_match^-1 T_query ((4, 4), metres).
    R (3, 3), t (3,) (metres where ``metric``, else a direction) or None. Returns rot_deg, dir_deg
    (angle between t and the true translation), metric_m (|t - t_true|, NaN unless metric) and
    pose_ok (within POSE_TARGETS: rotation and metric error, or direction without depth)."""
    if R is None or t is None:
        return dict(rot_deg=np.nan, dir_deg=np.nan, metric_m=np.nan, pose_ok=False)
    R, t, T = np.asarray(R, float), np.asarray(t, float).ravel(), np.asarray(T_true, float)
    cos_r = np.clip((np.trace(R @ T[:3, :3].T) - 1.0) / 2.0, -1.0, 1.0)
    rot = float(np.degrees(np.arccos(cos_r)))
    tt = T[:3, 3]
    cos_t = t @ tt / max(np.linalg.norm(t) * np.linalg.norm(tt), 1e-12)
    direction = float(np.degrees(np.arccos(np.clip(cos_t, -1.0, 1.0))))
    err = float(np.linalg.norm(t - tt)) if metric else np.nan
    ok = rot <= POSE_TARGETS["rot_deg"] and (err <= POSE_TARGETS["metric_m"] if metric
                                             else direction <= POSE_TARGETS["dir_deg"])
    return dict(rot_deg=rot, dir_deg=direction, metric_m=err, pose_ok=bool(ok))


def score_closures(folder, closures, exclude: int = 0, step: int = 1) -> dict:
    """Count a run's closures on a cut folder against its ground truth (module doc).

    closures: ``interface.Closure`` records (or any with query, match, R, t, metric), streamed frame
    numbers at ``step``; exclude: the run's exclusion in streamed frames (revisit frames are those
    with a loop more than exclude * step frames back). Returns closures, right, wrong, precision
    (NaN without closures), revisits, found (revisit frames a right closure declares), recall (NaN
    without revisits), posed (closures with a pose and true poses), pose_ok and the medians of
    rot_deg, dir_deg, metric_m over the posed closures (NaN where none)."""
    seq = sequence.open(folder)
    loops = groundtruth.for_sequence(seq, exclude=0)
    revisit = groundtruth.revisit_frames(groundtruth.for_sequence(seq, exclude=int(exclude) * step))
    has_poses = seq.ground_truth.kind == "poses"
    poses = seq.poses()[1] if has_poses else None
    right, found, errs = 0, set(), []
    for c in closures:
        q, m = int(c.query) * step, int(c.match) * step
        ok = m >= 0 and bool(loops[q, m])
        if has_poses and m >= 0 and c.R is not None:
            e = pose_errors(c.R, c.t, bool(c.metric), groundtruth.relative_poses(poses, np.array([[m, q]]))[0])
            errs.append(e)
            ok = ok or e["pose_ok"]
        right += ok
        if ok and revisit[q]:
            found.add(q)
    n, n_rev = len(closures), int(revisit.sum())
    med = {k: float(np.nanmedian([e[k] for e in errs])) if errs and not np.all(np.isnan([e[k] for e in errs]))
           else np.nan for k in ("rot_deg", "dir_deg", "metric_m")}
    return dict(closures=n, right=int(right), wrong=n - int(right), precision=right / n if n else np.nan,
                revisits=n_rev, found=len(found), recall=len(found) / n_rev if n_rev else np.nan,
                posed=len(errs), pose_ok=int(sum(e["pose_ok"] for e in errs)), **med)


def run_cut(folder, name: str = registry.DEFAULT, verify: bool = True) -> dict:
    """Run ``detect`` on a cut folder as a user does (``detect.plan`` / ``run``: the named
    configuration ``name``, verification on or off) and score it (:func:`score_closures`). Returns the
    score with verified (closures the verifier accepted), unverified (declared unchecked: too-small
    frames, or no verification), rejected (candidates verification dropped), exclude, seconds."""
    p = detect.plan(folder, name)
    verifier = detect.verifier_for(folder) if verify else None
    r = detect.run(p, folder, out=lambda line: None, verifier=verifier)
    verified = sum(c.verified is True for c in r.closures)
    return dict(score_closures(folder, r.closures, p.exclude, p.step), verified=verified,
                unverified=len(r.closures) - verified, rejected=int(r.rejected), exclude=p.exclude * p.step,
                seconds=round(float(r.seconds), 2))


def _far_loops(seq: sequence.Sequence) -> np.ndarray:
    """(N, N) bool loops of the whole source farther apart than MIN_EXCLUDE frames (its revisits)."""
    return groundtruth.for_sequence(seq, exclude=exclusion.MIN_EXCLUDE)


def _walks(seq: sequence.Sequence) -> tuple:
    """The traversals (sequence.Traversal) of a folder: its layout's, else those its protocol's first
    target stream names (Nordland's summer and winter in one rgb/ folder), else its one traversal."""
    if len(seq.traversals) < 2 and seq.protocol.streams:
        return tuple(seq.protocol.streams[0].traversals)
    return tuple(seq.traversals)


def _traversal_cuts(t: tuple, n: int) -> list[Cut]:
    """Each traversal's middle ``n`` places after the previous traversal's same places ('revisit',
    not day-time where either name holds a STATED_ONLY word), and the first traversal's middle 2n frames ('no-revisit').
    t: (T,) sequence.Traversal in stream order."""
    cuts = []
    for a, b in zip(t[:-1], t[1:]):
        k = min(n, a.stop - a.start, b.stop - b.start)
        s = (min(a.stop - a.start, b.stop - b.start) - k) // 2
        night = any(w in (a.name + b.name).lower() for w in STATED_ONLY)
        cuts.append(Cut(f"{a.name}-{b.name}", ((a.start + s, a.start + s + k), (b.start + s, b.start + s + k)),
                        "revisit", not night))
    k = min(2 * n, t[0].stop - t[0].start)
    s = t[0].start + (t[0].stop - t[0].start - k) // 2
    return cuts + [Cut(f"{t[0].name}-once", ((s, s + k),), "no-revisit")]


def _first_revisit(loops: np.ndarray, n: int) -> Cut | None:
    """Both visits of the first revisit: up to n frames from its first partner, up to n from its first revisit frame."""
    rev = np.flatnonzero(np.triu(loops, 1).any(0))
    if rev.size == 0:
        return None
    j0 = int(rev[0])
    j1 = j0 + int(np.argmax(np.append(np.diff(rev) > 1, True))) + 1     # end of the first run of revisit frames
    i0 = int(np.flatnonzero(loops[:j0, j0:j1].any(1))[0])
    k = min(n, j0 - i0, j1 - j0)
    return Cut("revisit", ((i0, i0 + k), (j0, j0 + k)), "revisit")


def _no_revisit(loops: np.ndarray, n: int) -> Cut | None:
    """The longest stretch (at most 2n frames) in which no frame revisits another of it."""
    last = np.array([int(np.flatnonzero(loops[:j, j])[-1]) if loops[:j, j].any() else -1 for j in range(len(loops))])
    best, a = (0, 0), 0
    for j in range(len(loops)):
        a = max(a, last[j] + 1, j + 1 - 2 * n)
        if j + 1 - a > best[1] - best[0]:
            best = (a, j + 1)
    return Cut("no-revisit", (best,), "no-revisit") if best[1] > best[0] else None


def legs(poses) -> list[tuple[int, int]]:
    """The straight legs of a route: (start, stop) frame runs of at least MIN_LEG frames whose heading
    (the optical axis on the first camera's x-z plane) stays within LEG_TURN_DEG of the run's first.
    poses: (N, 4, 4) camera-to-world, OpenCV camera axes (y down), world = the first camera's frame."""
    z = np.asarray(poses)[:, :3, 2]
    heading = np.degrees(np.arctan2(z[:, 0], z[:, 2]))
    runs, a = [], 0
    for j in range(1, len(heading) + 1):
        if j == len(heading) or abs((heading[j] - heading[a] + 180.0) % 360.0 - 180.0) > LEG_TURN_DEG:
            if j - a >= MIN_LEG:
                runs.append((a, j))
            a = j
    return runs


def _linked(loops: np.ndarray, a: tuple, b: tuple) -> bool:
    """Whether any frame of run a is a loop of any frame of run b."""
    return bool(loops[a[0]:a[1], b[0]:b[1]].any())


def _neighbour(poses, runs: list, loops: np.ndarray, n: int) -> Cut | None:
    """The two legs driven the same way that pass closest side by side (their mean positions'
    distance across the heading, at least NEIGHBOUR_MIN_M: another line, not the same aisle's next
    stretch), more than MIN_EXCLUDE frames apart and no loop of each other: up to n frames of each."""
    t, z = np.asarray(poses)[:, :3, 3], np.asarray(poses)[:, :3, 2]
    best = None
    for k, a in enumerate(runs):
        for b in runs[k + 1:]:
            da, db = z[a[0]:a[1]].mean(0), z[b[0]:b[1]].mean(0)
            if (da @ db < np.cos(np.radians(LEG_TURN_DEG)) * np.linalg.norm(da) * np.linalg.norm(db)
                    or b[0] - a[1] <= exclusion.MIN_EXCLUDE or _linked(loops, a, b)):
                continue
            d = t[b[0]:b[1]].mean(0) - t[a[0]:a[1]].mean(0)
            across = float(np.linalg.norm(d - (d @ da) * da / (da @ da)))
            if across >= NEIGHBOUR_MIN_M and (best is None or across < best[0]):
                best = (across, a, b)
    if best is None:
        return None
    (a0, a1), (b0, b1) = best[1], best[2]
    return Cut("neighbour", ((a0, min(a1, a0 + n)), (b0, min(b1, b0 + n))), "neighbour")


def _aisles_once(runs: list, loops: np.ndarray, n: int) -> Cut | None:
    """The legs that revisit none of the legs before them, in driving order, the middle 2n / L frames of
    each of the L (two at least) concatenated: a repetitive recording without a true revisit."""
    chosen = []
    for r in runs:
        if all(not _linked(loops, c, r) for c in chosen):
            chosen.append(r)
    if len(chosen) < 2:
        return None
    share = 2 * n // len(chosen)
    mid = [((a + b - min(share, b - a)) // 2, (a + b - min(share, b - a)) // 2 + min(share, b - a)) for a, b in chosen]
    return Cut("aisles-once", tuple(mid), "no-revisit")


def cuts_for(dataset, n: int = 100) -> list[Cut]:
    """The short recordings a sequence folder gives (module doc), each visit at most ``n`` frames (so a
    cut at most 2n <= CUT_FRAMES[1]): traversal cuts where it has traversals, else pose cuts where it
    has poses, else none; a cut shorter than CUT_FRAMES[0] frames is left out."""
    if not 0 < 2 * n <= CUT_FRAMES[1]:
        raise ValueError(f"n must be 1..{CUT_FRAMES[1] // 2} frames a visit (a cut holds two), got {n}")
    seq = sequence.open(dataset)
    walks = _walks(seq)
    if len(walks) >= 2:
        found = _traversal_cuts(walks, n)
    elif seq.ground_truth is None or seq.ground_truth.kind != "poses":
        found = []
    else:
        loops, poses = _far_loops(seq), seq.poses()[1]
        runs = legs(poses)
        found = [_first_revisit(loops, n), _no_revisit(loops, n), _neighbour(poses, runs, loops, n),
                 _aisles_once(runs, loops, n)]
    return [c for c in found if c is not None and len(c.frames) >= CUT_FRAMES[0]]


def targets(table: pd.DataFrame) -> pd.DataFrame:
    """The detector's targets on each row of :func:`short_recordings`' table: precision (>= MIN_PRECISION of
    the declared closures; met by a silent run), silent (a no-revisit cut declares nothing), recall
    (>= MIN_RECALL of the revisit frames on a day-time revisit cut), pose (medians within POSE_TARGETS
    where closures carry a pose and the cut has poses). Each is True / False, or None where it does
    not apply; ``met``: every one that applies."""
    t = table[["cut", "kind", "configuration", "verify", "closures", "right", "revisits", "found"]].copy()
    rev = table["kind"] == "revisit"
    t["precision"] = [None if k == "no-revisit" else bool(c == 0 or p >= MIN_PRECISION)
                      for k, c, p in zip(table["kind"], table["closures"], table["precision"])]
    t["silent"] = [bool(c == 0) if k == "no-revisit" else None for k, c in zip(table["kind"], table["closures"])]
    t["recall"] = [bool(r >= MIN_RECALL) if ok else None for ok, r in zip(rev & table["day"], table["recall"].fillna(0))]
    t["pose"] = [None if n == 0 else bool(not rot > POSE_TARGETS["rot_deg"] and not m > POSE_TARGETS["metric_m"]
                                          and (m == m or not d > POSE_TARGETS["dir_deg"]))
                 for n, rot, d, m in zip(table["posed"], table["rot_deg"], table["dir_deg"], table["metric_m"])]
    checks = t[["precision", "silent", "recall", "pose"]]
    t["met"] = [all(v is not False for v in row) for row in checks.itertuples(index=False)]
    return t


def short_recordings(dataset, out_dir, configurations=CONFIGURATIONS, verify=(False, True), n: int = 100,
                     cuts=None, cut_dir=None) -> pd.DataFrame | None:
    """Build the dataset's cuts (:func:`cuts_for` with ``n`` frames a visit, or ``cuts``) under ``cut_dir``
    (None: a temporary folder, removed after), run every configuration with and without verification on
    each (:func:`run_cut`) and write ``out_dir``/short_recordings.{csv,md} (one row per cut x
    configuration x verify, with the counts behind each rate) and ``out_dir``/short_targets.{csv,md}
    (:func:`targets`). Returns the table, or None where the dataset gives no cut (no traversals, no
    poses): notebook 13 then skips it."""
    cuts = cuts_for(dataset, n) if cuts is None else cuts
    if not cuts:
        return None
    if cut_dir is None:
        with tempfile.TemporaryDirectory(prefix="short-recordings-") as tmp:
            return short_recordings(dataset, out_dir, configurations, verify, n, cuts, tmp)
    rows = []
    for cut in cuts:
        folder = build_cut(dataset, cut, cut_dir)
        for name in configurations:
            for v in verify:
                rows.append(dict(cut=cut.name, kind=cut.kind, day=cut.day, frames=len(cut.frames), configuration=name,
                                 verify=bool(v), **run_cut(folder, name, bool(v))))
    table, out_dir = pd.DataFrame(rows), Path(out_dir)
    note = (f"A closure is right when its frames are a loop of the cut's ground truth (any distance in time) or its "
            f"relative pose is within {POSE_TARGETS} (cuts with poses); recall: revisit frames (a loop farther back "
            f"than the run's exclusion) a right closure declares. Cuts of {sequence.open(dataset).path}.")
    report.write_table(table, out_dir / "short_recordings", "Short recordings: detect's named configurations",
                       note, decimals=3)
    report.write_table(targets(table), out_dir / "short_targets", "Short recordings: the detector's targets",
                       f"precision >= {MIN_PRECISION:.0%} of declared closures; no closure on a no-revisit cut; "
                       f"recall >= {MIN_RECALL:.0%} of revisit frames on day-time revisit cuts; pose medians "
                       f"within {POSE_TARGETS}.")
    return table
