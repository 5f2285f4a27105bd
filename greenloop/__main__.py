"""Command line: ``python -m greenloop <command> ...`` (a thin argparse dispatcher).

Commands
    detect SEQUENCE_FOLDER --model MODEL [--threshold TAU] [--frames-per-spot L]
        run a trained model (.keras or .tflite) over a recording (a sequence folder or a folder of
        .jpg/.png frames of any size, in numeric order) and print each declared loop closure and a
        summary (frames, closures, frames/s). ``--method dictionary`` (the default) is the main
        paper's CNN + frequency dictionary (greenloop.speed.stream.Detector).
    detect SEQUENCE_FOLDER --method greenloop-seq (--tuned SUMMARY_JSON | --threshold T)
          [--variant greenloop-seq|greenloop-seq-fast] [--descriptor NAME] [--seq-len L]
          [--exclude FRAMES] [--contrast-window R] [--step N]
        greenloop's own sequence-matching detector (greenloop.seqmatch.Detector): no model, no
        poses; prints each closure (query frame, matched earlier frame, score).
    sweep NOTEBOOK --grid NAME=V1,V2,... [--grid ...] --out OUT [-f PARAMS.yaml] [-p NAME VALUE]
          [--dataset DIR] [--scheduler local|tcp://HOST:8786|slurm|pbs] [--workers N] [--metric SPEC]
        run the notebook once per point of the grids' cross product on Dask (greenloop.study.sweep) and
        write OUT/sweep.csv, sweep.md and sweep.png; complete points are not run again.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")

import cv2  # noqa: E402
import yaml  # noqa: E402

from greenloop import seqmatch  # noqa: E402
from greenloop.datasets.sequence import list_frames  # noqa: E402
from greenloop.speed import stream  # noqa: E402
from greenloop.study import sweep  # noqa: E402


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


def _tuned_knobs(args) -> dict:
    """greenloop-seq's knobs: from ``--tuned`` (a notebook 13 summary.json, the variant named by
    ``--variant``), overridden by any flag given explicitly. Returns dict(descriptor, seq_len,
    contrast_window, threshold, step, exclude), exclude and seq_len in streamed frames."""
    knobs = dict(descriptor="pixels-patchnorm", seq_len=10, contrast_window=10, threshold=None,
                 step=1, exclude=150)
    if not args.tuned and args.threshold is None:   # issue 28: the named default, its calibrated threshold
        knobs.update(seqmatch.DEFAULT_KNOBS, threshold=seqmatch.DEFAULT_THRESHOLD)
    elif args.tuned:
        path = Path(args.tuned)
        if not path.is_file():
            raise FileNotFoundError(f"--tuned {path}: no such file; run notebook 13 on a recording of "
                                    f"your site (make all DATASET=...), then pass its "
                                    f"<results>/13_leaderboard/summary.json")
        summary = json.loads(path.read_text())
        if args.variant not in summary.get("knobs", {}):
            raise ValueError(f"--tuned {path} has no variant {args.variant!r} (it has "
                             f"{sorted(summary.get('knobs', {}))})")
        knobs.update(summary["knobs"][args.variant], threshold=summary["thresholds"][args.variant],
                     step=int(summary["frame_step"]), exclude=int(summary["exclude_steps"]))
    for k in ("descriptor", "seq_len", "contrast_window", "threshold", "step", "exclude"):
        if getattr(args, k) is not None:
            knobs[k] = getattr(args, k)
    if knobs["threshold"] is None:
        raise ValueError("greenloop-seq needs a threshold chosen on your own data: pass --tuned "
                         "<results>/13_leaderboard/summary.json (notebook 13 picks the knobs and the "
                         "threshold on a tuning part) or --threshold T")
    if knobs["step"] < 1:
        raise ValueError(f"--step must be >= 1, got {knobs['step']}")
    return knobs


def _detect_seq(args) -> int:
    """``detect --method greenloop-seq``: greenloop.seqmatch.Detector over the frames in windows
    (every ``step``-th frame of the folder, the rate its knobs were tuned at)."""
    kn = _tuned_knobs(args)
    paths = list_frames(args.folder)[::kn["step"]]
    det = seqmatch.Detector(kn["threshold"], descriptor=kn["descriptor"], seq_len=kn["seq_len"],
                            exclude=kn["exclude"], contrast_window=kn["contrast_window"],
                            **{k: kn[k] for k in ("velocities", "center_window", "calibrate", "repeat_cos") if k in kn})
    print(f"# {len(paths)} frames from {args.folder} (every {kn['step']}); greenloop-seq "
          f"({kn['descriptor']}, seq_len {det.seq_len}, exclude {det.exclude}, contrast window "
          f"{det.contrast_window}); threshold {det.threshold:g}", flush=True)
    print("frame\tmatch\tscore\tfile\tmatch_file", flush=True)
    t0 = time.perf_counter()
    for start in range(0, len(paths), args.window):
        for e in det.update_many(_read_window(paths[start:start + args.window])):
            print(f"{e['frame']}\t{e['match']}\t{e['score']:.4f}\t{paths[e['frame']].name}\t"
                  f"{paths[e['match']].name}", flush=True)
    dt = time.perf_counter() - t0
    n = det.frame_index
    print(f"# summary: {n} frames, {len(det.events)} closures, {n / dt:.1f} frames/s (decoding "
          f"included, {dt:.2f} s); {det.bytes_per_frame} bytes per stored frame", flush=True)
    return 0


def _detect(args) -> int:
    """``detect``: frames decoded in colour (BGR) as a camera delivers them, fed to
    greenloop.speed.stream.Detector (``--method dictionary``) or greenloop.seqmatch.Detector
    (``--method greenloop-seq``) in windows; prints events as they are declared."""
    if args.method == "greenloop-seq":
        return _detect_seq(args)

    if args.model is None:
        raise ValueError("--method dictionary needs --model (a trained .keras or .tflite file)")
    if args.threshold is not None and int(args.threshold) != args.threshold:
        raise ValueError(f"--threshold (tau) must be an integer for --method dictionary, got {args.threshold:g}")
    if not Path(args.model).is_file():
        raise FileNotFoundError(f"model file {args.model} not found: pass a trained .keras model "
                                f"(greenloop.cnn.train saves results/models/<key>/model.keras) or a "
                                f".tflite file (greenloop.speed.stream.export_tflite)")
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
    t0 = time.perf_counter()
    for start in range(0, len(paths), args.window):
        chunk = paths[start:start + args.window]
        for e in det.update_many(_read_window(chunk)):
            print(f"{e['frame']}\t{e['spot']}\t{e['count']}\t{paths[e['frame']].name}", flush=True)
    dt = time.perf_counter() - t0
    n = det.frame_index
    print(f"# summary: {n} frames, {len(det.events)} closures, {n / dt:.1f} frames/s "
          f"(decoding included, {dt:.2f} s)", flush=True)
    return 0


def _sweep(args) -> int:
    """``sweep``: one papermill run per grid point on Dask; 0 when every point is ok, else 1."""
    base = {}
    for path in args.parameters_file:
        if not os.path.isfile(path):
            raise FileNotFoundError(f"parameters file {path} not found: pass a YAML file such as "
                                    f"params/quick.yaml")
        base.update(yaml.safe_load(open(path)) or {})
    for name, value in args.parameter:
        base[name] = yaml.safe_load(value)
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


def build_parser() -> argparse.ArgumentParser:
    """The argument parser: one subparser per command (add new commands here)."""
    ap = argparse.ArgumentParser(prog="python -m greenloop",
                                 description="greenloop: CNN visual loop-closure detection for "
                                             "agricultural robots.")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    d = sub.add_parser("detect", help="run a trained model over a recording and print loop closures",
                       description="Classify every frame of a recording with a trained spot CNN, "
                                   "count the predictions in the paper's dictionary and print each "
                                   "declared loop closure (frame, spot, count) and a summary.")
    d.add_argument("folder", metavar="SEQUENCE_FOLDER",
                   help="sequence folder (its rgb/) or folder of .jpg/.png frames, any size")
    d.add_argument("--method", default="dictionary", choices=("dictionary", "greenloop-seq"),
                   help="dictionary: the main paper's CNN + frequency dictionary (needs --model; "
                        "default); greenloop-seq: sequence matching (greenloop.seqmatch)")
    d.add_argument("--model", default=None, help="dictionary: trained model, .keras or .tflite file")
    d.add_argument("--threshold", "--tau", type=float, default=None,
                   help="dictionary: tau, declare a closure when a spot has been predicted this many "
                        "times (an integer; default frames-per-spot + margin); greenloop-seq: the "
                        "sequence score to reach (else read from --tuned)")
    d.add_argument("--frames-per-spot", type=int, default=None, metavar="L",
                   help="frames per spot the model was trained with (default 60)")
    d.add_argument("--margin", type=int, default=10, help="Delta in tau = L + Delta (default 10)")
    d.add_argument("--backend", default="auto", choices=("auto", "numpy", "tflite", "keras"),
                   help="inference backend (default auto)")
    d.add_argument("--window", type=int, default=70, help="frames per batch (default 70)")
    g = d.add_argument_group("greenloop-seq (greenloop.seqmatch.Detector)")
    g.add_argument("--tuned", default=None, metavar="SUMMARY_JSON",
                   help="knobs and threshold picked by notebook 13 on a tuning part "
                        "(<results>/13_leaderboard/summary.json); flags below override them")
    g.add_argument("--variant", default="greenloop-seq-fast", choices=("greenloop-seq", "greenloop-seq-fast"),
                   help="which of --tuned's variants (default greenloop-seq-fast: no CNN)")
    g.add_argument("--descriptor", default=None, choices=("pixels", "pixels-patchnorm", "mobilenetv2"),
                   help="per-frame descriptor (default pixels-patchnorm)")
    g.add_argument("--seq-len", type=int, default=None, help="frames per matched sequence (default 10)")
    g.add_argument("--exclude", type=int, default=None,
                   help="only frames more than this many streamed frames older are candidates (default 150)")
    g.add_argument("--contrast-window", type=int, default=None,
                   help="SeqSLAM local contrast window in frames, 0 = off (default 10)")
    g.add_argument("--step", type=int, default=None,
                   help="stream every step-th frame (default 1; --tuned: its frame_step)")
    d.set_defaults(func=_detect)
    _sweep_parser(sub)
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
