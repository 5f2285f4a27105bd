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
"""
from __future__ import annotations

import hashlib
import os
import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from greenloop.util import kernels
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
DEPTH_SCALE = 5000.0  # D435i convention: metres = value / DEPTH_SCALE
TRAJECTORY_NAMES = ("CameraTrajectory.txt",)
GROUND_TRUTH_NAME = "ground_truth.csv"
CAMERA_NAMES = ("camera.yaml", "D435i.yaml")


def _numeric_key(path: Path):
    """Sort key that orders ``2.png`` before ``10.png`` (numbers in the stem compare as ints)."""
    parts = re.split(r"(\d+)", path.stem)
    return [int(p) if p.isdigit() else p for p in parts], path.suffix


def list_frames(folder, subfolder: str = "rgb") -> list[Path]:
    """Image files of a sequence, in numeric capture order.

    folder: a sequence folder (its ``rgb/`` is used) or a folder that holds the images itself.
    Returns a list of paths to .png/.jpg/.jpeg files, ``2.png`` before ``10.png``.
    Raises FileNotFoundError if the folder does not exist and ValueError if it holds no images.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(
            f"sequence folder {folder} does not exist: run `make data` for the real GreenHouse set, "
            f"`make synthetic` for the embedded one, or point DATASET= at a folder of frames")
    root = folder / subfolder if (folder / subfolder).is_dir() else folder
    frames = [p for p in root.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()]
    if not frames:
        raise ValueError(
            f"no .png/.jpg images in {root}: a sequence folder needs {subfolder}/0.png, "
            f"{subfolder}/1.png, ... (or the images directly in the folder)")
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
    INTER_LINEAR when enlarging. ``load_frames`` and ``greenloop.speed.stream`` both call this, so a
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
            # cv2.resize(INTER_AREA), without OpenCV's scalar loop (greenloop.util.kernels.area_shrink)
            small = kernels.area_shrink(img, size) if w > size[0] else None
            if small is not None:
                return small
            interp = cv2.INTER_AREA if w > size[0] else cv2.INTER_LINEAR
            img = cv2.resize(img, (int(size[0]), int(size[1])), interpolation=interp)
    return img


def _read_one(path: Path, size, gray: bool) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"cannot read image {path}: the file is missing, empty or not an image; "
                         f"replace or delete it")
    return preprocess_image(img, size, gray)


def load_frames(folder, size=(32, 32), gray: bool = True, limit: int | None = None,
                progress: bool | None = None, dtype=np.float32, step: int = 1) -> np.ndarray:
    """Load and preprocess the frames of a sequence (the main paper's preprocessing by default).

    folder: sequence folder or folder of images (see ``list_frames``).
    size: (width, height) in pixels to resize to, or None to keep the native size (all frames
        must then share one size).
    gray: grayscale (the paper) or RGB.
    limit: load only the first ``limit`` frames. step: load every ``step``-th frame (0, step, ...),
        applied before ``limit``.
    Returns float32 in [0, 1] of shape (N, H, W, 1) for gray or (N, H, W, 3) RGB for colour
    (``dtype=np.uint8`` returns the raw 0..255 values instead). Decoding runs in parallel threads
    (OpenCV releases the GIL), with a progress bar for loads of more than 200 frames.
    """
    paths = _select(list_frames(folder), limit, step)
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
            it = tqdm(it, total=len(paths), desc=f"load {Path(folder).name}", unit="frame")
        images = list(it)
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
    folder = Path(folder)
    if not (folder / "depth").is_dir():
        raise FileNotFoundError(f"{folder} has no depth/ folder: RGB-D experiments need depth/0.png, ...")
    paths = _select(list_frames(folder, subfolder="depth"), limit, step)

    def read(p):
        d = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if d is None:
            raise ValueError(f"cannot read depth image {p}")
        if size is not None and (d.shape[1], d.shape[0]) != tuple(size):
            d = cv2.resize(d, tuple(size), interpolation=cv2.INTER_NEAREST)
        return d.astype(np.float32) / DEPTH_SCALE

    with ThreadPoolExecutor(4) as pool:
        return np.stack(list(pool.map(read, paths)))


def read_trajectory(path, n_frames: int | None = None):
    """Read a TUM trajectory ``t tx ty tz qx qy qz qw`` (comments with '#' allowed).

    path: the file, or a sequence folder holding ``CameraTrajectory.txt``.
    n_frames: if given, the number of images the poses must match (raises ValueError otherwise).
    Returns (frame_ids (N,) int64, poses (N, 4, 4) float64 camera-to-world homogeneous matrices).
    Quaternion sign is irrelevant (q and -q give the same matrix), so sign flips in the file
    (the real set flips between frames 922 and 987) do no harm here.
    """
    path = Path(path)
    if path.is_dir():
        path = path / TRAJECTORY_NAMES[0]
    if not path.is_file():
        raise FileNotFoundError(f"trajectory {path} not found: a sequence folder needs "
                                f"CameraTrajectory.txt (TUM format) for pose ground truth")
    rows = []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").split()
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            vals = []
        if len(vals) != 8 or not np.all(np.isfinite(vals)):
            raise ValueError(f"{path}:{lineno}: expected 8 numbers `t tx ty tz qx qy qz qw`, got "
                             f"{line[:80]!r}; fix or remove that line")
        rows.append(vals)
    if not rows:
        raise ValueError(f"{path} holds no poses: expected lines `t tx ty tz qx qy qz qw`")
    a = np.asarray(rows)
    q = a[:, 4:8]
    if np.any(np.linalg.norm(q, axis=1) < 1e-9):
        bad = int(np.argmin(np.linalg.norm(q, axis=1)))
        raise ValueError(f"{path}: pose {bad} has a zero quaternion; fix that line")
    poses = np.tile(np.eye(4), (len(a), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(q).as_matrix()  # scalar-last (x, y, z, w), normalises
    poses[:, :3, 3] = a[:, 1:4]
    frame_ids = np.rint(a[:, 0]).astype(np.int64)
    if n_frames is not None and len(frame_ids) != n_frames:
        raise ValueError(f"{path} has {len(frame_ids)} poses but the sequence has {n_frames} frames: "
                         f"use the trajectory that belongs to these images (or trim the frames to match)")
    return frame_ids, poses


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

    path: the file, or a sequence folder holding ``ground_truth.csv``.
    n_frames: if given, every i and j must lie in 0..n_frames-1 (raises ValueError otherwise).
    Returns (P, 3) int64: columns i, j (0-based frame numbers) and tolerance (frames, >= 0; 0
    where the line has no third column), in file order. Raises FileNotFoundError when the file
    is missing and ValueError, naming the line, for a missing header or a malformed line.
    """
    path = Path(path)
    if path.is_dir():
        path = path / GROUND_TRUTH_NAME
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
    choice), 'pairs' (ground_truth.csv), or None."""
    folder = Path(folder)
    if (folder / TRAJECTORY_NAMES[0]).is_file():
        return "poses"
    if (folder / GROUND_TRUTH_NAME).is_file():
        return "pairs"
    return None


def read_camera(path) -> dict:
    """Intrinsics from an ORB-SLAM style yaml (``Camera.fx: 602.897``).

    path: the file, or a sequence folder holding camera.yaml or D435i.yaml.
    Returns {'fx', 'fy', 'cx', 'cy' (pixels, float), 'width', 'height' (int), and
    'depth_scale' (float, default 5000)}.
    """
    path = Path(path)
    if path.is_dir():
        found = [path / n for n in CAMERA_NAMES if (path / n).is_file()]
        if not found:
            raise FileNotFoundError(f"no camera.yaml or D435i.yaml in {path}")
        path = found[0]
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
    paths = list_frames(folder)[:limit]
    h = hashlib.sha1(f"{len(paths)}".encode())
    sample = paths[:: max(1, len(paths) // 16)] + [paths[-1]]
    for p in sample:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    for name in (TRAJECTORY_NAMES[0], GROUND_TRUTH_NAME):
        if (Path(folder) / name).is_file():
            h.update((Path(folder) / name).read_bytes())
    return h.hexdigest()[:12]


def describe(folder) -> dict:
    """What a sequence folder holds: {'path', 'kind', 'n_frames', 'width', 'height', 'depth',
    'trajectory', 'camera', 'ground_truth'}. kind is 'synthetic' when the folder carries the
    generator's ``synthetic.json`` (greenloop.datasets.synthetic), else 'real or user-provided'.
    ground_truth is what ``greenloop.groundtruth.for_sequence`` will use: 'poses'
    (CameraTrajectory.txt), 'pairs' (ground_truth.csv) or None (no ground truth)."""
    folder = Path(folder)
    frames = list_frames(folder)
    img = cv2.imread(str(frames[0]), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"cannot read image {frames[0]}")
    return {"path": str(folder),
            "kind": "synthetic" if (folder / "synthetic.json").is_file() else "real or user-provided",
            "n_frames": len(frames), "width": int(img.shape[1]), "height": int(img.shape[0]),
            "depth": (folder / "depth").is_dir(),
            "trajectory": (folder / TRAJECTORY_NAMES[0]).is_file(),
            "camera": any((folder / n).is_file() for n in CAMERA_NAMES),
            "ground_truth": ground_truth_kind(folder)}
