"""Notebook 01's study: how many frames make a spot (the paper's Table 1), with the random split
and under the leakage control of notebook 02.

Every table comes back unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from greenloop.experiments import training_over_seeds
from greenloop.methods.dictionary import cnn, spots
from greenloop.study import verdict, wording

PAPER_ACC = {50: 97, 60: 98, 70: 97}       # Table 1, %  (the reference column only)
PAPER_SPOTS = {50: 46, 60: 38, 70: 33}


def accuracy_over_seeds(runs: list[dict], converged_at: float = 0.95) -> dict:
    """Test accuracy of one grouping over seeds (Table 1's columns).

    runs: ``cnn.run_seeds``' dicts of one grouping (at least one). Returns {'seeds', 'acc_mean_%',
    'acc_std_%' (0 with one seed), 'acc_median_%', 'acc_min_%', 'acc_max_%',
    'final_train_acc_min_%' (the worst seed's final training accuracy), 'converged_seeds'
    (``training_over_seeds.converged``), 'acc_median_converged_%' (NaN when none converged),
    'epochs_min', 'epochs_max' (epochs the seeds ran: below the cap where early stopping ended a run),
    'budget_limited' (``verdict.budget_limited``: fewer than half of the seeds converged)}:
    accuracies in %.
    """
    acc = np.array([r["test_accuracy"] for r in runs]) * 100
    conv = np.array([training_over_seeds.converged(r["history"], converged_at) for r in runs])
    return {"seeds": len(acc), "acc_mean_%": acc.mean(), "acc_std_%": acc.std(ddof=1) if len(acc) > 1 else 0.0,
            "acc_median_%": np.median(acc), "acc_min_%": acc.min(), "acc_max_%": acc.max(),
            "final_train_acc_min_%": 100 * min(r["history"]["accuracy"][-1] for r in runs),
            "converged_seeds": int(conv.sum()),
            "acc_median_converged_%": np.median(acc[conv]) if conv.any() else np.nan,
            "epochs_min": min(len(r["history"]["accuracy"]) for r in runs),
            "epochs_max": max(len(r["history"]["accuracy"]) for r in runs),
            "budget_limited": verdict.budget_limited(int(conv.sum()), len(acc))}


def table1(X: np.ndarray, frames_per_spot_list, frames_per_spot: int, seeds, seeds_per_grouping,
           converged_at: float = 0.95, **train_kw) -> tuple[pd.DataFrame, dict]:
    """Table 1: the random split's test accuracy over seeds for every spot length L.

    X: (N, H, W, C) frames; frames_per_spot_list: the L to group by (``spots.group``);
    seeds: the seeds of L = frames_per_spot (the paper's), seeds_per_grouping those of every
    other L; converged_at: as in
    :func:`accuracy_over_seeds`; train_kw go to ``cnn.train`` (epochs, batch_size, ...).
    Returns (table, runs): table one row per L: frames_per_spot, spots, last_spot_frames,
    :func:`accuracy_over_seeds`' columns, paper_acc_% and paper_spots (the paper's, "" where it
    gives none); runs {L: ``cnn.run_seeds``' dicts}.
    """
    rows, runs = [], {}
    for L in frames_per_spot_list:
        y = spots.group(len(X), L)
        runs[L] = cnn.run_seeds(X, y, seeds if L == frames_per_spot else seeds_per_grouping, **train_kw)
        rows.append({"frames_per_spot": L, "spots": int(y.max() + 1), "last_spot_frames": int(np.bincount(y)[-1]),
                     **accuracy_over_seeds(runs[L], converged_at),
                     "paper_acc_%": PAPER_ACC.get(L, ""), "paper_spots": PAPER_SPOTS.get(L, "")})
    return pd.DataFrame(rows), runs


def paper_rows(table1: pd.DataFrame) -> list[tuple]:
    """Table 1's paper-vs-run rows for ``report.paper_vs_run``: per L, the accuracy (mean ±
    std, median, min, seeds, converged, 2 decimals) and the number of spots."""
    rows = []
    for _, r in table1.iterrows():
        L = int(r.frames_per_spot)
        rows.append((f"accuracy, L = {L} (%)", PAPER_ACC.get(L),
                     f"{r['acc_mean_%']:.2f} ± {r['acc_std_%']:.2f}, median {r['acc_median_%']:.2f} "
                     f"(min {r['acc_min_%']:.2f}, {int(r.seeds)} seeds, {int(r.converged_seeds)} converged)"))
        rows.append((f"spots, L = {L}", PAPER_SPOTS.get(L), int(r.spots)))
    return rows


def controls_by_grouping(X: np.ndarray, frames_per_spot_list, seeds, gap: int, converged_at: float = 0.95,
                         progress: bool = True, **train_kw) -> pd.DataFrame:
    """Table 1 under the leakage control: ``training_over_seeds.leakage_controls`` at one gap for
    every grouping.

    X: (N, H, W, C) frames; frames_per_spot_list: the L (spot labels ``spots.group(N, L)``);
    seeds: ints; gap: frames dropped on each side of a test block, for the blocked and the
    centred runs alike. converged_at, train_kw: as in ``leakage_controls``. Returns its rows, L
    after L, each with 'frames_per_spot': L added last.
    """
    return pd.concat([training_over_seeds.leakage_controls(
        X, spots.group(len(X), L), seeds, gaps=[gap], centre_gap=gap, converged_at=converged_at,
        progress=progress, **train_kw).assign(frames_per_spot=L) for L in frames_per_spot_list], ignore_index=True)


def figure_table1(runs: dict, table1: pd.DataFrame, converged_at: float):
    """Table 1 as a figure: every seed's test accuracy (%) per L (filled: converged, hollow: not, by
    ``training_over_seeds.converged``), the median, the mean ± std beside them (no line joins the L
    values: their order is the seed ranges' to resolve), the paper's value per L as a dashed segment, and "budget-limited" written beside the lowest seed of every L whose row says so
    (and on a second title line).
    Returns the figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4))
    first, shown = next(iter(runs)), set()
    for L, rs in runs.items():       # the seeds left of L, the mean and std right of it: no marker hides another
        acc = np.array([r["test_accuracy"] * 100 for r in rs])
        conv = np.array([training_over_seeds.converged(r["history"], converged_at) for r in rs])
        for c, style in ((True, dict(color="tab:blue", label="one seed, converged")),
                         (False, dict(facecolors="white", edgecolors="tab:blue", linewidths=1.5,
                                      label="one seed, did not converge (hollow)"))):
            if (conv == c).any():
                ax.scatter(np.full((conv == c).sum(), L - 1.2), acc[conv == c], s=30, zorder=3,
                           **dict(style, label=None if c in shown else style["label"]))
                shown.add(c)
        ax.hlines(np.median(acc), L - 2.5, L + 0.2, color="tab:orange", lw=2, label="median" if L == first else None)
    # no line joins the L values: an order of L is for the seed ranges (the conclusion) to resolve, not for a line to draw
    ax.errorbar(table1.frames_per_spot + 1.2, table1["acc_mean_%"], yerr=table1["acc_std_%"], color="k", capsize=4,
                fmt="o", ms=4, ls="none", label="this run: mean ± std")
    paper = [L for L in runs if L in PAPER_ACC]
    for k, L in enumerate(paper):
        ax.hlines(PAPER_ACC[L], L - 3, L + 3, color="r", ls="--", lw=1.5,
                  label="paper (real set): " + " / ".join(f"{PAPER_ACC[x]} %" for x in paper) if k == 0 else None)
    limited = table1[table1.budget_limited.astype(bool)]
    for _, r in limited.iterrows():
        ax.annotate("budget-limited", (r.frames_per_spot, r["acc_min_%"]), xytext=(8, 0), textcoords="offset points",
                    ha="left", va="center", fontsize=8, color="tab:red")
    ax.set_xticks(list(runs), [str(L) for L in runs])
    ax.set_xlabel("frames per spot L"); ax.set_ylabel("test accuracy (%), random split")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    epochs = (f"{table1.epochs_max.max()} epochs" if table1.epochs_min.min() == table1.epochs_max.max()
              else f"{table1.epochs_min.min()}-{table1.epochs_max.max()} epochs (early stopping)")
    ax.set_title(f"Table 1: accuracy vs spot length, {epochs}"
                 + (f"\nbudget-limited at L = {', '.join(map(str, limited.frames_per_spot))}: fewer than half "
                    f"of the seeds converged" if len(limited) else ""), fontsize=9)
    fig.tight_layout()
    return fig


def figure_controls(ctrl: pd.DataFrame, summary: pd.DataFrame, title: str):
    """Table 1 under the leakage control: each control's median test accuracy (%) per L as bars with a
    whisker over the seeds' min-max, every run as a dot (hollow: not converged); ctrl:
    :func:`controls_by_grouping`' table, summary its ``training_over_seeds.summarise_controls`` by
    frames_per_spot and control (with median, min and max). Returns the figure."""
    import matplotlib.pyplot as plt

    wide = summary.pivot(index="frames_per_spot", columns="control", values="acc_median_%")
    fig, ax = plt.subplots(figsize=(8.5, 4))
    w = 0.8 / len(wide.columns)
    for k, c in enumerate(wide.columns):
        d = ctrl[ctrl.control == c]
        offset = (k - (len(wide.columns) - 1) / 2) * w
        x = np.array([list(wide.index).index(L) for L in d.frames_per_spot]) + offset
        lo, hi = (summary[summary.control == c].set_index("frames_per_spot").loc[wide.index, f"acc_{s}_%"].values
                  for s in ("min", "max"))
        ax.bar(np.arange(len(wide)) + offset, wide[c].values, w, alpha=0.5, label=f"{c} (median, min-max)",
               yerr=[wide[c].values - lo, hi - wide[c].values], capsize=3, error_kw={"lw": 0.8})
        ax.scatter(x, d["test_acc_%"], s=14, zorder=3, edgecolors="k", facecolors=np.where(d.converged, "k", "none"),
                   label="one seed (hollow: did not converge)" if k == 0 else None)
    ax.set_xticks(range(len(wide)), [f"L = {L}" for L in wide.index]); ax.set_ylabel("test accuracy (%)")
    ax.set_ylim(0, 102); ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5)); ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return fig


def _random_split(t: pd.DataFrame, name: str) -> str:
    """Table 1's accuracies per L with their seed ranges, and whether the ranges order the L values."""
    arms = {f"L = {int(r.frames_per_spot)}": (int(r.seeds), r["acc_min_%"], r["acc_max_%"]) for _, r in t.iterrows()}
    each = "; ".join(f"L = {int(r.frames_per_spot)}: {wording.num(r['acc_mean_%'])} "
                     f"{wording.span(r['acc_min_%'], r['acc_max_%'])} ({wording.count(r.seeds, 'seed')}, {int(r.converged_seeds)} "
                     f"converged)" for _, r in t.iterrows())
    budget = (" Fewer than half of the seeds converged (fit their training frames, or stopped rising before the epoch "
              "cap), so these accuracies measure the training "
              "budget more than the grouping (budget-limited)." if verdict.budget_limited(t.converged_seeds.sum(), t.seeds.sum())
              else "")
    return (f"On {name}, the random split's test accuracy (%, mean [seed min, max]) is {each}; the order of L "
            f"is {wording.order(arms)}.{budget}")


def _controls(c: pd.DataFrame, epochs) -> str:
    """Table 1 under the leakage control: per control, the seed range of every L and their order."""
    parts = []
    for control, d in c.groupby("control", sort=False):
        arms = {f"L = {int(r.frames_per_spot)}": (int(r.seeds), r["acc_min_%"], r["acc_max_%"]) for _, r in d.iterrows()}
        ranges = ", ".join(f"{k} {wording.span(v[1], v[2])}" for k, v in arms.items())
        parts.append(f"{control}: {ranges} ({wording.order(arms)})")
    return (f"Under the leakage control ({wording.count(c.seeds.max(), 'seed')} per L, {epochs} epochs; test accuracy %, seed "
            f"min-max), {'; '.join(parts)}.")


def conclusion(out_dir) -> str:
    """Notebook 01's last cell: the verdicts on Table 1 for its dataset, then Table 1's accuracies with
    their seed ranges and the order of L they resolve (or not), on the random split and under the
    leakage control. out_dir: the notebook's folder (``<results_dir>/01_spot_grouping``) holding
    table1.csv, table1_controls.csv and manifest.json. Returns Markdown."""
    out_dir = Path(out_dir)
    name = wording.verdict.dataset_name(out_dir.parent)
    t = pd.read_csv(out_dir / "table1.csv")
    sentences = [_random_split(t, name)]
    if (out_dir / "table1_controls.csv").is_file():
        epochs = json.loads((out_dir / "manifest.json").read_text())["parameters"].get("control_epochs", "?")
        sentences.append(_controls(pd.read_csv(out_dir / "table1_controls.csv"), epochs))
    return wording.compose(out_dir.parent, "01_spot_grouping", sentences)
