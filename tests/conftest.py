"""Shared fixtures: small sequence folders made on the fly (nothing downloaded)."""
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "greenhouse"


@pytest.fixture(scope="session")
def real_trajectory():
    """The real GreenHouse trajectory from ../shared/greenhouse (skipped where absent)."""
    path = SHARED / "CameraTrajectory.txt"
    if not path.is_file():
        pytest.skip(f"real GreenHouse trajectory not found at {path}")
    return path


def write_frames(folder: Path, n: int, size=(40, 30), ext=".png", seed=0) -> Path:
    """n colour frames of size (w, h) under folder/rgb, numbered 0..n-1."""
    rng = np.random.default_rng(seed)
    (folder / "rgb").mkdir(parents=True, exist_ok=True)
    for i in range(n):
        img = rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8)
        cv2.imwrite(str(folder / "rgb" / f"{i}{ext}"), img)
    return folder


@pytest.fixture(scope="session")
def tiny_sequence(tmp_path_factory):
    """A 200-frame, 160x120 synthetic greenhouse sequence (rgb, depth, trajectory, camera)."""
    from greenloop import synthetic
    folder = tmp_path_factory.mktemp("seq") / "tiny-greenhouse"
    return synthetic.make_greenhouse(folder, n_frames=200, size=(160, 120), seed=0, progress=False)
