"""Measure the named configurations' calibrations on short recordings and at scale (the target: one threshold that keeps >= 90 % precision and finds half the revisit on 60-300-frame cuts).

For each recording: revisit frames (queries with a ground-truth partner among their candidates),
right best matches (the best candidate is a partner), closures declared at the threshold, how many
of them are correct (precision) and the share of revisit frames found (recall), once per
calibration (``seqmatch.calibrate_scores``' methods), each at its threshold. The scores are
``seqstream.score_matrix``'s, i.e. what the streaming Detector sees; the exclusion is the one
``detect`` uses (``greenloop.exclusion``).

Recordings (built into --work, never into the repository): short cuts from ../shared/real (Gardens
Point day/night and day_left/night_right, day_left/day_right; Nordland summer/winter at several
starts), 300-frame synthetic sequences (three seeds) and the 200-frame one the tests render, with
GPS-only ground truth, drives that never come back (no ground truth: every closure is false); with --large also Gardens Point 200 + 200 and
Nordland 600 + 600.

    PYTHONPATH=. .venv/bin/python tools/calib_measure.py [--work /tmp/calib] [--large]
        [--descriptor gradients] [--method zscore=2.8 --method neighbourhood=3.0]
        [--targets data/nordland data/gardenspoint data/synthetic-greenhouse]

Numbers printed, not written: results/ holds the committed tables only.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from greenloop import evaluate, groundtruth  # noqa: E402
from greenloop.methods.greenloop_seq import seqmatch
from greenloop import exclusion  # noqa: E402
from greenloop.methods.greenloop_seq import seqstream  # noqa: E402
from tests import user_folders as u  # noqa: E402

SHORT = {   # name: builder(out) -> folder
    "gp day/night 100+100": lambda o: u.gardenspoint_pairs(o, n=100),
    "gp day/night 60+60": lambda o: u.gardenspoint_pairs(o, n=60),
    "gp day/night 100+100 from 50": lambda o: u.gardenspoint_pairs(o, n=100, start=50),
    "gp day_left/night 100+100": lambda o: u.gardenspoint_pairs(o, n=100, traversals=("day_left", "night_right")),
    "gp day_left/day_right 80+80 from 100": lambda o: u.gardenspoint_pairs(o, n=80, start=100, traversals=("day_left", "day_right")),
    "nordland 30+30 from 3000": lambda o: u.nordland_short(o, n=30, start=3000),
    "nordland 40+40 from 300": lambda o: u.nordland_short(o, n=40, start=300),
    "nordland 80+80 from 1000": lambda o: u.nordland_short(o, n=80, start=1000),
    "nordland 100+100 from 2500": lambda o: u.nordland_short(o, n=100, start=2500),
    "nordland 100+100 from 200": lambda o: u.nordland_short(o, n=100, start=200),
    "nordland 150+150 from 2000": lambda o: u.nordland_short(o, n=150, start=2000),
}
LARGE = {
    "gp day/night 200+200": lambda o: u.gardenspoint_pairs(o, n=200),
    "gp day_left/night 200+200": lambda o: u.gardenspoint_pairs(o, n=200, traversals=("day_left", "night_right")),
    "nordland 600+600 from 0": lambda o: u.nordland_short(o, n=600, start=0),
}


def synthetic(work: Path) -> dict:
    """300-frame synthetic sequences (seeds 0..2) as GPS-only folders, and drives that never come back."""
    from greenloop.datasets.synthetic import make_greenhouse
    out = {}
    for seed in (0, 1, 2):
        src = work / f"synthetic-300-seed{seed}"
        if not src.exists():
            make_greenhouse(src, n_frames=300, size=(160, 120), seed=seed, progress=False)
        out[f"synthetic 300 seed {seed}"] = lambda o, s=src: u.synthetic_gps(o, s)
        out[f"no revisit: synthetic seed {seed}, 150 frames"] = lambda o, s=src: u.no_revisit(o, s, n=150)
    tiny = work / "synthetic-200-seed0"          # tests/conftest.py's tiny_sequence, as tests/test_user_folders.py cuts it
    if not tiny.exists():
        make_greenhouse(tiny, n_frames=200, size=(160, 120), seed=0, progress=False)
    out["synthetic 200 seed 0"] = lambda o: u.synthetic_gps(o, tiny)
    out["no revisit: synthetic 200 seed 0, 100 frames"] = lambda o: u.no_revisit(o, tiny, n=100)
    return out


def folder(work: Path, name: str, build) -> Path:
    f = work / name.replace(" ", "_").replace("/", "-").replace(":", "").replace(",", "")
    return f if f.exists() else build(f)


def measure(f: Path, descriptor: str, knobs: dict, methods: dict) -> dict:
    """{method: dict(revisits, right, declared, correct, precision, recall)} on one recording."""
    e = exclusion.exclusion(f).frames
    X = seqmatch.describe(f, descriptor)
    try:
        G = groundtruth.for_sequence(f, exclude=e)
    except FileNotFoundError:
        G = np.zeros((len(X), len(X)), bool)
    out = {}
    for method, t in methods.items():
        S = seqstream.score_matrix(X, e, knobs["seq_len"], knobs["velocities"], knobs["contrast_window"], None,
                                   center_window=knobs["center_window"], calibrate=method, repeat_cos=knobs["repeat_cos"],
                                   cell_shift=knobs["cell_shift"])
        js, best, score, ok, rev = seqmatch._best_per_query(S, G, e, None)
        c = seqmatch.closures(S, G, t, e)
        out[method] = dict(frames=len(X), exclude=e, revisits=int(evaluate.revisit_queries(G, e).sum()),
                           right=int((ok & rev).sum()), declared=c["declared"], correct=c["correct"],
                           precision=c["precision"], recall=c["correct"] / max(int(rev.sum()), 1))
    return out


def targets(nordland, gardenspoint, synthetic, descriptor: str, knobs: dict, methods: dict) -> None:
    """The target streams ``greenloop.experiments.default_choice`` picks thresholds on (Nordland at its full
    rate, the Gardens Point pairs, the synthetic leaderboard stream), split as notebook 13 splits
    them: closures on the tuning and on the evaluation queries, at each method's threshold."""
    from greenloop.experiments import default_choice as dc
    for label, (X, G, e, tune) in dc.streams(nordland, gardenspoint, synthetic, descriptor=descriptor).items():
        cells = []
        for method, t in methods.items():
            S = seqstream.score_matrix(X, e, knobs["seq_len"], knobs["velocities"], knobs["contrast_window"], None,
                                       center_window=knobs["center_window"], calibrate=method,
                                       repeat_cos=knobs["repeat_cos"], cell_shift=knobs["cell_shift"])
            for part, q in (("tune", tune), ("eval", ~tune)):
                c = seqmatch.closures(S, G, t, e, q)
                cells.append(f"{method} {part}: {c['declared']}, {c['correct']}, {c['precision']:.3f}, {c['recall']:.2f}")
        print(f"{label} ({len(X)} frames, exclude {e}) | " + " | ".join(cells), flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", default="/tmp/calib-measure", help="where the recordings are built (default %(default)s)")
    p.add_argument("--large", action="store_true", help="also Gardens Point 200 + 200 and Nordland 600 + 600")
    p.add_argument("--descriptor", default=None, help="gradients (the named default's) or gradients+efficientnetlite0 (the CNN one's)")
    p.add_argument("--method", action="append", default=None, metavar="NAME=THRESHOLD",
                   help="a calibration and its threshold (repeatable); default: zscore at 2.8 beside the named "
                        "configuration's calibration at its threshold")
    p.add_argument("--targets", nargs=3, metavar=("NORDLAND", "GARDENSPOINT", "SYNTHETIC"), default=None,
                   help="built dataset folders (make nordland gardenspoint synthetic): also the target streams "
                        "default_choice reads, tuning and evaluation queries apart")
    a = p.parse_args(argv)
    name = seqmatch.CNN_NAME if a.descriptor == seqmatch.CNN_KNOBS["descriptor"] else seqmatch.DEFAULT_NAME
    knobs, threshold = seqmatch.NAMED[name]
    descriptor = a.descriptor or knobs["descriptor"]
    if a.method:
        methods = {m.split("=")[0]: float(m.split("=")[1]) for m in a.method}
    else:
        methods = {"zscore": 2.8 if name == seqmatch.DEFAULT_NAME else 3.1,
                   seqmatch.check_calibration(knobs["calibrate"]): threshold}
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    recs = dict(SHORT, **synthetic(work), **(LARGE if a.large else {}))
    print(f"# {name} knobs on {descriptor}; " + ", ".join(f"{m} at {t:g}" for m, t in methods.items()))
    print("recording | frames | exclude | revisit frames | right best | " +
          " | ".join(f"{m}: closures, correct, precision, recall" for m in methods))
    for rec, build in recs.items():
        try:
            f = folder(work, rec, build)
        except FileNotFoundError as err:
            print(f"{rec} | skipped: {err}")
            continue
        r = measure(f, descriptor, knobs, methods)
        first = next(iter(r.values()))
        cells = " | ".join(f"{x['declared']}, {x['correct']}, {x['precision']:.2f}, {x['recall']:.2f}" for x in r.values())
        print(f"{rec} | {first['frames']} | {first['exclude']} | {first['revisits']} | {first['right']} | {cells}", flush=True)
    if a.targets:
        print("target stream | " + " | ".join(f"{m} {part}: closures, correct, precision, recall"
                                                for m in methods for part in ("tune", "eval")))
        targets(*a.targets, descriptor, knobs, methods)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
