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
    sequence.yaml                  only the detector targets' protocol (:func:`description`):
                                   Nordland's target set, on every frame, summer then winter,
                                   +- TARGET_TOLERANCE frames (not the traversals themselves, which
                                   would make every notebook's first_traversal_end)

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

Run ``make nordland`` or ``python -m greenloop data nordland data/nordland [--src FOLDER]``; without
``--src`` the source is cloned (``git clone --depth 1``) into a temporary folder. ``--describe``
rewrites only the sequence.yaml of a folder built before, from its nordland.json.
"""
from __future__ import annotations

import json
import shutil
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from greenloop.datasets import sequence, sources
from greenloop.util.files import write_atomic
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

SOURCE_URL = "https://github.com/TimQuelch/seqslam"
SOURCE_SUBDIR = "datasets/nordland_trimmed"
SEASONS = ("summer", "winter")
SAMPLE_STEP = 10        # the sample's rows cover every SAMPLE_STEP-th image (358 = ceil(3576 / 10))
SAMPLE_TOLERANCE = 15   # the tolerance column of the source's sample ground truth
TOLERANCE = SAMPLE_TOLERANCE   # default: read as frames of these images (module doc)
TARGET_TOLERANCE = sequence.TARGET_TOLERANCE   # frames: the targets' stream, frame k of each season +- 2
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
    seasons = sources.aligned_traversals(source_folder(src), SEASONS, FIX)
    summer, winter = seasons["summer"], seasons["winter"]
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


def traversals(folder) -> list:
    """The two seasons of a built Nordland folder as ``sequence.Traversal(name, start, stop)``, in
    stream order, from its nordland.json (summer [0, n), winter [n, 2n))."""
    meta = json.loads((Path(folder) / "nordland.json").read_text())
    return sorted((sequence.Traversal(k, int(a), int(b)) for k, (a, b) in meta["traversals"].items()),
                  key=lambda t: t.start)


def description(n: int) -> str:
    """The sequence.yaml of a Nordland folder of two seasons of n frames: the detector targets'
    protocol only (greenloop.datasets.description): Nordland's target set, on one stream of every
    frame, summer [0, n) then winter [n, 2n), frame k of each the same place +- TARGET_TOLERANCE."""
    return (f"# Nordland (greenloop.datasets.nordland): summer frames 0..{n - 1}, then winter {n}..{2 * n - 1}; the\n"
            f"# ground truth is ground_truth.csv. How the detector's targets judge it (greenloop.study.targets):\n"
            f"# Nordland's set, on every frame at the full rate, frame k of each season one place +- {TARGET_TOLERANCE}.\n"
            f"protocol:\n"
            f"  targets: nordland\n"
            f"  target_streams:\n"
            f"    - name: every frame, +- {TARGET_TOLERANCE} frames\n"
            f"      traversals: {{summer: [0, {n}], winter: [{n}, {2 * n}]}}\n"
            f"      tolerance: {TARGET_TOLERANCE}\n")


def describe(out) -> Path:
    """Rewrite the sequence.yaml of a built Nordland folder ``out`` (:func:`description`) from its
    nordland.json; frames and ground truth untouched. Returns the file's path."""
    meta = json.loads((Path(out) / "nordland.json").read_text())
    return write_atomic(Path(out) / sequence.DESCRIPTION_NAME, description(int(meta["frames_per_season"])))


def _write(tmp: Path, summer, winter, tolerance: int, meta: dict, progress: bool) -> None:
    """Copy the frames (summer then winter) and write ground_truth.csv, nordland.json and sequence.yaml."""
    (tmp / "rgb").mkdir(parents=True)
    frames = summer + winter
    for k, p in enumerate(tqdm(frames, desc="nordland", unit="frame", disable=not progress)):
        shutil.copyfile(p, tmp / "rgb" / f"{k}{p.suffix.lower()}")
    n = len(summer)
    sequence.write_loop_pairs(tmp / sequence.GROUND_TRUTH_NAME, alignment_pairs(n, tolerance))
    (tmp / "nordland.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    (tmp / sequence.DESCRIPTION_NAME).write_text(description(n))


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
    out = sources.check_output(out, tolerance, overwrite)
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
    return sources.write_folder(out, lambda tmp: _write(tmp, summer, winter, tolerance, meta, progress))


def clone_source(dest, url: str = SOURCE_URL, timeout: float = 20.0,
                 clone_timeout: float = 1800.0) -> Path:
    """``git clone --depth 1 url dest`` (:func:`greenloop.datasets.sources.shallow_clone`); returns the source folder inside
    it. Raises RuntimeError with the fix (NORDLAND_SRC=path) when the clone fails."""
    return source_folder(sources.shallow_clone(dest, url, FIX, "Nordland", timeout, clone_timeout))
