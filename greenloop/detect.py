"""Stream a user's recording through a registered detector: what ``python -m greenloop detect`` runs.

Every method goes one way: its registry entry (``greenloop.methods.registry``) gives the knob
record (``Entry.cli_knobs``, or a notebook 13 ``summary.json`` row with ``tuned``), the streaming
detector (``Entry.stream``) and, for a detector fed descriptors, the frame -> descriptor step
(``Entry.describer``); a detector with ``update_many`` (greenloop-seq's, the dictionary's) takes
the decoded frames itself. The exclusion follows ``greenloop.exclusion`` (make's rule) unless
given. A recording is an image folder, a ROS bag (one camera topic) or a video
(``greenloop.datasets.recording``); its frames are decoded in colour (BGR, as a camera delivers
them) in windows.

Units: ``step``, ``exclude`` and ``seq_len`` count streamed frames (every ``step``-th frame of
the folder); an event is a dict with ``frame`` (streamed frame number) and the detector's
``event_columns`` (default ``match``, ``score``).

Verification (``run(verifier=...)``, :class:`Checker`): each event the detector declares is a
candidate; a geometric verifier ``(query, match, frame_q, frame_m, depth_q, depth_m) ->
Verification-like`` (fields accepted, inliers, model, R, t, metric; by default ``registry.verifier``'s
``verification.PairCheck``: the pair's geometry, then 3 consistent candidates) is applied to its frame
numbers and its two decoded frames (the match read from disk when it is older than the window; depth
in metres from the folder's depth/ where it has one, else None). The rule, stated once (:meth:`Checker.check`): a candidate is declared when
the verifier accepts it, and declared unverified (verified None) where it could not check it
(accepted None, or model "too-small"); a rejected one is not declared. Each declared closure is an
``interface.Closure`` (``Run.closures``) carrying the inlier count and the relative pose.
"""
from __future__ import annotations

import json
import pickle
import sys
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np

from greenloop import exclusion
from greenloop.datasets import recording, sequence
from greenloop.datasets.sequence import DESCRIPTION_NAME
from greenloop.methods import registry
from greenloop.methods.interface import Closure, Data
from greenloop.util.clock import timed
from greenloop.util.files import write_atomic
from greenloop.util.progress import bar

MATCH_COLUMNS = ("frame", "file", "match", "match_file", "score", "closure")
# --matches' columns after MATCH_COLUMNS under a verifier: verified 1/0 (empty: unchecked), the inlier count,
# the model, the rotation vector (rad) and translation of the relative pose, metric 1 (t in metres) / 0 (direction)
VERIFY_COLUMNS = ("verified", "inliers", "model", "rx", "ry", "rz", "tx", "ty", "tz", "metric")
UNCHECKED = dict(verified=None, inliers=0, model="none", R=None, t=None, metric=False)   # a closure not verified
OVERRIDES = ("descriptor", "seq_len", "contrast_window", "store_dtype", "model", "frames_per_spot", "margin", "backend")


class Plan(NamedTuple):
    """What one detect run streams. name: the method; knobs: its knob record (with where each
    came from in ``lines``); threshold: the score (or tau) to reach; step, exclude: streamed frames;
    frames: the streamed frames (a ``recording.FrameSource`` view: len, names, read); lines: the
    header lines printed before the stream."""
    name: str
    knobs: dict
    threshold: float
    step: int
    exclude: int
    frames: recording.FrameSource
    lines: list


def read_window(frames: recording.FrameSource) -> list[np.ndarray]:
    """Every frame of a FrameSource view, (H, W, 3) uint8 BGR; ValueError naming an unreadable one."""
    return frames.read()


def read_tuned(path, variant: str) -> tuple[dict, float, int, int]:
    """A notebook 13 summary.json's row ``variant``: (knobs, threshold, frame_step, exclude in ORIGINAL frames)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--tuned {path}: no such file; run notebook 13 on a recording of your site "
                                f"(make all DATASET=...), then pass its <results>/13_leaderboard/summary.json")
    summary = json.loads(path.read_text())
    if variant not in summary.get("knobs", {}):
        raise ValueError(f"--tuned {path} has no variant {variant!r} (it has {sorted(summary.get('knobs', {}))})")
    step = int(summary["frame_step"])
    return summary["knobs"][variant], summary["thresholds"][variant], step, int(summary["exclude_steps"]) * step


def _base(name: str, entry, tuned, variant) -> tuple[dict, float | None, str, int | None, int | None]:
    """(knobs, threshold, origin, tuned frame_step, tuned exclude) before the flags."""
    if tuned:
        variant = variant or entry.cli_variant
        if variant is None:
            raise ValueError(f"--tuned needs --variant: the leaderboard row whose knobs --method {name} streams")
        knobs, threshold, step, ex = read_tuned(tuned, variant)
        return dict(entry.cli_knobs, **knobs), threshold, "--tuned", step, ex
    knobs = dict(entry.cli_knobs)
    return knobs, knobs.get("fixed_threshold"), f"default {name}", None, None


def knobs_for(name: str, folder, tuned=None, variant=None, threshold=None, step=None, **flags) -> tuple:
    """The knob record, threshold and step ``detect`` streams with, and one line per knob saying
    where it came from (the entry's defaults, ``tuned``'s row, sequence.yaml's frame_step, a flag,
    which wins). flags: OVERRIDES given (None: not given). Returns (knobs, threshold, step, lines,
    tuned exclude in original frames or None)."""
    entry = registry.get(name)
    if entry.stream is None or entry.cli_knobs is None:
        raise ValueError(f"--method {name} has no streaming form for detect")
    knobs, threshold0, where, tuned_step, tuned_ex = _base(name, entry, tuned, variant)
    origin = dict.fromkeys(knobs, where)
    for k, v in flags.items():
        if v is None:
            continue
        if k not in entry.cli_knobs:
            takes = [n for n, e in registry.REGISTRY.items() if e.cli_knobs and k in e.cli_knobs]
            raise ValueError(f"--{k.replace('_', '-')} does not apply to --method {name}"
                             + (" (it needs no model)" if k == "model" else "")
                             + f": it is a knob of --method {' / '.join(takes)}")
        knobs[k], origin[k] = v, f"--{k.replace('_', '-')}"
    if entry.cli_threshold is not None:        # a default that follows the knobs (the dictionary's tau = L + margin)
        threshold0 = entry.cli_threshold(knobs)
    threshold = threshold if threshold is not None else threshold0
    if threshold is None:
        raise ValueError(f"--method {name} needs a threshold chosen on your own data: pass --threshold T or --tuned "
                         f"<results>/13_leaderboard/summary.json (notebook 13 picks knobs and threshold on a tuning "
                         f"part); --method {registry.DEFAULT} (the default) has a fixed one")
    seq = recording.open_frames(folder).sequence
    own_step = seq.frame_step if seq is not None else None
    step_from = "--step" if step is not None else (DESCRIPTION_NAME if own_step else "default")
    step = step or own_step or 1
    if step < 1:
        raise ValueError(f"--step must be >= 1, got {step}")
    lines = [f"# {k} {knobs[k]} ({origin[k]})" for k in knobs if k != "fixed_threshold"]
    lines += [f"# threshold {threshold:g} ({'--threshold' if threshold != threshold0 else where})",
              f"# step {step} ({step_from})"]
    if tuned_step is not None and tuned_step != step:
        lines.append(f"# --tuned picked its knobs streaming every {tuned_step}th frame; here every {step} (no frame "
                     f"is dropped unless asked): pass --step {tuned_step} to stream at the tuned rate")
    return knobs, float(threshold), int(step), lines, tuned_ex


def exclusion_for(folder, n: int, step: int, exclude=None, tuned_exclude=None) -> tuple[int, str, str]:
    """The exclusion in streamed frames, its source and the rule's sentence: ``exclude`` (streamed frames), else
    the folder's sequence.yaml, else ``tuned_exclude`` (original frames), else greenloop.exclusion's
    rule (a bag's or a video's: its frame times, ``exclusion.of_recording``). folder: a recording or its
    FrameSource. Warns on stderr when fewer than half of the ``n`` streamed frames have a candidate."""
    src = recording.open_frames(folder)
    if exclude is not None:
        frames, source, rule = exclude, "--exclude", f"--exclude {exclude} streamed frames"
    else:
        found = exclusion.of_recording(src)
        if tuned_exclude is not None and found.source != DESCRIPTION_NAME:
            found = exclusion.Exclusion(tuned_exclude, "--tuned", f"exclude {tuned_exclude} frames, from --tuned")
        frames, source = found.frames // step, found.source
        rule = found.rule + ("" if step == 1 else f"; {frames} streamed frames at step {step}")
    if exclusion.candidate_share(n, frames) < 0.5:
        print(f"warning: exclude {frames} leaves only {max(n - frames - 1, 0)} of the {n} streamed frames any "
              f"candidate (a loop is searched among frames more than {frames} frames older): pass --exclude N"
              + (f" or write `exclude: N` in {src.path / DESCRIPTION_NAME}" if src.sequence is not None else ""),
              file=sys.stderr, flush=True)
    return frames, source, rule


def plan(folder, name: str = registry.DEFAULT, tuned=None, variant=None, threshold=None, step=None,
         exclude=None, topic=None, **flags) -> Plan:
    """Everything a detect run decides before its first frame (:func:`knobs_for`, :func:`exclusion_for`).
    folder: a recording (a sequence folder or a folder of images, a ROS bag, a video) or its
    ``sequence.Sequence`` or ``recording.FrameSource``; topic: a bag's camera topic (``recording.open_frames``)."""
    src = recording.open_frames(folder, topic)
    knobs, threshold, step, lines, tuned_ex = knobs_for(name, src, tuned, variant, threshold, step, **flags)
    frames = src[::step]
    ex, source, rule = exclusion_for(src, len(frames), step, exclude, tuned_ex)
    return Plan(name, knobs, threshold, step, ex, frames, lines + [f"# exclude {ex} ({source})", f"# exclusion: {rule}"])


def header(p: Plan, folder, index=None, candidates: int = 20) -> str:
    """The line before the stream: frames, method, its main knobs, exclusion, threshold, candidates."""
    k = p.knobs
    main = (f"{k['descriptor']}, seq_len {k['seq_len']}, exclude {p.exclude}, contrast window {k['contrast_window']}"
            if "seq_len" in k else f"exclude {p.exclude}")
    return (f"# {len(p.frames)} frames from {p.frames} (every {p.step}); {p.name} ({main}); threshold {p.threshold:g}; "
            f"candidates: {'every stored frame' if index is None else f'{candidates} from {index}'}")


def data_for(p: Plan, folder, index=None, candidates: int = 20) -> Data:
    """The ``Data`` a registry entry's ``stream`` and ``describer`` read on a user's recording: no
    ground truth, no split; params: ``registry.user_params`` (default velocities, ImageNet weights, the index)."""
    params = registry.user_params(index, candidates)
    return Data(str(folder), p.step, np.arange(len(p.frames)) * p.step, None, p.exclude, None, None, params, {}, {}, {})


class FrameStream:
    """A registered detector fed decoded frames: ``update_many(frames)`` -> closure events and
    ``decide_many(frames)`` -> one decision per frame ({'frame', 'match', 'score', 'closure'});
    a detector that takes frames itself is called directly, one fed descriptors through ``describe``
    (``update_descriptor(describe(frame))``, the path ``speed.timing`` times)."""

    def __init__(self, name: str, detector, describe):
        self.detector = detector
        self._step = None if describe is None else (lambda det, frame: det.update_descriptor(describe(frame)))

    def update_many(self, frames) -> list[dict]:
        if self._step is None:
            return self.detector.update_many(frames)
        return [e for e in (self._step(self.detector, f) for f in frames) if e]

    def decide_many(self, frames) -> list[dict]:
        if self._step is None:
            return self.detector.decide_many(frames)
        rows = []
        for f in frames:
            j, event = self.detector.frame_index, self._step(self.detector, f)
            match, score = registry.best_candidate(self.detector)
            rows.append(dict(event or {"frame": j, "match": match, "score": score}, closure=event is not None))
        return rows


def open_stream(p: Plan, folder, index=None, candidates: int = 20, state=None) -> FrameStream:
    """The plan's detector: new from its registry entry, or the one saved in ``state`` (a file from
    :func:`save_state` for the same recording and knobs; ValueError otherwise)."""
    key = state_key(p, folder, index, candidates)
    if state and Path(state).is_file():
        with open(state, "rb") as f:
            saved = pickle.load(f)
        if saved.get("key") != key:
            raise ValueError(f"--state {state} was saved for another run ({saved.get('key')}); pass the same folder "
                             f"and options, or delete the file to start over")
        det = saved["detector"]
    else:
        det = registry.stream(p.name, p.knobs, p.threshold, data_for(p, folder, index, candidates))
    entry = registry.get(p.name)
    # a detector that describes frames with the record's own descriptor takes them in windows (one
    # batched pass); the others are fed the entry's describer's output, frame by frame
    own = entry.describer is None or getattr(det, "descriptor", None) == p.knobs.get("descriptor")
    return FrameStream(p.name, det, None if own else entry.describer(p.knobs, data_for(p, folder)))


def state_key(p: Plan, folder, index, candidates) -> dict:
    """What a saved state must match to be resumed: knobs, threshold, step, exclusion, folder, frames, index."""
    return dict(p.knobs, method=p.name, threshold=p.threshold, step=p.step, exclude=p.exclude,
                folder=str(Path(folder).resolve()), frames=len(p.frames), index=index, candidates=candidates)


def save_state(stream: FrameStream, key: dict, path) -> None:
    """Write the detector (stored frames, index, buffers, events) and its key to ``path``, atomically."""
    def dump(tmp):
        with open(tmp, "wb") as f:
            pickle.dump({"key": key, "detector": stream.detector}, f, protocol=pickle.HIGHEST_PROTOCOL)
    write_atomic(path, dump)


def matches_writer(path, names, append: bool, verified: bool = False):
    """A function taking a window's decisions (``FrameStream.decide_many``) and appending one CSV line
    per frame (MATCH_COLUMNS: frame and file, its best stored match and file, empty while none is a
    candidate, the score, 1 where a closure was declared; with ``verified``, VERIFY_COLUMNS, empty
    where the frame was not checked) to ``path``; a new file unless ``append``.
    names: the streamed frames' names (a file name, or a bag's or video's time stamp)."""
    path = Path(path)
    if path.parent and not path.parent.is_dir():
        raise FileNotFoundError(f"--matches {path}: folder {path.parent} does not exist")
    if not append or not path.is_file():
        path.write_text(",".join(MATCH_COLUMNS + (VERIFY_COLUMNS if verified else ())) + "\n")

    def write(rows):
        with open(path, "a") as f:
            for r in rows:
                m = r["match"]
                f.write(f"{r['frame']},{names[r['frame']]},{m if m >= 0 else ''},"
                        f"{names[m] if m >= 0 else ''},{'' if m < 0 else format(r['score'], '.6g')},"
                        f"{int(r['closure'])}" + (("," + verification_fields(r)) if verified else "") + "\n")
    return write


def verification_fields(r: dict) -> str:
    """VERIFY_COLUMNS of one decision as CSV fields: verified 1/0, inliers, model, rotation vector
    rx ry rz (rad, ``cv2.Rodrigues``), translation tx ty tz (metres where metric, else a unit
    direction), metric 1/0; empty fields where the frame was not checked or has no pose."""
    if r.get("model") is None:
        return "," * (len(VERIFY_COLUMNS) - 1)
    pose = ["", "", ""] * 2
    if r["R"] is not None and r["t"] is not None:
        pose = [format(v, ".6g") for v in (*rotation_vector(r["R"]), *np.asarray(r["t"], float).ravel())]
    flag = "" if r["verified"] is None else str(int(r["verified"]))
    return ",".join([flag, str(r["inliers"]), r["model"], *pose, str(int(r["metric"]))])


def rotation_vector(R) -> np.ndarray:
    """(3,) float64 rotation vector (axis times angle, rad) of a (3, 3) rotation matrix."""
    return cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].ravel()


def pose_text(e: dict) -> str:
    """A verified closure's printed columns: verified (yes / no / unchecked), inliers, model, the
    rotation as its angle in degrees about a unit axis, the translation with its unit (m, or dir
    for a unit direction); '-' where there is no pose."""
    flag = {True: "yes", False: "no", None: "unchecked"}[e["verified"]]
    rot = trans = "-"
    if e["R"] is not None and e["t"] is not None:
        v = rotation_vector(e["R"])
        angle = float(np.linalg.norm(v))
        axis = v / angle if angle > 0 else np.array([0.0, 0.0, 1.0])
        rot = f"{np.degrees(angle):.1f} deg about ({axis[0]:.2f},{axis[1]:.2f},{axis[2]:.2f})"
        t = np.asarray(e["t"], float).ravel()
        trans = f"({t[0]:.3f},{t[1]:.3f},{t[2]:.3f}) {'m' if e['metric'] else 'dir'}"
    return "\t".join([flag, str(e["inliers"]), e["model"], rot, trans])


class Checker:
    """A run's geometric verification (module doc): the verifier, the streamed frames (a FrameSource) and
    depth files (None without depth/), and how many candidates it checked and rejected."""

    def __init__(self, verifier, frames, depth_paths=None):
        self.verifier, self.frames, self.depth_paths = verifier, frames, depth_paths
        self.checked = self.rejected = 0

    def check(self, e: dict, frames, start: int) -> dict:
        """Event ``e`` (a closure candidate: frame, match) with UNCHECKED's fields from the verifier
        and ``closure`` False where it rejects. frames: the window's decoded frames, frames[0] is
        streamed frame ``start``."""
        q, m = int(e["frame"]), int(e["match"])
        fm = frames[m - start] if m >= start else self.frames.read([m])[0]
        dq, dm = ((None, None) if self.depth_paths is None else
                  (sequence.read_depth(self.depth_paths[q]), sequence.read_depth(self.depth_paths[m])))
        v = self.verifier(q, m, frames[q - start], fm, dq, dm)
        verified = None if v.accepted is None or v.model == "too-small" else bool(v.accepted)
        self.checked += 1
        self.rejected += verified is False
        as_array = lambda a: None if a is None else np.asarray(a, dtype=np.float64)
        return dict(e, closure=verified is not False, verified=verified, inliers=int(v.inliers), model=str(v.model),
                    R=as_array(v.R), t=as_array(v.t), metric=bool(v.metric))


def closure(e: dict) -> Closure:
    """The ``interface.Closure`` of a declared event (UNCHECKED's values where it was not verified)."""
    return Closure(int(e["frame"]), int(e.get("match", -1)), float(e.get("score", np.nan)),
                   *(e.get(k, v) for k, v in UNCHECKED.items()))


def event_columns(detector) -> tuple[str, ...]:
    """The columns of the detector's events after ``frame``: its ``event_columns`` or (match, score)."""
    return tuple(getattr(detector, "event_columns", ("match", "score")))


def event_line(e: dict, columns, names) -> str:
    """One printed closure: frame, the event's columns, the frame's name (file or stamp; the match's too, if any)."""
    vals = [f"{e[c]:.4f}" if isinstance(e[c], float) else str(e[c]) for c in columns]
    files = [names[e["frame"]]] + ([names[e["match"]]] if "match" in e else [])
    return "\t".join([str(e["frame"]), *vals, *files])


def run_windows(stream: FrameStream, frames, window: int, first: int = 0, stop=None, after=None, matches=None,
                out=print, desc: str = "detect", checker: Checker | None = None, declared=None) -> float:
    """Decode frames[first:stop] (a FrameSource) in windows of ``window`` frames, feed each to ``stream``, verify each
    candidate with ``checker`` when given (:meth:`Checker.check`), ``out`` one line per declared closure
    (:func:`event_line`, then :func:`pose_text` under a checker) and append its ``Closure`` to the list
    ``declared`` when given, ``matches(rows)`` per window when given, ``after()`` per window (state
    saving); a progress bar on stderr. Returns the wall seconds (decoding and verification included)."""
    stop = len(frames) if stop is None else stop
    columns, names = event_columns(stream.detector), frames.names
    progress = bar(total=len(frames), initial=first, desc=desc, unit="frame")

    def go():
        for start in range(first, stop, window):
            chunk = frames[start:min(start + window, stop)]
            decoded = read_window(chunk)
            rows = stream.decide_many(decoded) if matches else stream.update_many(decoded)
            if checker is not None:
                rows = [checker.check(e, decoded, start) if e.get("closure", True) and e["match"] >= 0 else e
                        for e in rows]
            for e in rows:
                if e.get("closure", True):
                    out(event_line(e, columns, names) + ("" if checker is None else "\t" + pose_text(e)))
                    if declared is not None:
                        declared.append(closure(e))
            if matches is not None:
                matches(rows)
            progress.update(len(chunk))
            if after is not None:
                after()
    try:
        return timed(go)[1]
    finally:
        progress.close()


class Run(NamedTuple):
    """A finished (or stopped) detect run: the stream, the first and next frame numbers, the wall
    seconds (decoding and verification included), whether the recording was finished, the closures
    declared in this run (``interface.Closure``, in order) and the candidates verification rejected."""
    stream: FrameStream
    first: int
    next: int
    seconds: float
    finished: bool
    closures: list = ()        # interface.Closure records (a list from run)
    rejected: int = 0


def checker_for(p: Plan, folder, verifier, columns, strict: bool = True) -> Checker | None:
    """The run's :class:`Checker` (None without ``verifier``): the plan's frames and, where the folder
    has depth/, its depth frames at the plan's step. A detector that names no match (the dictionary's
    spots): ValueError where ``strict`` (verification was asked for), else None (it runs unverified)."""
    if verifier is None or ("match" not in columns and not strict):
        return None
    if "match" not in columns:
        raise ValueError(f"--verify needs a method that matches frames (--method {p.name} names no earlier "
                         f"frame to verify against): pass --method {registry.DEFAULT} or --no-verify")
    seq = p.frames.sequence
    depths = None if seq is None else seq.depth_paths
    return Checker(verifier, p.frames, None if depths is None else depths[::p.step])


def verifier_for(folder):
    """The registered geometric verifier for ``folder`` (``registry.verifier`` given its camera's
    intrinsics, from camera.yaml, or None: a bag's or a video's), or None where none is registered."""
    seq = recording.open_frames(folder).sequence
    return registry.verifier(seq.camera() if seq is not None and seq.has_camera else None)


def run(p: Plan, folder, window: int = 70, index=None, candidates: int = 20, state=None, save_every: int = 10000,
        stop_after=None, matches=None, out=print, verifier=None, verify_strict: bool = True) -> Run:
    """Stream the plan's frames (from where ``state`` stopped, if it exists) through its detector:
    closures to ``out`` as declared, every frame's decision to the ``matches`` CSV, the detector to
    ``state`` every ``save_every`` frames, on Ctrl-C (re-raised) and at the end; at most
    ``stop_after`` frames in this run. verifier: None (every candidate the detector declares is a
    closure, unverified) or a callable (query, match, frame_q, frame_m, depth_q, depth_m) -> a record with
    fields accepted, inliers, model, R, t, metric applied to each candidate (module doc: the rule); its
    fields follow each printed closure and fill --matches' VERIFY_COLUMNS. verify_strict: a detector that
    names no match (the dictionary) with a verifier is an error (True) or runs unverified (False)."""
    if matches is not None and registry.get(p.name).describer is None:
        raise ValueError("--matches needs a method that matches frames (the dictionary counts spot labels): "
                         f"pass --method {registry.DEFAULT} (the default) or another registered one")
    stream = open_stream(p, folder, index, candidates, state)
    key, first = state_key(p, folder, index, candidates), stream.detector.frame_index
    stop = len(p.frames) if stop_after is None else min(len(p.frames), first + stop_after)
    saved = [first]

    def save_now(force=False):
        if state and (force or stream.detector.frame_index - saved[0] >= save_every):
            save_state(stream, key, state)
            saved[0] = stream.detector.frame_index
    columns = event_columns(stream.detector)
    checker = checker_for(p, folder, verifier, columns, verify_strict)
    write = None if matches is None else matches_writer(matches, p.frames.names, append=first > 0, verified=checker is not None)
    if first:
        out(f"# resumed at frame {first} (--state {state})")
    out("\t".join(["frame", *columns, "file"] + (["match_file"] if "match" in columns else [])
                  + ([] if checker is None else ["verified", "inliers", "model", "rotation", "translation"])))
    declared = []
    try:
        seconds = run_windows(stream, p.frames, window, first, stop, save_now, write, out, p.name, checker, declared)
    except KeyboardInterrupt:
        save_now(force=True)
        raise
    save_now(force=True)
    n = stream.detector.frame_index
    return Run(stream, first, n, seconds, n == len(p.frames), declared, 0 if checker is None else checker.rejected)


def closures_of(recording, topic=None, out=None) -> list[Closure]:
    """The closures ``python -m greenloop detect RECORDING`` declares (the named default, verified where
    a verifier is registered), as ``Closure`` records numbered by the recording's frames (the plan's
    step applied), for a consumer such as ``slam``. out: where detect's lines go (default: nowhere)."""
    p = plan(recording, topic=topic)
    r = run(p, recording, verifier=verifier_for(p.frames), out=out or (lambda line: None), verify_strict=False)
    return [c._replace(query=c.query * p.step, match=c.match * p.step) for c in r.closures]

