"""Gardens Point Walking as a sequence folder of three traversals: day_left, day_right, night_right.

Source (github.com/aghagol/loop-detection, folder ``PR_bench/GardensPointWalking``; a copy of the
set Glover and Chen recorded at QUT, Zenodo record 4590133; cite Suenderhauf et al., "On the
performance of ConvNet features for place recognition", IROS 2015): ``day_left/``, ``day_right/``
and ``night_right/``, ``Image000.jpg ... Image199.jpg`` each, frame k of every traversal the same
place of one campus walk. day_left walks the left side of the path, the other two the right side
(a lateral viewpoint change, then an illumination change). The day traversals are 960x540, the
night one 640x360. ``build`` writes (the traversals layout of ``greenloop.datasets.sequence``)::

    traversals/day_left/0.jpg ... 199.jpg      every frame resized to one size (default 640x360,
    traversals/day_right/...                   INTER_AREA, JPEG quality 95; a frame already of
    traversals/night_right/...                 that size is copied byte for byte)
    sequence.yaml       the stream order day_left, day_right, night_right (600 frames, each place
                        revisited twice), ``ground_truth: aligned`` with a tolerance of TOLERANCE
                        frames (VPR-Bench's), frame_step 1 (200 frames a traversal leave nothing
                        to subsample) and the detector targets' protocol: Gardens Point's target
                        set on the streams TARGET_PAIRS, +- TARGET_TOLERANCE frames
    gardenspoint.json   source, counts, size, traversal boundaries

Run ``make gardenspoint`` or ``python -m greenloop data gardenspoint data/gardenspoint
[--src FOLDER]``; without ``--src`` the source is cloned (``git clone --depth 1``) into a
temporary folder. ``--describe`` rewrites only the sequence.yaml of a folder built before, from
its gardenspoint.json.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2

from greenloop.datasets import sequence, sources
from greenloop.util.files import write_atomic
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

SOURCE_URL = "https://github.com/aghagol/loop-detection"
SOURCE_SUBDIR = "PR_bench/GardensPointWalking"
TRAVERSALS = ("day_left", "day_right", "night_right")
TOLERANCE = 2                 # frames: VPR-Bench's ground truth for this set (frame k +- 2)
TARGET_PAIRS = (("day_right", "night_right"), ("day_left", "night_right"))   # the targets' streams, database first
TARGET_TOLERANCE = sequence.TARGET_TOLERANCE   # frames: the targets' streams, frame k of each walk +- 2
SIZE = (640, 360)             # (width, height): night_right's size, the day sets shrunk to it
JPEG_QUALITY = 95
FIX = ("set GARDENSPOINT_SRC=path (make) or pass --src path to a local copy of the source folder "
       f"`{SOURCE_SUBDIR}` (day_left/, day_right/, night_right/), e.g. from "
       f"`git clone --depth 1 {SOURCE_URL}`")


def source_folder(src) -> Path:
    """The folder holding the three traversals: ``src`` itself or ``src/PR_bench/GardensPointWalking``
    (a clone of the source repository). Raises FileNotFoundError naming the fix."""
    return sources.source_folder(src, SOURCE_SUBDIR, TRAVERSALS, "Gardens Point", FIX)


def check_source(src) -> dict:
    """Validate a source folder: every traversal holds the same file names (frame k of each is
    one place). Returns {traversal: [paths in numeric order]}; raises ValueError naming the first
    traversal that differs and FileNotFoundError for a missing folder."""
    return sources.aligned_traversals(source_folder(src), TRAVERSALS, FIX)


def _convert(src: Path, dest: Path, size: tuple[int, int]) -> tuple[int, int]:
    """One frame to ``dest`` at ``size`` (copied when already that size); returns its source (w, h)."""
    img = cv2.imread(str(src), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"cannot read image {src}: replace it from the source")
    h, w = img.shape[:2]
    if (w, h) == size and src.suffix.lower() in (".jpg", ".jpeg"):
        shutil.copyfile(src, dest)
        return w, h
    small = cv2.resize(img, size, interpolation=cv2.INTER_AREA if w > size[0] else cv2.INTER_LINEAR)
    if not cv2.imwrite(str(dest), small, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]):
        raise OSError(f"could not write {dest}")
    return w, h


def _description(tolerance: int) -> str:
    """The sequence.yaml the builder writes (read by sequence.read_description)."""
    return (f"# Gardens Point Walking (greenloop.datasets.gardenspoint): three walks of one campus route.\n"
            f"# The stream is the traversals in this order, 600 frames; each place is revisited twice.\n"
            f"traversals: [{', '.join(TRAVERSALS)}]\n"
            f"# frame k of every traversal is the same place, +- tolerance frames (VPR-Bench's)\n"
            f"ground_truth: {sequence.ALIGNED}\n"
            f"tolerance: {tolerance}\n"
            f"# 200 frames a traversal: the descriptor notebooks describe every frame\n"
            f"frame_step: 1\n"
            f"# how the detector's targets judge it (greenloop.study.targets): Gardens Point's set, on\n"
            f"# two walks at a time, the first the database, frame k of each one place +- {TARGET_TOLERANCE}\n"
            f"protocol:\n"
            f"  targets: gardenspoint\n"
            f"  target_streams:\n"
            + "".join(f"    - traversals: [{a}, {b}]\n      tolerance: {TARGET_TOLERANCE}\n" for a, b in TARGET_PAIRS))


def describe(out) -> Path:
    """Rewrite the sequence.yaml of a built Gardens Point folder ``out`` (its ground-truth tolerance
    from its gardenspoint.json); frames untouched. Returns the file's path."""
    meta = json.loads((Path(out) / "gardenspoint.json").read_text())
    return write_atomic(Path(out) / sequence.DESCRIPTION_NAME, _description(int(meta["ground_truth"]["tolerance_frames"])))


def build(out, src, size=SIZE, tolerance: int = TOLERANCE, overwrite: bool = False,
          progress: bool = True, source_name: str | None = None) -> Path:
    """Build the Gardens Point sequence folder ``out`` from a local source folder (module doc).

    src: the source folder (day_left/, day_right/, night_right/) or a clone of the repository.
    size: (width, height) every frame is resized to. tolerance: ground-truth frames (>= 0).
    overwrite: replace an existing non-empty ``out`` (otherwise FileExistsError).
    Writes into a temporary folder beside ``out`` and renames it at the end, so a complete folder
    means a complete build. Returns ``out`` as a Path.
    """
    out = sources.check_output(out, tolerance, overwrite)
    size = (int(size[0]), int(size[1]))
    if min(size) < 1:
        raise ValueError(f"size must be positive (width, height), got {size}")
    found = check_source(src)
    n = len(found[TRAVERSALS[0]])

    def write(tmp: Path) -> None:
        native = {}
        for t in TRAVERSALS:
            (tmp / sequence.TRAVERSALS_DIR / t).mkdir(parents=True)
            paths = tqdm(found[t], desc=t, unit="frame", disable=not progress)
            native[t] = sorted({_convert(p, tmp / sequence.TRAVERSALS_DIR / t / f"{k}.jpg", size)
                                for k, p in enumerate(paths)})
        meta = {"generator": "greenloop.datasets.gardenspoint", "format": 1,
                "source": source_name or str(source_folder(src)), "source_repository": SOURCE_URL,
                "source_folder": SOURCE_SUBDIR, "frames_per_traversal": n, "n_frames": len(TRAVERSALS) * n,
                "width": size[0], "height": size[1], "source_sizes": {t: [list(s) for s in v] for t, v in native.items()},
                "traversals": {t: [k * n, (k + 1) * n] for k, t in enumerate(TRAVERSALS)},
                "source_names": [found[TRAVERSALS[0]][0].name, found[TRAVERSALS[0]][-1].name],
                "ground_truth": {"file": sequence.DESCRIPTION_NAME, "pairs": "frame k of every traversal "
                                 "with frame k +- tolerance of every later one", "tolerance_frames": tolerance}}
        (tmp / "gardenspoint.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
        (tmp / sequence.DESCRIPTION_NAME).write_text(_description(tolerance))
    return sources.write_folder(out, write)
