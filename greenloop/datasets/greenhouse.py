"""Download the real GreenHouse sequence (Qi et al. 2024) into a sequence folder; resumable.

Source: github.com/SCAU-AIUS/SLAM-for-agricultural-equipment, folder ``dataset/``: ``rgb/``,
``depth/`` (2261 frames each, about 1.2 GB), ``CameraTrajectory.txt`` and ``D435i.yaml``.
Run ``make data`` or ``python -m greenloop data greenhouse data/greenhouse``.
"""
from __future__ import annotations

import os
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from greenloop.util.files import write_atomic
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

REPO = "SCAU-AIUS/SLAM-for-agricultural-equipment"
BASE_URL = os.environ.get("GREENLOOP_DATA_URL",
                          f"https://raw.githubusercontent.com/{REPO}/main/dataset")
N_FRAMES = 2261
TEXT_FILES = ("CameraTrajectory.txt", "D435i.yaml")

MANUAL = """\
Could not reach {url}
({err}).
To use the real GreenHouse set offline, download it by hand on a machine with internet:
    git clone --depth 1 https://github.com/{repo}
and copy its dataset/ folder so that these exist:
    {folder}/rgb/0.png ... rgb/2260.png
    {folder}/depth/0.png ... depth/2260.png
    {folder}/CameraTrajectory.txt
    {folder}/D435i.yaml
then run the notebooks with DATASET={folder}."""


def _fetch(url: str, dest: Path, timeout: float) -> int:
    """Download url to dest atomically (util.files.write_atomic: a temporary file, then a rename).
    Returns bytes written."""
    n = 0

    def stream(tmp: Path) -> None:
        nonlocal n
        with urllib.request.urlopen(url, timeout=timeout) as r, open(tmp, "wb") as fh:
            while chunk := r.read(1 << 16):
                fh.write(chunk)
                n += len(chunk)
        if n == 0:
            raise OSError(f"{url} returned an empty file")

    write_atomic(dest, stream)
    return n


def download(folder="data/greenhouse", base_url: str = BASE_URL, n_frames: int = N_FRAMES,
             workers: int = 8, timeout: float = 20.0, progress: bool = True) -> Path:
    """Fetch the sequence into ``folder``; files already there are kept (resumable).

    folder: destination sequence folder. base_url: the ``dataset/`` folder's raw URL (http(s) or
    file://). n_frames: frames expected (2261). Raises RuntimeError at once when the source cannot
    be reached (with what to download by hand and where to put it), and ValueError when the frame
    count at the end is not ``n_frames``.
    """
    folder = Path(folder)
    base_url = base_url.rstrip("/")
    jobs = [(f"{base_url}/{name}", folder / name) for name in TEXT_FILES]
    jobs += [(f"{base_url}/{sub}/{i}.png", folder / sub / f"{i}.png")
             for sub in ("rgb", "depth") for i in range(n_frames)]
    for sub in ("rgb", "depth"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    todo = [(u, d) for u, d in jobs if not (d.is_file() and d.stat().st_size > 0)]
    if todo:  # fail fast when offline: try one file before starting the pool
        try:
            _fetch(*todo[0], timeout=timeout)
        except (urllib.error.URLError, OSError, TimeoutError) as e:
            raise RuntimeError(MANUAL.format(url=todo[0][0], err=e, repo=REPO, folder=folder)) from e
        todo = todo[1:]

    with ThreadPoolExecutor(workers) as pool, tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc="GreenHouse",
                                                   unit="file", disable=not progress) as bar:
        futures = [pool.submit(_fetch, u, d, timeout) for u, d in todo]
        failed = []
        for f, (u, _) in zip(futures, todo):
            try:
                f.result()
            except (urllib.error.URLError, OSError, TimeoutError) as e:
                failed.append(f"{u}: {e}")
            bar.update(1)
    if failed:
        raise RuntimeError(f"{len(failed)} files failed (rerun to resume), e.g. {failed[0]}")
    counts = {sub: len(list((folder / sub).glob("*.png"))) for sub in ("rgb", "depth")}
    if any(c != n_frames for c in counts.values()):
        raise ValueError(f"{folder} has {counts} frames, expected {n_frames} each: rerun to resume")
    return folder
