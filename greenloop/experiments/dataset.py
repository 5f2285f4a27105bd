"""Notebook 00's study: what a sequence holds (frames, path, ground-truth loops), beside the real
GreenHouse trajectory where one is found; its figures, and the conclusion its last cell shows.

Every table comes back unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import groundtruth
from greenloop.datasets import groundtruth_formats, sequence
from greenloop.datasets.synthetic import daysmake, dayscene
from greenloop.groundtruth import DEFAULT_EXCLUDE
from greenloop.methods.dictionary import spots
from greenloop.study import wording

# where notebook 00 looks for the real GreenHouse trajectory when none is named
REFERENCE_CANDIDATES = ("data/greenhouse/CameraTrajectory.txt", "../shared/greenhouse/CameraTrajectory.txt")


def _row(name: str, frames: int, ground_truth, poses, gt, path_m=None) -> dict:
    pairs = None if gt is None else groundtruth.loop_pairs(gt)
    return {"sequence": name, "frames": frames, "ground_truth": ground_truth,
            "path_m": groundtruth.path_length(poses) if poses is not None else path_m,
            "loop_pairs": None if gt is None else len(pairs),
            "revisit_frames": None if gt is None else int(groundtruth.revisit_frames(gt).sum()),
            "first_revisit_frame": int(pairs[:, 1].min()) if gt is not None and len(pairs) else None}


def find_reference(reference_trajectory: str = ""):
    """The real GreenHouse CameraTrajectory.txt: reference_trajectory when given, else the first
    of ``REFERENCE_CANDIDATES`` that exists (relative to the working directory); None if none is."""
    candidates = [reference_trajectory] if reference_trajectory else REFERENCE_CANDIDATES
    return next((Path(c) for c in candidates if c and Path(c).is_file()), None)


def reference(path, loop_threshold: float = 0.5, exclude: int = DEFAULT_EXCLUDE):
    """The real trajectory at ``path``: (row, poses, pairs): its summary row (as :func:`summary`'s),
    its (M, 4, 4) poses and its (P, 2) Eq. 5 loop pairs (``groundtruth.loop_matrix``)."""
    _, poses = sequence.read_trajectory(path)
    gt = groundtruth.loop_matrix(poses, loop_threshold, exclude)
    return _row(f"real GreenHouse ({path})", len(poses), "poses", poses, gt), poses, groundtruth.loop_pairs(gt)


def summary(dataset, info: dict, poses, gt, reference_row: dict | None = None) -> pd.DataFrame:
    """One row per sequence: the dataset's, then the real trajectory's when given.

    dataset: the sequence folder; info: ``sequence.folder_info(dataset)``; poses: (N, 4, 4) or None;
    gt: (N, N) bool loops or None; reference_row: :func:`reference`'s row or None. Columns:
    sequence, frames, ground_truth, path_m (metres: the poses' path, else the track of a positions /
    GPS ground-truth file; None without either), loop_pairs, revisit_frames, first_revisit_frame
    (None without ground truth or loops).
    """
    source = sequence.ground_truth_source(dataset) if poses is None else None
    track = groundtruth_formats.track_length(source.path) if source and source.format == "positions" else None
    rows = [_row(f"{info['kind']} ({dataset})", len(sequence.list_frames(dataset)), info["ground_truth"], poses, gt,
                 track)]
    return pd.DataFrame(rows + ([reference_row] if reference_row else []))


def figure_trajectory(poses, gt, gt_metric, frames_per_spot: int, titles: tuple):
    """Top view of the path with its loop pairs, the spots on the path, and the two ground truths
    (Eq. 5 and the metric variant) as matrices. poses: (N, 4, 4); gt, gt_metric: (N, N) bool;
    titles: the two matrices' titles. Returns the figure."""
    import matplotlib.pyplot as plt

    t, pairs = poses[:, :3, 3], groundtruth.loop_pairs(gt)
    fig, (ax, axs, ax1, ax2) = plt.subplots(1, 4, figsize=(21, 5.2), gridspec_kw={"width_ratios": [1, 1, 1.3, 1.3]})
    # top view: the camera moves in x (right) and z (forward); y points down
    sc = ax.scatter(t[:, 0], t[:, 2], c=np.arange(len(t)), s=3, cmap="viridis")
    for i, j in pairs[:: max(1, len(pairs) // 300)]:
        ax.plot(t[[i, j], 0], t[[i, j], 2], color="crimson", lw=0.4, alpha=0.5)
    ax.plot(*t[0, [0, 2]], "k^", ms=9, label="start"); ax.plot(*t[-1, [0, 2]], "ks", ms=8, label="end")
    ax.plot([], [], color="crimson", lw=0.8, label="loop pair (Eq. 5)")
    ax.set_aspect("equal"); ax.set_xlabel("x (m)"); ax.set_ylabel("z (m)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3, fontsize=8)
    ax.set_title(f"top view, {groundtruth.path_length(poses):.1f} m; red: loop pairs")
    fig.colorbar(sc, ax=ax, label="frame (capture order)")
    lab = spots.group(len(t), frames_per_spot)
    axs.scatter(t[:, 0], t[:, 2], c=lab % 20, s=3, cmap="tab20", vmin=0, vmax=19)
    for c in range(0, int(lab.max()) + 1, max(1, (int(lab.max()) + 1) // 12)):
        m = np.flatnonzero(lab == c)[len(np.flatnonzero(lab == c)) // 2]
        axs.annotate(str(c + 1), t[m, [0, 2]], fontsize=7, xytext=(3, 3), textcoords="offset points")
    axs.set_aspect("equal"); axs.set_xlabel("x (m)"); axs.set_ylabel("z (m)")
    axs.set_title(f"spots of {frames_per_spot} frames on the path (numbered from 1)", fontsize=10)
    im1 = ax1.imshow(gt, cmap="gray_r", interpolation="nearest"); ax1.set_title(titles[0])
    ax2.imshow(gt_metric, cmap="gray_r", interpolation="nearest"); ax2.set_title(titles[1])
    fig.colorbar(im1, ax=[ax1, ax2], ticks=[0, 1], label="loop (1) or not (0)", shrink=0.8)
    for a in (ax1, ax2):
        a.set_xlabel("frame j (index)"); a.set_ylabel("frame i (index)")
    return fig


def figure_frames(paths, small: np.ndarray, pick, depth: np.ndarray | None = None):
    """The frames ``pick`` (indices) along the path: RGB as recorded from ``paths`` (top), the CNN's
    32x32 grayscale input from ``small`` ((N, 32, 32, 1) in [0, 1], middle) and, when given, ``depth``
    ((len(pick), H, W) metres, bottom). Returns the figure."""
    import matplotlib.pyplot as plt

    rows = 2 if depth is None else 3
    fig, axes = plt.subplots(rows, len(pick), figsize=(2 * len(pick), 1.8 * rows), squeeze=False)
    for col, k in enumerate(pick):
        axes[0, col].imshow(sequence.read_image(paths[k])[..., ::-1])         # BGR -> RGB
        axes[0, col].set_title(f"frame {k}", fontsize=9)
        axes[1, col].imshow(small[k, ..., 0], cmap="gray", vmin=0, vmax=1)
        if depth is not None:
            dm = axes[2, col].imshow(depth[col], cmap="magma", vmin=0, vmax=float(np.nanpercentile(depth, 99)))
    for ax in axes.ravel():
        ax.axis("off")
    if depth is not None:
        fig.colorbar(dm, ax=axes[2].tolist(), shrink=0.8, label="depth (m)")
    fig.suptitle("frames along the path: RGB (top), the CNN's 32x32 grayscale input (middle)"
                 + ("" if depth is None else ", depth (bottom)"))
    return fig


def figure_spots(small: np.ndarray, labels: np.ndarray, frames_per_spot: int):
    """The first frame of every spot as the CNN sees it; small: (N, 32, 32, 1) in [0, 1], labels:
    (N,) spots (``spots.group(N, frames_per_spot)``). Returns the figure."""
    import matplotlib.pyplot as plt

    k = int(labels.max()) + 1
    cols = min(k, 12)
    rows = int(np.ceil(k / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(1.3 * cols, 1.5 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for c in range(k):
        first = int(np.flatnonzero(labels == c)[0])
        a = axes.ravel()[c]
        a.imshow(small[first, ..., 0], cmap="gray", vmin=0, vmax=1)
        a.set_title(f"spot {c}\n#{first}", fontsize=7)
    fig.suptitle(f"first frame of each of the {k} spots of {frames_per_spot} frames")
    return fig


def figure_pairs(gt, title: str):
    """The loop matrix of a sequence without poses (gt: (N, N) bool, from its loop pairs), frame i
    against frame j; title: the figure's title. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 5.2))
    im = ax.imshow(gt, cmap="gray_r", interpolation="nearest"); ax.set_title(title)
    ax.set_xlabel("frame j (index)"); ax.set_ylabel("frame i (index)")
    fig.colorbar(im, ax=ax, ticks=[0, 1], label="loop (1) or not (0)", shrink=0.8)
    return fig


def figure_reference(poses, pairs):
    """Top view of the real trajectory (poses (M, 4, 4)) with its loop pairs ((P, 2)) in red."""
    import matplotlib.pyplot as plt

    rt = poses[:, :3, 3]
    fig, ax = plt.subplots(figsize=(6, 5))
    ax.scatter(rt[:, 0], rt[:, 2], c=np.arange(len(rt)), s=3)
    for i, j in pairs[:: max(1, len(pairs) // 300)]:
        ax.plot(rt[[i, j], 0], rt[[i, j], 2], color="crimson", lw=0.4, alpha=0.5)
    ax.set_aspect("equal"); ax.set_title(f"real GreenHouse path: {len(pairs)} loop pairs")
    ax.set_xlabel("x (m)"); ax.set_ylabel("z (m)")
    return fig


def is_days(dataset) -> bool:
    """Whether ``dataset`` is a render of the greenhouse over days (``daysmake.is_days``)."""
    return daysmake.is_days(dataset)


def same_place_frames(dataset, aisles=None) -> pd.DataFrame:
    """The same places on every day of a days render: for each aisle in ``aisles`` (default: the first,
    the middle and the last aisle), day-00's middle frame of that aisle (the place) and, on every day,
    the frame on that aisle nearest the place's camera, looking the same way where the day drives the
    aisle that way, else the nearest looking the other way. Columns: place (aisle), day, light,
    offset_days, frame (stream index), distance_m (hall frame, to the place's camera), direction (+1 / -1),
    same_direction. A day that never enters the aisle has no row for it."""
    p = daysmake.frame_places(dataset)
    n = p.hall.n_aisles
    aisles = sorted({0, n // 2, n - 1}) if aisles is None else list(aisles)
    rows = []
    for a in aisles:
        ref = np.flatnonzero((p.day == 0) & (p.aisle == a))
        if not len(ref):
            continue
        r = int(ref[len(ref) // 2])
        for k, name in enumerate(p.names):
            on = np.flatnonzero((p.day == k) & (p.aisle == a))
            if not len(on):
                continue
            same = on[p.direction[on] == p.direction[r]]
            pool = same if len(same) else on
            d = np.hypot(p.x[pool] - p.x[r], p.z[pool] - p.z[r])
            f = int(pool[np.argmin(d)])
            rows.append({"place": f"aisle {a}", "day": name, "light": p.lights[k], "offset_days": p.offsets[k],
                         "frame": f, "distance_m": float(d.min()), "direction": int(p.direction[f]),
                         "same_direction": bool(len(same))})
    return pd.DataFrame(rows)


def figure_days(dataset, table: pd.DataFrame):
    """Frames of every day side by side (columns: days; rows: the places of ``table``, from
    :func:`same_place_frames`), each titled with its day, light, offset and frame, "other way" where
    the day drives the aisle in the other direction. Returns the figure."""
    import matplotlib.pyplot as plt

    paths = sequence.list_frames(dataset)
    days, places = list(dict.fromkeys(table.day)), list(dict.fromkeys(table.place))
    fig, axes = plt.subplots(len(places), len(days), figsize=(2.6 * len(days), 2.5 * len(places)), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for r in table.itertuples():
        ax = axes[places.index(r.place), days.index(r.day)]
        ax.imshow(sequence.read_image(paths[r.frame])[..., ::-1])            # BGR -> RGB
        ax.set_title(f"{r.day} (+{r.offset_days} d), {r.light}\n{r.place}, frame {r.frame}"
                     + ("" if r.same_direction else ", other way"), fontsize=7)
    fig.suptitle("the same places on every day (columns), as rendered")
    fig.tight_layout()
    return fig


def renderer_scope() -> str:
    """Markdown: what the days' renderer models and what it does not (``dayscene.MODELLED`` and
    ``dayscene.NOT_MODELLED``), for notebook 00 and the README."""
    return ("**What the renderer models:** " + "; ".join(dayscene.MODELLED) + ".\n\n"
            "**What it does not model:** " + "; ".join(dayscene.NOT_MODELLED) + ".")


PAPER_FRAMES = 2260           # the main paper's frames of the real GreenHouse set (2261 recorded)


def _frames(row, spots_row: pd.Series | None, name: str) -> str:
    """Frames and spots of the sequence against the paper's 2260 frames and 38 spots of 60."""
    text = f"The {name} sequence holds {int(row.frames)} frames (the paper's GreenHouse set: {PAPER_FRAMES})"
    if spots_row is not None:
        paper = "" if pd.isna(spots_row.paper) or spots_row.paper == "" else f" (the paper: {spots_row.paper})"
        text += f", grouped into {spots_row['this run']} {spots_row.quantity}{paper}"
    return text + "."


def _loops(row) -> str:
    """The ground truth of one row of dataset.csv: loop pairs, revisit frames, the first revisit, the path."""
    if pd.isna(row.loop_pairs):
        return "It carries no ground truth (neither poses nor loop pairs), so no loop can be scored on it."
    path = "" if pd.isna(row.path_m) else f", along {wording.num(row.path_m, 1)} m of camera path"
    if not row.loop_pairs:
        return f"Its ground truth ({row.ground_truth}) leaves no loop pair outside the exclusion window{path}."
    return (f"Its ground truth ({row.ground_truth}) holds {int(row.loop_pairs)} loop pairs over {int(row.revisit_frames)} "
            f"revisit frames, the first revisit at frame {int(row.first_revisit_frame)}{path}.")


def conclusion(out_dir) -> str:
    """Notebook 00's last cell (no claim of the papers concludes here): the dataset's frames, spots and
    ground-truth loops beside the paper's, and the real GreenHouse trajectory's loops where one was
    found. out_dir: the notebook's folder (``<results_dir>/00_dataset``) holding dataset.csv and
    paper_vs_run.csv. Returns Markdown."""
    out_dir = Path(out_dir)
    t = pd.read_csv(out_dir / "dataset.csv")
    cmp = pd.read_csv(out_dir / "paper_vs_run.csv", keep_default_na=False)
    spots_rows = cmp[cmp.quantity.str.startswith("spots of")]
    name = wording.verdict.dataset_name(out_dir.parent)
    sentences = [_frames(t.iloc[0], spots_rows.iloc[0] if len(spots_rows) else None, name), _loops(t.iloc[0])]
    if len(t) > 1:
        r = t.iloc[1]
        sentences.append(f"For comparison, the real GreenHouse trajectory holds {int(r.loop_pairs)} loop pairs over "
                         f"{int(r.revisit_frames)} revisit frames from frame {int(r.first_revisit_frame)} under the "
                         f"same definition and exclusion, along {wording.num(r.path_m, 1)} m.")
    return wording.compose(out_dir.parent, "00_dataset", sentences)
