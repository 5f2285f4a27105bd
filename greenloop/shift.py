"""Robustness perturbations: pixel shifts (the main paper's Table 3) and small rotations.

A shift moves image content and fills the vacated rows/columns; which fill it uses (the border)
and whether the shift happens before or after the CNN's downsampling are the two controls of
notebook 04: ``shift(..., border=...)`` and ``shift_before_downsampling``. ``pixel_change``
measures what a perturbation did to the CNN's input. The scoring functions at the end take the
classifier's predict function as an argument (``predict(model, X) -> (M,) labels``, e.g.
``greenloop.cnn.predict``), so that this module needs no model library.
"""
from __future__ import annotations

import cv2
import numpy as np

from greenloop.datasets import sequence

BORDERS = ("zero", "replicate")
# unit (dx, dy) of each shift direction, in pixels (x to the right, y down)
DIRECTIONS = {"right": (1, 0), "left": (-1, 0), "down": (0, 1), "up": (0, -1)}
# the frames a shift is scored on: the paper's (all frames, training frames included), and apart
FRAME_SETS = ("all frames (the paper's protocol)", "training frames only", "held-out test frames only")


def shift(X: np.ndarray, dx: int = 1, dy: int = 0, border: str = "zero") -> np.ndarray:
    """Move image content by (dx, dy) pixels and fill the vacated rows/columns.

    X: (N, H, W, C) images, any dtype. dx > 0 moves content right (the paper: dx=1, leftmost
    column set to zero), dy > 0 moves it down; dx, dy are whole pixels of X.
    border: "zero" (the paper's) fills the vacated pixels with 0; "replicate" repeats the nearest
        edge row/column of the original image (a 1-px right shift copies column 0 into columns 0
        and 1), so the frame gets no artificial black edge.
    Returns a new array of the same shape and dtype.
    """
    X = np.asarray(X)
    if X.ndim != 4:
        raise ValueError(f"X must have shape (N, H, W, C), got {X.shape}")
    if border not in BORDERS:
        raise ValueError(f"border must be one of {BORDERS}, got {border!r}")
    dx, dy = int(dx), int(dy)
    H, W = X.shape[1:3]
    if border == "replicate":
        rows = np.clip(np.arange(H) - dy, 0, H - 1)
        cols = np.clip(np.arange(W) - dx, 0, W - 1)
        return X[:, rows][:, :, cols]
    out = np.zeros_like(X)
    if abs(dx) >= W or abs(dy) >= H:
        return out
    src_y = slice(max(0, -dy), H - max(0, dy))
    dst_y = slice(max(0, dy), H - max(0, -dy))
    src_x = slice(max(0, -dx), W - max(0, dx))
    dst_x = slice(max(0, dx), W - max(0, -dx))
    out[:, dst_y, dst_x] = X[:, src_y, src_x]
    return out


def full_resolution_offset(full_shape, dx: float, dy: float, size=(32, 32)) -> tuple[int, int]:
    """The shift at full resolution that equals (dx, dy) pixels of the downsampled frame.

    full_shape: (H, W) of the full-resolution frame in pixels. dx, dy: shift in pixels of the
    downsampled frame (fractions allowed). size: (width, height) of the downsampled frame.
    Returns (DX, DY) whole full-resolution pixels: dx * W / width and dy * H / height, rounded to
    the nearest integer (exact for 640x480 -> 32x32: 20 and 15 px per downsampled pixel).
    """
    H, W = int(full_shape[0]), int(full_shape[1])
    return int(round(dx * W / int(size[0]))), int(round(dy * H / int(size[1])))


def shift_before_downsampling(full: np.ndarray, dx: float = 1, dy: float = 0, size=(32, 32),
                              border: str = "zero") -> np.ndarray:
    """Shift full-resolution frames, then downsample them exactly as the CNN's input is made.

    full: (N, H, W, 1) uint8 gray frames at native resolution, as
        ``sequence.load_frames(folder, size=None, dtype=np.uint8)`` returns them.
    dx, dy: shift in pixels of the downsampled frame; the full frame moves by
        ``full_resolution_offset`` (e.g. 20 px for dx=1 at 640 -> 32 wide).
    size: (width, height) of the CNN input. border: as in ``shift``, applied at full resolution.
    Returns (N, size[1], size[0], 1) float32 in [0, 1]: ``sequence.preprocess_image`` (the one
    preprocessing path) on each shifted frame, scaled by 1/255 like ``sequence.load_frames``; with
    dx = dy = 0 it equals ``sequence.load_frames(folder, size)``.
    """
    full = np.asarray(full)
    if full.ndim != 4 or full.shape[-1] != 1 or full.dtype != np.uint8:
        raise ValueError(f"full must be (N, H, W, 1) uint8 gray frames, got {full.shape} {full.dtype}")
    DX, DY = full_resolution_offset(full.shape[1:3], dx, dy, size)
    out = np.empty((len(full), int(size[1]), int(size[0]), 1), np.float32)
    for k in range(len(full)):                 # one frame at a time: no second full-size copy
        moved = shift(full[k:k + 1], DX, DY, border)[0]
        out[k, ..., 0] = sequence.preprocess_image(moved, size, gray=True)
    return out / np.float32(255.0)


CONTROLS = ("zero border (paper)", "replicate border", "full-res shift, zero border",
            "full-res shift, replicate border")


def control_inputs(X: np.ndarray, full: np.ndarray, dx: int = 1, dy: int = 0) -> dict[str, np.ndarray]:
    """The CNN inputs of one shift under each control, keyed by the names in ``CONTROLS``.

    X: (N, h, w, 1) float32 in [0, 1], the CNN's inputs (``sequence.load_frames(folder)``).
    full: (N, H, W, 1) uint8, the same frames at native resolution
        (``sequence.load_frames(folder, size=None, dtype=np.uint8)``).
    dx, dy: the shift in pixels of X. Returns {name: (N, h, w, 1) float32 in [0, 1]}: the
    paper's shift of X (zero border), the same with a replicated border, and the full-resolution
    frames shifted by the equivalent amount with either border, then downsampled.
    """
    if len(full) != len(X):
        raise ValueError(f"full has {len(full)} frames but X has {len(X)}: load both with the same limit/step")
    size = (X.shape[2], X.shape[1])
    return {CONTROLS[0]: shift(X, dx, dy, "zero"), CONTROLS[1]: shift(X, dx, dy, "replicate"),
            CONTROLS[2]: shift_before_downsampling(full, dx, dy, size, "zero"),
            CONTROLS[3]: shift_before_downsampling(full, dx, dy, size, "replicate")}


def pixel_change(X: np.ndarray, Y: np.ndarray, atol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """How much Y differs from X, per image: how many pixels changed and by how much.

    X, Y: (N, H, W, C) images of one shape, e.g. the CNN's inputs, float in [0, 1].
    atol: a pixel counts as changed when any channel differs by more than atol.
    Returns (changed, mean_abs): changed (N,) int64, the number of pixels (of H * W) that changed;
    mean_abs (N,) float64, the absolute difference averaged over all H * W pixels and C channels,
    in the intensity units of X (for the CNN input: 0 = identical, 1 = black <-> white everywhere).
    """
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if X.shape != Y.shape or X.ndim != 4:
        raise ValueError(f"X and Y must be (N, H, W, C) of one shape, got {X.shape} and {Y.shape}")
    d = np.abs(X - Y).reshape(len(X), -1, X.shape[-1])
    return (d > atol).any(-1).sum(1).astype(np.int64), d.mean(axis=(1, 2))


def rotate(X: np.ndarray, degrees: float) -> np.ndarray:
    """Rotate images about their centre by ``degrees`` (counter-clockwise), zero-filling corners.

    X: (N, H, W, C) float images. Returns the same shape and dtype.
    """
    X = np.asarray(X)
    if X.ndim != 4:
        raise ValueError(f"X must have shape (N, H, W, C), got {X.shape}")
    H, W, C = X.shape[1:]
    M = cv2.getRotationMatrix2D(((W - 1) / 2, (H - 1) / 2), float(degrees), 1.0)
    out = np.empty_like(X)
    for k in range(len(X)):
        r = cv2.warpAffine(X[k], M, (W, H), flags=cv2.INTER_LINEAR, borderValue=0)
        out[k] = r.reshape(H, W, C)
    return out


# ------------------------------------------------------- scoring a classifier under perturbations
def accuracy(predict, model, X: np.ndarray, labels: np.ndarray) -> float:
    """Accuracy (%) of ``predict(model, X)`` against labels: X (M, H, W, C), labels (M,) int."""
    return 100 * float(np.mean(predict(model, X) == labels))


def frame_sets(split: dict, n_frames: int) -> dict[str, np.ndarray]:
    """The frame indices of each of ``FRAME_SETS`` for one run: all n_frames frames, the run's
    split['train'] and its split['test'] (arrays of frame indices)."""
    return dict(zip(FRAME_SETS, (np.arange(n_frames), split["train"], split["test"])))


def paper_scores(predict, runs: list[dict], X1: np.ndarray, labels: np.ndarray) -> list[dict]:
    """The paper's Table 3 per run: unshifted test accuracy beside the shifted frames' accuracy.

    predict: ``predict(model, X) -> labels``; runs: ``cnn.run_seeds``' dicts ('seed', 'model',
    'test_accuracy' (fraction), 'split' {'test'}); X1: (N, H, W, C) every frame shifted (the
    paper's 1 px right); labels: (N,) spots. Returns one dict per run: seed, original_test_%,
    shift1_all_frames_% (all N frames, training frames included: the paper's protocol) and
    shift1_test_only_% (the held-out test frames), in %.
    """
    return [{"seed": r["seed"], "original_test_%": 100 * r["test_accuracy"],
             "shift1_all_frames_%": accuracy(predict, r["model"], X1, labels),
             "shift1_test_only_%": accuracy(predict, r["model"], X1[r["split"]["test"]], labels[r["split"]["test"]])}
            for r in runs]


def perturbation_grid(predict, runs: list[dict], X: np.ndarray, labels: np.ndarray, shifts, rotations) -> list[dict]:
    """Each run's held-out test frames under every shift and rotation.

    predict: ``predict(model, X) -> labels``; runs: ``cnn.run_seeds``' dicts ('seed', 'model',
    'split' {'test'}); X: (N, H, W, C) the CNN's inputs, labels: (N,) spots; shifts: pixels,
    applied in each of ``DIRECTIONS`` (zero border); rotations: degrees, each both ways.
    Returns one dict per run and perturbation: seed, perturbation ("shift <direction>" or
    "rotation"), amount (pixels, or signed degrees), accuracy_% of the perturbed test frames.
    """
    grid = []
    for r in runs:
        test = r["split"]["test"]
        for name, (ux, uy) in DIRECTIONS.items():
            for s in shifts:
                grid.append({"seed": r["seed"], "perturbation": f"shift {name}", "amount": s,
                             "accuracy_%": accuracy(predict, r["model"], shift(X[test], dx=ux * s, dy=uy * s), labels[test])})
        for deg in rotations:
            for sign in (1, -1):
                grid.append({"seed": r["seed"], "perturbation": "rotation", "amount": sign * deg,
                             "accuracy_%": accuracy(predict, r["model"], rotate(X[test], sign * deg), labels[test])})
    return grid


def perturbation_summary(grid):
    """:func:`perturbation_grid`'s rows (a DataFrame) summarised over runs: one row per
    perturbation and amount (sorted), with the mean, std and min of accuracy_% (2 decimals)."""
    return grid.groupby(["perturbation", "amount"])["accuracy_%"].agg(["mean", "std", "min"]).round(2).reset_index()


def frame_set_scores(predict, runs: list[dict], X: np.ndarray, X1: np.ndarray, labels: np.ndarray):
    """A shift scored on each of ``FRAME_SETS``: does including the training frames change it.

    predict, runs: as in :func:`perturbation_grid`; X: (N, H, W, C) the CNN's inputs, X1: the
    same frames shifted (the paper's 1 px right), labels: (N,) spots.
    Returns (per_seed, summary), DataFrames: per_seed one row per run and frame set (seed,
    frames, n_frames, unshifted_% and shift1_% accuracies, shift1_vs_test_only_points: shift1_%
    minus the same run's on the held-out test frames); summary their means per frame set, in
    ``FRAME_SETS`` order, rounded to 2 decimals.
    """
    import pandas as pd

    rows = []
    for r in runs:
        for part, idx in frame_sets(r["split"], len(X)).items():
            rows.append({"seed": r["seed"], "frames": part, "n_frames": len(idx),
                         "unshifted_%": accuracy(predict, r["model"], X[idx], labels[idx]),
                         "shift1_%": accuracy(predict, r["model"], X1[idx], labels[idx])})
    per_seed = pd.DataFrame(rows)
    test_only = per_seed[per_seed.frames == FRAME_SETS[2]].set_index("seed")["shift1_%"]
    per_seed["shift1_vs_test_only_points"] = per_seed["shift1_%"] - per_seed.seed.map(test_only)
    summary = (per_seed.groupby("frames", sort=False)[["n_frames", "unshifted_%", "shift1_%", "shift1_vs_test_only_points"]]
               .mean().round(2).reset_index())
    return per_seed, summary


def control_scores(predict, runs: list[dict], X: np.ndarray, full: np.ndarray, labels: np.ndarray, shifts):
    """Every run's held-out test frames under each of ``CONTROLS``, for every shift and direction.

    predict, runs: as in :func:`perturbation_grid`; X: (N, h, w, 1) the CNN's inputs, full:
    (N, H, W, 1) uint8 the same frames at native resolution (:func:`control_inputs`); labels: (N,)
    spots; shifts: pixels of X, in each of ``DIRECTIONS``.
    Returns (controls, identical): controls a DataFrame, one row per direction, shift_px and input:
    accuracy_mean_% and accuracy_std_% over runs (2 decimals), changed_pixels_per_frame (1 decimal)
    and mean_abs_change_per_pixel (4 decimals, [0, 1] intensity), means over all N frames
    (:func:`pixel_change`); identical: one bool per direction and shift, True when the
    full-resolution shift with a zero border gave exactly the paper's input.
    """
    import pandas as pd

    acc_rows, change_rows, identical = [], [], []
    for name, (ux, uy) in DIRECTIONS.items():
        for s in shifts:
            inputs = control_inputs(X, full, ux * s, uy * s)
            identical.append(bool(np.array_equal(inputs[CONTROLS[0]], inputs[CONTROLS[2]])))
            for control, Xs in inputs.items():
                n, m = pixel_change(X, Xs)
                change_rows.append({"direction": name, "shift_px": s, "input": control,
                                    "changed_pixels_per_frame": n.mean(), "mean_abs_change_per_pixel": m.mean()})
                acc_rows += [{"seed": r["seed"], "direction": name, "shift_px": s, "input": control,
                              "accuracy_%": accuracy(predict, r["model"], Xs[r["split"]["test"]], labels[r["split"]["test"]])}
                             for r in runs]
    keys = ["direction", "shift_px", "input"]
    controls = (pd.DataFrame(acc_rows).groupby(keys, sort=False)["accuracy_%"]
                .agg(**{"accuracy_mean_%": "mean", "accuracy_std_%": "std"})
                .reset_index().merge(pd.DataFrame(change_rows), on=keys)
                .round({"accuracy_mean_%": 2, "accuracy_std_%": 2, "changed_pixels_per_frame": 1,
                        "mean_abs_change_per_pixel": 4}))
    return controls, identical


def controls_by_direction(controls, shift_px: int, no_shift: float):
    """One shift of :func:`control_scores`' table: each input's mean accuracy (%) per direction,
    and what the border costs.

    controls: :func:`control_scores`' DataFrame; shift_px: the shift (pixels) to show; no_shift:
    the accuracy (%) of the unshifted test frames. Returns a DataFrame, one row per direction in
    ``DIRECTIONS`` order: direction, no shift, one column per ``CONTROLS`` input,
    lost_to_shift_points (no shift - zero border) and won_back_by_replicate_points (replicate
    border - zero border), in points.
    """
    wide = controls[controls.shift_px == shift_px].pivot(index="direction", columns="input", values="accuracy_mean_%")
    wide = wide.loc[list(DIRECTIONS), list(CONTROLS)].reset_index()
    wide.insert(1, "no shift", no_shift)
    wide["lost_to_shift_points"] = wide["no shift"] - wide[CONTROLS[0]]
    wide["won_back_by_replicate_points"] = wide[CONTROLS[1]] - wide[CONTROLS[0]]
    return wide
