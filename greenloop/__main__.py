"""Command line: ``python -m greenloop <command> ...`` (a thin argparse dispatcher).

Commands
    detect SEQUENCE_FOLDER --model MODEL [--threshold TAU] [--frames-per-spot L]
        run a trained model (.keras or .tflite) over a recording (a sequence folder or a folder of
        .jpg/.png frames of any size, in numeric order) and print each declared loop closure and a
        summary (frames, closures, frames/s).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")


def _detect(args) -> int:
    """``detect``: frames decoded in colour (BGR) as a camera delivers them, fed to
    greenloop.stream.Detector in windows; prints events as they are declared."""
    from pathlib import Path

    import cv2

    from .data import list_frames
    from .stream import Detector

    if not Path(args.model).is_file():
        raise FileNotFoundError(f"model file {args.model} not found: pass a trained .keras model "
                                f"(greenloop.cnn.train saves results/models/<key>/model.keras) or a "
                                f".tflite file (greenloop.stream.export_tflite)")
    paths = list_frames(args.folder)
    if args.frames_per_spot is not None and args.frames_per_spot < 1:
        raise ValueError(f"--frames-per-spot must be >= 1, got {args.frames_per_spot}")
    tau = args.threshold
    if tau is None:
        tau = (args.frames_per_spot or 60) + args.margin
    elif args.frames_per_spot is not None and tau < args.frames_per_spot:
        raise ValueError(f"--threshold {tau} is below --frames-per-spot {args.frames_per_spot}: the "
                         f"paper's tau = L + margin must be >= L")
    det = Detector(args.model, tau, backend=args.backend)
    print(f"# {len(paths)} frames from {args.folder}; model {args.model} ({det.backend}, "
          f"{det.n_classes} spots); tau = {tau}", flush=True)
    print("frame\tspot\tcount\tfile", flush=True)
    t0 = time.perf_counter()
    for start in range(0, len(paths), args.window):
        chunk = paths[start:start + args.window]
        frames = []
        for p in chunk:
            img = cv2.imread(str(p), cv2.IMREAD_COLOR)
            if img is None:
                raise ValueError(f"cannot read image {p}: the file is missing, empty or not an "
                                 f"image; replace or delete it")
            frames.append(img)
        for e in det.update_many(frames):
            print(f"{e['frame']}\t{e['spot']}\t{e['count']}\t{paths[e['frame']].name}", flush=True)
    dt = time.perf_counter() - t0
    n = det.frame_index
    print(f"# summary: {n} frames, {len(det.events)} closures, {n / dt:.1f} frames/s "
          f"(decoding included, {dt:.2f} s)", flush=True)
    return 0


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
    d.add_argument("--model", required=True, help="trained model: .keras or .tflite file")
    d.add_argument("--threshold", "--tau", type=int, default=None,
                   help="tau: declare a closure when a spot has been predicted this many times "
                        "(default: frames-per-spot + margin)")
    d.add_argument("--frames-per-spot", type=int, default=None, metavar="L",
                   help="frames per spot the model was trained with (default 60)")
    d.add_argument("--margin", type=int, default=10, help="Delta in tau = L + Delta (default 10)")
    d.add_argument("--backend", default="auto", choices=("auto", "numpy", "tflite", "keras"),
                   help="inference backend (default auto)")
    d.add_argument("--window", type=int, default=70, help="frames per batch (default 70)")
    d.set_defaults(func=_detect)
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
