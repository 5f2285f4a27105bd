"""Ground-truth files in the formats users already have, read as loop pairs (i, j, tolerance).

Each reader returns (P, 3) int64 rows of ``ground_truth.csv`` (greenloop.datasets.sequence:
0-based frame numbers of the stream, tolerance in frames), so a folder holding one of these files
works as if it held ground_truth.csv (``sequence.ground_truth_source`` finds it by name), and
``python -m greenloop import-gt FILE`` writes it as ground_truth.csv. Formats (``FORMATS``):

``vpr-bench``  VPR-Bench's ``ground_truth_new.npy``: an object array, one entry per query image,
               ``[query_index, [reference indices]]`` (or just the list of reference indices,
               entry q for query q). Indices count the images of ``query/`` and ``ref/``
               separately; in the stream the reference frames come first, so query q is frame
               n_reference + q. Read with ``allow_pickle=True`` (the format pickles its lists):
               import files you trust only.
``matrix``     a binary loop matrix, (N, N), nonzero = loop, row/column k = frame k: ``.npy``,
               ``.mat`` (the City Centre / New College loop files of Cummins and Newman: one 2-D
               variable, e.g. ``truth``) or an image (``.png``, ``.bmp``, ``.tif``; any nonzero
               pixel). Only one triangle needs to be filled: loops are symmetric.
``positions``  a CSV with a header: ``lat,lon`` (degrees, WGS84; great-circle distance by the
               haversine formula, Earth radius 6371.0088 km) or ``x,y[,z]`` (metres); frames whose
               positions are at most ``threshold_m`` metres apart are loops. An optional ``frame``
               column gives each row's frame number (default: row k is frame k); other columns
               are ignored.
``pairs``      ground_truth.csv itself (``sequence.read_loop_pairs``).

Imports nothing of greenloop (``sequence`` imports this module).
"""
from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np

FORMATS = {"vpr-bench": "VPR-Bench ground_truth_new.npy", "matrix": "binary loop matrix",
           "positions": "positions / GPS", "pairs": "loop pairs", "aligned": "aligned traversals"}
IMAGE_SUFFIXES = (".png", ".bmp", ".tif", ".tiff", ".pgm")
# names looked for in a sequence folder without ground_truth.csv, in this order
AUTO_NAMES = ("ground_truth_new.npy", "ground_truth.npy", "*GroundTruth.mat", "ground_truth.mat",
              "ground_truth.png", "positions.csv", "gps.csv")
EARTH_RADIUS_M = 6371008.8          # mean Earth radius (IUGG), metres
DEFAULT_THRESHOLD_M = 25.0          # the usual VPR radius (Pittsburgh, Tokyo 24/7, MSLS: 25 m)


def find(folder) -> Path | None:
    """The ground-truth file of another format in ``folder`` (AUTO_NAMES), or None. Raises
    ValueError when several match, naming them and the fix."""
    hits = []
    for pattern in AUTO_NAMES:
        hits += [p for p in sorted(Path(folder).glob(pattern)) if p.is_file() and p not in hits]
    if len(hits) > 1:
        raise ValueError(f"{folder} holds several ground-truth files ({', '.join(p.name for p in hits)}): "
                         f"keep one, or name it in sequence.yaml (`ground_truth: {hits[0].name}`), or "
                         f"write ground_truth.csv with `python -m greenloop import-gt`")
    return hits[0] if hits else None


def detect_format(path) -> str:
    """The format of a ground-truth file from its suffix and first bytes (module doc)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        arr = np.load(path, allow_pickle=True, mmap_mode=None)
        return "vpr-bench" if arr.dtype == object else "matrix"
    if suffix == ".mat" or suffix in IMAGE_SUFFIXES:
        return "matrix"
    if suffix in (".csv", ".txt"):
        header = next((ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")), "")
        cols = [c.strip().lower() for c in header.split(",")]
        if cols[:2] == ["i", "j"]:
            return "pairs"
        if {"lat", "lon"} <= set(cols) or {"latitude", "longitude"} <= set(cols) or {"x", "y"} <= set(cols):
            return "positions"
        raise ValueError(f"{path}:1: cannot tell the format from the header {header[:80]!r}: loop pairs "
                         f"start `i,j[,tolerance]`, positions name columns `lat,lon` or `x,y[,z]`")
    raise ValueError(f"{path}: unknown ground-truth format (suffix {suffix!r}); the formats are "
                     f"{', '.join(f'{k} ({v})' for k, v in FORMATS.items() if k != 'aligned')}")


def read_vpr_bench(path, n_reference: int) -> np.ndarray:
    """VPR-Bench ``ground_truth_new.npy`` -> (P, 3) rows (reference r, n_reference + q, 0).

    n_reference: reference images, which come first in the stream (len of ref/ or reference/).
    Raises ValueError naming the entry for a malformed entry or an index outside the references.
    """
    path = Path(path)
    if n_reference is None:
        raise ValueError(f"{path}: VPR-Bench indices count the query and reference images separately, "
                         f"so the number of reference images is needed: keep the file in a folder with "
                         f"reference/ (or ref/) and query/, or pass --reference-frames N")
    try:
        arr = np.load(path, allow_pickle=True)
    except (ValueError, OSError) as e:
        raise ValueError(f"{path}: not a NumPy .npy file ({e}): VPR-Bench's ground_truth_new.npy "
                         f"holds one [query, [references]] entry per query") from None
    rows = []
    for e, entry in enumerate(arr):
        q, entry = e, (list(entry) if np.ndim(entry) else [entry])
        if len(entry) == 2 and np.ndim(entry[1]) == 1 and np.ndim(entry[0]) == 0:
            q, refs = entry                               # [query index, [reference indices]]
        else:
            refs = entry
        try:
            q, refs = int(q), np.asarray(refs, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise ValueError(f"{path}: entry {e}: expected [query index, [reference "
                             f"indices]] (integers), got {str(entry)[:80]}") from None
        if q < 0 or np.any(refs != np.round(refs)) or np.any((refs < 0) | (refs >= n_reference)):
            raise ValueError(f"{path}: entry {e} (query {q}): indices must be integers, references within "
                             f"0..{n_reference - 1} (the reference images), got {refs[:5].tolist()}")
        rows += [(int(r), n_reference + q, 0) for r in refs]
    return np.asarray(rows, dtype=np.int64).reshape(-1, 3)


def _load_matrix(path: Path) -> np.ndarray:
    """A loop-matrix file as a 2-D array (.npy, .mat or an image)."""
    suffix = path.suffix.lower()
    if suffix == ".mat":
        from scipy.io import loadmat
        try:
            data = loadmat(str(path))
        except (ValueError, OSError, NotImplementedError) as e:
            raise ValueError(f"{path}: cannot read the .mat file ({e}); save it as MATLAB v7 or earlier, "
                             f"or as .npy") from None
        arrays = {k: v for k, v in data.items() if not k.startswith("__") and np.ndim(v) == 2
                  and np.issubdtype(np.asarray(v).dtype, np.number) and min(np.shape(v)) > 1}
        pick = [k for k in ("truth", "GT", "gt", "ground_truth") if k in arrays] or list(arrays)
        if len(pick) != 1:
            raise ValueError(f"{path}: expected one 2-D loop matrix variable (e.g. `truth`), found "
                             f"{sorted(arrays) or 'none'}; save the matrix alone")
        return np.asarray(arrays[pick[0]])
    if suffix in IMAGE_SUFFIXES:
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"{path}: cannot read the image: replace it with a readable .png")
        return img if img.ndim == 2 else img.max(axis=2)
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError) as e:
        raise ValueError(f"{path}: not a numeric .npy loop matrix ({e})") from None


def read_matrix(path, n_frames: int | None = None) -> np.ndarray:
    """A binary loop matrix (N, N), nonzero = loop -> (P, 3) rows (i, j, 0), i < j, each loop once.

    n_frames: if given, N must equal it. Raises ValueError naming the file and the first bad entry
    (not square, not finite).
    """
    path = Path(path)
    m = _load_matrix(path)
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise ValueError(f"{path}: a loop matrix must be square (N, N), one row and column per frame, "
                         f"got shape {m.shape}")
    if n_frames is not None and m.shape[0] != n_frames:
        raise ValueError(f"{path}: the matrix is {m.shape[0]}x{m.shape[0]} but the sequence has {n_frames} "
                         f"frames: use the matrix that belongs to these frames")
    m = np.asarray(m, dtype=np.float64)
    bad = np.argwhere(~np.isfinite(m))
    if len(bad):
        raise ValueError(f"{path}: entry [{bad[0][0]}, {bad[0][1]}] is {m[tuple(bad[0])]}: a loop matrix "
                         f"holds 0 (no loop) or nonzero (loop)")
    nz = m != 0
    i, j = np.nonzero(np.triu(nz | nz.T, 1))
    return np.column_stack([i, j, np.zeros_like(i)]).astype(np.int64).reshape(-1, 3)


def _positions(path: Path) -> tuple[np.ndarray, np.ndarray, bool]:
    """(frames (M,) int, coordinates (M, d) float, geographic) of a positions CSV (module doc)."""
    lines = [(k, ln) for k, ln in enumerate(path.read_text().splitlines(), 1)
             if ln.strip() and not ln.lstrip().startswith("#")]
    if len(lines) < 2:
        raise ValueError(f"{path}: expected a header (`lat,lon` or `x,y[,z]`, optional `frame`) and one "
                         f"position per line")
    k0, header = lines[0]
    cols = [c.strip().lower() for c in next(csv.reader([header]))]
    geo = [c for c in (("lat", "lon"), ("latitude", "longitude")) if set(c) <= set(cols)]
    names = list(geo[0]) if geo else [c for c in ("x", "y", "z") if c in cols]
    if not geo and names[:2] != ["x", "y"]:
        raise ValueError(f"{path}:{k0}: the header must name `lat,lon` (degrees) or `x,y[,z]` "
                         f"(metres), got {header[:80]!r}")
    idx = [cols.index(c) for c in names]
    fcol = cols.index("frame") if "frame" in cols else None
    frames, coords = [], []
    for k, ln in lines[1:]:
        parts = next(csv.reader([ln]))
        try:
            vals = [float(parts[c]) for c in idx]
            frame = int(parts[fcol]) if fcol is not None else len(frames)
        except (ValueError, IndexError):
            vals = None
        if vals is None or not np.all(np.isfinite(vals)) or (geo and not (
                -90 <= vals[0] <= 90 and -180 <= vals[1] <= 180)):
            raise ValueError(f"{path}:{k}: expected numbers for {', '.join(names)}"
                             f"{' (degrees within +-90, +-180)' if geo else ' (metres)'}"
                             f"{' and an integer frame' if fcol is not None else ''}, got {ln[:80]!r}; "
                             f"fix or remove that line")
        frames.append(frame)
        coords.append(vals)
    return np.asarray(frames, dtype=np.int64), np.asarray(coords), bool(geo)


def read_positions(path, threshold_m: float | None = None) -> np.ndarray:
    """Positions or GPS per frame -> (P, 3) rows (i, j, 0), i < j, for frames at most threshold_m
    metres apart (haversine for lat/lon; Euclidean for x, y, z in metres).

    threshold_m: metres (> 0; default DEFAULT_THRESHOLD_M). Raises ValueError naming the line of a
    malformed row.
    """
    from scipy.spatial import cKDTree
    path = Path(path)
    threshold_m = DEFAULT_THRESHOLD_M if threshold_m is None else float(threshold_m)
    if not threshold_m > 0:
        raise ValueError(f"threshold_m must be > 0 metres, got {threshold_m}")
    frames, xyz, geo = _positions(path)
    radius = threshold_m
    if geo:       # points on a sphere: chord length 2 R sin(d / 2R) is monotone in the great-circle d
        lat, lon = np.radians(xyz[:, 0]), np.radians(xyz[:, 1])
        xyz = EARTH_RADIUS_M * np.column_stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon),
                                                np.sin(lat)])
        radius = 2 * EARTH_RADIUS_M * np.sin(min(threshold_m / (2 * EARTH_RADIUS_M), np.pi / 2))
    pairs = cKDTree(xyz).query_pairs(radius * (1 + 1e-12), output_type="ndarray")
    if not len(pairs):
        return np.zeros((0, 3), dtype=np.int64)
    a, b = frames[pairs[:, 0]], frames[pairs[:, 1]]
    keep = a != b
    i, j = np.minimum(a, b)[keep], np.maximum(a, b)[keep]
    order = np.lexsort((j, i))
    return np.column_stack([i[order], j[order], np.zeros(len(order), np.int64)]).astype(np.int64)


def track_length(path) -> float:
    """Length in metres of a positions / GPS file's track, its points in frame order: consecutive
    points' Euclidean distances for x, y[, z] in metres, great-circle (haversine) ones for lat, lon."""
    frames, xyz, geo = _positions(Path(path))
    xyz = np.asarray(xyz, dtype=np.float64)[np.argsort(frames, kind="stable")]
    if not geo:
        return float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum())
    lat, lon = np.radians(xyz[:, 0]), np.radians(xyz[:, 1])
    a = np.sin(np.diff(lat) / 2) ** 2 + np.cos(lat[:-1]) * np.cos(lat[1:]) * np.sin(np.diff(lon) / 2) ** 2
    return float((2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(np.minimum(a, 1.0)))).sum())


def read(path, fmt: str = "auto", n_frames: int | None = None, n_reference: int | None = None,
         threshold_m: float | None = None) -> np.ndarray:
    """Any supported ground-truth file -> (P, 3) int64 loop pairs (i, j, tolerance).

    fmt: 'auto' (detect_format) or a key of FORMATS other than 'aligned'. n_frames: frames of the
    stream (checked: every frame number must lie within). n_reference: reference frames before
    the queries (vpr-bench). threshold_m: metres (positions).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ground-truth file {path} not found")
    fmt = detect_format(path) if fmt in (None, "auto") else fmt
    if fmt == "vpr-bench":
        pairs = read_vpr_bench(path, n_reference)
    elif fmt == "matrix":
        pairs = read_matrix(path, n_frames)
    elif fmt == "positions":
        pairs = read_positions(path, threshold_m)
    elif fmt == "pairs":
        raise ValueError(f"{path} is already a loop-pair file: read it with "
                         f"greenloop.datasets.sequence.read_loop_pairs")
    else:
        raise ValueError(f"unknown ground-truth format {fmt!r}: one of auto, "
                         f"{', '.join(k for k in FORMATS if k not in ('pairs', 'aligned'))}")
    if n_frames is not None and len(pairs) and pairs[:, :2].max() >= n_frames:
        bad = pairs[np.argmax(pairs[:, :2].max(1))]
        raise ValueError(f"{path}: loop ({bad[0]}, {bad[1]}) names a frame beyond the sequence's "
                         f"{n_frames} frames: use the ground truth that belongs to these frames")
    return pairs
