"""``python -m greenloop data SET OUT ...``: build a dataset's sequence folder (``make synthetic``,
``make nordland``, ``make gardenspoint``, ``make data``) or a long augmented recording. Argument
parsing and printing only; the builders are ``greenloop.datasets``' modules."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from greenloop.datasets import augment, gardenspoint, greenhouse, nordland, sequence, sources, synthetic


def _builder(sets, name: str, what: str, example: str, subfolders: str, url: str):
    """A real set's subparser with the arguments every builder shares: OUT, --src, --url,
    --overwrite, --quiet, --describe."""
    s = sets.add_parser(name, help=what, description=what)
    s.add_argument("out", help=f"output sequence folder, e.g. {example}")
    s.add_argument("--src", help=f"local source folder ({subfolders}) or a clone of the source repository; "
                                 "without it the source is cloned into a temporary folder")
    s.add_argument("--url", default=url, help="repository to clone when --src is not given")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--describe", action="store_true",
                   help="only rewrite OUT's sequence.yaml from its build record (no frame is read or written): "
                        "an older build gets what the builder writes now, e.g. its targets' protocol")
    return s


def _nordland(sets) -> None:
    s = _builder(sets, "nordland", "Build the Nordland summer+winter sequence folder.", "data/nordland",
                 "summer/, winter/", nordland.SOURCE_URL)
    s.add_argument("--tolerance", type=int, default=nordland.TOLERANCE,
                   help="ground-truth tolerance in frames (default %(default)s, from the source's sample)")

    def run(a) -> int:
        if a.describe:
            return sources.run_describe(a.out, nordland.describe)

        def summary(out: Path) -> str:
            meta = json.loads((out / "nordland.json").read_text())
            return (f"wrote {meta['n_frames']} frames ({meta['frames_per_season']} per season), "
                    f"{sequence.GROUND_TRUTH_NAME} and {sequence.DESCRIPTION_NAME} to {out}")
        return sources.run_builder(
            a, lambda src, **more: nordland.build(a.out, src, a.tolerance, a.overwrite, progress=not a.quiet, **more),
            lambda tmp: nordland.clone_source(tmp / "seqslam", a.url), nordland.SOURCE_SUBDIR, summary)
    s.set_defaults(func=run)


def _gardenspoint(sets) -> None:
    gp = gardenspoint
    s = _builder(sets, "gardenspoint", "Build the Gardens Point Walking sequence folder (3 traversals).",
                 "data/gardenspoint", "day_left/, day_right/, night_right/", gp.SOURCE_URL)
    s.add_argument("--size", default=f"{gp.SIZE[0]}x{gp.SIZE[1]}", help="WIDTHxHEIGHT of every frame (default %(default)s)")
    s.add_argument("--tolerance", type=int, default=gp.TOLERANCE,
                   help="ground-truth tolerance in frames (default %(default)s, VPR-Bench's)")

    def run(a) -> int:
        if a.describe:
            return sources.run_describe(a.out, gp.describe)
        w, _, h = a.size.lower().partition("x")
        if not (w.isdigit() and h.isdigit()):
            s.error(f"--size must be WIDTHxHEIGHT in pixels (e.g. 640x360), got {a.size!r}")
        kw = dict(size=(int(w), int(h)), tolerance=a.tolerance, overwrite=a.overwrite, progress=not a.quiet)

        def summary(out: Path) -> str:
            meta = json.loads((out / "gardenspoint.json").read_text())
            return (f"wrote {meta['n_frames']} frames ({meta['frames_per_traversal']} per traversal, "
                    f"{meta['width']}x{meta['height']}) and {sequence.DESCRIPTION_NAME} to {out}")
        return sources.run_builder(
            a, lambda src, **more: gp.build(a.out, src, **kw, **more),
            lambda tmp: gp.source_folder(sources.shallow_clone(tmp / "loop-detection", a.url, gp.FIX, "Gardens Point")),
            gp.SOURCE_SUBDIR, summary)
    s.set_defaults(func=run)


def _size(text: str) -> tuple[int, int]:
    """'640x480' -> (640, 480) for argparse."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got {text!r}") from None
    return w, h


def _synthetic(sets) -> None:
    mk = synthetic.make
    s = sets.add_parser("synthetic", help="render the synthetic GreenHouse sequence folder (the embedded default)")
    s.add_argument("out", help="output sequence folder (created; must not exist unless --overwrite)")
    s.add_argument("--frames", type=int, default=mk.DEFAULT_FRAMES, help="number of frames (>= 200)")
    s.add_argument("--size", type=_size, default=mk.DEFAULT_SIZE, help="WxH, e.g. 640x480")
    s.add_argument("--seed", type=int, default=0, help="random seed (>= 0)")
    s.add_argument("--noise", type=float, default=mk.DEFAULT_NOISE,
                   help="per-pixel Gaussian noise std in grey levels (default %(default)s; 1.0 looks like a real "
                        "sensor but doubles the disk size)")
    s.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    s.add_argument("--quiet", action="store_true", help="no progress bar")

    def run(a) -> int:
        t0 = time.perf_counter()
        out = mk.make_greenhouse(a.out, a.frames, a.size, a.seed, progress=not a.quiet, workers=a.workers,
                                 overwrite=a.overwrite, noise=a.noise)
        print(f"wrote {a.frames} frames to {out} in {time.perf_counter() - t0:.1f} s")
        return 0
    s.set_defaults(func=run)


def _greenhouse_days(sets) -> None:
    dm = synthetic.daysmake
    s = sets.add_parser("greenhouse-days", help="render the greenhouse over days: a larger hall, "
                                                "one sequence folder per day and the multi-day stream")
    s.add_argument("out", help="output folder (the stream; the days in OUT/days/)")
    s.add_argument("--days", type=int, default=5, help="recording days (default %(default)s; >= 5 for every light)")
    s.add_argument("--tiny", action="store_true", help="the two-aisle hall at 160x120 every 0.25 m (tests)")
    s.add_argument("--size", type=_size, default=None, help="WxH (default 640x480, --tiny 160x120)")
    s.add_argument("--spacing", type=float, default=None,
                   help=f"metres between frames (default {dm.SPACING}, --tiny {dm.TINY_SPACING})")
    s.add_argument("--seed", type=int, default=0, help="random seed (>= 0)")
    s.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    s.add_argument("--quiet", action="store_true", help="no progress bar")

    def run(a) -> int:
        t0 = time.perf_counter()
        kw = dict(n_days=a.days, tiny=a.tiny, seed=a.seed, size=a.size, spacing=a.spacing)
        if not a.overwrite and dm.up_to_date(a.out, **kw):
            print(f"{a.out} is up to date (same arguments in {dm.META}); --overwrite renders it again")
            return 0
        out = dm.make_greenhouse_days(a.out, workers=a.workers, overwrite=a.overwrite, progress=not a.quiet, **kw)
        meta = json.loads((out / dm.META).read_text())
        frames = ", ".join(f"{d['name']} {d['frames']}" for d in meta["days"])
        print(f"wrote {meta['n_days']} days ({frames} frames) to {out} in {time.perf_counter() - t0:.1f} s")
        return 0
    s.set_defaults(func=run)


def _others(sets) -> None:
    g = sets.add_parser("greenhouse", help="download the real GreenHouse set (needs the internet)")
    g.add_argument("out", nargs="?", default="data/greenhouse")
    g.add_argument("--url", default=greenhouse.BASE_URL, help="raw URL of the dataset/ folder")

    def get(a) -> int:
        try:
            print(greenhouse.download(a.out, a.url))
        except RuntimeError as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
        return 0
    g.set_defaults(func=get)
    m = sets.add_parser("augment", help="an augmented long recording over Nordland's frames, as numbered PNGs")
    m.add_argument("out", help="folder to write (outside the repository: 10^5 frames are ~0.5 GB)")
    m.add_argument("--src", default="../shared/real/nordland", help="Nordland source (summer/, winter/)")
    m.add_argument("--frames", type=int, default=100_000)
    m.add_argument("--seed", type=int, default=0)

    def write(a) -> int:
        augment.write_recording(a.src, a.out, a.frames, a.seed)
        return 0
    m.set_defaults(func=write)


def add_parser(sub) -> None:
    """The ``data`` command and its sets."""
    d = sub.add_parser("data", help="build a dataset's sequence folder (synthetic, nordland, gardenspoint, greenhouse)")
    sets = d.add_subparsers(dest="set", metavar="SET", required=True)
    _synthetic(sets)
    _greenhouse_days(sets)
    _nordland(sets)
    _gardenspoint(sets)
    _others(sets)
