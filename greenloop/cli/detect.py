"""``python -m greenloop detect RECORDING``: argument parsing and printing only; the run is
``greenloop.detect`` (every method through its registry entry)."""
from __future__ import annotations

import argparse
import sys

from greenloop import detect, exclusion, features
from greenloop.datasets import recording
from greenloop.methods import registry

_DEFAULT = registry.get(registry.DEFAULT).cli_knobs
_OTHERS = [f"{n} (descriptor {registry.get(n).cli_knobs['descriptor']}, threshold {t:g})"
           for n, t in registry.named().items() if n != registry.DEFAULT]
_DICTIONARY = registry.get("dictionary")
DESCRIPTION = (
    f"Stream a recording frame by frame through a detector and print each declared loop closure "
    f"(frame, matched earlier frame, score) and a summary. With no flags it runs the named default "
    f"{registry.DEFAULT} (descriptor {_DEFAULT['descriptor']}, seq_len "
    f"{_DEFAULT['seq_len']}, threshold {_DEFAULT['fixed_threshold']:g}): no model, no poses, no "
    f"tuning. The other named configuration{'s' if len(_OTHERS) > 1 else ''}: {'; '.join(_OTHERS)}. The frames it "
    f"never compares with a query (the exclusion) follow one rule, the one make uses, printed at the start. "
    f"For long recordings --index hnsw (or ivf, ...) runs the same configuration and threshold on the frames "
    f"an index retrieves, at a cost per frame that does not grow with the recording; --state makes it resumable. "
    f"--matches writes every frame's best match for your own scoring.")


def _defaults(knob: str) -> str:
    """One knob's default per method that has it, for --help (the registry's cli_knobs)."""
    return "; ".join(f"{n}: {e.cli_knobs[knob]}" for n, e in registry.REGISTRY.items()
                     if e.cli_knobs and knob in e.cli_knobs)


def _stream_options(d) -> None:
    """--index, --candidates, --state, --save-every, --stop-after."""
    g = d.add_argument_group("long recordings")
    g.add_argument("--index", default=None, choices=registry.INDEX.kinds,
                   help="verify sequences on the --candidates frames this index retrieves (scan, flat: exact; ivf, "
                        "hnsw, swp, qdp: approximate) instead of on every stored frame, so the per-frame cost stops "
                        "growing with the recording (greenloop.methods.lsh.retrieval); the method's configuration and "
                        "fixed threshold apply as they are (the calibration's null from "
                        f"{registry.INDEX.null_sample} sampled stored frames); the index holds the stored descriptors "
                        f"reduced to {registry.INDEX.dim} dims by a PCA fitted on the first {registry.INDEX.fit} "
                        "candidate frames, the verification reads them in full")
    g.add_argument("--candidates", type=int, default=20, help="--index: frames retrieved per query (default 20)")
    g.add_argument("--state", default=None, metavar="FILE",
                   help="save the detector here (every --save-every frames, on Ctrl-C, at the end) and resume from "
                        "it when it exists: the closures equal an uninterrupted run")
    g.add_argument("--save-every", type=int, default=10000, help="--state: frames between saves (default 10000)")
    g.add_argument("--stop-after", type=int, default=None, metavar="N",
                   help="process at most N frames in this run, then save --state and stop")


def _knob_options(d) -> None:
    """The knobs a method's record may take from a flag (detect.OVERRIDES) and --tuned / --variant."""
    g = d.add_argument_group("knobs (default: the method's record, printed at the start; a flag given wins)")
    g.add_argument("--tuned", default=None, metavar="SUMMARY_JSON",
                   help="knobs and threshold picked by notebook 13 on a tuning part (<results>/13_leaderboard/summary.json)")
    g.add_argument("--variant", default=None, metavar="ROW",
                   help="which of --tuned's rows (greenloop-seq: greenloop-seq-fast by default; another --method: "
                        "the row to stream, e.g. 'SeqSLAM (tuned)')")
    g.add_argument("--descriptor", default=None, choices=features.names(), metavar="NAME",
                   help="per-frame descriptor, a name of greenloop.features' registry (default: " + _defaults("descriptor")
                        + "); --method single-frame matches single frames on any of them")
    g.add_argument("--seq-len", type=int, default=None, help="frames per matched sequence (default: " + _defaults("seq_len") + ")")
    g.add_argument("--contrast-window", type=int, default=None,
                   help="local contrast window in frames, 0 = off (default: " + _defaults("contrast_window") + ")")
    g.add_argument("--store-dtype", default=None, choices=registry.STORE_DTYPES,
                   help="the stored descriptors' type (default: " + _defaults("store_dtype") + "); int8: each row as int8 "
                        "with a scale, a quarter of float32's bytes read per stored frame (not with --index)")
    g.add_argument("--model", default=None, help="dictionary: the trained CNN, a .keras or .tflite file (needed)")
    g.add_argument("--frames-per-spot", type=int, default=None, metavar="L",
                   help=f"dictionary: frames per spot the model was trained with (default "
                        f"{_DICTIONARY.cli_threshold(_DICTIONARY.cli_knobs) - _DICTIONARY.cli_knobs['margin']}, the paper's)")
    g.add_argument("--margin", type=int, default=None,
                   help=f"dictionary: Delta in tau = L + Delta (default {_DICTIONARY.cli_knobs['margin']})")
    g.add_argument("--backend", default=None, choices=("auto", "numpy", "tflite", "keras"),
                   help="dictionary: inference backend (default auto)")


def add_parser(sub) -> None:
    """The ``detect`` subcommand's arguments."""
    d = sub.add_parser("detect", help="stream a recording through a loop-closure detector and print its closures",
                       description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    d.add_argument("folder", metavar="RECORDING",
                   help="sequence folder (its rgb/) or folder of .jpg/.png frames, any size; a ROS 1 .bag or ROS 2 bag "
                        "folder (its camera topic: --topic); a video (" + " ".join(recording.VIDEO_SUFFIXES) + ")")
    d.add_argument("--topic", default=None,
                   help="a bag's camera topic (sensor_msgs/Image or CompressedImage); needed when the bag has several, "
                        "which are listed when it is missing")
    d.add_argument("--method", default=registry.DEFAULT, choices=list(registry.REGISTRY),
                   help=f"a registered detector (greenloop.methods.registry); default {registry.DEFAULT}, "
                        f"the named default, which needs no model and no tuning")
    d.add_argument("--threshold", "--tau", type=float, default=None,
                   help="the score to reach: " + "; ".join(f"{n}: {t:g}" for n, t in registry.named().items())
                        + " (calibrated z-scores, with or without --index; a value given overrides it); "
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
    d.add_argument("--verify", action=argparse.BooleanOptionalAction, default=None,
                   help="verify each closure candidate geometrically (local features, a robust fit of the relative "
                        "pose; the registry's verifier) and declare only the accepted ones, each with its inliers "
                        "and relative pose; default: verify when a verifier is registered")
    _knob_options(d)
    _stream_options(d)
    d.set_defaults(func=run)


def _verifier(args, frames):
    """The verifier --verify / --no-verify asks for (``detect.verifier_for`` of the plan's ``frames``):
    None for --no-verify, and by default where none is registered; ValueError for --verify where none is."""
    if args.verify is False:
        return None
    found = detect.verifier_for(frames)
    if found is None and args.verify:
        raise ValueError("--verify: no geometric verifier is registered yet (greenloop.methods.registry.verifier); "
                         "run without --verify")
    return found


def run(args) -> int:
    """Plan, print the header, stream, print the summary (``greenloop.detect``)."""
    p = detect.plan(args.folder, args.method, args.tuned, args.variant, args.threshold, args.step, args.exclude,
                    args.topic, **{k: getattr(args, k) for k in detect.OVERRIDES})
    verifier = _verifier(args, p.frames)
    print("\n".join(p.lines), flush=True)
    print(detect.header(p, args.folder, args.index, args.candidates), flush=True)
    try:
        r = detect.run(p, args.folder, args.window, args.index, args.candidates, args.state, args.save_every,
                       args.stop_after, args.matches, out=lambda line: print(line, flush=True), verifier=verifier,
                       verify_strict=args.verify is True)
    except KeyboardInterrupt:
        print("detect: interrupted" + (f"; state saved in {args.state}: run the same command again to continue"
                                       if args.state else ""), file=sys.stderr)
        return 130
    det = r.stream.detector
    closures = (f"{len(det.events)} closures" if verifier is None else
                f"{len(r.closures)} closures ({sum(c.verified is None for c in r.closures)} unverified), "
                f"{r.rejected} candidates rejected by verification")
    print(f"# summary: {r.next} frames, {closures}, {(r.next - r.first) / max(r.seconds, 1e-9):.1f} "
          f"frames/s (decoding included, {r.seconds:.2f} s for frames {r.first}..{r.next - 1})"
          + (f"; {det.bytes_per_frame} bytes per stored frame" if hasattr(det, "bytes_per_frame") else "")
          + ("" if r.finished else f"; stopped, state in {args.state}: run again to continue"), flush=True)
    return 0
