"""Sequence folders: frames, trajectory and camera files (the one data contract of greenloop).

A sequence folder is laid out like the real GreenHouse set::

    rgb/0.png ... rgb/N-1.png   colour frames in capture order (sorted numerically: 2 < 10)
    depth/0.png ...             optional uint16 depth, metres = value / 5000
    CameraTrajectory.txt        optional TUM poses ``t tx ty tz qx qy qz qw`` (t = frame number)
    ground_truth.csv            optional loop pairs, for sequences without poses (below)
    camera.yaml / D435i.yaml    optional intrinsics (``Camera.fx: ...``)

Ground truth comes from the poses when ``CameraTrajectory.txt`` exists, else from
``ground_truth.csv`` (``greenloop.groundtruth.for_sequence`` reads either). That file is a header
line, then one loop pair per line::

    i,j,tolerance
    0,3576,150
    1,3577,150

``i`` and ``j`` are 0-based frame numbers (``rgb/0.png`` is frame 0); the third column is
optional (0 when absent) and in frames: frame ``i`` is a loop with every frame ``j'`` with
``|j' - j| <= tolerance``, and the relation is symmetric. Blank lines and lines starting with
``#`` are skipped.

Two more layouts hold the frames of several traversals of one route (read by the same calls):

    traversals/<name>/*.jpg     one folder per traversal; the stream is the traversals in the
                                order sequence.yaml lists them (else sorted by name), each in
                                numeric order of its file names
    reference/*.jpg, query/*.jpg   place recognition's two sets (``ref/`` also works): the
                                stream is the reference frames, then the query frames

``traversals(folder)`` gives each traversal's name and frame range in the stream,
``traversal_index(folder)`` the traversal of every frame, and ``reference_frames(folder)`` the
(N,) bool mask of the first traversal (the database of place recognition; the others query it).
Loop ground truth may also come from ``sequence.yaml`` (``ground_truth: aligned``: frame k of every
traversal is the same place, +- ``tolerance`` frames) or from a file in another common format
(greenloop.datasets.groundtruth_formats), found in the folder when ground_truth.csv is absent.

``sequence.yaml`` (optional) describes the sequence; :func:`read_description` reads it
(greenloop.datasets.description checks it)::

    exclude: 50           # frames |i - j| <= exclude are never loops (default 150)
    frame_step: 1         # the default step of the notebooks that describe every k-th frame
    frame_rate: 15        # frames per second of the recording (reported only)
    traversals: [day_left, day_right, night_right]   # traversals/ order; for rgb/: {name: [start, stop]}
    ground_truth: aligned # or a file of the folder (ground_truth.csv, ground_truth_new.npy, gps.csv, ...)
    tolerance: 2          # frames, for aligned
    threshold_m: 25       # metres, for a positions / GPS file
    protocol:             # how the detector's targets judge it (absent: the generic targets, no stream)
      targets: gardenspoint                       # generic | nordland | gardenspoint (greenloop.study.targets)
      target_streams:                             # streams the targets are defined on: every frame of
        - traversals: [day_right, night_right]    # these traversals, the first the database, frame k
          tolerance: 2                            # of each one place +- tolerance (default 2) frames;
        - name: every frame, +- 2 frames          # a label (default "day_right -> night_right") and
          traversals: {summer: [0, 3576], winter: [3576, 7152]}   # frame ranges instead of names

One folder, read once: :func:`open` returns a :class:`Sequence` (frames, depth, poses, loop pairs,
traversals, what sequence.yaml says, its protocol), each part read from disk on first use and then
kept; opening the same unchanged folder again returns the same object, an edited one is read anew.
Every function of this module that takes a folder takes a Sequence too and reads through it, and
a Sequence is ``os.PathLike`` (its path), so code written for folders takes it unchanged.
"""
from __future__ import annotations

import copy
import hashlib
import os
import re
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from greenloop.datasets import description as _description, groundtruth_formats as gt_formats
from greenloop.util import numba_kernels
from greenloop.util.checks import positive_int
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
DEPTH_SCALE = 5000.0  # D435i convention: metres = value / DEPTH_SCALE
TRAJECTORY_NAMES = ("CameraTrajectory.txt",)
GROUND_TRUTH_NAME = "ground_truth.csv"
CAMERA_NAMES = ("camera.yaml", "D435i.yaml")
DESCRIPTION_NAME = _description.NAME
TRAVERSALS_DIR = "traversals"
REFERENCE_DIRS = ("reference", "ref")   # place recognition's database (VPR-Bench names it ref/)
QUERY_DIR = "query"
ALIGNED = "aligned"
DESCRIPTION_KEYS = _description.KEYS
PROTOCOL_TARGETS = _description.PROTOCOL_TARGETS   # the target sets a protocol may name (study.targets)
TARGET_TOLERANCE = _description.TARGET_TOLERANCE   # frames: a target stream's default tolerance
MEMO_SIZE = 32                                     # folders open() keeps (the most recently used)


def _numeric_key(path: Path):
    """Sort key that orders ``2.png`` before ``10.png`` (numbers in the stem compare as ints)."""
    parts = re.split(r"(\d+)", path.stem)
    return [int(p) if p.isdigit() else p for p in parts], path.suffix


# ------------------------------------------------------------- what a folder holds, as records
class Traversal(NamedTuple):
    """One traversal of a sequence: frames ``start .. stop - 1`` of the stream."""
    name: str
    start: int
    stop: int


class GroundTruthSource(NamedTuple):
    """Where a folder's ground truth comes from (:func:`ground_truth_source`)."""
    kind: str            # 'poses' or 'pairs'
    path: Path | None    # the file read (None for sequence.yaml's aligned traversals)
    format: str          # 'poses', 'pairs' (ground_truth.csv), 'aligned', or a groundtruth_formats format
    label: str           # one phrase naming it, for printouts


class TargetStream(NamedTuple):
    """One stream the detector's targets are defined on (sequence.yaml's ``protocol.target_streams``):
    every frame of ``traversals`` (Traversal, ... of the sequence, in stream order; the first is the
    place-recognition database), frame k of each the same place as frame k of the others
    +- ``tolerance`` frames. name: its label (targets.csv's protocol column)."""
    name: str
    traversals: tuple
    tolerance: int


class Protocol(NamedTuple):
    """How the detector's targets judge a sequence (sequence.yaml's ``protocol``): targets, the
    target set (one of PROTOCOL_TARGETS, greenloop.study.targets; "generic" where sequence.yaml says
    none); streams, the TargetStreams they are defined on (empty: the leaderboard alone)."""
    targets: str
    streams: tuple


# ------------------------------------------------------------- the Sequence, read once
class Sequence:
    """One sequence folder (module doc), read once: what :func:`open` returns.

    Attributes, each read from disk on first use and then kept (:func:`open` reads all of them but
    the fingerprint): path (Path, as given), name (str), frame_paths (list[Path], stream order),
    n_frames (int), width, height (int, pixels of frame 0), layout (:func:`layout`), description
    (dict: sequence.yaml checked, :func:`read_description`), traversals (list[Traversal]),
    frame_step, tolerance, exclude (int or None: what sequence.yaml says; frames), ground_truth
    (GroundTruthSource or None), has_depth, has_trajectory, has_camera (bool), protocol (Protocol),
    fingerprint (str, 12 hex digits).
    Loaded on demand (arrays, copies of what is kept): :meth:`frames` (N, H, W, 1 | 3) float32 in
    [0, 1]; :meth:`depth` (N, H, W) float32 metres; :meth:`loop_pairs` (P, 3) int64 (i, j,
    tolerance); :meth:`poses` ((N,) int64 frame numbers, (N, 4, 4) float64 camera-to-world, metres);
    :meth:`camera`; :meth:`traversal_index`; :meth:`reference_frames`; :meth:`info`.
    ``os.fspath(seq)`` and ``str(seq)`` are the folder as it was given (``open("data/x/")``:
    "data/x/"), so text that names the folder reads as it did with the path itself.
    """

    def __init__(self, folder):
        self._given = os.fspath(folder)
        self.path = Path(folder)
        self.name = self.path.name
        self._memo: dict = {}

    def __fspath__(self) -> str:
        return self._given

    def __str__(self) -> str:
        return self._given

    def __repr__(self) -> str:
        return f"Sequence({self._given!r})"

    def _once(self, key, compute):
        """compute() the first time ``key`` is asked for, the kept value after."""
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]

    # -- frames and layout
    @cached_property
    def description(self) -> dict:
        return _description.read(self.path)

    @cached_property
    def _dir_images(self) -> list[tuple[str, list[Path]]]:
        """(name, its images in numeric order) of each traversal folder, in stream order ([]: none)."""
        order = self.description["traversals"] if (self.path / TRAVERSALS_DIR).is_dir() else None
        return [(name, _images(d)) for name, d in _traversal_dirs(self.path, order)]

    @cached_property
    def frame_paths(self) -> list[Path]:
        return self._frames_of("rgb")

    @property
    def depth_paths(self) -> list[Path] | None:
        """The depth frames' files (depth/, in stream order, one per frame), None without depth/."""
        return self._frames_of("depth") if self.has_depth else None

    def _frames_of(self, subfolder: str) -> list[Path]:
        return self._once(("frames", subfolder), lambda: _list_frames(self, subfolder))

    @property
    def n_frames(self) -> int:
        return len(self.frame_paths)

    @cached_property
    def _size(self) -> tuple[int, int]:
        img = cv2.imread(str(self.frame_paths[0]), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"cannot read image {self.frame_paths[0]}")
        return int(img.shape[1]), int(img.shape[0])

    @property
    def width(self) -> int:
        return self._size[0]

    @property
    def height(self) -> int:
        return self._size[1]

    @cached_property
    def layout(self) -> str:
        if (self.path / "rgb").is_dir():
            return "rgb"
        if (self.path / TRAVERSALS_DIR).is_dir():
            return "traversals"
        return "reference/query" if _traversal_dirs(self.path, None) else "images"

    @cached_property
    def traversals(self) -> list[Traversal]:
        return _traversals(self)

    # -- what sequence.yaml says, and what the folder holds besides frames
    @property
    def frame_step(self) -> int | None:
        return self.description["frame_step"]

    @property
    def tolerance(self) -> int | None:
        return self.description["tolerance"]

    @property
    def exclude(self) -> int | None:
        return self.description["exclude"]

    @property
    def has_depth(self) -> bool:
        return (self.path / "depth").is_dir()

    @property
    def has_trajectory(self) -> bool:
        return (self.path / TRAJECTORY_NAMES[0]).is_file()

    @property
    def has_camera(self) -> bool:
        return any((self.path / n).is_file() for n in CAMERA_NAMES)

    @cached_property
    def ground_truth(self) -> GroundTruthSource | None:
        return _ground_truth_source(self.path, self.description)

    @cached_property
    def protocol(self) -> Protocol:
        return _protocol(self)

    @cached_property
    def fingerprint(self) -> str:
        return _fingerprint(self, None)

    # -- loaded on demand
    def frames(self, size=(32, 32), gray: bool = True, limit: int | None = None, progress: bool | None = None,
               dtype=np.float32, step: int = 1) -> np.ndarray:
        """The frames, preprocessed: :func:`load_frames` of this sequence."""
        return load_frames(self, size, gray, limit, progress, dtype, step)

    def depth(self, size=None, limit: int | None = None, step: int = 1) -> np.ndarray:
        """Depth in metres (N, H, W) float32: :func:`load_depth` of this sequence."""
        return load_depth(self, size, limit, step)

    def loop_pairs(self) -> np.ndarray:
        """(P, 3) int64 loop pairs (i, j, tolerance) from whichever source the folder has, checked
        against its frames (:func:`read_loop_pairs`)."""
        return self._pairs(self.n_frames)

    def _pairs(self, n_frames: int | None) -> np.ndarray:
        return self._once(("pairs", n_frames), lambda: _folder_pairs(self, n_frames)).copy()

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """(frame_ids (N,) int64, poses (N, 4, 4) float64) of CameraTrajectory.txt, one per frame
        (:func:`read_trajectory`)."""
        return self._poses(self.n_frames)

    def _poses(self, n_frames: int | None) -> tuple[np.ndarray, np.ndarray]:
        ids, poses = self._once(("poses", n_frames), lambda: _read_trajectory_file(
            self.path / TRAJECTORY_NAMES[0], n_frames))
        return ids.copy(), poses.copy()

    def camera(self) -> dict:
        """The intrinsics of camera.yaml / D435i.yaml (:func:`read_camera`)."""
        return dict(self._once("camera", lambda: _read_camera_folder(self.path)))

    def traversal_index(self) -> np.ndarray:
        """(N,) int64: the traversal of every frame, an index into ``traversals`` (-1 for none)."""
        idx = np.full(self.n_frames, -1, dtype=np.int64)
        for k, t in enumerate(self.traversals):
            idx[t.start:t.stop] = k
        return idx

    def reference_frames(self) -> np.ndarray:
        """(N,) bool: the frames of the first traversal, the database of place recognition."""
        return self.traversal_index() == 0

    def info(self) -> dict:
        """What the folder holds: :func:`folder_info`."""
        n, (w, h) = self.n_frames, self._size
        src = self.ground_truth
        return {"path": str(self.path),
                "kind": "synthetic" if (self.path / "synthetic.json").is_file() else "real or user-provided",
                "n_frames": n, "width": w, "height": h,
                "depth": self.has_depth, "trajectory": self.has_trajectory, "camera": self.has_camera,
                "ground_truth": None if src is None else src.kind, "layout": self.layout,
                "traversals": ", ".join(f"{t.name} {t.start}-{t.stop - 1}" for t in self.traversals)}


_OPENED: OrderedDict = OrderedDict()     # {folder as given: (its state, Sequence)}, MEMO_SIZE at most


def open(folder) -> Sequence:  # noqa: A001 (sequence.open, as io.open: the module's one door)
    """The sequence folder ``folder`` (a path or a Sequence) read once, as a :class:`Sequence`.

    Reads the frame list, frame 0's size, sequence.yaml, the traversals, the ground truth's source
    and the protocol now (so a broken folder fails here, with the error that names the fix), the
    rest on first use. Opening the same folder again returns the same object while nothing in it
    changed (:func:`_state`: its entries, their times and sizes, sequence.yaml's text); a Sequence
    passed in is returned as it is. Raises FileNotFoundError for a missing folder and ValueError
    for one without frames or with a malformed sequence.yaml.
    """
    seq = _lookup(folder)
    seq.frame_paths, seq._size, seq.traversals, seq.ground_truth, seq.protocol   # noqa: B018 (read now)
    return seq


def _lookup(folder) -> Sequence:
    """The Sequence of ``folder`` without reading anything yet: a Sequence as it is, the kept one
    while the folder is unchanged, else a new one (kept). A missing folder is never kept."""
    if isinstance(folder, Sequence):
        return folder
    key = os.fspath(folder)
    state = _state(Path(key))
    if state is None:
        return Sequence(key)
    kept_state, seq = _OPENED.get(key, (None, None))
    if seq is None or kept_state != state:
        seq = Sequence(key)
    _OPENED[key] = (state, seq)
    _OPENED.move_to_end(key)
    while len(_OPENED) > MEMO_SIZE:
        _OPENED.popitem(last=False)
    return seq


def _stat(path: Path) -> tuple | None:
    try:
        s = path.stat()
    except OSError:
        return None
    return s.st_ino, s.st_mtime_ns, s.st_size


def _state(folder: Path) -> tuple | None:
    """What says a folder is unchanged (None: no such folder): its resolved path; (inode, mtime,
    size) of it, of every entry at its top (rgb/, depth/, the ground-truth files, ...) and of each
    traversal folder (a frame added or removed changes its folder's time; images at its top count
    through its own time); sequence.yaml's text."""
    if not folder.is_dir():
        return None
    entries = sorted((p.name, _stat(p)) for p in folder.iterdir() if p.suffix.lower() not in IMAGE_SUFFIXES)
    subdirs = [folder / TRAVERSALS_DIR] if (folder / TRAVERSALS_DIR).is_dir() else []
    inner = sorted((p.name, _stat(p)) for d in subdirs for p in d.iterdir())
    text = (folder / DESCRIPTION_NAME).read_bytes() if (folder / DESCRIPTION_NAME).is_file() else None
    return str(folder.resolve()), _stat(folder), tuple(entries), tuple(inner), text


# ------------------------------------------------------------- frames
def list_frames(folder, subfolder: str = "rgb") -> list[Path]:
    """Image files of a sequence, in numeric capture order.

    folder: a sequence folder (its ``rgb/`` is used), a Sequence, or a folder that holds the images itself.
    Returns a list of paths to .png/.jpg/.jpeg files, ``2.png`` before ``10.png``.
    Raises FileNotFoundError if the folder does not exist and ValueError if it holds no images.
    A folder without ``rgb/`` but with ``traversals/`` or ``reference/`` + ``query/`` gives the
    frames of its traversals one after the other (module doc, :func:`traversals`).
    """
    seq = _lookup(folder)
    return list(seq.frame_paths if subfolder == "rgb" else seq._frames_of(subfolder))


def _list_frames(seq: Sequence, subfolder: str) -> list[Path]:
    """:func:`list_frames` read from disk."""
    folder = seq.path
    if not folder.is_dir():
        raise FileNotFoundError(
            f"sequence folder {folder} does not exist: run `make data` for the real GreenHouse set, "
            f"`make synthetic` for the embedded one, or point DATASET= at a folder of frames")
    if subfolder == "rgb" and not (folder / subfolder).is_dir() and seq._dir_images:
        return [p for _, paths in seq._dir_images for p in paths]
    return _images(folder / subfolder if (folder / subfolder).is_dir() else folder, subfolder)


def _images(root: Path, subfolder: str = "rgb") -> list[Path]:
    """The images of one folder in numeric order (ValueError naming the folder when it has none)."""
    frames = [p for p in root.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()]
    if not frames:
        raise ValueError(
            f"no .png/.jpg images in {root}: a sequence folder needs {subfolder}/0.png, "
            f"{subfolder}/1.png, ... (or the images directly in the folder, or traversals/<name>/ "
            f"folders of images)")
    return sorted(frames, key=_numeric_key)


def _select(paths: list, limit, step: int) -> list:
    """Every ``step``-th path, then the first ``limit`` of those."""
    if int(step) != step or step < 1:
        raise ValueError(f"step must be an integer >= 1, got {step}")
    return paths[::int(step)][:limit]


def preprocess_image(img: np.ndarray, size=(32, 32), gray: bool = True, color: str = "bgr") -> np.ndarray:
    """One decoded frame -> the model's input, uint8 (the one preprocessing path of greenloop).

    img: (H, W, 3) uint8 BGR as OpenCV decodes it (``color="rgb"`` for RGB), or (H, W) /
    (H, W, 1) gray. size: (width, height) or None to keep the size. gray: convert to gray with
    OpenCV's cvtColor (else return RGB).
    Returns (h, w) uint8 gray or (h, w, 3) uint8 RGB, resized with INTER_AREA when shrinking and
    INTER_LINEAR when enlarging. ``load_frames`` and ``greenloop.methods.dictionary.stream`` both call this, so a
    frame from disk and the same frame from a live camera give identical model inputs.
    """
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3:
        code = {("bgr", True): cv2.COLOR_BGR2GRAY, ("rgb", True): cv2.COLOR_RGB2GRAY,
                ("bgr", False): cv2.COLOR_BGR2RGB, ("rgb", False): None}[(color, bool(gray))]
        img = img if code is None else cv2.cvtColor(img, code)
    elif not gray:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    if size is not None:
        h, w = img.shape[:2]
        if (w, h) != (int(size[0]), int(size[1])):
            # integer shrink factors of a gray frame (640x480 -> 32x32): the same bytes as
            # cv2.resize(INTER_AREA), without OpenCV's scalar loop (greenloop.util.numba_kernels.area_shrink)
            small = numba_kernels.area_shrink(img, size) if w > size[0] else None
            if small is not None:
                return small
            interp = cv2.INTER_AREA if w > size[0] else cv2.INTER_LINEAR
            img = cv2.resize(img, (int(size[0]), int(size[1])), interpolation=interp)
    return img


def read_image(path) -> np.ndarray:
    """One image file decoded as a camera delivers it: (H, W, 3) uint8 BGR (``cv2.imread``'s
    IMREAD_COLOR; a gray file is repeated into 3 channels). The one decoder of image files
    (greenloop.datasets.recording reads a folder's frames through it). Raises ValueError naming
    an unreadable file."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"cannot read image {path}: the file is missing, empty or not an image; "
                         f"replace or delete it")
    return img


def _read_one(path: Path, size, gray: bool) -> np.ndarray:
    return preprocess_image(read_image(path), size, gray)


def load_frames(folder, size=(32, 32), gray: bool = True, limit: int | None = None,
                progress: bool | None = None, dtype=np.float32, step: int = 1) -> np.ndarray:
    """Load and preprocess the frames of a sequence (the main paper's preprocessing by default).

    folder: sequence folder, Sequence or folder of images (see ``list_frames``).
    size: (width, height) in pixels to resize to, or None to keep the native size (all frames
        must then share one size).
    gray: grayscale (the paper) or RGB.
    limit: load only the first ``limit`` frames. step: load every ``step``-th frame (0, step, ...),
        applied before ``limit``.
    Returns float32 in [0, 1] of shape (N, H, W, 1) for gray or (N, H, W, 3) RGB for colour
    (``dtype=np.uint8`` returns the raw 0..255 values instead). Decoding runs in parallel threads
    (OpenCV releases the GIL), with a progress bar for loads of more than 200 frames.
    """
    seq = _lookup(folder)
    paths = _select(seq.frame_paths, limit, step)
    if limit is not None:
        if limit < 1:
            raise ValueError(f"limit must be >= 1, got {limit}")
    if size is not None:
        size = (int(size[0]), int(size[1]))
        if min(size) < 1:
            raise ValueError(f"size must be positive (width, height), got {size}")
    workers = min(8, (os.cpu_count() or 1) * 2)
    show = len(paths) > 200 if progress is None else progress
    with ThreadPoolExecutor(workers) as pool:
        it = pool.map(lambda p: _read_one(p, size, gray), paths)
        if show:
            it = tqdm(it, total=len(paths), desc=f"load {seq.name}", unit="frame")
        images = list(it)
    return _stacked(images, paths, gray, dtype)


def _stacked(images: list, paths: list, gray: bool, dtype) -> np.ndarray:
    """Decoded frames -> (N, H, W, C) of ``dtype`` (ValueError naming the first frame of another size)."""
    shapes = {im.shape for im in images}
    if len(shapes) > 1:
        first = images[0].shape
        bad, shape = next((p, im.shape) for p, im in zip(paths, images) if im.shape != first)
        raise ValueError(f"frames have mixed sizes: {bad} is {shape} while {paths[0]} is {first}; "
                         f"pass size=(w, h) to resize them all")
    X = np.stack(images)
    if gray:
        X = X[..., None]
    if dtype == np.uint8:
        return X
    return (X.astype(np.float32) / np.float32(255.0)).astype(dtype, copy=False)


def load_depth(folder, size=None, limit: int | None = None, step: int = 1) -> np.ndarray:
    """Depth frames of a sequence in metres, float32 of shape (N, H, W); 0 = no reading.

    Reads ``depth/*.png`` (uint16, metres = value / 5000). Raises FileNotFoundError when the
    sequence has no ``depth/`` folder.
    """
    seq = _lookup(folder)
    if not seq.has_depth:
        raise FileNotFoundError(f"{seq.path} has no depth/ folder: RGB-D experiments need depth/0.png, ...")
    paths = _select(seq._frames_of("depth"), limit, step)
    with ThreadPoolExecutor(4) as pool:
        return np.stack(list(pool.map(lambda p: read_depth(p, size), paths)))


def read_depth(path, size=None) -> np.ndarray:
    """One depth frame (a uint16 PNG, metres = value / DEPTH_SCALE) as (H, W) float32 metres, 0 = no
    reading; resized (nearest) to ``size`` (W, H) when given. ValueError naming an unreadable file."""
    d = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if d is None:
        raise ValueError(f"cannot read depth image {path}: the file is missing, empty or not an image; replace or delete it")
    if size is not None and (d.shape[1], d.shape[0]) != tuple(size):
        d = cv2.resize(d, tuple(size), interpolation=cv2.INTER_NEAREST)
    return d.astype(np.float32) / DEPTH_SCALE


# ------------------------------------------------------------- poses, loop pairs, camera
def read_trajectory(path, n_frames: int | None = None):
    """Read a TUM trajectory ``t tx ty tz qx qy qz qw`` (comments with '#' allowed).

    path: the file, or a sequence folder (or Sequence) holding ``CameraTrajectory.txt`` (read once
        per folder: :func:`open`).
    n_frames: if given, the number of images the poses must match (raises ValueError otherwise).
    Returns (frame_ids (N,) int64, poses (N, 4, 4) float64 camera-to-world homogeneous matrices).
    Quaternion sign is irrelevant (q and -q give the same matrix), so sign flips in the file
    (the real set flips between frames 922 and 987) do no harm here.
    """
    if isinstance(path, Sequence) or Path(path).is_dir():
        return _lookup(path)._poses(n_frames)
    return _read_trajectory_file(Path(path), n_frames)


def _read_trajectory_file(path: Path, n_frames: int | None):
    """:func:`read_trajectory` of one file."""
    if not path.is_file():
        raise FileNotFoundError(f"trajectory {path} not found: a sequence folder needs "
                                f"CameraTrajectory.txt (TUM format) for pose ground truth")
    t, poses = read_tum(path)
    frame_ids = np.rint(t).astype(np.int64)
    if n_frames is not None and len(frame_ids) != n_frames:
        raise ValueError(f"{path} has {len(frame_ids)} poses but the sequence has {n_frames} frames: "
                         f"use the trajectory that belongs to these images (or trim the frames to match)")
    return frame_ids, poses


def number_rows(path, n: int, what: str, expected: str) -> list[list[float]]:
    """The rows of ``n`` finite numbers (commas allowed) of a text file's lines that are neither blank
    nor ``#`` comments: a trajectory's poses (TUM's 8, KITTI's 12). ValueError naming the first bad line
    (``what`` says what its numbers are) or a file without a row (``expected``: the lines it should hold)."""
    rows = []
    for lineno, line in enumerate(Path(path).read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            vals = [float(v) for v in line.replace(",", " ").split()]
        except ValueError:
            vals = []
        if len(vals) != n or not np.all(np.isfinite(vals)):
            raise ValueError(f"{path}:{lineno}: expected {n} numbers {what}, got {line[:80]!r}; fix or remove that line")
        rows.append(vals)
    if not rows:
        raise ValueError(f"{path} holds no poses: expected {expected}")
    return rows


def read_tum(path) -> tuple[np.ndarray, np.ndarray]:
    """A TUM trajectory file ``t tx ty tz qx qy qz qw`` (``#`` comments, commas allowed), as written:
    (t (N,) float64 as in the file (seconds, or frame numbers in CameraTrajectory.txt), poses
    (N, 4, 4) float64 homogeneous, translation in the file's unit). ValueError naming a bad line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"trajectory {path} not found: give a TUM file `t tx ty tz qx qy qz qw`")
    rows = number_rows(path, 8, "`t tx ty tz qx qy qz qw`", "lines `t tx ty tz qx qy qz qw`")
    a = np.asarray(rows)
    q = a[:, 4:8]
    if np.any(np.linalg.norm(q, axis=1) < 1e-9):
        bad = int(np.argmin(np.linalg.norm(q, axis=1)))
        raise ValueError(f"{path}: pose {bad} has a zero quaternion; fix that line")
    poses = np.tile(np.eye(4), (len(a), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(q).as_matrix()  # scalar-last (x, y, z, w), normalises
    poses[:, :3, 3] = a[:, 1:4]
    return a[:, 0].copy(), poses


def write_trajectory(path, frame_ids, poses) -> None:
    """Write (N,) frame ids and (N, 4, 4) camera-to-world poses as a TUM trajectory file."""
    q = Rotation.from_matrix(np.asarray(poses)[:, :3, :3]).as_quat(canonical=True)
    t = np.asarray(poses)[:, :3, 3]
    lines = [f"{float(i):.6f} {x:.9f} {y:.9f} {z:.9f} {a:.9f} {b:.9f} {c:.9f} {d:.9f}"
             for i, (x, y, z), (a, b, c, d) in zip(frame_ids, t, q)]
    Path(path).write_text("\n".join(lines) + "\n")


def _pair_fields(path: Path, lineno: int, line: str) -> list[int]:
    """One data line of ground_truth.csv -> [i, j, tolerance] (ValueError naming the line)."""
    parts = [p.strip() for p in line.split(",")]
    try:
        vals = [int(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) not in (2, 3):
        raise ValueError(f"{path}:{lineno}: expected `i,j` or `i,j,tolerance` (integer frame "
                         f"numbers), got {line[:80]!r}; fix or remove that line")
    if len(vals) == 3 and vals[2] < 0:
        raise ValueError(f"{path}:{lineno}: tolerance must be >= 0 frames, got {vals[2]}; "
                         f"fix that line")
    return vals + [0] * (3 - len(vals))


def read_loop_pairs(path, n_frames: int | None = None) -> np.ndarray:
    """Read ``ground_truth.csv``: a header line, then ``i,j[,tolerance]`` per line (module doc).

    path: the file, or a sequence folder (or Sequence): its loop pairs from whichever source it
        has (:func:`ground_truth_source`: ground_truth.csv, sequence.yaml's aligned traversals, or
        a file in another format), read once per folder (:func:`open`).
    n_frames: if given, every i and j must lie in 0..n_frames-1 (raises ValueError otherwise).
    Returns (P, 3) int64: columns i, j (0-based frame numbers) and tolerance (frames, >= 0; 0
    where the line has no third column), in file order. Raises FileNotFoundError when the file
    is missing and ValueError, naming the line, for a missing header or a malformed line.
    """
    if isinstance(path, Sequence) or Path(path).is_dir():
        return _lookup(path)._pairs(n_frames)
    return _read_pairs_file(Path(path), n_frames)


def _read_pairs_file(path: Path, n_frames: int | None) -> np.ndarray:
    """:func:`read_loop_pairs` of one file."""
    if not path.is_file():
        raise FileNotFoundError(f"loop-pair file {path} not found: a sequence folder without poses "
                                f"needs {GROUND_TRUTH_NAME} (header, then `i,j[,tolerance]` lines)")
    lines = [(k, ln.strip()) for k, ln in enumerate(path.read_text().splitlines(), 1)]
    lines = [(k, ln) for k, ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise ValueError(f"{path} is empty: write the header `i,j,tolerance`, then one pair a line")
    k, header = lines[0]
    if header.split(",")[0].strip().lstrip("+-").isdigit():
        raise ValueError(f"{path}:{k}: the first line must be the header `i,j,tolerance` (or "
                         f"`i,j`), got the numbers {header[:80]!r}; add the header line")
    rows = [_pair_fields(path, k, ln) for k, ln in lines[1:]]
    pairs = np.asarray(rows, dtype=np.int64).reshape(-1, 3)
    if n_frames is not None and len(pairs):
        bad = np.flatnonzero((pairs[:, :2] < 0).any(1) | (pairs[:, :2] >= n_frames).any(1))
        if bad.size:
            k, ln = lines[1 + int(bad[0])]
            raise ValueError(f"{path}:{k}: pair {ln!r} is outside the sequence's frames 0..{n_frames - 1} "
                             f"({len(bad)} such lines): frame numbers are 0-based (rgb/0.png is "
                             f"frame 0) and must name frames that exist")
    return pairs


def write_loop_pairs(path, pairs) -> Path:
    """Write ``ground_truth.csv``: the header ``i,j,tolerance`` and one line per row of pairs.

    pairs: (P, 2) or (P, 3) integers (i, j[, tolerance]); a missing tolerance is written as 0.
    Returns the path written.
    """
    a = np.asarray(pairs, dtype=np.int64)
    if a.ndim != 2 or a.shape[1] not in (2, 3):
        raise ValueError(f"pairs must have shape (P, 2) or (P, 3), got {a.shape}")
    if a.shape[1] == 2:
        a = np.column_stack([a, np.zeros(len(a), np.int64)])
    if (a[:, 2] < 0).any():
        raise ValueError("tolerances must be >= 0 frames")
    path = Path(path)
    path.write_text("i,j,tolerance\n" + "".join(f"{i},{j},{t}\n" for i, j, t in a))
    return path


def ground_truth_kind(folder) -> str | None:
    """Which ground truth a sequence folder carries: 'poses' (CameraTrajectory.txt, the first
    choice), 'pairs' (loop pairs: ground_truth.csv, sequence.yaml's aligned traversals or a file
    in another format, :func:`ground_truth_source`), or None."""
    src = _lookup(folder).ground_truth
    return None if src is None else src.kind


def read_camera(path) -> dict:
    """Intrinsics from an ORB-SLAM style yaml (``Camera.fx: 602.897``).

    path: the file, or a sequence folder (or Sequence) holding camera.yaml or D435i.yaml.
    Returns {'fx', 'fy', 'cx', 'cy' (pixels, float), 'width', 'height' (int), and
    'depth_scale' (float, default 5000)}.
    """
    if isinstance(path, Sequence) or Path(path).is_dir():
        return _lookup(path).camera()
    return _read_camera_file(Path(path))


def _read_camera_folder(folder: Path) -> dict:
    found = [folder / n for n in CAMERA_NAMES if (folder / n).is_file()]
    if not found:
        raise FileNotFoundError(f"no camera.yaml or D435i.yaml in {folder}")
    return _read_camera_file(found[0])


def _read_camera_file(path: Path) -> dict:
    if not path.is_file():
        raise FileNotFoundError(f"camera file {path} not found")
    vals = {}
    for line in path.read_text().splitlines():
        m = re.match(r"\s*(?:Camera\.)?(\w+)\s*:\s*([-+0-9.eE]+)\s*(?:#.*)?$", line)
        if m:
            vals[m.group(1)] = float(m.group(2))
    missing = [k for k in ("fx", "fy", "cx", "cy", "width", "height") if k not in vals]
    if missing:
        raise ValueError(f"{path} lacks {', '.join('Camera.' + k for k in missing)}")
    cam = {k: vals[k] for k in ("fx", "fy", "cx", "cy")}
    cam["width"], cam["height"] = int(vals["width"]), int(vals["height"])
    cam["depth_scale"] = vals.get("DepthMapFactor", DEPTH_SCALE)
    return cam


def fingerprint(folder, limit: int | None = None) -> str:
    """Short content hash of a sequence (names, sizes and mtimes-free bytes of the first/last
    frames plus the frame count, trajectory and loop-pair file), stable across copies of the same
    data.

    Returns a 12-character hex string used to key caches and results manifests.
    """
    seq = _lookup(folder)
    return seq.fingerprint if limit is None else seq._once(("fingerprint", limit), lambda: _fingerprint(seq, limit))


def _fingerprint(seq: Sequence, limit: int | None) -> str:
    """:func:`fingerprint` computed."""
    paths = seq.frame_paths[:limit]
    h = hashlib.sha1(f"{len(paths)}".encode())
    sample = paths[:: max(1, len(paths) // 16)] + [paths[-1]]
    for p in sample:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    for name in (TRAJECTORY_NAMES[0], GROUND_TRUTH_NAME):
        if (seq.path / name).is_file():
            h.update((seq.path / name).read_bytes())
    src = seq.ground_truth                     # a ground truth in another format, sequence.yaml
    extra = [src.path] if src is not None and src.path is not None and src.path.name not in (
        TRAJECTORY_NAMES[0], GROUND_TRUTH_NAME) else []
    for path in extra + [seq.path / DESCRIPTION_NAME]:
        if path.is_file():
            h.update(path.read_bytes())
    return h.hexdigest()[:12]


def folder_info(folder) -> dict:
    """What a sequence folder holds: {'path', 'kind', 'n_frames', 'width', 'height', 'depth',
    'trajectory', 'camera', 'ground_truth', 'layout', 'traversals'}. layout as :func:`layout`;
    traversals: "name start-stop, ..." (:func:`traversals`). kind is 'synthetic' when the folder carries the
    generator's ``synthetic.json`` (greenloop.datasets.synthetic), else 'real or user-provided'.
    ground_truth is what ``greenloop.groundtruth.for_sequence`` will use: 'poses'
    (CameraTrajectory.txt), 'pairs' (ground_truth.csv) or None (no ground truth)."""
    return _lookup(folder).info()


# ------------------------------------------------------------- sequence.yaml and traversals
def read_description(folder) -> dict:
    """``sequence.yaml`` of a sequence folder (module doc), checked: {key: value or None} for every
    key of DESCRIPTION_KEYS (None where the file or the key is absent).

    exclude: int >= 0 frames; frame_step: int >= 1; frame_rate: float > 0 frames/s; traversals: a
    list of names (traversals/ layout) or {name: [start, stop]} (an rgb/ stream); ground_truth:
    "aligned" or a file name in the folder; tolerance: int >= 0 frames; threshold_m: float > 0
    metres; ground_truth_format: a format of greenloop.datasets.groundtruth_formats; protocol:
    {"targets", "target_streams"} as written (:attr:`Sequence.protocol` resolves it).
    Raises ValueError naming the file and the key for unknown keys or bad values
    (greenloop.datasets.description).
    """
    return copy.deepcopy(_lookup(folder).description)


def _traversal_dirs(folder: Path, order) -> list[tuple[str, Path]]:
    """(name, folder) of each traversal of a traversals/ or reference/ + query/ layout, in stream
    order (``order``: sequence.yaml's traversals, read only for a traversals/ layout); [] for
    another layout."""
    if (folder / TRAVERSALS_DIR).is_dir():
        found = {p.name: p for p in (folder / TRAVERSALS_DIR).iterdir() if p.is_dir()}
        if isinstance(order, list):
            missing = [n for n in order if n not in found]
            if missing:
                raise ValueError(f"{folder / DESCRIPTION_NAME} lists traversals {missing} that are not "
                                 f"folders of {folder / TRAVERSALS_DIR} (it has {sorted(found)})")
            return [(n, found[n]) for n in order]
        return [(n, found[n]) for n in sorted(found, key=lambda n: _numeric_key(Path(n)))]
    ref = next((folder / r for r in REFERENCE_DIRS if (folder / r).is_dir()), None)
    if ref is not None and (folder / QUERY_DIR).is_dir():
        return [("reference", ref), ("query", folder / QUERY_DIR)]
    return []


def layout(folder) -> str:
    """How a folder holds its frames: 'rgb' (rgb/), 'traversals' (traversals/<name>/),
    'reference/query' or 'images' (the images directly in the folder)."""
    return _lookup(folder).layout


def traversals(folder) -> list[Traversal]:
    """The traversals of a sequence, in stream order: [Traversal(name, start, stop)], frames
    start .. stop - 1 of ``list_frames(folder)``.

    traversals/ or reference/ + query/: one per folder. rgb/ (or images): sequence.yaml's
    ``traversals: {name: [start, stop]}`` (sorted by start, non-overlapping, within the frames;
    frames outside every range belong to none), else one traversal 'all' of every frame.
    """
    return list(_lookup(folder).traversals)


def _traversals(seq: Sequence) -> list[Traversal]:
    """:func:`traversals` read from the folder and its sequence.yaml."""
    dirs = seq._dir_images if not (seq.path / "rgb").is_dir() else []
    out, start = [], 0
    for name, paths in dirs:
        out.append(Traversal(name, start, start + len(paths)))
        start += len(paths)
    if out:
        return out
    n = seq.n_frames
    spec = seq.description["traversals"]
    if not isinstance(spec, dict):
        return [Traversal("all", 0, n)]
    ranges = sorted((int(a), int(b), str(k)) for k, (a, b) in spec.items())
    for (a, b, k), nxt in zip(ranges, ranges[1:] + [(n, n, "")]):
        if not 0 <= a < b <= min(nxt[0], n):
            raise ValueError(f"{seq.path / DESCRIPTION_NAME}: traversal {k}: [{a}, {b}] must be a "
                             f"non-empty range [start, stop) within the {n} frames, not overlapping "
                             f"the next one")
    return [Traversal(k, a, b) for a, b, k in ranges]


def traversal_index(folder) -> np.ndarray:
    """(N,) int64: the traversal of every frame of the stream, an index into ``traversals(folder)``
    (-1 for a frame of none)."""
    return _lookup(folder).traversal_index()


def reference_frames(folder) -> np.ndarray:
    """(N,) bool: the frames of the first traversal (reference/ in that layout), the database of
    place recognition; the frames of the other traversals are its queries."""
    return _lookup(folder).reference_frames()


# ------------------------------------------------------------- the protocol of sequence.yaml
def _protocol(seq: Sequence) -> Protocol:
    """sequence.yaml's protocol resolved against the sequence (module doc; "generic" and no stream
    where it says none). Raises ValueError naming the key and the fix."""
    p = seq.description["protocol"]
    if p is None:
        return Protocol("generic", ())
    where = f"{seq.path / DESCRIPTION_NAME}: protocol: target_streams"
    return Protocol(p["targets"], tuple(_target_stream(seq, s, f"{where}[{k}]")
                                        for k, s in enumerate(p["target_streams"])))


def _target_stream(seq: Sequence, spec: dict, where: str) -> TargetStream:
    """One target stream of sequence.yaml's protocol, its traversals those of ``seq`` it names or
    the frame ranges it gives; checked: in stream order, not overlapping, of one length."""
    t = spec["traversals"]
    if isinstance(t, list):
        known = {x.name: x for x in seq.traversals}
        missing = [n for n in t if n not in known]
        if missing:
            raise ValueError(f"{where}: traversals {missing} are not traversals of {seq.path} (it has "
                             f"{', '.join(known)}): fix the names, or give frame ranges {{name: [start, stop]}}")
        ts = [known[n] for n in t]
    else:
        ts = [Traversal(str(k), int(a), int(b)) for k, (a, b) in t.items()]
    for a, b in zip(ts, ts[1:] + [Traversal("", seq.n_frames, seq.n_frames)]):
        if not 0 <= a.start < a.stop <= b.start:
            raise ValueError(f"{where}: traversal {a.name} [{a.start}, {a.stop}) must be a non-empty range of the "
                             f"{seq.n_frames} frames, before the next one named (stream order, no overlap): fix it")
    if len({x.stop - x.start for x in ts}) != 1:
        raise ValueError(f"{where}: traversals {[x.name for x in ts]} must be of one length (frame k of each "
                         f"is one place), got {[x.stop - x.start for x in ts]} frames: fix the ranges")
    name = spec["name"] or " -> ".join(x.name for x in ts)
    return TargetStream(name, tuple(ts), TARGET_TOLERANCE if spec["tolerance"] is None else spec["tolerance"])


# ------------------------------------------------------------- ground truth
def aligned_pairs(ranges, tolerance: int = 0) -> np.ndarray:
    """Loop pairs of traversals aligned frame by frame: frame k of traversal a is the same place
    as frame k of every later traversal b, +- ``tolerance`` frames, the window clipped to b.

    ranges: [(start, stop)] of each traversal in the stream (e.g. ``traversals(folder)``), all of
        one length n. tolerance: frames (>= 0).
    Returns (P, 3) int64 ground_truth.csv rows (i, j, tolerance): for each a < b and k, the window
    [s_b + k - tolerance, s_b + k + tolerance] cut to frames of b, as its centre and half-width
    (plus its last frame alone when its length is even); a window left whole (or running past the
    stream's last frame, where there are no frames) is the row (s_a + k, s_b + k, tolerance).
    """
    tolerance = positive_int("tolerance", tolerance, 0, unit="frames")
    ranges = [(int(r[-2]), int(r[-1])) for r in ranges]      # Traversal(name, start, stop) or (start, stop)
    lengths = {b - a for a, b in ranges}
    if len(lengths) != 1:
        raise ValueError(f"aligned ground truth needs traversals of one length (frame k of each is "
                         f"one place), got lengths {[b - a for a, b in ranges]}: give the ground "
                         f"truth as a file instead (ground_truth.csv, or import one)")
    n, last = lengths.pop(), max(b for _, b in ranges)
    rows = []
    for ia, (sa, _) in enumerate(ranges):
        for sb, eb in ranges[ia + 1:]:
            for k in range(n):
                c, lo, hi = sb + k, sb + k - tolerance, sb + k + tolerance
                if lo >= sb and (hi < eb or eb == last):
                    rows.append((sa + k, c, tolerance))
                    continue
                lo, hi = max(lo, sb), min(hi, eb - 1)
                half = (hi - lo) // 2
                rows.append((sa + k, lo + half, half))
                if (hi - lo) % 2:
                    rows.append((sa + k, hi, 0))
    return np.asarray(rows, dtype=np.int64).reshape(-1, 3)


def ground_truth_source(folder) -> GroundTruthSource | None:
    """The ground truth of a folder, first found: CameraTrajectory.txt (poses); sequence.yaml's
    ``ground_truth`` (``aligned`` or a file); ground_truth.csv; a file in another format found by
    name (greenloop.datasets.groundtruth_formats.find). None when there is none."""
    return _lookup(folder).ground_truth


def _ground_truth_source(folder: Path, d: dict) -> GroundTruthSource | None:
    """:func:`ground_truth_source` of a folder whose sequence.yaml says ``d``."""
    if (folder / TRAJECTORY_NAMES[0]).is_file():
        return GroundTruthSource("poses", folder / TRAJECTORY_NAMES[0], "poses", TRAJECTORY_NAMES[0])
    if d["ground_truth"] == ALIGNED:
        return GroundTruthSource("pairs", None, ALIGNED, f"{DESCRIPTION_NAME}: traversals aligned frame "
                                 f"by frame, tolerance {d['tolerance'] or 0} frames")
    path = folder / d["ground_truth"] if d["ground_truth"] else folder / GROUND_TRUTH_NAME
    if d["ground_truth"] and not path.is_file():
        raise FileNotFoundError(f"{folder / DESCRIPTION_NAME} names ground_truth: {d['ground_truth']}, "
                                f"which is not a file of {folder}: fix the name or add the file")
    if not path.is_file():
        path = gt_formats.find(folder)
        if path is None:
            return None
    fmt = d["ground_truth_format"] or ("pairs" if path.name == GROUND_TRUTH_NAME
                                       else gt_formats.detect_format(path))
    label = path.name if fmt == "pairs" else f"{path.name} ({gt_formats.FORMATS.get(fmt, fmt)})"
    return GroundTruthSource("pairs", path, fmt, label)


def _folder_pairs(seq: Sequence, n_frames: int | None) -> np.ndarray:
    """The loop pairs of a folder from whichever source it has (ground_truth_source)."""
    src = seq.ground_truth
    if src is None or src.kind != "pairs":
        raise FileNotFoundError(f"{seq.path} has no loop pairs: add {GROUND_TRUTH_NAME} (header, then "
                                f"`i,j[,tolerance]` lines), `ground_truth: aligned` in {DESCRIPTION_NAME}, "
                                f"or import a file with `python -m greenloop import-gt`")
    if src.format == "pairs":
        return _read_pairs_file(src.path, n_frames)
    d = seq.description
    if src.format == ALIGNED:
        return aligned_pairs(seq.traversals, d["tolerance"] or 0)
    n_ref = seq.traversals[0].stop if seq.layout in ("traversals", "reference/query") else None
    return gt_formats.read(src.path, src.format, n_frames=n_frames, n_reference=n_ref,
                           threshold_m=d["threshold_m"])
