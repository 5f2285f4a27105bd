"""Command line: ``python -m greenloop <command> ...`` (a thin argparse dispatcher).

Commands
    detect SEQUENCE_FOLDER [--method NAME] [--matches FILE.csv] [--exclude N] [--step N] ...
        stream a recording (a sequence folder or a folder of .jpg/.png frames of any size, in
        numeric order) through a registered detector (greenloop.methods.registry) and print each
        declared loop closure (query frame, matched earlier frame, score) and a summary. With no
        flags: the named default (seqmatch.DEFAULT_NAME), no model, no poses, no tuning; the
        exclusion follows greenloop.exclusion (make's rule), printed. The greenloop-seq
        methods (greenloop.seqstream.Detector) take [--tuned SUMMARY_JSON] [--descriptor ...]
        [--seq-len L] [--contrast-window R] [--index KIND [--candidates K]] [--state FILE ...];
        ``--method dictionary --model MODEL`` is the main paper's CNN + frequency dictionary
        (greenloop.methods.dictionary.stream.Detector). ``--matches`` writes every frame's best match, its score
        and the decision (MATCH_COLUMNS) for scoring against your own ground truth.
    sweep NOTEBOOK --grid NAME=V1,V2,... [--grid ...] --out OUT [-f PARAMS.yaml] [-p NAME VALUE]
          [--dataset DIR] [--scheduler local|tcp://HOST:8786|slurm|pbs] [--workers N] [--metric SPEC]
        run the notebook once per point of the grids' cross product on Dask (greenloop.study.sweep) and
        write OUT/sweep.csv, sweep.md and sweep.png; complete points are not run again.
    import-gt SRC [--out FOLDER/ground_truth.csv] [--format auto|vpr-bench|matrix|positions]
          [--threshold-m M] [--reference-frames N]
        convert a ground-truth file of a common format (greenloop.datasets.groundtruth_formats) to
        ground_truth.csv loop pairs, checked against the frames of the output's folder.
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import sys
from pathlib import Path

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")

import cv2  # noqa: E402
import yaml  # noqa: E402

import numpy as np  # noqa: E402

from greenloop import exclusion  # noqa: E402
from greenloop.methods.greenloop_seq import seqmatch
from greenloop.methods.lsh import retrieval
from greenloop.datasets import groundtruth_formats as gt_formats  # noqa: E402
from greenloop.datasets.sequence import (DESCRIPTION_NAME, GROUND_TRUTH_NAME, layout, list_frames,  # noqa: E402
                                         read_description, traversals, write_loop_pairs)
from greenloop.methods import registry as detectors  # noqa: E402
from greenloop.methods.interface import Data  # noqa: E402
from greenloop.speed import timing  # noqa: E402
from greenloop.methods.dictionary import stream
from greenloop.methods.greenloop_seq import seqstream
from greenloop.study import params as study_params  # noqa: E402
from greenloop.study import sweep  # noqa: E402
from greenloop.util.files import write_atomic  # noqa: E402
from greenloop.util.progress import bar  # noqa: E402


def _read_window(paths):
    """Frames decoded in colour (BGR) as a camera delivers them."""
    frames = []
    for p in paths:
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"cannot read image {p}: the file is missing, empty or not an "
                             f"image; replace or delete it")
        frames.append(img)
    return frames


def _stream_windows(paths, window: int, events_of, line_of, desc: str, first: int = 0,
                    stop: int | None = None, after=None, matches=None) -> float:
    """The CLI's one streaming loop: decode paths[first:stop] in windows of ``window`` frames
    (:func:`_read_window`), print ``line_of(e)`` for each event ``events_of(frames)`` returns (rows
    with ``closure`` False are per-frame decisions: not printed), ``matches(rows)`` per window when
    given, a progress bar on stderr, ``after()`` once per window (state saving). Returns the wall
    seconds (decoding included; ``speed.timing.timed``)."""
    stop = len(paths) if stop is None else stop
    progress = bar(total=len(paths), initial=first, desc=desc, unit="frame")

    def run():
        for start in range(first, stop, window):
            chunk = paths[start:min(start + window, stop)]
            rows = events_of(_read_window(chunk))
            for e in rows:
                if e.get("closure", True):
                    print(line_of(e), flush=True)
            if matches is not None:
                matches(rows)
            progress.update(len(chunk))
            if after is not None:
                after()
    try:
        return timing.timed(run)[1]
    finally:
        progress.close()


MATCH_COLUMNS = ("frame", "file", "match", "match_file", "score", "closure")


def _matches_writer(path, paths, append: bool):
    """``--matches FILE.csv``: a function taking a window's decisions ({'frame', 'match', 'score',
    'closure'}, ``seqstream.Detector.decide_many``) and appending one CSV line per frame (MATCH_COLUMNS:
    streamed frame number and file, its best stored match and file, empty while none is a candidate,
    the score, 1 where a closure was declared); a new file (header first) unless ``append``."""
    path = Path(path)
    if path.parent and not path.parent.is_dir():
        raise FileNotFoundError(f"--matches {path}: folder {path.parent} does not exist")
    if not append or not path.is_file():
        path.write_text(",".join(MATCH_COLUMNS) + "\n")

    def write(rows):
        with open(path, "a") as f:
            for r in rows:
                m = r["match"]
                f.write(f"{r['frame']},{paths[r['frame']].name},{m if m >= 0 else ''},"
                        f"{paths[m].name if m >= 0 else ''},{'' if m < 0 else format(r['score'], '.6g')},"
                        f"{int(r['closure'])}\n")
    return write


def _closure_line(paths):
    """An event {'frame', 'match', 'score'} -> the detect table's line (tab-separated, with files)."""
    return lambda e: (f"{e['frame']}\t{e['match']}\t{e['score']:.4f}\t{paths[e['frame']].name}\t"
                      f"{paths[e['match']].name}")


def _read_tuned(path, variant: str) -> tuple[dict, float, int, int]:
    """A notebook 13 summary.json's knob record of one method (``variant``): (knobs, threshold,
    frame_step, exclude in ORIGINAL frames)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--tuned {path}: no such file; run notebook 13 on a recording of "
                                f"your site (make all DATASET=...), then pass its "
                                f"<results>/13_leaderboard/summary.json")
    summary = json.loads(path.read_text())
    if variant not in summary.get("knobs", {}):
        raise ValueError(f"--tuned {path} has no variant {variant!r} (it has "
                         f"{sorted(summary.get('knobs', {}))})")
    step = int(summary["frame_step"])
    return summary["knobs"][variant], summary["thresholds"][variant], step, int(summary["exclude_steps"]) * step


SEQ_METHODS = ("greenloop-seq", *seqmatch.NAMED)   # the methods detect streams with seqstream.Detector
PLAIN_SEQ_KNOBS = dict(descriptor="pixels-patchnorm", seq_len=10, contrast_window=10)   # greenloop-seq with --threshold


def _base_knobs(args) -> tuple[dict, str]:
    """The knobs a greenloop-seq method starts from and where they come from: a named configuration
    (``seqmatch.NAMED``: its knobs and fixed threshold), ``--tuned``'s record, or for
    ``--method greenloop-seq`` with ``--threshold`` the plain PLAIN_SEQ_KNOBS (with neither, the named
    default). Returns (knobs with threshold and step, origin)."""
    name = args.method
    if name == "greenloop-seq" and args.tuned:
        tuned, threshold, _, _ = _read_tuned(args.tuned, args.variant or "greenloop-seq-fast")
        return dict(PLAIN_SEQ_KNOBS, **tuned, threshold=threshold, step=1), "--tuned"
    if name == "greenloop-seq" and args.threshold is not None:
        return dict(PLAIN_SEQ_KNOBS, threshold=None, step=1), "default"
    name = name if name in seqmatch.NAMED else seqmatch.DEFAULT_NAME
    knobs, threshold = seqmatch.NAMED[name]
    return dict(knobs, threshold=threshold, step=1), f"default {name}"


def _tuned_knobs(args) -> tuple[dict, list[str]]:
    """A greenloop-seq method's knobs and one line per knob saying where it came from
    (:func:`_base_knobs`, the folder's sequence.yaml ``frame_step``, any flag given, which wins),
    and the exclusion (:func:`_exclusion`). The frames are never subsampled unless asked (``--step``
    or sequence.yaml's frame_step): the tuned frame_step is reported, not applied. Returns
    (dict(descriptor, seq_len, contrast_window, threshold, step, exclude, ...), lines); exclude and
    seq_len in streamed frames."""
    knobs, where = _base_knobs(args)
    origin = dict.fromkeys(knobs, where)
    origin["step"] = "default"
    desc = read_description(args.folder) if Path(args.folder).is_dir() else {}
    tuned_step = tuned_exclude = None
    if args.tuned:
        _, _, tuned_step, tuned_exclude = _read_tuned(args.tuned, args.variant or "greenloop-seq-fast")
    if desc.get("frame_step") is not None:
        knobs["step"], origin["step"] = desc["frame_step"], f"{DESCRIPTION_NAME}"
    for k in ("descriptor", "seq_len", "contrast_window", "threshold", "step"):
        if getattr(args, k) is not None:
            knobs[k], origin[k] = getattr(args, k), f"--{k.replace('_', '-')}"
    if knobs["threshold"] is None:
        raise ValueError("greenloop-seq needs a threshold chosen on your own data: pass --tuned "
                         "<results>/13_leaderboard/summary.json (notebook 13 picks the knobs and the "
                         "threshold on a tuning part) or --threshold T")
    if knobs["step"] < 1:
        raise ValueError(f"--step must be >= 1, got {knobs['step']}")
    knobs["exclude"], origin["exclude"], rule = _exclusion(args, knobs["step"], tuned_exclude)
    lines = [f"# {k} {knobs[k]} ({origin[k]})" for k in knobs] + [f"# exclusion: {rule}"]
    if tuned_step is not None and tuned_step != knobs["step"]:
        lines.append(f"# --tuned picked its knobs streaming every {tuned_step}th frame; here every "
                     f"{knobs['step']} (no frame is dropped unless asked): seq_len and the contrast window "
                     f"count streamed frames, so they span {knobs['step']}/{tuned_step} of the original frames "
                     f"they spanned there; pass --step {tuned_step} to stream at the tuned rate")
    return knobs, lines


def _exclusion(args, step: int, tuned_exclude: int | None = None) -> tuple[int, str, str]:
    """The exclusion in streamed frames, its source and the rule's sentence: ``--exclude`` (streamed frames), else
    the folder's sequence.yaml, else ``--tuned``'s, else greenloop.exclusion's rule (the
    ground truth, the frame rate or a fraction of the recording: the rule make uses). Warns on
    stderr when it leaves fewer than half of the streamed frames any candidate."""
    n = len(list_frames(args.folder)[::step])
    if args.exclude is not None:
        frames, source, rule = args.exclude, "--exclude", f"--exclude {args.exclude} streamed frames"
    else:
        found = exclusion.exclusion(args.folder)
        if tuned_exclude is not None and found.source != DESCRIPTION_NAME:
            found = exclusion.Exclusion(tuned_exclude, "--tuned", f"exclude {tuned_exclude} frames, from --tuned")
        frames, source = found.frames // step, found.source
        rule = found.rule + ("" if step == 1 else f"; {frames} streamed frames at step {step}")
    if exclusion.candidate_share(n, frames) < 0.5:
        print(f"warning: exclude {frames} leaves only {max(n - frames - 1, 0)} of the {n} streamed frames any "
              f"candidate (a loop is searched among frames more than {frames} frames older): pass --exclude N "
              f"or write `exclude: N` in {Path(args.folder) / DESCRIPTION_NAME}", file=sys.stderr, flush=True)
    return frames, source, rule


def _detect_seq(args) -> int:
    """``detect --method greenloop-seq``: greenloop.seqstream.Detector over the frames in windows
    (every ``step``-th frame of the folder: 1 unless --step or sequence.yaml says otherwise); with
    ``--index`` on the retrieved candidates only, with ``--state`` resumable (:func:`_seq_stream`)."""
    kn, lines = _tuned_knobs(args)
    paths = list_frames(args.folder)[::kn["step"]]
    det = _seq_detector(args, kn, paths)
    print("\n".join(lines), flush=True)
    print(f"# {len(paths)} frames from {args.folder} (every {kn['step']}); {args.method} "
          f"({kn['descriptor']}, seq_len {det.seq_len}, exclude {det.exclude}, contrast window "
          f"{det.contrast_window}); threshold {det.threshold:g}; candidates: "
          f"{'every stored frame' if det.index_kind is None else f'{det.k} from {det.index_kind}'}"
          + (f"; resumed at frame {det.frame_index}" if det.frame_index else ""), flush=True)
    print("frame\tmatch\tscore\tfile\tmatch_file", flush=True)
    start = det.frame_index
    try:
        done, dt = _seq_stream(det, paths, args, kn)
    except KeyboardInterrupt:
        print(f"detect: interrupted at frame {det.frame_index}" + (
            f"; state saved in {args.state}: run the same command again to continue" if args.state else ""),
            file=sys.stderr)
        return 130
    n = det.frame_index
    print(f"# summary: {n} frames, {len(det.events)} closures, {(n - start) / max(dt, 1e-9):.1f} "
          f"frames/s (decoding included, {dt:.2f} s for frames {start}..{n - 1}); "
          f"{det.bytes_per_frame} bytes per stored frame"
          + ("" if done else f"; stopped, state in {args.state}: run again to continue"), flush=True)
    return 0


def _seq_detector(args, kn: dict, paths) -> seqstream.Detector:
    """A new Detector, or the one saved in ``--state`` (the same recording and knobs only)."""
    key = dict(kn, folder=str(Path(args.folder).resolve()), frames=len(paths), index=args.index,
               candidates=args.candidates)
    if args.state and Path(args.state).is_file():
        with open(args.state, "rb") as f:
            saved = pickle.load(f)
        if saved.get("key") != key:
            raise ValueError(f"--state {args.state} was saved for another run ({saved.get('key')}); "
                             f"pass the same folder and options, or delete the file to start over")
        return saved["detector"]
    extra = {k: kn[k] for k in ("velocities", "center_window", "calibrate", "repeat_cos", "cell_shift") if k in kn}
    if args.index is not None:              # the index holds a PCA of the stored rows (seqstream.INDEX_DIM)
        retrieval.one_thread()
        extra["index_dim"] = seqstream.INDEX_DIM
    return seqstream.Detector(kn["threshold"], descriptor=kn["descriptor"], seq_len=kn["seq_len"],
                             exclude=kn["exclude"], contrast_window=kn["contrast_window"],
                             index=args.index, k=args.candidates, **extra)


def _seq_save(det: seqstream.Detector, args, kn: dict, paths) -> None:
    """Write the detector (stored frames, index, sequence buffers, events) to ``--state``, atomically."""
    key = dict(kn, folder=str(Path(args.folder).resolve()), frames=len(paths), index=args.index,
               candidates=args.candidates)
    def dump(path):
        with open(path, "wb") as f:
            pickle.dump({"key": key, "detector": det}, f, protocol=pickle.HIGHEST_PROTOCOL)
    write_atomic(args.state, dump)


def _seq_stream(det: seqstream.Detector, paths, args, kn: dict) -> tuple[bool, float]:
    """Feed paths[det.frame_index:] to det in windows (:func:`_stream_windows`), printing closures;
    with --state save every --save-every frames, on Ctrl-C and at the end; stop after
    --stop-after frames of this run. Returns (whether the recording was finished, wall seconds)."""
    first, last_save = det.frame_index, [det.frame_index]
    stop = len(paths) if args.stop_after is None else min(len(paths), first + args.stop_after)

    def save_now():
        if args.state and det.frame_index - last_save[0] >= args.save_every:
            _seq_save(det, args, kn, paths)
            last_save[0] = det.frame_index
    matches = None if args.matches is None else _matches_writer(args.matches, paths, append=first > 0)
    try:
        dt = _stream_windows(paths, args.window, det.decide_many if matches else det.update_many,
                             _closure_line(paths), args.method, first, stop, save_now, matches)
    except KeyboardInterrupt:
        if args.state:
            _seq_save(det, args, kn, paths)
        raise
    if args.state:
        _seq_save(det, args, kn, paths)
    return det.frame_index == len(paths), dt


def _registered_stream(args):
    """The streaming detector and frame describer of a registered detector (``--method NAME``,
    greenloop.methods.registry): its ``cli_knobs``, or ``--tuned``'s record of ``--variant``;
    the threshold from --threshold, --tuned or the record's fixed one. Returns (detector,
    describe, knobs, step, paths)."""
    entry = detectors.get(args.method)
    if entry.stream is None or entry.cli_knobs is None:
        raise ValueError(f"--method {args.method} has no streaming form for detect")
    knobs, threshold = dict(entry.cli_knobs), entry.cli_knobs.get("fixed_threshold")
    desc = read_description(args.folder) if Path(args.folder).is_dir() else {}
    tuned_exclude = None
    if args.tuned:
        if args.variant is None:
            raise ValueError(f"--tuned needs --variant: the leaderboard row whose knobs --method {args.method} streams")
        knobs, threshold, _, tuned_exclude = _read_tuned(args.tuned, args.variant)
    threshold = args.threshold if args.threshold is not None else threshold
    if threshold is None:
        raise ValueError(f"--method {args.method} needs a threshold chosen on your own data: pass --threshold T or "
                         f"--tuned <results>/13_leaderboard/summary.json --variant ROW")
    step = args.step or desc.get("frame_step") or 1
    if step < 1:
        raise ValueError(f"--step must be >= 1, got {step}")
    exclude, _, rule = _exclusion(args, step, tuned_exclude)
    print(f"# exclusion: {rule}", flush=True)
    paths = list_frames(args.folder)[::step]
    data = Data(args.folder, step, np.arange(len(paths)) * step, None, exclude, None, None,
                {"velocities": seqmatch.DEFAULT_VELOCITIES, "weights": "auto"}, {}, {}, {})
    return entry.stream(knobs, float(threshold), data), entry.describer(knobs, data), knobs, step, paths


def _detect_registered(args) -> int:
    """``detect --method NAME`` for any other registered detector: frame -> its describer -> its
    stream (``speed.timing.detector_method``'s step, the timed path); prints each closure."""
    det, describe, knobs, step, paths = _registered_stream(args)
    update = timing.detector_method(args.method, det, describe).step
    print(f"# {len(paths)} frames from {args.folder} (every {step}); {args.method} ({knobs}); exclude "
          f"{det.exclude}; threshold {det.threshold:g}", flush=True)
    print("frame\tmatch\tscore\tfile\tmatch_file", flush=True)

    def decide(frames):
        rows = []
        for f in frames:
            j, event = det.frame_index, update(det, f)
            match, score = seqstream.best_candidate(det)
            rows.append(dict(event or {"frame": j, "match": match, "score": score}, closure=event is not None))
        return rows
    matches = None if args.matches is None else _matches_writer(args.matches, paths, append=False)
    dt = _stream_windows(paths, args.window, decide if matches else
                         (lambda frames: [e for e in (update(det, f) for f in frames) if e]),
                         _closure_line(paths), args.method, matches=matches)
    print(f"# summary: {det.frame_index} frames, {len(det.events)} closures, {det.frame_index / max(dt, 1e-9):.1f} "
          f"frames/s (decoding included, {dt:.2f} s); {det.bytes_per_frame} bytes per stored frame", flush=True)
    return 0


def _detect(args) -> int:
    """``detect``: frames decoded in colour (BGR) as a camera delivers them, fed to
    greenloop.methods.dictionary.stream.Detector (``--method dictionary``), greenloop.seqstream.Detector
    (``--method greenloop-seq``, with --index / --state) or any other registered detector's
    stream (:func:`_detect_registered`) in windows; prints events as they are declared."""
    if args.model is not None and args.method != "dictionary":
        raise ValueError(f"--model is the main paper's trained CNN, used by --method dictionary only; "
                         f"--method {args.method} needs no model: pass --method dictionary with it, or drop it")
    if args.method in SEQ_METHODS:
        return _detect_seq(args)
    if args.method != "dictionary":
        return _detect_registered(args)
    if args.matches is not None:
        raise ValueError("--matches needs a method that matches frames (the dictionary counts spot labels): "
                         f"pass --method {seqmatch.DEFAULT_NAME} (the default) or another registered one")

    if args.model is None:
        raise ValueError(f"--method dictionary needs --model (a trained .keras or .tflite file); without "
                         f"--method, detect runs the named default {seqmatch.DEFAULT_NAME}, which needs no model")
    if args.threshold is not None and int(args.threshold) != args.threshold:
        raise ValueError(f"--threshold (tau) must be an integer for --method dictionary, got {args.threshold:g}")
    if not Path(args.model).is_file():
        raise FileNotFoundError(f"model file {args.model} not found: pass a trained .keras model "
                                f"(greenloop.methods.dictionary.cnn.train saves results/models/<key>/model.keras) or a "
                                f".tflite file (greenloop.methods.dictionary.stream.export_tflite)")
    paths = list_frames(args.folder)
    if args.frames_per_spot is not None and args.frames_per_spot < 1:
        raise ValueError(f"--frames-per-spot must be >= 1, got {args.frames_per_spot}")
    tau = None if args.threshold is None else int(args.threshold)
    if tau is None:
        tau = (args.frames_per_spot or 60) + args.margin
    elif args.frames_per_spot is not None and tau < args.frames_per_spot:
        raise ValueError(f"--threshold {tau} is below --frames-per-spot {args.frames_per_spot}: the "
                         f"paper's tau = L + margin must be >= L")
    det = stream.Detector(args.model, tau, backend=args.backend)
    print(f"# {len(paths)} frames from {args.folder}; model {args.model} ({det.backend}, "
          f"{det.n_classes} spots); tau = {tau}", flush=True)
    print("frame\tspot\tcount\tfile", flush=True)
    dt = _stream_windows(paths, args.window, det.update_many,
                         lambda e: f"{e['frame']}\t{e['spot']}\t{e['count']}\t{paths[e['frame']].name}",
                         "dictionary")
    n = det.frame_index
    print(f"# summary: {n} frames, {len(det.events)} closures, {n / dt:.1f} frames/s "
          f"(decoding included, {dt:.2f} s)", flush=True)
    return 0


def _sweep(args) -> int:
    """``sweep``: one papermill run per grid point on Dask; 0 when every point is ok, else 1. The
    parameters the dataset implies (its sequence.yaml: greenloop.study.params) come first, as in make."""
    base = dict(study_params.sequence_parameters(args.dataset)[0]) if Path(args.dataset).is_dir() else {}
    for path in args.parameters_file:
        if not os.path.isfile(path):
            raise FileNotFoundError(f"parameters file {path} not found: pass a YAML file such as "
                                    f"params/quick.yaml")
        base.update(yaml.safe_load(open(path)) or {})
    for name, value in args.parameter:
        base[name] = yaml.safe_load(value)
    if Path(args.notebook).is_file():       # a name no notebook declares: a typo? (plan drops it)
        given = {**{k: path for path in args.parameters_file for k in yaml.safe_load(open(path)) or {}},
                 **{name: "-p" for name, _ in args.parameter}}
        for line in study_params.undeclared(given, args.notebook):
            print(line, file=sys.stderr)
    options = dict(queue=args.queue, cores=args.cores, memory=args.memory, walltime=args.walltime,
                   account=args.account, job_extra_directives=args.job_extra)
    try:
        table = sweep.run_sweep(args.notebook, sweep.parse_grid(args.grid), args.out, base=base,
                                dataset=args.dataset, scheduler=args.scheduler, workers=args.workers,
                                cache=args.cache, metrics=args.metric, x=args.x, force=args.force,
                                timeout=args.timeout, kernel=args.kernel, retries=args.retries,
                                cluster_options=options)
    except KeyboardInterrupt:
        print(f"sweep: interrupted; the finished points in {args.out} are kept: run the same command "
              f"again to resume", file=sys.stderr)
        return 130
    return 0 if (table.status == "ok").all() else 1


def _sweep_parser(sub) -> None:
    """The ``sweep`` subcommand's arguments."""
    s = sub.add_parser("sweep", help="run a notebook over a parameter grid on Dask (local or cluster)",
                       description="Run NOTEBOOK once per point of the cross product of the grids, "
                                   "each point a papermill run on a Dask worker, into OUT/<point>/; "
                                   "assemble OUT/sweep.csv, sweep.md and sweep.png. Points whose "
                                   "point.json says ok are not run again (an interrupted sweep resumes).")
    s.add_argument("notebook", metavar="NOTEBOOK", help="notebook with a cell tagged 'parameters'")
    s.add_argument("--grid", action="append", required=True, metavar="NAME=V1,V2,...",
                   help="a swept parameter; values are YAML (20, 0.5, null, [0,1], text); repeat for a "
                        "cross product")
    s.add_argument("--out", required=True, help="sweep folder, e.g. results/sweep/NAME")
    s.add_argument("-f", "--parameters-file", action="append", default=[], metavar="YAML",
                   help="parameters for every point (e.g. params/quick.yaml); repeatable")
    s.add_argument("-p", "--parameter", action="append", nargs=2, default=[], metavar=("NAME", "VALUE"),
                   help="one parameter for every point (VALUE read as YAML); repeatable")
    s.add_argument("--dataset", default=str(sweep.DEFAULT_DATASET),
                   help="sequence folder injected as `dataset` (default data/synthetic-greenhouse)")
    s.add_argument("--scheduler", default="local",
                   help="local (a LocalCluster, default), a scheduler address (tcp://host:8786), or "
                        "slurm / pbs (dask-jobqueue; see --queue ...)")
    s.add_argument("--workers", type=int, default=None,
                   help="local: worker processes (default one per 4 cores); slurm/pbs: jobs")
    s.add_argument("--metric", action="append", default=[], metavar="SPEC",
                   help="numbers for the table: a summary.json key (a.b), FILE.csv:COLUMN or "
                        "FILE.csv[KEY=VALUE]:COLUMN; the first is plotted; repeatable")
    s.add_argument("--x", default=None, help="swept parameter on the figure's x axis (default: the "
                                             "first numeric one)")
    s.add_argument("--cache", default=None, help="model cache shared by every point (default "
                                                 "$GREENLOOP_CACHE or results/models)")
    s.add_argument("--force", action="store_true", help="run complete points again")
    s.add_argument("--retries", type=int, default=1, help="reruns of a failed point (default 1)")
    s.add_argument("--timeout", type=int, default=7200, help="per-cell timeout, s (default 7200)")
    s.add_argument("--kernel", default="greenloop", help="Jupyter kernel (default greenloop)")
    q = s.add_argument_group("slurm / pbs jobs (default: the dask config jobqueue.<kind>.*)")
    q.add_argument("--queue", help="partition / queue")
    q.add_argument("--cores", type=int, help="cores per job (one point runs per job at a time)")
    q.add_argument("--memory", help="memory per job, e.g. 16GB")
    q.add_argument("--walltime", help="job wall time, e.g. 04:00:00")
    q.add_argument("--account", help="account / project to charge")
    q.add_argument("--job-extra", action="append", default=None, metavar="DIRECTIVE",
                   help="extra job-script directive, e.g. --job-extra=--gres=gpu:1; repeatable")
    s.set_defaults(func=_sweep)


def _import_gt(args) -> int:
    """``import-gt``: a ground-truth file of another format -> ground_truth.csv (loop pairs)."""
    src = Path(args.src)
    out = Path(args.out) if args.out else src.parent / GROUND_TRUTH_NAME
    folder = out.parent
    n_frames = n_ref = None
    try:
        n_frames = len(list_frames(folder))
        ts = traversals(folder)
        n_ref = ts[0].stop if layout(folder) in ("traversals", "reference/query") else None
    except (FileNotFoundError, ValueError):
        pass                                   # not a sequence folder: nothing to check against
    n_ref = args.reference_frames if args.reference_frames is not None else n_ref
    fmt = gt_formats.detect_format(src) if args.format == "auto" else args.format
    pairs = gt_formats.read(src, fmt, n_frames=n_frames, n_reference=n_ref, threshold_m=args.threshold_m)
    write_atomic(out, lambda p: write_loop_pairs(p, pairs))
    print(f"wrote {len(pairs)} loop pairs from {src} ({gt_formats.FORMATS[fmt]}"
          f"{f', within {args.threshold_m or gt_formats.DEFAULT_THRESHOLD_M:g} m' if fmt == 'positions' else ''}"
          f"{f', {n_ref} reference frames first' if fmt == 'vpr-bench' else ''}) to {out}"
          f"{'' if n_frames is None else f' (checked against the {n_frames} frames of {folder})'}")
    return 0


def _import_gt_parser(sub) -> None:
    """The ``import-gt`` subcommand's arguments."""
    s = sub.add_parser("import-gt", help="convert a ground-truth file (VPR-Bench .npy, loop matrix, GPS) "
                                         "to ground_truth.csv",
                       description="Read a ground-truth file of a common format (greenloop.datasets."
                                   "groundtruth_formats) and write it as ground_truth.csv loop pairs.")
    s.add_argument("src", metavar="SRC", help="ground_truth_new.npy, a loop matrix (.npy, .mat, image) or a "
                                              "positions / GPS .csv")
    s.add_argument("--out", default=None, help="output file (default: ground_truth.csv beside SRC); its "
                                               "folder's frames are used to check the frame numbers")
    s.add_argument("--format", default="auto", choices=("auto", "vpr-bench", "matrix", "positions"),
                   help="the file's format (default: from its name and contents)")
    s.add_argument("--threshold-m", type=float, default=None, metavar="M",
                   help=f"positions: frames at most M metres apart are loops (default "
                        f"{gt_formats.DEFAULT_THRESHOLD_M:g})")
    s.add_argument("--reference-frames", type=int, default=None, metavar="N",
                   help="vpr-bench: reference frames before the queries (default: the folder's first traversal)")
    s.set_defaults(func=_import_gt)


def _knob_defaults(knob: str) -> str:
    """One knob's default per greenloop-seq method, for --help: from seqmatch.NAMED and PLAIN_SEQ_KNOBS."""
    return "; ".join([f"{n}: {k[knob]}" for n, (k, _) in seqmatch.NAMED.items()]
                     + [f"greenloop-seq with --threshold: {PLAIN_SEQ_KNOBS[knob]}"])


_DETECT_DESCRIPTION = (
    f"Stream a recording frame by frame through a detector and print each declared loop closure "
    f"(frame, matched earlier frame, score) and a summary. With no flags it runs the named default "
    f"{seqmatch.DEFAULT_NAME} (descriptor {seqmatch.DEFAULT_KNOBS['descriptor']}, seq_len "
    f"{seqmatch.DEFAULT_KNOBS['seq_len']}, threshold {seqmatch.DEFAULT_THRESHOLD:g}): no model, no poses, no "
    f"tuning. {seqmatch.CNN_NAME} adds an ImageNet CNN (threshold {seqmatch.CNN_THRESHOLD:g}). The frames it "
    f"never compares with a query (the exclusion) follow one rule, the one make uses, printed at the start. "
    f"For long recordings --index hnsw (or ivf, ...) runs the same configuration and threshold on the frames "
    f"an index retrieves, at a cost per frame that does not grow with the recording; --state makes it resumable. "
    f"--matches writes every frame's best match for your own scoring.")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser: one subparser per command (add new commands here)."""
    ap = argparse.ArgumentParser(prog="python -m greenloop",
                                 description="greenloop: CNN visual loop-closure detection for "
                                             "agricultural robots.")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    d = sub.add_parser("detect", help="stream a recording through a loop-closure detector and print its closures",
                       description=_DETECT_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    d.add_argument("folder", metavar="SEQUENCE_FOLDER",
                   help="sequence folder (its rgb/) or folder of .jpg/.png frames, any size")
    d.add_argument("--method", default=seqmatch.DEFAULT_NAME, choices=list(detectors.REGISTRY),
                   help=f"a registered detector (greenloop.methods.registry); default {seqmatch.DEFAULT_NAME}, "
                        f"the named default, which needs no model and no tuning")
    d.add_argument("--threshold", "--tau", type=float, default=None,
                   help="the score to reach: " + "; ".join(f"{n}: {t:g}" for n, (_, t) in seqmatch.NAMED.items())
                        + " (calibrated z-scores, with or without --index; a value given overrides it); "
                          "--method greenloop-seq with --threshold: the plain knobs (--help's defaults); "
                          "dictionary: tau, an integer (default frames-per-spot + margin)")
    d.add_argument("--matches", default=None, metavar="FILE.csv",
                   help="also write every frame's best stored match, its score and the decision (1: closure) to "
                        "this CSV, to score the detector against your own ground truth or pick your own threshold")
    d.add_argument("--exclude", type=int, default=None,
                   help="only frames more than this many streamed frames older are candidates (default: the "
                        "exclusion rule, printed: sequence.yaml's exclude, else the ground truth's, else "
                        f"{exclusion.EXCLUDE_SECONDS:g} s at sequence.yaml's frame_rate, else "
                        f"{100 * exclusion.EXCLUDE_FRACTION:g} %% of the recording within "
                        f"{exclusion.MIN_EXCLUDE}..{exclusion.DEFAULT_EXCLUDE} frames)")
    d.add_argument("--step", type=int, default=None,
                   help="stream every step-th frame (default: sequence.yaml's frame_step, else 1; --tuned's "
                        "frame_step is printed, not applied)")
    d.add_argument("--window", type=int, default=70, help="frames decoded per batch (default 70)")
    g = d.add_argument_group("greenloop-seq knobs (greenloop.seqstream.Detector; default: the method's "
                             "configuration, printed at the start)")
    g.add_argument("--tuned", default=None, metavar="SUMMARY_JSON",
                   help="knobs and threshold picked by notebook 13 on a tuning part "
                        "(<results>/13_leaderboard/summary.json); flags below override them")
    g.add_argument("--variant", default=None, metavar="ROW",
                   help="which of --tuned's rows (greenloop-seq: greenloop-seq or greenloop-seq-fast, the default: no "
                        "CNN; another --method: the row to stream, e.g. 'SeqSLAM (tuned)')")
    g.add_argument("--descriptor", default=None, choices=seqmatch.DESCRIPTORS,
                   help="per-frame descriptor (default: " + _knob_defaults("descriptor") + ")")
    g.add_argument("--seq-len", type=int, default=None,
                   help="frames per matched sequence (default: " + _knob_defaults("seq_len") + ")")
    g.add_argument("--contrast-window", type=int, default=None,
                   help="SeqSLAM local contrast window in frames, 0 = off (default: "
                        + _knob_defaults("contrast_window") + ")")
    g.add_argument("--index", default=None, choices=retrieval.KINDS,
                   help="long recordings: verify sequences on the --candidates frames this index retrieves (scan, "
                        "flat: exact; ivf, hnsw, swp, qdp: approximate) instead of on every stored frame, so the "
                        "per-frame cost stops growing with the recording (greenloop.methods.lsh.retrieval). The method's "
                        "configuration and fixed threshold apply as they are (the named default's calibration, "
                        "repeat gate, cell shift and reverse velocities included; the calibration's null from "
                        f"{seqstream.NULL_SAMPLE} sampled stored frames); the index holds the stored descriptors "
                        f"reduced to {seqstream.INDEX_DIM} dims by a PCA fitted on the first {seqstream.INDEX_FIT} "
                        "candidate frames, the verification reads them in full")
    g.add_argument("--candidates", type=int, default=20, help="--index: frames retrieved per query (default 20)")
    g.add_argument("--state", default=None, metavar="FILE",
                   help="save the detector here (every --save-every frames, on Ctrl-C, at the end) and "
                        "resume from it when it exists: the closures equal an uninterrupted run")
    g.add_argument("--save-every", type=int, default=10000, help="--state: frames between saves (default 10000)")
    g.add_argument("--stop-after", type=int, default=None, metavar="N",
                   help="process at most N frames in this run, then save --state and stop")
    m = d.add_argument_group("dictionary (the main paper's CNN + frequency dictionary, greenloop.methods.dictionary.stream)")
    m.add_argument("--model", default=None, help="trained model, .keras or .tflite file (needed)")
    m.add_argument("--frames-per-spot", type=int, default=None, metavar="L",
                   help="frames per spot the model was trained with (default 60)")
    m.add_argument("--margin", type=int, default=10, help="Delta in tau = L + Delta (default 10)")
    m.add_argument("--backend", default="auto", choices=("auto", "numpy", "tflite", "keras"),
                   help="inference backend (default auto)")
    d.set_defaults(func=_detect)
    _sweep_parser(sub)
    _import_gt_parser(sub)
    return ap


def main(argv=None) -> int:
    """Parse ``argv`` and run the command; errors print one line ``error: ...`` and return 2."""
    ap = build_parser()
    args = ap.parse_args(argv)
    if not getattr(args, "func", None):
        ap.print_help()
        return 0
    try:
        return args.func(args)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
