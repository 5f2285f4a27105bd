"""Recordings a new user could bring, cut from the real sets beside the repository (../shared/real)
and from the synthetic generator: short, loop pairs only, GPS only, no revisit. Used by
tests/test_user_folders.py; also by hand, to try ``make quick DATASET=...`` as a stranger would:

    PYTHONPATH=. .venv/bin/python -c "from tests import user_folders as u; u.gardenspoint_pairs('/tmp/gp')"
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from greenloop.datasets import sequence

REAL = Path(__file__).resolve().parents[2] / "shared" / "real"


def _write(folder: Path, images) -> Path:
    (folder / "rgb").mkdir(parents=True, exist_ok=True)
    for k, img in enumerate(images):
        cv2.imwrite(str(folder / "rgb" / f"{k}.jpg"), img)
    return folder


def gardenspoint_pairs(out, n: int = 100, src=REAL / "gardenspoint", start: int = 0,
                       traversals=("day_right", "night_right")) -> Path:
    """Gardens Point ``traversals[0]`` frames start..start+n-1 then the same places of ``traversals[1]``
    (default day_right then night_right; 640x360), loop pairs only (k, n + k, tolerance 2) in
    ground_truth.csv: a short recording driven twice, day then night (day_left: also from the
    other side of the path)."""
    out, src = Path(out), Path(src)
    if not (src / "night_right").is_dir():
        raise FileNotFoundError(f"Gardens Point not found at {src}")
    imgs = [cv2.resize(cv2.imread(str(src / t / f"Image{start + k:03d}.jpg")), (640, 360))
            for t in traversals for k in range(n)]
    _write(out, imgs)
    sequence.write_loop_pairs(out / sequence.GROUND_TRUTH_NAME, [(k, n + k, 2) for k in range(n)])
    return out


def nordland_short(out, n: int = 80, start: int = 1000, src=REAL / "nordland") -> Path:
    """Nordland summer frames start..start+n-1 then the same places in winter (64x32), loop pairs
    (k, n + k, tolerance 2): 2n frames, revisits n frames apart."""
    out, src = Path(out), Path(src)
    if not (src / "winter").is_dir():
        raise FileNotFoundError(f"Nordland not found at {src}")
    name = "images-{:05d}.png"
    imgs = [cv2.imread(str(src / s / name.format(10 * (start + k + 1)))) for s in ("summer", "winter") for k in range(n)]
    _write(out, imgs)
    sequence.write_loop_pairs(out / sequence.GROUND_TRUTH_NAME, [(k, n + k, 2) for k in range(n)])
    return out


def synthetic_gps(out, synthetic_folder) -> Path:
    """A synthetic sequence's frames with its poses replaced by positions only (positions.csv
    ``frame,x,y,z``, as GPS gives them; no CameraTrajectory.txt, no depth) and sequence.yaml's
    threshold_m 0.5: ground truth from positions alone."""
    out, src = Path(out), Path(synthetic_folder)
    paths = sequence.list_frames(src)
    _write(out, [cv2.imread(str(p)) for p in paths])
    _, poses = sequence.read_trajectory(src, n_frames=len(paths))
    rows = "".join(f"{k},{x:.4f},{y:.4f},{z:.4f}\n" for k, (x, y, z) in enumerate(poses[:, :3, 3]))
    (out / "positions.csv").write_text("frame,x,y,z\n" + rows)
    (out / sequence.DESCRIPTION_NAME).write_text("threshold_m: 0.5\n")
    return out


def no_revisit(out, synthetic_folder, n: int = 120) -> Path:
    """The first n frames of a synthetic sequence, no ground truth at all: a drive that never
    comes back."""
    paths = sequence.list_frames(synthetic_folder)[:n]
    return _write(Path(out), [cv2.imread(str(p)) for p in paths])


def gps_survey(out, strips: int = 6, strip_frames: int = 13, size=(64, 48), seed: int = 0) -> Path:
    """A drone survey of a field flown twice, the second time in reverse, with a ``gps.csv``
    (``frame,x,y`` in metres) and nothing else: ``strips`` lawnmower strips of ``strip_frames`` frames,
    10 m between frames and 20 m between strips (within the 25 m GPS radius, so neighbouring strips
    revisit each other early, as an overlapping survey does). 2 * strips * strip_frames frames (156 by
    default), revisits 1..155 frames apart; each frame a ``size`` (W, H) crop of one smooth random
    field at its position, so a place looks the same on both flights."""
    out = Path(out)
    xy = [(10.0 * (k if s % 2 == 0 else strip_frames - 1 - k), 20.0 * s)
          for s in range(strips) for k in range(strip_frames)]
    xy = np.asarray(xy + xy[::-1])
    w, h = size
    rng = np.random.default_rng(seed)
    field = cv2.GaussianBlur(rng.integers(0, 256, (int(xy[:, 1].max()) + 2 * h, int(xy[:, 0].max()) + 2 * w, 3),
                                          dtype=np.uint8), (0, 0), 3)
    field = cv2.normalize(field, None, 0, 255, cv2.NORM_MINMAX)
    _write(out, [field[int(y):int(y) + h, int(x):int(x) + w] for x, y in xy])
    rows = "".join(f"{k},{x:.1f},{y:.1f}\n" for k, (x, y) in enumerate(xy))
    (out / "gps.csv").write_text("frame,x,y\n" + rows)
    return out
