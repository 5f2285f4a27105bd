"""``python -m greenloop import-gt SRC``: argument parsing and printing only; the work is
``greenloop.groundtruth.import_file``."""
from __future__ import annotations

from greenloop import groundtruth
from greenloop.datasets import groundtruth_formats as gt_formats


def add_parser(sub) -> None:
    """The ``import-gt`` subcommand's arguments."""
    s = sub.add_parser("import-gt", help="convert a ground-truth file (VPR-Bench .npy, loop matrix, GPS) to ground_truth.csv",
                       description="Read a ground-truth file of a common format (greenloop.datasets."
                                   "groundtruth_formats) and write it as ground_truth.csv loop pairs.")
    s.add_argument("src", metavar="SRC", help="ground_truth_new.npy, a loop matrix (.npy, .mat, image) or a positions / GPS .csv")
    s.add_argument("--out", default=None, help="output file (default: ground_truth.csv beside SRC); its folder's frames "
                                               "are used to check the frame numbers")
    s.add_argument("--format", default="auto", choices=("auto", "vpr-bench", "matrix", "positions"),
                   help="the file's format (default: from its name and contents)")
    s.add_argument("--threshold-m", type=float, default=None, metavar="M",
                   help=f"positions: frames at most M metres apart are loops (default {gt_formats.DEFAULT_THRESHOLD_M:g})")
    s.add_argument("--reference-frames", type=int, default=None, metavar="N",
                   help="vpr-bench: reference frames before the queries (default: the folder's first traversal)")
    s.set_defaults(func=run)


def run(args) -> int:
    """Import, then one line saying what was written."""
    r = groundtruth.import_file(args.src, args.out, args.format, args.threshold_m, args.reference_frames)
    within = f", within {args.threshold_m or gt_formats.DEFAULT_THRESHOLD_M:g} m" if r.fmt == "positions" else ""
    ref = f", {r.n_reference} reference frames first" if r.fmt == "vpr-bench" else ""
    checked = "" if r.n_frames is None else f" (checked against the {r.n_frames} frames of {r.out.parent})"
    print(f"wrote {len(r.pairs)} loop pairs from {args.src} ({gt_formats.FORMATS[r.fmt]}{within}{ref}) to {r.out}{checked}")
    return 0
