"""The Nordland railway as a sequence folder: the summer traversal, then the winter one.

Source (github.com/TimQuelch/seqslam, folder ``datasets/nordland_trimmed``; NRK's
"Nordlandsbanen: minute by minute, season by season", Creative Commons; cite Suenderhauf,
Neubert, Protzel, ICRA 2013 workshop): ``summer/images-00010.png ... images-35760.png`` and
``winter/`` with the same names, every 10th frame of the 10 fps recordings, 64x32 RGB. Frame k of
summer and frame k of winter show the same place. ``build`` writes (see ``greenloop.datasets.sequence``)::

    rgb/0.png ... rgb/n-1.png      summer, in numeric order of the source names
    rgb/n.png ... rgb/2n-1.png     winter: winter frame k is frame n + k
    ground_truth.csv               the alignment: summer frame k is a loop with winter frames
                                   n + k +- TOLERANCE, never with summer frames (alignment_pairs)
    nordland.json                  source, counts, traversal boundaries [0, n) and [n, 2n)

Read in order, the second half revisits the first: a loop-closure sequence without poses or
depth whose loops are the rows of ground_truth.csv (``greenloop.groundtruth.for_sequence``).

The tolerance. The source's ``sample_ground_truth.csv`` (``query,ref,tolerance``, 1-based,
no header) has 358 rows ``q,q,15``; ../shared/real/README.md reads it as a tolerance of 15
frames, and that is the default here (``TOLERANCE``): about 15 s of the recording at the 1 frame
per second of these images. Another reading fits the file too: 358 = ceil(3576 / 10), so the
sample may index every 10th of these images (OpenSeqSLAM2's ``subsample_factor``), which makes
its 15 mean 150 of these frames. We keep the stricter window, so that naming a place a few
minutes of travel away is not counted as a loop; ``tolerance=150`` (``--tolerance 150``) gives
the looser reading.

Run ``make nordland`` or ``python -m greenloop.datasets.nordland data/nordland [--src FOLDER]``; without
``--src`` the source is cloned (``git clone --depth 1``) into a temporary folder.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from greenloop.datasets import sequence, sources
from greenloop.util.files import publish_folder
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

SOURCE_URL = "https://github.com/TimQuelch/seqslam"
SOURCE_SUBDIR = "datasets/nordland_trimmed"
SEASONS = ("summer", "winter")
SAMPLE_STEP = 10        # the sample's rows cover every SAMPLE_STEP-th image (358 = ceil(3576 / 10))
SAMPLE_TOLERANCE = 15   # the tolerance column of the source's sample ground truth
TOLERANCE = SAMPLE_TOLERANCE   # default: read as frames of these images (module doc)
FIX = ("set NORDLAND_SRC=path (make) or pass --src path to a local copy of the source folder "
       f"`{SOURCE_SUBDIR}` (summer/ and winter/), e.g. from `git clone --depth 1 {SOURCE_URL}`")


def source_folder(src) -> Path:
    """The folder holding summer/ and winter/: ``src`` itself or ``src/datasets/nordland_trimmed``
    (a clone of the source repository). Raises FileNotFoundError naming the fix."""
    return sources.source_folder(src, SOURCE_SUBDIR, SEASONS, "Nordland", FIX)


def _size(path: Path) -> tuple[int, int]:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"cannot read image {path}: replace it from the source")
    return int(img.shape[1]), int(img.shape[0])


def check_source(src) -> tuple[list[Path], list[Path], tuple[int, int]]:
    """Validate a source folder: both seasons hold the same file names (so frame k of each is the
    same place) and every image has one size.

    Returns (summer paths, winter paths) in numeric order of their names and (width, height).
    Raises FileNotFoundError for a missing folder and ValueError for empty or mismatched seasons
    or mixed sizes, each naming the first offending file.
    """
    src = source_folder(src)
    seasons = {}
    for s in SEASONS:
        try:
            seasons[s] = sequence.list_frames(src / s)
        except ValueError:
            raise ValueError(f"{src / s} holds no .png/.jpg images: {FIX}") from None
    summer, winter = seasons["summer"], seasons["winter"]
    a, b = [p.name for p in summer], [p.name for p in winter]
    if a != b:
        only_s, only_w = sorted(set(a) - set(b)), sorted(set(b) - set(a))
        raise ValueError(f"the seasons do not match ({len(a)} summer, {len(b)} winter frames): "
                         f"only in summer/: {only_s[:3]}, only in winter/: {only_w[:3]}; frame k of "
                         f"each season must show the same place, so both need the same file names")
    with ThreadPoolExecutor(8) as pool:
        sizes = list(pool.map(_size, summer + winter))
    first = sizes[0]
    for p, size in zip(summer + winter, sizes):
        if size != first:
            raise ValueError(f"{p} is {size[0]}x{size[1]} while {summer[0]} is {first[0]}x{first[1]}: "
                             f"every frame of both seasons must have one size")
    return summer, winter, first


def alignment_pairs(n: int, tolerance: int) -> np.ndarray:
    """ground_truth.csv rows for two aligned traversals of n frames each: summer frame k is a
    loop with winter frames n + k - tolerance ... n + k + tolerance, clipped to the winter
    traversal (its start is not a place near the end of summer).

    Returns (P, 3) int64 rows (i, j, tolerance): (k, n + k, tolerance) where the window does
    not reach back into summer (past the end of winter there are no frames to clip); for
    k < tolerance the clipped window [n, min(2n - 1, n + k + tolerance)] as its centre and
    half-width, plus its last frame alone when its length is even.
    """
    return sequence.aligned_pairs([(0, n), (n, 2 * n)], tolerance)


def _write(tmp: Path, summer, winter, tolerance: int, meta: dict, progress: bool) -> None:
    """Copy the frames (summer then winter) and write ground_truth.csv and nordland.json."""
    (tmp / "rgb").mkdir(parents=True)
    frames = summer + winter
    for k, p in enumerate(tqdm(frames, desc="nordland", unit="frame", disable=not progress)):
        shutil.copyfile(p, tmp / "rgb" / f"{k}{p.suffix.lower()}")
    n = len(summer)
    sequence.write_loop_pairs(tmp / sequence.GROUND_TRUTH_NAME, alignment_pairs(n, tolerance))
    (tmp / "nordland.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")


def build(out, src, tolerance: int = TOLERANCE, overwrite: bool = False, progress: bool = True,
          source_name: str | None = None) -> Path:
    """Build the Nordland sequence folder ``out`` from a local source folder (module doc).

    src: the source folder (summer/, winter/) or a clone of the source repository.
    tolerance: frames of ground-truth tolerance around each winter frame n + k (>= 0).
    overwrite: replace an existing non-empty ``out`` (otherwise FileExistsError).
    source_name: what nordland.json records as the source (default: the path of src).
    Writes into a temporary folder beside ``out`` and renames it at the end, so a complete
    folder means a complete build. Returns ``out`` as a Path.
    """
    if isinstance(tolerance, bool) or not isinstance(tolerance, int) or tolerance < 0:
        raise ValueError(f"tolerance must be an integer >= 0 frames, got {tolerance!r}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder: choose another output path")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise FileExistsError(f"{out} already exists and is not empty: delete it, choose another "
                              f"folder, or pass overwrite=True (CLI: --overwrite)")
    summer, winter, (w, h) = check_source(src)
    n = len(summer)
    meta = {"generator": "greenloop.datasets.nordland", "format": 1,
            "source": source_name or str(source_folder(src)), "source_repository": SOURCE_URL,
            "source_folder": SOURCE_SUBDIR, "seasons": list(SEASONS), "frames_per_season": n,
            "n_frames": 2 * n, "width": w, "height": h,
            "traversals": {"summer": [0, n], "winter": [n, 2 * n]},
            "source_names": [summer[0].name, summer[-1].name],
            "ground_truth": {"file": sequence.GROUND_TRUTH_NAME,
                             "pairs": "summer k with winter n + k +- tolerance, clipped to winter",
                             "tolerance_frames": tolerance,
                             "default_tolerance": f"{SAMPLE_TOLERANCE}: the source's "
                             "sample_ground_truth.csv tolerance, read as frames of these images"}}
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        _write(tmp, summer, winter, tolerance, meta, progress)
        publish_folder(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def clone_source(dest, url: str = SOURCE_URL, timeout: float = 20.0,
                 clone_timeout: float = 1800.0) -> Path:
    """``git clone --depth 1 url dest`` (:func:`greenloop.datasets.sources.shallow_clone`); returns the source folder inside
    it. Raises RuntimeError with the fix (NORDLAND_SRC=path) when the clone fails."""
    return source_folder(sources.shallow_clone(dest, url, FIX, "Nordland", timeout, clone_timeout))


def main(argv=None) -> int:
    """CLI: ``python -m greenloop.datasets.nordland OUT [--src SRC] [--url URL] [--tolerance T]``."""
    ap = argparse.ArgumentParser(prog="python -m greenloop.datasets.nordland",
                                 description="Build the Nordland summer+winter sequence folder.")
    ap.add_argument("out", help="output sequence folder, e.g. data/nordland")
    ap.add_argument("--src", help="local source folder (summer/, winter/) or a clone of the source "
                                  "repository; without it the source is cloned into a temporary folder")
    ap.add_argument("--url", default=SOURCE_URL, help="repository to clone when --src is not given")
    ap.add_argument("--tolerance", type=int, default=TOLERANCE,
                    help="ground-truth tolerance in frames (default %(default)s, from the source's sample)")
    ap.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    try:
        if a.src:
            out = build(a.out, a.src, a.tolerance, a.overwrite, progress=not a.quiet)
        else:
            with tempfile.TemporaryDirectory(prefix="nordland-src-") as tmp:
                print(f"cloning {a.url} (no --src given) ...", file=sys.stderr, flush=True)
                src = clone_source(Path(tmp) / "seqslam", a.url)
                out = build(a.out, src, a.tolerance, a.overwrite, progress=not a.quiet,
                            source_name=f"{a.url} ({SOURCE_SUBDIR})")
    except (RuntimeError, ValueError, FileNotFoundError, FileExistsError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    meta = json.loads((out / "nordland.json").read_text())
    print(f"wrote {meta['n_frames']} frames ({meta['frames_per_season']} per season) and "
          f"{sequence.GROUND_TRUTH_NAME} to {out} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
