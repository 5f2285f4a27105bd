"""Notebook 04's study: the paper's CNN scored under pixel shifts (Table 3) and small rotations,
on all frames (the paper's protocol) and on held-out frames only, with the border and
full-resolution controls of ``greenloop.methods.dictionary.shift``.

The scoring functions take the classifier's predict function as an argument
(``predict(model, X) -> (M,) labels``, e.g. ``greenloop.methods.dictionary.cnn.predict``). Every table comes back
unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import report
from greenloop.methods.dictionary import shift as sh
from greenloop.study import wording

PAPER_SHIFT1 = 92        # Table 3: % of all 2260 frames shifted 1 px right, training frames included

# the frames a shift is scored on: the paper's (all frames, training frames included), and apart
FRAME_SETS = ("all frames (the paper's protocol)", "training frames only", "held-out test frames only")
# how control_scores' columns are written (decimals)
CONTROL_DECIMALS = {"accuracy_mean_%": 2, "accuracy_std_%": 2, "changed_pixels_per_frame": 1,
                    "mean_abs_change_per_pixel": 4}


def accuracy(predict, model, X: np.ndarray, labels: np.ndarray) -> float:
    """Accuracy (%) of ``predict(model, X)`` against labels: X (M, H, W, C), labels (M,) int."""
    return 100 * float(np.mean(predict(model, X) == labels))


def frame_sets(split: dict, n_frames: int) -> dict[str, np.ndarray]:
    """The frame indices of each of ``FRAME_SETS`` for one run: all n_frames frames, the run's
    split['train'] and its split['test'] (arrays of frame indices)."""
    return dict(zip(FRAME_SETS, (np.arange(n_frames), split["train"], split["test"])))


def paper_scores(predict, runs: list[dict], X1: np.ndarray, labels: np.ndarray) -> pd.DataFrame:
    """The paper's Table 3 per run: unshifted test accuracy beside the shifted frames' accuracy.

    predict: ``predict(model, X) -> labels``; runs: ``cnn.run_seeds``' dicts ('seed', 'model',
    'test_accuracy' (fraction), 'split' {'test'}); X1: (N, H, W, C) every frame shifted (the
    paper's 1 px right); labels: (N,) spots. Returns a DataFrame, one row per run: seed, original_test_%,
    shift1_all_frames_% (all N frames, training frames included: the paper's protocol) and
    shift1_test_only_% (the held-out test frames), in %.
    """
    return pd.DataFrame([{"seed": r["seed"], "original_test_%": 100 * r["test_accuracy"],
             "shift1_all_frames_%": accuracy(predict, r["model"], X1, labels),
             "shift1_test_only_%": accuracy(predict, r["model"], X1[r["split"]["test"]], labels[r["split"]["test"]])}
                         for r in runs])


def _scored(predict, r: dict, Xp: np.ndarray, labels: np.ndarray) -> dict:
    """One run's accuracy (%) on perturbed frames Xp (N, H, W, C), labels (N,): on the held-out
    test frames (``heldout_%``, judged) and on all N frames, training frames included (``all_frames_%``)."""
    test = r["split"]["test"]
    return {"heldout_%": accuracy(predict, r["model"], Xp[test], labels[test]),
            "all_frames_%": accuracy(predict, r["model"], Xp, labels)}


def perturbation_grid(predict, runs: list[dict], X: np.ndarray, labels: np.ndarray, shifts, rotations) -> pd.DataFrame:
    """Each run under every shift and rotation, scored on its held-out test frames and on all frames.

    predict: ``predict(model, X) -> labels``; runs: ``cnn.run_seeds``' dicts ('seed', 'model',
    'split' {'test'}); X: (N, H, W, C) the CNN's inputs, labels: (N,) spots; shifts: pixels,
    applied in each of ``DIRECTIONS`` (zero border); rotations: degrees, each both ways.
    Returns a DataFrame, one row per run and perturbation: seed, perturbation ("shift <direction>" or
    "rotation"), amount (pixels, or signed degrees), heldout_% (the perturbed held-out test frames:
    the number to judge) and all_frames_% (all N frames, training frames included: the paper's protocol).
    """
    grid = []
    for r in runs:
        for name, (ux, uy) in sh.DIRECTIONS.items():
            for s in shifts:
                grid.append({"seed": r["seed"], "perturbation": f"shift {name}", "amount": s,
                             **_scored(predict, r, sh.shift(X, dx=ux * s, dy=uy * s), labels)})
        for deg in rotations:
            for sign in (1, -1):
                grid.append({"seed": r["seed"], "perturbation": "rotation", "amount": sign * deg,
                             **_scored(predict, r, sh.rotate(X, sign * deg), labels)})
    return pd.DataFrame(grid)


def perturbation_summary(grid):
    """:func:`perturbation_grid`'s rows (a DataFrame) summarised over runs: one row per
    perturbation and amount (sorted): heldout_mean, heldout_std, heldout_min of heldout_% (the
    judged number) beside all_frames_mean, all_frames_std, all_frames_min of all_frames_%, and
    all_frames_minus_heldout_points (the mean of the per-run differences, in points)."""
    g = grid.assign(d=grid["all_frames_%"] - grid["heldout_%"]).groupby(["perturbation", "amount"])
    out = pd.concat([g["heldout_%"].agg(["mean", "std", "min"]).add_prefix("heldout_"),
                     g["all_frames_%"].agg(["mean", "std", "min"]).add_prefix("all_frames_"),
                     g["d"].mean().rename("all_frames_minus_heldout_points")], axis=1)
    return out.reset_index()


def frame_set_scores(predict, runs: list[dict], X: np.ndarray, X1: np.ndarray, labels: np.ndarray):
    """A shift scored on each of ``FRAME_SETS``: does including the training frames change it.

    predict, runs: as in :func:`perturbation_grid`; X: (N, H, W, C) the CNN's inputs, X1: the
    same frames shifted (the paper's 1 px right), labels: (N,) spots.
    Returns (per_seed, summary), DataFrames: per_seed one row per run and frame set (seed,
    frames, n_frames, unshifted_% and shift1_% accuracies, shift1_vs_test_only_points: shift1_%
    minus the same run's on the held-out test frames); summary their means per frame set, in
    ``FRAME_SETS`` order.
    """
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
               .mean().reset_index())
    return per_seed, summary


def control_scores(predict, runs: list[dict], X: np.ndarray, full: np.ndarray, labels: np.ndarray, shifts):
    """Every run's held-out test frames under each of ``CONTROLS``, for every shift and direction.

    predict, runs: as in :func:`perturbation_grid`; X: (N, h, w, 1) the CNN's inputs, full:
    (N, H, W, 1) uint8 the same frames at native resolution (:func:`control_inputs`); labels: (N,)
    spots; shifts: pixels of X, in each of ``DIRECTIONS``.
    Returns (controls, identical): controls a DataFrame, one row per direction, shift_px and input:
    accuracy_mean_% and accuracy_std_% over runs, changed_pixels_per_frame
    and mean_abs_change_per_pixel ([0, 1] intensity), means over all N frames
    (:func:`pixel_change`); identical: one bool per direction and shift, True when the
    full-resolution shift with a zero border gave exactly the paper's input.
    """
    acc_rows, change_rows, identical = [], [], []
    for name, (ux, uy) in sh.DIRECTIONS.items():
        for s in shifts:
            inputs = sh.control_inputs(X, full, ux * s, uy * s)
            identical.append(bool(np.array_equal(inputs[sh.CONTROLS[0]], inputs[sh.CONTROLS[2]])))
            for control, Xs in inputs.items():
                n, m = sh.pixel_change(X, Xs)
                change_rows.append({"direction": name, "shift_px": s, "input": control,
                                    "changed_pixels_per_frame": n.mean(), "mean_abs_change_per_pixel": m.mean()})
                acc_rows += [{"seed": r["seed"], "direction": name, "shift_px": s, "input": control,
                              "accuracy_%": accuracy(predict, r["model"], Xs[r["split"]["test"]], labels[r["split"]["test"]])}
                             for r in runs]
    keys = ["direction", "shift_px", "input"]
    controls = (pd.DataFrame(acc_rows).groupby(keys, sort=False)["accuracy_%"]
                .agg(**{"accuracy_mean_%": "mean", "accuracy_std_%": "std"})
                .reset_index().merge(pd.DataFrame(change_rows), on=keys))
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
    wide = wide.loc[list(sh.DIRECTIONS), list(sh.CONTROLS)].reset_index()
    wide.insert(1, "no shift", no_shift)
    wide["lost_to_shift_points"] = wide["no shift"] - wide[sh.CONTROLS[0]]
    wide["won_back_by_replicate_points"] = wide[sh.CONTROLS[1]] - wide[sh.CONTROLS[0]]
    return wide


def controls_statement(controls_1px: pd.DataFrame, shift_px: int) -> str:
    """One sentence per direction of :func:`controls_by_direction`'s table: the points lost to
    the shift with the zero border and what replicating the border changes (1 decimal)."""
    return "\n".join(
        f"{shift_px} px {row.direction}: {row.lost_to_shift_points:.1f} points lost with the zero border; replicating "
        f"the border changes the accuracy by {row.won_back_by_replicate_points:+.1f} points, leaving it "
        f"{row['no shift'] - row[sh.CONTROLS[1]]:.1f} points below no shift" for _, row in controls_1px.iterrows())


def figure_examples(X: np.ndarray, k: int, degrees: float):
    """Frame k of X (N, H, W, 1) as the CNN sees it: original, 1 px right with the zero and the
    replicated border, rotated by ``degrees``; below each, |change| against the original."""
    import matplotlib.pyplot as plt

    one = X[k:k + 1]
    examples = {"original": X[k], "1 px right, zero border (paper)": sh.shift(one, dx=1)[0],
                "1 px right, replicate border": sh.shift(one, dx=1, border="replicate")[0],
                f"{degrees}° rotation": sh.rotate(one, degrees)[0]}
    fig, axes = plt.subplots(2, len(examples), figsize=(3.2 * len(examples), 6.4))
    for col, (name, img) in enumerate(examples.items()):
        axes[0, col].imshow(img[..., 0], cmap="gray", vmin=0, vmax=1); axes[0, col].set_title(name, fontsize=9)
        d = axes[1, col].imshow(np.abs(img - X[k])[..., 0], cmap="magma", vmin=0, vmax=0.5)
        axes[1, col].set_title("|change| vs original", fontsize=8)
    for ax in axes.ravel():
        ax.axis("off")
    fig.colorbar(d, ax=axes[1].tolist(), shrink=0.8, label="absolute change (intensity in [0, 1])")
    fig.suptitle(f"frame {k}: the perturbations of this notebook, as the CNN's input")
    return fig


def _curve(ax, d: pd.DataFrame, color, label: str) -> None:
    """One perturbation's accuracy against its amount on ax: held-out frames solid (mean ± std over
    runs), all frames dashed with hollow markers (mean). d: :func:`perturbation_grid`'s rows of it."""
    h = d.groupby("amount")["heldout_%"]
    ax.errorbar(h.mean().index, h.mean(), yerr=h.std().fillna(0), marker="o", capsize=3, color=color,
                label=f"{label}: held-out frames, mean ± std")
    a = d.groupby("amount")["all_frames_%"].mean()
    ax.plot(a.index, a.values, ls="--", marker="o", mfc="none", color=color, alpha=0.7,
            label=f"{label}: all frames, training included (mean)")


def figure_grid(grid: pd.DataFrame, no_shift: float, table3: pd.DataFrame | None = None):
    """:func:`perturbation_grid`'s accuracy (%) against the shift per direction (left) and the
    rotation (right): held-out test frames solid (mean ± std over runs), all frames dashed;
    no_shift: the unshifted held-out accuracy (%); the paper's 92 % dashed red, and beside it, from
    ``table3`` (:func:`paper_scores`, when given), this run's 1 px right on the held-out frames and on
    all frames (mean, whisker over the seeds' min-max)."""
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 5.2))
    for k, name in enumerate(sh.DIRECTIONS):
        _curve(a, grid[grid.perturbation == f"shift {name}"], f"C{k}", name)
    if table3 is not None:
        for col, fmt, what in (("shift1_test_only_%", "k*", "held-out frames (judged)"),
                               ("shift1_all_frames_%", "kP", "all frames (paper's protocol)")):
            v = table3[col]
            a.errorbar([0.85], [v.mean()], yerr=[[v.mean() - v.min()], [v.max() - v.mean()]], fmt=fmt, ms=10, capsize=4,
                       label=f"1 px right, {what}: mean, seed min-max")
    a.axhline(PAPER_SHIFT1, color="r", ls="--", label=f"paper: {PAPER_SHIFT1} % (1 px right, all frames)")
    a.axhline(no_shift, color="k", ls=":", label="no shift (held-out frames)")
    a.set_xscale("log", base=2); a.set_xlabel("shift (pixels at 32x32)"); a.set_ylabel("accuracy (%)")
    a.set_title("shifted"); a.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    _curve(b, grid[grid.perturbation == "rotation"], "C0", "rotation")
    b.axhline(no_shift, color="k", ls=":", label="no shift (held-out frames)")
    b.set_xlabel("rotation (degrees)"); b.set_ylabel("accuracy (%)"); b.set_title("rotated")
    b.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    fig.tight_layout()
    return fig


def comparison(table3: pd.DataFrame, n_frames: int, changed: np.ndarray, mean_abs: np.ndarray, pixels: int):
    """Notebook 04's paper-vs-run table (``report.paper_vs_run``), the paper's 92 % set against the
    held-out test frames (the frames the model never saw; the judged row) and shown beside all frames,
    training frames included (the paper's protocol, not judged). table3: :func:`paper_scores`' table;
    n_frames: frames in the experiment; changed, mean_abs: ``shift.pixel_change``'s (N,) arrays of a
    1-px shift; pixels: pixels per CNN input."""
    def stat(col):
        v = table3[col]
        return f"{v.mean():.2f} (seeds {v.min():.2f} to {v.max():.2f})"
    return report.paper_vs_run([
        ("accuracy, original test frames (%)", 98, f"{table3['original_test_%'].mean():.2f}", f"{len(table3)} seeds, mean"),
        ("accuracy, held-out test frames shifted 1 px right (%)", PAPER_SHIFT1, stat("shift1_test_only_%"),
         "judged: frames the model never saw"),
        ("accuracy, all frames shifted 1 px right (%)", PAPER_SHIFT1, stat("shift1_all_frames_%"),
         "paper protocol, training frames included: not judged"),
        ("frames in the shift experiment", 2260, n_frames),
        ("pixels changed per image by a 1-px shift", 32, f"{changed.mean():.0f} of {pixels}", "measured"),
        ("mean absolute change per pixel, 1-px shift ([0, 1] intensity)", None, f"{mean_abs.mean():.4f}", "measured"),
    ])


def figure_controls(controls: pd.DataFrame, shifts, no_shift: float, input_shape):
    """:func:`control_scores`' table in four panels: test accuracy (%) of right shifts (mean ± std over
    seeds, the paper's 92 % dashed), of all four directions, changed pixels and mean absolute change,
    against the shift, one line per input; input_shape: (H, W) of the CNN input. Returns the figure."""
    import matplotlib.pyplot as plt

    H, W = input_shape
    styles = {sh.CONTROLS[0]: dict(color="C0", marker="o"), sh.CONTROLS[1]: dict(color="C1", marker="s"),
              sh.CONTROLS[2]: dict(color="C2", marker="o", ls="--", mfc="none", ms=10),
              sh.CONTROLS[3]: dict(color="C3", marker="s", ls="--", mfc="none", ms=10)}
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    panels = [("accuracy_mean_%", controls.direction == "right", "test accuracy (%)", "right shifts (the paper's direction)"),
              ("accuracy_mean_%", slice(None), "test accuracy (%), mean of 4 directions", "all four directions"),
              ("changed_pixels_per_frame", slice(None), f"changed pixels per frame (of {H * W})", "pixels changed"),
              ("mean_abs_change_per_pixel", slice(None), "mean absolute change per pixel ([0, 1] intensity)", "how much they changed")]
    for ax, (col, rows, ylabel, title) in zip(axes.flat, panels):
        for control, style in styles.items():
            d = controls[rows][controls[rows].input == control]
            g = d.groupby("shift_px")[col].mean()
            if rows is not slice(None) and col.startswith("accuracy"):     # one row per shift: its spread over seeds
                ax.errorbar(g.index, g.values, yerr=d.groupby("shift_px")["accuracy_std_%"].mean().fillna(0).values,
                            capsize=3, label=control, **style)
            else:
                ax.plot(g.index, g.values, label=control, **style)
        if col.startswith("accuracy"):
            ax.axhline(no_shift, color="k", ls=":", label="no shift")
        if rows is not slice(None) and col.startswith("accuracy"):
            ax.axhline(PAPER_SHIFT1, color="r", ls="--", label=f"paper: {PAPER_SHIFT1} % (1 px right, all frames)")
        ax.set_xscale("log", base=2); ax.set_xticks(shifts, [str(s) for s in shifts]); ax.minorticks_off()
        ax.set_xlabel(f"shift (pixels at {W}x{H})"); ax.set_ylabel(ylabel); ax.set_title(title)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="lower center", ncol=4, bbox_to_anchor=(0.5, 0))
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return fig


def _paper_protocol(t3: pd.DataFrame, name: str) -> str:
    """Table 3's accuracies (%) with their seed ranges: the held-out test frames shifted (judged
    against the paper's 92 %), unshifted, and all frames shifted (the paper's protocol, shown)."""
    def one(col):
        v = t3[col]
        return f"{wording.num(v.mean())} % {wording.span(v.min(), v.max())}"
    return (f"On {name}, the held-out test frames shifted 1 px right are classified at {one('shift1_test_only_%')} over "
            f"{wording.count(len(t3), 'seed')} (mean [seed min, max]; the paper: {PAPER_SHIFT1} %, judged on these frames, "
            f"which the model never saw), against {one('original_test_%')} unshifted; every frame shifted, training "
            f"frames included (the paper's protocol), at {one('shift1_all_frames_%')}.")


def _training_frames(t3: pd.DataFrame) -> str:
    """What scoring the training frames too adds to the shifted accuracy, per seed, with its sign."""
    d = t3["shift1_all_frames_%"] - t3["shift1_test_only_%"]
    flatter = ": the paper's protocol flatters the model here" if d.min() > 0 and len(d) >= wording.verdict.MIN_SEEDS else ""
    return (f"Scoring all frames, training frames included, instead of the held-out ones changes the shifted "
            f"accuracy by {wording.signed(d.mean())} points (per seed {wording.signed(d.min())} to "
            f"{wording.signed(d.max())}, {wording.sign(d.min(), d.max(), len(d))}){flatter}.")


def _cost(t3: pd.DataFrame) -> str:
    """What the 1-px shift costs the held-out test frames, per seed, with its sign."""
    d = t3["original_test_%"] - t3["shift1_test_only_%"]
    return (f"On the held-out frames the shift costs {wording.num(d.mean())} points (per seed "
            f"{wording.num(d.min())} to {wording.num(d.max())}, {wording.sign(d.min(), d.max(), len(d))}).")


def conclusion(out_dir) -> str:
    """Notebook 04's last cell: the verdict on Table 3 for its dataset, then the shifted accuracies
    with their seed ranges, what including the training frames adds (points, with its sign over
    seeds) and what the shift costs the held-out frames. out_dir: the notebook's folder
    (``<results_dir>/04_shift_robustness``) holding table3.csv. Returns Markdown."""
    out_dir = Path(out_dir)
    t3 = pd.read_csv(out_dir / "table3.csv")
    name = wording.verdict.dataset_name(out_dir.parent)
    return wording.compose(out_dir.parent, "04_shift_robustness",
                           [_paper_protocol(t3, name), _training_frames(t3), _cost(t3)])
