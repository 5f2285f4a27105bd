"""The sequence folder: ``make_greenhouse(folder)`` (its command line: ``python -m greenloop data synthetic``).

Renders the route (``route``) through the scene (``scene``, ``render``, ``sensor``), chunks of
frames over a pool of worker processes, and writes a sequence folder (see
``greenloop.datasets.sequence``)::

    rgb/0.png ...            8-bit colour, 640x480 by default
    depth/0.png ...          uint16, metres = value / 5000, 0 = no reading (beyond 10 m, edges)
    CameraTrajectory.txt     TUM, t = frame number, camera-to-world, OpenCV camera axes
                             (x right, y down, z forward), relative to the first camera
    camera.yaml              ORB-SLAM / D435i layout (Camera.fx ... DepthMapFactor)
    synthetic.json           the generator's arguments (marks the folder as synthetic)

CLI: ``python -m greenloop data synthetic OUT_FOLDER [--frames N] [--size WxH] [--seed S]
[--noise STD] [--workers K] [--overwrite] [--quiet]`` (``make synthetic``).
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np

from greenloop.datasets.sequence import DEPTH_SCALE, write_trajectory
from greenloop.datasets.synthetic.camera import _check_size, DEFAULT_SIZE, write_camera_yaml
from greenloop.datasets.synthetic.hall import _check_seed
from greenloop.datasets.synthetic.render import _grid, render_frame
from greenloop.datasets.synthetic.route import (DEFAULT_FRAMES, _check_frames, route, route_length,
                                                route_world)
from greenloop.datasets.synthetic.scene import build_scene
from greenloop.datasets.synthetic.sensor import _sensor, DEFAULT_NOISE
from greenloop.util.progress import bar as tqdm  # in the terminal, never in a notebook

PNG_LEVEL = 5             # zlib level: 5 is ~10% smaller than 3 at about the same speed

_WORKER: dict = {}


def _worker_init(seed: int, n_frames: int, size, out: str, noise: float) -> None:
    """Per-process state: scene, pixel grid, poses (N, 4, 4) and arc lengths (N,) metres."""
    poses, s = route_world(n_frames, seed)
    _WORKER.update(scene=build_scene(seed), grid=_grid(size), poses=poses, s=s, seed=seed,
                   out=Path(out), size=size, noise=noise)


def _render_chunk(frames) -> int:
    """Render and write the frames (list of int indices); returns how many were written."""
    wk = _WORKER
    for i in frames:
        _write_frame(wk["out"], i, wk["scene"], wk["poses"][i], float(wk["s"][i]), wk["grid"],
                     np.random.default_rng([wk["seed"], int(i), 0xF4A3E]), wk["noise"])
    return len(frames)


def _write_frame(out: Path, i: int, scene, pose: np.ndarray, s_m: float, grid, rng, noise: float) -> None:
    """Render frame ``i`` of ``scene`` from ``pose`` (4, 4) camera-to-hall at route position
    ``s_m`` metres, pass it through the sensor model (``rng`` the frame's generator, ``noise`` grey
    levels) and write out/rgb/i.png and out/depth/i.png."""
    img, depth = render_frame(scene, pose, (grid.w, grid.h), grid)
    bgr, d16 = _sensor(scene, img, depth, s_m, grid, rng, noise)
    for sub, im in (("rgb", bgr), ("depth", d16)):
        if not cv2.imwrite(str(out / sub / f"{i}.png"), im, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL]):
            raise OSError(f"could not write {out / sub / f'{i}.png'}")


def make_greenhouse(folder, n_frames: int = DEFAULT_FRAMES, size=DEFAULT_SIZE, seed: int = 0,
                    progress: bool = True, workers: int | None = None,
                    overwrite: bool = False, noise: float = DEFAULT_NOISE) -> Path:
    """Render the synthetic GreenHouse sequence into ``folder`` (a sequence folder).

    n_frames: frames along the same ~61 m route (>= 200; 2260 like the paper's run).
    size: (width, height) pixels (>= 160x120); intrinsics are the D435i's scaled linearly.
    seed: seeds plant details, textures, route jitter, lighting drift and sensor noise; the
        output is byte-identical for the same arguments (each frame's noise is seeded by
        (seed, frame index), so the worker count does not matter).
    workers: processes (default os.cpu_count(); 1 renders in this process).
    overwrite: replace an existing non-empty ``folder`` (otherwise FileExistsError).
    noise: std of the per-pixel Gaussian sensor noise in grey levels (0..255). Every frame also
        gets a seeded exposure / white-balance flicker, and depth a smooth seeded error field.
        Per-pixel noise is incompressible, so it makes the PNG files much larger.
    Writes into a temporary folder beside ``folder`` and renames it at the end, so an
    interrupted run leaves nothing half-written. Returns the folder as a Path.
    """
    n = _check_frames(n_frames)
    size = _check_size(size)
    seed = _check_seed(seed)
    noise, workers = _check_noise_workers(noise, workers)
    folder = Path(folder)
    _check_output(folder, overwrite)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.parent / f".{folder.name}.tmp-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        (tmp / "rgb").mkdir(parents=True)
        (tmp / "depth").mkdir()
        _render_frames(tmp, f"render {folder.name}", n, size, seed, noise, workers, progress)
        _write_metadata(tmp, n, size, seed, noise)
        _move_into_place(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def _check_noise_workers(noise, workers) -> tuple[float, int]:
    """Validated (noise std in grey levels, 0..50; worker processes, >= 1, None = all cores)."""
    if not (isinstance(noise, (int, float)) and 0 <= noise <= 50):
        raise ValueError(f"noise must be a std in grey levels between 0 and 50, got {noise!r}")
    if workers is None:
        workers = os.cpu_count() or 1
    if isinstance(workers, bool) or int(workers) != workers or int(workers) < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    return float(noise), int(workers)


def _check_output(folder: Path, overwrite: bool) -> None:
    """FileExistsError unless ``folder`` is absent, an empty folder, or may be overwritten."""
    if folder.exists() and not folder.is_dir():
        raise FileExistsError(f"{folder} exists and is not a folder: choose another output path")
    if folder.is_dir() and any(folder.iterdir()) and not overwrite:
        raise FileExistsError(f"{folder} already exists and is not empty: delete it, choose another "
                              f"folder, or pass overwrite=True (CLI: --overwrite)")


def _render_frames(tmp: Path, desc: str, n: int, size, seed: int, noise: float, workers: int,
                   progress: bool) -> None:
    """Render frames 0..n-1 into tmp/rgb and tmp/depth, in chunks of 8 frames over ``workers``
    processes (1: in this process), with a progress bar labelled ``desc``."""
    chunk = 8
    chunks = [list(range(i, min(i + chunk, n))) for i in range(0, n, chunk)]
    bar = tqdm(total=n, desc=desc, unit="frame", disable=not progress)
    try:
        if workers == 1:
            _worker_init(seed, n, size, str(tmp), noise)
            for c in chunks:
                bar.update(_render_chunk(c))
        else:
            import multiprocessing as mp
            with mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn").Pool(
                    workers, _worker_init, (seed, n, size, str(tmp), noise)) as pool:
                for done in pool.imap_unordered(_render_chunk, chunks):
                    bar.update(done)
    finally:
        bar.close()
        _WORKER.clear()


def _write_metadata(tmp: Path, n: int, size, seed: int, noise: float) -> None:
    """CameraTrajectory.txt (n poses, TUM, first camera's frame), camera.yaml and synthetic.json."""
    poses = route(n, seed)
    write_trajectory(tmp / "CameraTrajectory.txt", np.arange(n), poses)
    write_camera_yaml(tmp / "camera.yaml", size)
    meta = {"generator": "greenloop.datasets.synthetic", "format": 1, "n_frames": n,
            "width": size[0], "height": size[1], "seed": seed, "noise": noise,
            "route_length_m": round(route_length(), 3), "depth_scale": DEPTH_SCALE}
    (tmp / "synthetic.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")


def _move_into_place(tmp: Path, folder: Path) -> None:
    """Rename the finished ``tmp`` to ``folder``, moving an existing ``folder`` aside first and
    deleting it afterwards."""
    if folder.exists():
        old = folder.parent / f".{folder.name}.old-{os.getpid()}"
        folder.rename(old)
        tmp.rename(folder)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(folder)
