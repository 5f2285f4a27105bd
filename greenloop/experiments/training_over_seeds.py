"""Notebook 02's study: the paper's CNN trained over seeds on the random and the blocked split
(Figures 3 and 4), and how much of the random split's accuracy is memory of neighbouring frames
(the leakage controls, also run per grouping by notebook 01).

Every table comes back unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import report
from greenloop.methods.dictionary import cnn
from greenloop.study import verdict, wording

# the runs of ``leakage_controls``: a blocked split, a random split with its number of training
# frames, and a blocked split with the test block centred in its spot
LEAKAGE_CONTROLS = ("blocked", "random, same n_train", "blocked, centred")
SPLITS = ("random", "blocked")


def runs_by_split(X: np.ndarray, y: np.ndarray, seeds, splits=SPLITS, **train_kw) -> dict:
    """``cnn.run_seeds`` once per split: {split: run_seeds' list of dicts}.

    X: (N, H, W, C) frames, y: (N,) spot labels, seeds: ints; splits: names of ``cnn.SPLITS``;
    train_kw go to ``cnn.train`` (epochs, batch_size, gap, ...)."""
    return {split: cnn.run_seeds(X, y, seeds, split=split, **train_kw) for split in splits}


def converged(history: dict, converged_at: float = 0.95) -> bool:
    """Did a run converge: it fit its training frames (its final training accuracy, a fraction in
    [0, 1], ``history['accuracy'][-1]``, is at least converged_at, a fraction), or its training
    accuracy stopped rising before the epoch cap (``history['stopped_early']``, the early-stopping
    rule ``util.stopping.stops_here``). A run that is neither ended on its budget while still able to rise."""
    return bool(history["accuracy"][-1] >= converged_at or history.get("stopped_early", False))


def budget_label(runs, converged_at: float = 0.95) -> str:
    """"budget-limited: k of n seeds converged" where fewer than half of the runs converged
    (``verdict.budget_limited`` on :func:`converged`), else "". runs: ``cnn.run_seeds``' dicts, as a
    list or as {split: list} (``runs_by_split``), all counted. What a table's note carries and
    :func:`label_budget` writes above a figure, so that the label stands where the numbers are read."""
    runs = [r for rs in runs.values() for r in rs] if isinstance(runs, dict) else list(runs)
    k = sum(converged(r["history"], converged_at) for r in runs)
    return f"budget-limited: {k} of {len(runs)} seeds converged" if verdict.budget_limited(k, len(runs)) else ""


def label_budget(fig, runs, converged_at: float = 0.95):
    """Write :func:`budget_label` in red above the figure (over its title, outside the axes; the
    saved figure's tight bounding box takes it in), nothing where the runs converged. Returns the
    figure."""
    return report.label_figure(fig, budget_label(runs, converged_at))


def first_epoch(history: dict, target: float):
    """The first epoch (1-based) whose validation accuracy (fraction) reaches target (fraction),
    or None when no epoch does."""
    hit = np.flatnonzero(np.asarray(history["val_accuracy"]) >= target)
    return int(hit[0]) + 1 if len(hit) else None


def per_seed(runs: dict, target_accuracy: float = 0.98, converged_at: float = 0.95,
             after_epoch: int = 45) -> pd.DataFrame:
    """One row per run: the figures the paper gives for its learning curves (Figures 3 and 4).

    runs: {split name: ``cnn.run_seeds``' dicts}. target_accuracy, converged_at: fractions.
    Returns a DataFrame: split, seed, n_train, n_test, test_acc_%, epoch_to_<target in %>% (first
    epoch whose validation accuracy reaches the target, None if none), min_val_acc_after_ep<after_epoch>_%
    (lowest validation accuracy from epoch after_epoch + 1 on, or of the last epoch in a shorter
    run), final_train_acc_%, converged, train_seconds (s); accuracies in %.
    """
    rows = []
    for split, rs in runs.items():
        for r in rs:
            h = r["history"]
            va = np.asarray(h["val_accuracy"])
            rows.append({"split": split, "seed": r["seed"], "n_train": len(r["split"]["train"]),
                         "n_test": len(r["split"]["test"]), "test_acc_%": 100 * r["test_accuracy"],
                         f"epoch_to_{int(target_accuracy * 100)}%": first_epoch(h, target_accuracy),
                         f"min_val_acc_after_ep{after_epoch}_%": 100 * float(va[min(after_epoch, len(va) - 1):].min()),
                         "final_train_acc_%": 100 * h["accuracy"][-1],
                         "converged": converged(h, converged_at), "train_seconds": h["seconds"]})
    return pd.DataFrame(rows)


def seed_summary(per_seed: pd.DataFrame) -> pd.DataFrame:
    """Test accuracy over seeds per split, from :func:`per_seed`'s table.

    Returns a DataFrame, one row per split (sorted by name): split, seeds, converged_seeds,
    mean, std, median, worst, best (of test_acc_%) and median_of_converged (median test_acc_% of
    the converged seeds, NaN when none).
    """
    summ = per_seed.groupby("split").agg(seeds=("seed", "count"), converged_seeds=("converged", "sum"),
                                         mean=("test_acc_%", "mean"), std=("test_acc_%", "std"),
                                         median=("test_acc_%", "median"), worst=("test_acc_%", "min"),
                                         best=("test_acc_%", "max")).reset_index()
    summ["median_of_converged"] = [per_seed[(per_seed.split == s) & per_seed.converged]["test_acc_%"].median()
                                   for s in summ.split]
    return summ


def _control_row(control: str, gap: int, r: dict, converged_at: float) -> dict:
    return {"control": control, "gap": int(gap), "seed": r["seed"],
            "n_train": len(r["split"]["train"]), "n_test": len(r["split"]["test"]),
            "test_acc_%": 100 * r["test_accuracy"], "final_train_acc_%": 100 * r["history"]["accuracy"][-1],
            "converged": converged(r["history"], converged_at)}


def leakage_controls(X: np.ndarray, y: np.ndarray, seeds, gaps=(0, 5, 10, 20, 40),
                     centre_gap: int = 5, converged_at: float = 0.95, progress: bool = True,
                     **train_kw) -> pd.DataFrame:
    """How much of the random split's accuracy is memory: the blocked split at every gap, beside a
    random split with the same number of training frames, and a block centred in its spot.

    X: (N, H, W, C) frames, y: (N,) spot labels, seeds: ints; gaps: frames dropped on each side of
    a test block (``cnn.split_indices``); centre_gap: the gap of the centred-block run.
    converged_at: a seed whose final training accuracy is below this fraction did not fit its own
    training frames ("converged" False). train_kw go to ``cnn.train`` (epochs, batch_size, ...).
    The matched random run keeps as many training frames as the blocked run, or all of the random
    split's where the blocked split keeps more (a frame or so at gap 0, from per-spot rounding).
    Returns a DataFrame, one row per run: control (``LEAKAGE_CONTROLS``), gap (frames; the matched
    random run carries the gap of the blocked run it matches), seed, n_train, n_test, test_acc_%
    and final_train_acc_% (in %), converged (bool).
    """
    rows = []
    for gap in gaps:
        for r in cnn.run_seeds(X, y, seeds, progress, split="blocked", gap=gap, **train_kw):
            rows.append(_control_row(LEAKAGE_CONTROLS[0], gap, r, converged_at))
            n_random = len(cnn.split_indices(y, r["seed"], train_kw.get("test_size", 0.2))[0])
            m = cnn.run_seeds(X, y, [r["seed"]], progress, split="random",
                              train_size=min(len(r["split"]["train"]), n_random), **train_kw)[0]
            rows.append(_control_row(LEAKAGE_CONTROLS[1], gap, m, converged_at))
    for r in cnn.run_seeds(X, y, seeds, progress, split="blocked", gap=centre_gap, block="centre",
                           **train_kw):
        rows.append(_control_row(LEAKAGE_CONTROLS[2], centre_gap, r, converged_at))
    return pd.DataFrame(rows)


_ACC_STATS = {"mean": lambda a: a.mean(), "std": lambda a: a.std(ddof=1) if len(a) > 1 else 0.0,
              "median": lambda a: a.median(), "min": lambda a: a.min(), "max": lambda a: a.max()}


def summarise_controls(runs: pd.DataFrame, by, stats=("median", "min", "max")) -> pd.DataFrame:
    """Leakage-control runs summarised per group.

    runs: :func:`leakage_controls`' table (or ``spot_grouping.controls_by_grouping``'s); by: the
    columns that make a group (e.g. ["control", "gap"]); stats: which of mean, std (0 for one run),
    median, min, max of test_acc_% to give, in that order. Returns a DataFrame, one row per group
    in order of appearance: the by columns, seeds, converged_seeds, n_train_median, acc_<stat>_%
    per stat, acc_median_converged_% (NaN when none converged).
    """
    unknown = [s for s in stats if s not in _ACC_STATS]
    if unknown:
        raise ValueError(f"unknown stats {unknown}: choose from {list(_ACC_STATS)}")

    def summarise(d):
        acc, conv = d["test_acc_%"], d[d.converged]["test_acc_%"]
        return pd.Series({"seeds": len(d), "converged_seeds": int(d.converged.sum()),
                          "n_train_median": int(d.n_train.median()),
                          **{f"acc_{s}_%": _ACC_STATS[s](acc) for s in stats},
                          "acc_median_converged_%": conv.median() if len(conv) else np.nan})

    return runs.groupby(list(by), sort=False).apply(summarise, include_groups=False).reset_index()


def memory_points(runs: pd.DataFrame) -> pd.DataFrame:
    """What memory of neighbours buys: per seed and gap, the random split with the blocked
    split's number of training frames minus the blocked (and the centred-block) run.

    runs: :func:`leakage_controls`' table. Returns a DataFrame indexed by (control, gap), control
    in "blocked", "blocked, centred" (those present), with columns memory_points_median,
    memory_points_min, memory_points_max over seeds (points of test accuracy); pairs missing
    either run are left out.
    """
    pair = runs.pivot_table(index=["gap", "seed"], columns="control", values="test_acc_%")
    matched = pair[LEAKAGE_CONTROLS[1]]
    memory = pd.concat({c: (matched - pair[c]).dropna().groupby("gap").agg(["median", "min", "max"])
                        for c in (LEAKAGE_CONTROLS[0], LEAKAGE_CONTROLS[2]) if c in pair},
                       names=["control"])
    memory.columns = [f"memory_points_{c}" for c in memory.columns]
    return memory


def memory_statement(memory: pd.DataFrame, gap: int, epochs: int, n_seeds: int) -> str:
    """The sentences that say what memory buys at one gap, from :func:`memory_points`' table
    (points with 1 decimal; one sentence per control present at that gap, "" when none)."""
    what = {"blocked": "a test block anywhere in its spot", "blocked, centred": "a test block centred in its spot"}
    return "\n".join(
        f"At gap {gap} frames and {epochs} epochs, with the training sets matched in size, the random split is "
        f"{m['memory_points_median']:.1f} points (median; {m['memory_points_min']:.1f} to {m['memory_points_max']:.1f} "
        f"over {n_seeds} seeds) more accurate than {what[c]}."
        for c in what if (c, gap) in memory.index for m in [memory.loc[(c, gap)]])


PAPER_EPOCH, PAPER_FLOOR = 45, 0.96     # Figures 3-4: about 98 % by epoch 45, never below 96 % after it


def figure_learning_curves(runs: dict, target_accuracy: float):
    """Figures 3 and 4: training (solid) and validation (dashed) accuracy (fraction) and categorical
    cross-entropy loss per epoch of every run, linear and log scale; on the accuracy panels the
    paper's claim dashed: target_accuracy (a fraction) by epoch 45, never below 96 % after it.
    runs: {split: ``cnn.run_seeds``' dicts}. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(18, 7.5), sharex=True)
    last = max(PAPER_EPOCH + 5, max(len(r["history"]["accuracy"]) for rs in runs.values() for r in rs))
    for row, scale in enumerate(("linear", "log")):
        for col, (split, metric) in enumerate([(s, m) for s in runs for m in ("accuracy", "loss")]):
            ax = axes[row, col]
            for r in runs[split]:
                h = r["history"]
                ep = np.arange(1, len(h[metric]) + 1)
                line, = ax.plot(ep, h[metric], lw=1, alpha=0.8, label=f"train, seed {r['seed']}")
                ax.plot(ep, h["val_" + metric], lw=1, ls="--", color=line.get_color(), label=f"validation, seed {r['seed']}")
            if metric == "accuracy":
                ax.axhline(target_accuracy, color="r", lw=1, ls="--",
                           label=f"paper: {target_accuracy:.0%} validation accuracy by epoch {PAPER_EPOCH}")
                ax.hlines(PAPER_FLOOR, PAPER_EPOCH, last, color="m", lw=1, ls="--",
                          label=f"paper: never below {PAPER_FLOOR:.0%} after epoch {PAPER_EPOCH}")
                ax.axvline(PAPER_EPOCH, color="0.5", lw=0.8, ls=":")
            ax.set_yscale(scale); ax.set_title(f"{metric}, {split} split ({scale})"); ax.grid(alpha=0.3)
            ax.set_ylabel("accuracy (fraction)" if metric == "accuracy" else "loss (categorical cross-entropy)")
            if row == 1:
                ax.set_xlabel("epoch")
    fig.suptitle("Figures 3 and 4: learning curves over seeds (solid: train, dashed: validation = test split)")
    fig.tight_layout(rect=(0, 0, 0.86, 1))
    fig.legend(*axes[0, 0].get_legend_handles_labels(), fontsize=8, loc="center left", bbox_to_anchor=(0.86, 0.5))
    return fig


def figure_leakage(ctrl: pd.DataFrame, title: str):
    """Test accuracy of every leakage-control run against its gap (hollow: not converged), with
    each control's median per gap as a line; ctrl: :func:`leakage_controls`' table. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for control, color, mk in zip(LEAKAGE_CONTROLS, ("tab:red", "tab:blue", "tab:green"), "osD"):
        d = ctrl[ctrl.control == control]
        for conv, fill in ((True, color), (False, "none")):
            e = d[d.converged == conv]
            ax.scatter(e.gap, e["test_acc_%"], marker=mk, facecolors=fill, edgecolors=color, alpha=0.8,
                       label=f"{control}{'' if conv else ' (not converged)'}" if len(e) else None)
        med = d.groupby("gap")["test_acc_%"].median()
        if len(med) > 1:
            ax.plot(med.index, med.values, color=color, lw=1.2)
    ax.set_xlabel("gap: frames dropped on each side of a test block"); ax.set_ylabel("test accuracy (%)")
    ax.set_ylim(0, 102); ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    return fig


def _splits(per_seed: pd.DataFrame, name: str) -> str:
    """The final test accuracy of each split with its seed range, and whether the ranges order them."""
    g = {s: d["test_acc_%"] for s, d in per_seed.groupby("split")}
    conv = per_seed.groupby("split").converged.sum()
    each = " and ".join(f"{wording.num(a.mean())} % {wording.span(a.min(), a.max())} on the {s} split "
                        f"({int(conv[s])} of {len(a)} converged)" for s, a in sorted(g.items(), reverse=True))
    arms = {f"the {s} split": (len(a), a.min(), a.max()) for s, a in g.items()}
    return f"On {name}, the final test accuracy (mean [seed min, max]) is {each}; their order is {wording.order(arms)}."


def _epochs(per_seed: pd.DataFrame) -> str:
    """When the random split's seeds reach the target validation accuracy, and how low it falls after
    epoch 45 (the paper: about 45, never below 96 %)."""
    r = per_seed[per_seed.split == "random"]
    col = next(c for c in r.columns if c.startswith("epoch_to_"))
    target = col[len("epoch_to_"):].replace("%", " %")
    ep = pd.to_numeric(r[col], errors="coerce").dropna()
    low = r[f"min_val_acc_after_ep{PAPER_EPOCH}_%"]
    reached = (f"{len(ep)} of {len(r)} random-split seeds reached {target} validation accuracy, at epochs "
               f"{int(ep.min())}-{int(ep.max())}" if len(ep) else
               f"No random-split seed reached {target} validation accuracy")
    return (f"{reached} (the paper: about epoch {PAPER_EPOCH}); after epoch {PAPER_EPOCH} the lowest validation accuracy "
            f"lies in {wording.span(low.min(), low.max())} % over seeds (the paper: never below 96 %).")


def _memory(summary: pd.DataFrame, gap: int, epochs) -> str:
    """What memory of neighbours buys at one gap (leakage_summary.csv's memory_points_*), with its sign."""
    parts = []
    for control, what in (("blocked", "the blocked split's"), ("blocked, centred", "the centred block's")):
        m = summary[(summary.control == control) & (summary.gap == gap)]
        if len(m) and pd.notna(m.memory_points_median.iloc[0]):
            m = m.iloc[0]
            parts.append(f"minus {what} is {wording.num(m.memory_points_median, 1)} points (median; per seed "
                         f"{wording.num(m.memory_points_min, 1)} to {wording.num(m.memory_points_max, 1)}, "
                         f"{wording.sign(m.memory_points_min, m.memory_points_max, m.seeds)})")
    if not parts:
        return ""
    return (f"With training sets matched in size (gap {gap}, {epochs} epochs, {wording.count(summary.seeds.max(), 'seed')}), the "
            f"random split's accuracy {', and '.join(parts)}.")


def conclusion(out_dir) -> str:
    """Notebook 02's last cell: the verdict on Figures 3-4 for its dataset, then each split's final
    test accuracy with its seed range, when the target was reached, and what memory of neighbours
    buys (points of accuracy, with its sign over seeds). out_dir: the notebook's folder
    (``<results_dir>/02_training_over_seeds``) with per_seed.csv, leakage_summary.csv and
    manifest.json. Returns Markdown."""
    out_dir = Path(out_dir)
    name = wording.verdict.dataset_name(out_dir.parent)
    per_seed = pd.read_csv(out_dir / "per_seed.csv")
    params = json.loads((out_dir / "manifest.json").read_text())["parameters"]
    sentences = [_splits(per_seed, name), _epochs(per_seed)]
    if (out_dir / "leakage_summary.csv").is_file():
        sentences.append(_memory(pd.read_csv(out_dir / "leakage_summary.csv"), params.get("gap", 5),
                                 params.get("sweep_epochs", "?")))
    return wording.compose(out_dir.parent, "02_training_over_seeds", sentences)
