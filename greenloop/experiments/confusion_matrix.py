"""Notebook 03's study: which spots the paper's CNN confuses (Figure 5, Table 2), on the random
and the blocked split, and how many of its errors name the same place seen at another time.

Every table comes back unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import evaluate
from greenloop.datasets import sequence
from greenloop.study import wording

PAPER_ERRORS, PAPER_TEST_FRAMES = 10, 452       # Figure 5 / Table 2: misclassified of the test frames


def errors_per_seed(runs: dict, labels, gt=None) -> pd.DataFrame:
    """Misclassified test frames of every run.

    runs: {split name: ``cnn.run_seeds``' dicts (each with 'seed', 'split' {'test': (M,) frame
    indices}, 'test_pred' (M,) predicted spots)}; labels: (N,) spot of every frame; gt: (N, N)
    bool ground-truth loops, or None (then errors on a revisited place are not counted).
    Returns a DataFrame, one row per run: split, seed, test_frames, misclassified, accuracy_%,
    errors_on_adjacent_spot, adjacent_share_% (None without errors) (``evaluate.spot_errors``),
    errors_on_same_place_other_time (``evaluate.same_place_errors``; None without gt).
    """
    labels = np.asarray(labels)
    rows = []
    for split, rs in runs.items():
        for r in rs:
            test = r["split"]["test"]
            e = evaluate.spot_errors(labels[test], r["test_pred"])
            same = None if gt is None else evaluate.same_place_errors(test, r["test_pred"], labels, gt)
            rows.append({"split": split, "seed": r["seed"], "test_frames": e["frames"], "misclassified": e["misclassified"],
                         "accuracy_%": 100 * e["accuracy"], "errors_on_adjacent_spot": e["adjacent"],
                         "adjacent_share_%": None if e["adjacent_share"] is None else 100 * e["adjacent_share"],
                         "errors_on_same_place_other_time": same})
    return pd.DataFrame(rows)


def first_seed_tables(runs: dict, labels, n_classes: int) -> tuple[dict, dict]:
    """Table 2 and Figure 5 of each split's first run: its test frames' per-spot metrics
    (``evaluate.per_spot``) and confusion matrix.

    runs: as in :func:`errors_per_seed`; labels: (N,) spots; n_classes: K. Returns (tables,
    matrices): {split: DataFrame}, {split: (K, K) int64 confusion matrix, rows true, columns
    predicted spot (sklearn's confusion_matrix)}.
    """
    from sklearn.metrics import confusion_matrix

    labels = np.asarray(labels)
    tables, matrices = {}, {}
    for split, rs in runs.items():
        t, p = labels[rs[0]["split"]["test"]], rs[0]["test_pred"]
        tables[split] = evaluate.per_spot(t, p, n_classes)
        matrices[split] = confusion_matrix(t, p, labels=np.arange(n_classes))
    return tables, matrices


def paper_rows(errors: pd.DataFrame, tables: dict, n_classes: int, has_gt: bool) -> list[tuple]:
    """The paper-vs-run rows of every split for ``report.paper_vs_run``: test frames,
    misclassified (first seed, and mean over seeds with 1 decimal), the share of errors on an
    adjacent spot and on the same place at another time (pooled over seeds, %, 1 decimal), and
    the classes with precision = recall = 1. errors: :func:`errors_per_seed`; tables:
    :func:`first_seed_tables`' per-spot tables; has_gt: whether a ground truth was given."""
    rows = []
    for split, t2 in tables.items():
        e = errors[errors.split == split]
        paper = split == "random"                   # the paper's values belong to its random split
        wrong = max(1, e["misclassified"].sum())
        rows += [
            (f"test frames ({split} split)", 452 if paper else None, int(e.test_frames.iloc[0])),
            (f"misclassified test frames, first seed ({split} split)", 10 if paper else None, int(e.misclassified.iloc[0])),
            (f"misclassified, mean over seeds ({split} split)", None,
             f"{e.misclassified.mean():.1f} (min {e.misclassified.min()}, max {e.misclassified.max()})"),
            (f"share of errors on an adjacent spot, {split} split (%)", "'most'" if paper else None,
             f"{100 * (e['errors_on_adjacent_spot'].sum() / wrong):.1f}", f"pooled over {len(e)} seeds"),
            (f"share of errors naming the same place at another time, {split} split (%)", None,
             f"{100 * e['errors_on_same_place_other_time'].sum() / wrong:.1f}" if has_gt else "no ground truth",
             "beyond the paper: the predicted spot holds a ground-truth loop partner (a revisit)"),
            (f"classes with precision = recall = 1 ({split} split)", None,
             f"{int(((t2.precision == 1) & (t2.recall == 1)).sum())} of {n_classes}"),
        ]
    return rows


def figure_confusion(runs: dict, matrices: dict):
    """Figure 5: each split's first-run confusion matrix, off-diagonal counts written in;
    runs as in :func:`errors_per_seed`, matrices :func:`first_seed_tables`'. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(matrices), figsize=(17, 7.8), squeeze=False)
    for ax, (split, cm) in zip(axes[0], matrices.items()):
        K, r0 = len(cm), runs[split][0]
        ticks = list(range(0, K, max(1, K // 19)))
        im = ax.imshow(np.ma.masked_where(cm == 0, cm), cmap="viridis", interpolation="nearest")
        for (i, j), v in np.ndenumerate(cm):
            if v and i != j:
                ax.text(j, i, v, ha="center", va="center", color="w", fontsize=6, fontweight="bold")
        ax.set_xlabel("predicted class (spot, numbered from 1 as in Table 2)"); ax.set_ylabel("true class")
        ax.set_xticks(ticks, [k + 1 for k in ticks], fontsize=7); ax.set_yticks(ticks, [k + 1 for k in ticks], fontsize=7)
        ax.set_title(f"{split} split, seed {r0['seed']}: {int(cm.sum())} test frames, {int(cm.sum() - np.trace(cm))} errors",
                     fontsize=10)
        fig.colorbar(im, ax=ax, shrink=0.8, label="test frames")
    fig.suptitle("Figure 5: confusion matrices (numbers: off-diagonal counts)")
    fig.tight_layout()
    return fig


def figure_misclassified(dataset, run: dict, labels, n: int = 6):
    """The first n misclassified test frames of one run (top), the middle frame of the spot each
    was taken for (middle) and of its true spot (bottom), in colour from the dataset's frames.
    run: one ``cnn.run_seeds`` dict; labels: (N,) spots. Returns the figure, or None when the run
    misclassified no test frame."""
    import matplotlib.pyplot as plt

    labels = np.asarray(labels)
    test, pred = run["split"]["test"], run["test_pred"]
    wrong = np.flatnonzero(pred != labels[test])[:n]
    if not len(wrong):
        return None
    paths = sequence.list_frames(dataset)
    middle = {c: int(np.flatnonzero(labels == c)[len(np.flatnonzero(labels == c)) // 2]) for c in np.unique(labels)}
    fig, axes = plt.subplots(3, len(wrong), figsize=(2.6 * len(wrong), 6.2), squeeze=False)
    for col, w in enumerate(wrong):
        f, p = int(test[w]), int(pred[w])
        for row, (k, what) in enumerate(((f, f"test frame {f}"), (middle[p], f"predicted: class {p + 1}"),
                                         (middle[labels[f]], f"true: class {labels[f] + 1}"))):
            axes[row, col].imshow(sequence.read_image(paths[k])[..., ::-1])     # BGR -> RGB
            axes[row, col].set_title(f"{what}\n(frame {k})" if row else what, fontsize=8)
            axes[row, col].axis("off")
    fig.suptitle(f"Misclassified test frames (random split, seed {run['seed']}): the frame, the middle frame of the "
                 "class it was taken for, and of its true class", fontsize=10)
    fig.tight_layout()
    return fig


def _counts(e: pd.DataFrame, name: str) -> str:
    """Misclassified test frames per split (seed ranges) and whether the accuracy ranges order the splits."""
    parts, arms = [], {}
    for split, d in sorted(e.groupby("split"), key=lambda x: x[0] != "random"):
        parts.append(f"the {split} split misclassifies {wording.between(d.misclassified.min(), d.misclassified.max())} of "
                     f"{int(d.test_frames.iloc[0])} test frames ({wording.count(len(d), 'seed')})")
        arms[f"the {split} split"] = (len(d), d["accuracy_%"].min(), d["accuracy_%"].max())
    return (f"On {name}, {' and '.join(parts)} (the paper: {PAPER_ERRORS} of {PAPER_TEST_FRAMES}); the order of "
            f"their accuracies is {wording.order(arms)}.")


def _adjacent(e: pd.DataFrame) -> str:
    """The share of the random split's errors on an adjacent spot, pooled and per seed, against the
    paper's "most" (more than half)."""
    r = e[e.split == "random"]
    share = r["adjacent_share_%"].dropna()
    if not len(share):
        return "The random split made no error, so no share of adjacent errors is measured."
    pooled = 100 * r.errors_on_adjacent_spot.sum() / r.misclassified.sum()
    if share.min() > 50:
        word = "more than half in every seed, as the paper's 'most' says"
    elif share.max() < 50:
        word = "less than half in every seed, not the 'most' the paper says"
    else:
        word = f"on both sides of half across seeds: whether 'most' holds is {wording.UNRESOLVED}"
    return (f"{wording.num(pooled, 1)} % of the random split's errors fall on an adjacent spot (per seed "
            f"{wording.span(share.min(), share.max(), 1)} %): {word}.")


def _same_place(e: pd.DataFrame) -> str:
    """The share of the random split's errors that name the same place at another time (a revisit)."""
    r = e[e.split == "random"]
    same = r.errors_on_same_place_other_time
    if same.isna().all() or r.misclassified.sum() == 0:
        return ""
    per = 100 * same / r.misclassified.where(r.misclassified > 0)
    return (f"{wording.num(100 * same.sum() / r.misclassified.sum(), 1)} % of them (per seed "
            f"{wording.span(per.min(), per.max(), 1)} %) take the frame for the spot of the same place seen at "
            f"another time (a revisit), which labels by frame index count as an error.")


def conclusion(out_dir) -> str:
    """Notebook 03's last cell: the verdict on Figure 5 / Table 2 for its dataset, then the
    misclassified test frames per split with their seed ranges, the share of errors on an adjacent
    spot against the paper's "most", and the share on a revisited place. out_dir: the notebook's
    folder (``<results_dir>/03_confusion_matrix``) holding errors_per_seed.csv. Returns Markdown."""
    out_dir = Path(out_dir)
    e = pd.read_csv(out_dir / "errors_per_seed.csv")
    name = wording.verdict.dataset_name(out_dir.parent)
    return wording.compose(out_dir.parent, "03_confusion_matrix", [_counts(e, name), _adjacent(e), _same_place(e)])
