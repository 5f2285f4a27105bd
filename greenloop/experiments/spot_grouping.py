"""Notebook 01's study: how many frames make a spot (the paper's Table 1), with the random split
and under the leakage control of notebook 02.

Every table comes back unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from greenloop import cnn, spots
from greenloop.experiments import training_over_seeds

PAPER_ACC = {50: 97, 60: 98, 70: 97}       # Table 1, %  (the reference column only)
PAPER_SPOTS = {50: 46, 60: 38, 70: 33}


def accuracy_over_seeds(runs: list[dict], converged_at: float = 0.95) -> dict:
    """Test accuracy of one grouping over seeds (Table 1's columns).

    runs: ``cnn.run_seeds``' dicts of one grouping (at least one). Returns {'seeds', 'acc_mean_%',
    'acc_std_%' (0 with one seed), 'acc_median_%', 'acc_min_%', 'acc_max_%',
    'final_train_acc_min_%' (the worst seed's final training accuracy), 'converged_seeds'
    (``training_over_seeds.converged``), 'acc_median_converged_%' (NaN when none converged)}:
    accuracies in %.
    """
    acc = np.array([r["test_accuracy"] for r in runs]) * 100
    conv = np.array([training_over_seeds.converged(r["history"], converged_at) for r in runs])
    return {"seeds": len(acc), "acc_mean_%": acc.mean(), "acc_std_%": acc.std(ddof=1) if len(acc) > 1 else 0.0,
            "acc_median_%": np.median(acc), "acc_min_%": acc.min(), "acc_max_%": acc.max(),
            "final_train_acc_min_%": 100 * min(r["history"]["accuracy"][-1] for r in runs),
            "converged_seeds": int(conv.sum()),
            "acc_median_converged_%": np.median(acc[conv]) if conv.any() else np.nan}


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
    """Table 1 as a figure: every seed's accuracy per L (hollow: not converged), the median, the
    mean ± std and the paper's values. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    first = next(iter(runs))
    for L, rs in runs.items():
        acc = [r["test_accuracy"] * 100 for r in rs]
        conv = [training_over_seeds.converged(r["history"], converged_at) for r in rs]
        ax.scatter([L] * len(acc), acc, facecolors=["tab:blue" if c else "none" for c in conv], edgecolors="tab:blue",
                   alpha=0.7, label="one seed (hollow: did not converge)" if L == first else None)
        ax.hlines(np.median(acc), L - 2, L + 2, color="tab:orange", lw=2, label="median" if L == first else None)
    ax.errorbar(table1.frames_per_spot, table1["acc_mean_%"], yerr=table1["acc_std_%"], color="k", capsize=4,
                label="this run: mean ± std")
    paper = [(L, PAPER_ACC[L]) for L in runs if L in PAPER_ACC]
    if paper:
        ax.plot(*zip(*paper), "r*", ms=12, label="paper (real set)")
    ax.set_xlabel("frames per spot L"); ax.set_ylabel("test accuracy (%)"); ax.legend()
    ax.set_title("Table 1: accuracy vs spot length")
    return fig


def figure_controls(ctrl: pd.DataFrame, summary: pd.DataFrame, title: str):
    """Table 1 under the leakage control: each control's median accuracy per L as bars, every run
    as a dot (hollow: not converged); ctrl: :func:`controls_by_grouping`' table, summary its
    ``training_over_seeds.summarise_controls`` by frames_per_spot and control. Returns the figure."""
    import matplotlib.pyplot as plt

    wide = summary.pivot(index="frames_per_spot", columns="control", values="acc_median_%")
    fig, ax = plt.subplots(figsize=(8.5, 4))
    w = 0.8 / len(wide.columns)
    for k, c in enumerate(wide.columns):
        d = ctrl[ctrl.control == c]
        offset = (k - (len(wide.columns) - 1) / 2) * w
        x = np.array([list(wide.index).index(L) for L in d.frames_per_spot]) + offset
        ax.bar(np.arange(len(wide)) + offset, wide[c].values, w, alpha=0.5, label=f"{c} (median)")
        ax.scatter(x, d["test_acc_%"], s=14, zorder=3, edgecolors="k", facecolors=np.where(d.converged, "k", "none"),
                   label="one seed (hollow: did not converge)" if k == 0 else None)
    ax.set_xticks(range(len(wide)), [f"L = {L}" for L in wide.index]); ax.set_ylabel("test accuracy (%)")
    ax.set_ylim(0, 102); ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5)); ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return fig
