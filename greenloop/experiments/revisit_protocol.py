"""Notebook 12's study: places learnt on the first traversal, named on the revisit.

One function per table of ``notebooks/12_revisit_protocol.ipynb``; each returns unrounded values
(accuracies in %, precision and recall as fractions), and the notebook rounds them by
``DECIMALS`` where it writes the tables. The main paper's CNN (``greenloop.methods.dictionary.cnn``), its spots
(``greenloop.methods.dictionary.spots``) and the dictionary's counting rule (``greenloop.methods.dictionary.dictionary``) are the
building blocks; what is here is the protocol: train on the frames before the first revisit,
name every revisit frame, then choose the dictionary's τ on one part of the revisits and score
it on the other.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from greenloop import evaluate, groundtruth, report
from greenloop.datasets import sequence
from greenloop.experiments import training_over_seeds
from greenloop.groundtruth import DEFAULT_EXCLUDE
from greenloop.methods.dictionary import cnn, dictionary, spots
from greenloop.study import verdict, wording

# decimals of the written tables' columns (rounded only where the notebook writes them)
DECIMALS = {"final_train_acc_%": 2, "in_traversal_test_acc_%": 2, "revisit_acc_%": 2, "mean": 2, "std": 2,
            "median": 2, "min": 2, "max": 2, "precision": 4, "recall": 4}
NOT_AVAILABLE = ("not available: no honest tuning/scoring split (every revisit frame lies within L frames of "
                 "the others)")


class FirstTraversal(NamedTuple):
    """The places and the revisit of a sequence of N frames.

    X: (N, 32, 32, 1) float32 frames in [0, 1] (the paper's preprocessing); GT: (N, N) bool;
    n_ref: frames 0 .. n_ref - 1 are the first traversal; y: (n_ref,) int spot labels (K spots of
    frames_per_spot frames); queries: (Q,) int revisit frames (a ground-truth partner in the
    first traversal); acceptable: (Q, K) bool, spot k holds a partner of query q; text: the line
    the notebook prints.
    """
    X: np.ndarray
    GT: np.ndarray
    n_ref: int
    y: np.ndarray
    queries: np.ndarray
    acceptable: np.ndarray
    text: str


class Tuned(NamedTuple):
    """The dictionary table and what its figure needs: table (one row per seed and τ rule),
    curve (one row per seed and candidate τ: tune_f1, score_precision, score_recall), tau_paper,
    note (Markdown, or None where an honest split exists), scored (what the scores are on), text."""
    table: pd.DataFrame
    curve: pd.DataFrame
    tau_paper: int
    note: str | None
    scored: str
    text: str


def first_traversal(dataset, frames_per_spot: int, loop_threshold: float, exclude: int,
                    first_traversal_end: int | None = None) -> FirstTraversal:
    """The frames, the ground truth, the first traversal's spots and the revisit frames.

    dataset: a sequence folder; frames_per_spot: L (frames); loop_threshold, exclude: as
    ``groundtruth.for_sequence``; first_traversal_end: the first frame after the first traversal,
    None for the ground truth's first revisit frame (``spots.first_traversal``: ValueError naming the
    fix where it holds fewer than 2 spots).
    """
    X = sequence.load_frames(dataset)
    GT = groundtruth.for_sequence(dataset, threshold=loop_threshold, exclude=exclude)
    n_ref, y = spots.first_traversal(GT, frames_per_spot, first_traversal_end)
    queries, acceptable = spots.revisit_targets(y, GT, n_ref)
    text = (f"first traversal: frames 0..{n_ref - 1} ({int(y.max()) + 1} spots of {frames_per_spot}); "
            f"{len(queries)} revisit frames after it have a ground-truth partner in it")
    return FirstTraversal(X, GT, n_ref, y, queries, acceptable, text)


def revisit_predictions(X_first: np.ndarray, y: np.ndarray, X_revisit: np.ndarray, acceptable,
                        seeds, splits=("random", "blocked"), converged_at: float = 0.95, **train_kw):
    """The per-seed table: the places learnt on the first traversal, named on the revisit.

    X_first: (n_ref, H, W, C) frames of the first traversal, y: (n_ref,) their spot labels (K
    spots); the CNN is trained on them (``cnn.run_seeds``) once per split in ``splits`` and seed.
    X_revisit: (Q, H, W, C) revisit frames, never trained on; acceptable: (Q, K) bool, True where
    spot k holds a ground-truth partner of revisit frame q (``spots.revisit_targets``): a revisit
    frame is named right when its predicted spot is acceptable. converged_at: a fraction, as
    ``training_over_seeds.converged``. train_kw go to ``cnn.run_seeds`` (epochs, stop_patience, ...).
    Returns (runs, per_seed, revisit): runs {split: run_seeds' list}; per_seed, a DataFrame with
    one row per (split, seed): split, seed, n_train, epochs (trained), final_train_acc_%, converged
    (``training_over_seeds.converged``), in_traversal_test_acc_% (the run's own test split),
    revisit_acc_% (in %, unrounded), revisit_frames (Q); revisit
    {(split, seed): dict(pred (Q,) int64 predicted spots, right (Q,) bool)}.
    """
    ok = np.asarray(acceptable, dtype=bool)
    if ok.ndim != 2 or len(ok) != len(X_revisit):
        raise ValueError(f"acceptable must be (Q, K) bool for the {len(X_revisit)} revisit frames, got {ok.shape}")
    train_kw.setdefault("progress", False)
    runs = {split: cnn.run_seeds(X_first, y, seeds, split=split, **train_kw) for split in splits}
    rows, revisit = [], {}
    for split, rs in runs.items():
        for r in rs:
            p = cnn.predict(r["model"], X_revisit)
            right = ok[np.arange(len(ok)), p]
            revisit[split, r["seed"]] = {"pred": p, "right": right}
            rows.append({"split": split, "seed": r["seed"], "n_train": len(r["split"]["train"]),
                         "epochs": len(r["history"]["accuracy"]),
                         "final_train_acc_%": 100 * r["history"]["accuracy"][-1],
                         "converged": training_over_seeds.converged(r["history"], converged_at),
                         "in_traversal_test_acc_%": 100 * r["test_accuracy"],
                         "revisit_acc_%": 100 * right.mean(), "revisit_frames": len(ok)})
    return runs, pd.DataFrame(rows), revisit


def accuracy_summary(per_seed: pd.DataFrame) -> pd.DataFrame:
    """The summary table: accuracy over seeds by split and by what is scored.

    per_seed: :func:`revisit_predictions`' table. Returns one row per (split, scored_on), scored_on
    in "in_traversal_test_acc_%", "revisit_acc_%": seeds (count), mean, std (sample, ddof 1),
    median, min, max, in %, unrounded.
    """
    long = per_seed.melt(id_vars=["split", "seed"], value_vars=["in_traversal_test_acc_%", "revisit_acc_%"],
                         var_name="scored_on", value_name="acc_%")
    return (long.groupby(["split", "scored_on"])["acc_%"]
            .agg(seeds="count", mean="mean", std="std", median="median", min="min", max="max").reset_index())


def tune_and_score(pred, reference_labels, gt, taus, tune, score, paper_tau: int,
                   exclude: int = DEFAULT_EXCLUDE) -> tuple[list[dict], list[dict]]:
    """The dictionary's τ chosen on a tuning part and scored on a scoring part, beside the paper's τ.

    pred, reference_labels, gt, exclude: as in ``dictionary.score_closures`` ((T,) labels, (T, T)
    bool). taus: candidate thresholds (detections); tune, score: (T,) bool masks of the tuning and
    the scoring frames (``evaluate.split_mask``), or both None when no honest split exists: then
    nothing is chosen and only the paper's τ (fixed in advance) is scored, on every frame.
    paper_tau: the paper's τ = L + Δ (``dictionary.threshold``).
    Returns (rules, curve). rules: one dict per τ rule ("chosen on the tuning part" by
    ``dictionary.choose_threshold``, then "paper: L + Δ"; only "paper: L + Δ, every frame (no
    honest split)" without a split): tau_rule, tau, precision, recall (fractions, unrounded),
    flagged_frames, false_frames, events, false_events, first_delay_frames (the first run of
    revisit frames' delay that is not None, else None). curve: one dict per candidate τ: tau,
    tune_f1 (NaN without a split), score_precision, score_recall (frame level, on the scoring part).
    """
    if (tune is None) != (score is None):
        raise ValueError("tune and score must both be masks, or both None (no honest split)")
    if tune is not None:
        tau, tune_rows = dictionary.choose_threshold(pred, reference_labels, gt, taus, tune, exclude)
        f1 = {row["tau"]: row["f1"] for row in tune_rows}
        rules = (("chosen on the tuning part", tau), ("paper: L + Δ", paper_tau))
    else:
        rules = (("paper: L + Δ, every frame (no honest split)", paper_tau),)
    curve = []
    for t in taus:
        s = dictionary.score_closures(pred, reference_labels, gt, t, exclude, queries=score)
        curve.append({"tau": t, "tune_f1": f1[int(t)] if tune is not None else np.nan,
                      "score_precision": s["precision"], "score_recall": s["recall"]})
    out = []
    for rule, t in rules:
        s = dictionary.score_closures(pred, reference_labels, gt, t, exclude, queries=score)
        out.append({"tau_rule": rule, "tau": t, "precision": s["precision"], "recall": s["recall"],
                    "flagged_frames": s["flagged"], "false_frames": s["false_frames"],
                    "events": s["events"], "false_events": s["false_events"],
                    "first_delay_frames": next((d for d in s["delays"] if d is not None), None)})
    return out, curve


def dictionary_scores(t: FirstTraversal, runs, tau_list, tune_fraction: float, frames_per_spot: int,
                      margin: int, exclude: int) -> Tuned:
    """The dictionary table: over the whole sequence, on each model's predictions, τ chosen on a
    tuning part of the revisits and scored on the other part, beside the paper's τ = L + Δ.

    t: :func:`first_traversal`. runs: ``cnn.run_seeds``' list (dicts with seed and model; the
    random-split runs in notebook 12). tau_list:
    candidate τ; tune_fraction: share of the revisit frames in the tuning part
    (``evaluate.honest_split`` with a gap of frames_per_spot frames); margin: the paper's Δ;
    exclude: frames. Frames after the first traversal belong to no spot. Where no honest split
    exists no τ is chosen and the paper's τ is scored on every frame (note says so).
    """
    N = len(t.X)
    tune, score, note = evaluate.honest_split(
        N, tune_fraction, t.GT, frames_per_spot, dropped="the τ chosen on a tuning part and its scores",
        kept="the paper's τ = L + Δ, fixed in advance, is scored on every frame instead")
    ref = np.r_[t.y, -np.ones(N - t.n_ref, dtype=np.int64)]
    tau_paper = dictionary.threshold(frames_per_spot, 0.1, margin)["tau"]
    rows, curve = [], []
    for r in runs:
        rules, c = tune_and_score(cnn.predict(r["model"], t.X), ref, t.GT, tau_list, tune, score, tau_paper, exclude)
        rows += [{"seed": r["seed"], **row} for row in rules]
        curve += [{"seed": r["seed"], **row} for row in c]
    text = "" if note else (f"tuning part: frames < {int(np.flatnonzero(tune)[-1]) + 1}; scoring part: frames >= "
                            f"{int(np.flatnonzero(score)[0])} ({int((score & np.tril(t.GT, -1).any(1)).sum())} "
                            f"revisit frames)")
    return Tuned(pd.DataFrame(rows), pd.DataFrame(curve), tau_paper, note,
                 "scoring part" if note is None else "whole sequence, no split", text)


def _over_seeds(per_seed, split, col) -> str:
    v = per_seed[per_seed.split == split][col]
    return f"{v.mean():.2f} ± {v.std():.2f} (median {v.median():.2f}, {len(v)} seeds)"


def paper_vs_run(per_seed: pd.DataFrame, tuned: Tuned, frames_per_spot: int) -> pd.DataFrame:
    """The paper's 98 % and τ = 70 beside this run's accuracies (mean ± std over seeds) and the
    dictionary's frame-level precision / recall (``report.paper_vs_run``'s table)."""
    d = tuned.table
    chosen, paper = d[d.tau_rule.str.startswith("chosen")], d[~d.tau_rule.str.startswith("chosen")]
    split = tuned.note is None
    acc = "in_traversal_test_acc_%"
    return report.paper_vs_run([
        (f"test accuracy, random 80/20 split, L = {frames_per_spot} (%)", 98, _over_seeds(per_seed, "random", acc),
         "paper: all frames of the real GreenHouse set; here the first traversal only"),
        ("test accuracy, blocked split (%)", None, _over_seeds(per_seed, "blocked", acc),
         "beyond the paper: no near-duplicate neighbour in training"),
        ("revisit accuracy, random-split models (%)", None, _over_seeds(per_seed, "random", "revisit_acc_%"),
         "beyond the paper: frames never trained on, a real return to the place"),
        ("revisit accuracy, blocked-split models (%)", None, _over_seeds(per_seed, "blocked", "revisit_acc_%"),
         "beyond the paper"),
        ("dictionary τ", 70,
         f"chosen on the tuning part: {sorted(chosen.tau.unique().tolist())}" if split else NOT_AVAILABLE,
         "paper: L + Δ = 60 + 10, argued from accuracy, never scored"),
        ("dictionary precision / recall on the scoring part, chosen τ", None,
         f"{chosen.precision.mean():.3f} / {chosen.recall.mean():.3f} (mean of {len(chosen)} seeds)" if split
         else NOT_AVAILABLE, "frame level"),
        (f"dictionary precision / recall on the {tuned.scored}, τ = {tuned.tau_paper}", None,
         f"{paper.precision.mean():.3f} / {paper.recall.mean():.3f} (mean of {len(paper)} seeds)", "frame level"),
    ])


def _arm(row, unit: str = " %") -> tuple[str, tuple]:
    """(text, (n, min, max)) of one row of summary_table.csv: 'mean [min, max] %' and its seed range."""
    return f"{wording.num(row['mean'])} {wording.span(row['min'], row['max'], unit=unit)}", (row.seeds, row["min"], row["max"])


def _accuracy_sentence(summary: pd.DataFrame, split: str, dataset: str) -> str:
    """One split's models: in-traversal test accuracy against revisit accuracy (%, over seeds)."""
    t = summary[summary.split == split].set_index("scored_on")
    (a, arm_a), (b, arm_b) = _arm(t.loc["in_traversal_test_acc_%"]), _arm(t.loc["revisit_acc_%"])
    head = f"On {dataset}, the random-split models (the paper's protocol; mean [min, max] over {int(arm_a[0])} seeds): " \
        if split == "random" else "The blocked-split models: "
    text = head + wording.pair_order(f"in-traversal test accuracy {a}", arm_a, f"the revisit accuracy {b}", arm_b)
    if split == "random":
        text += f"; the paper's 98 % is reached by {'the best seed' if arm_a[2] >= 98 else 'no seed'}"
    return text + "."


def _budget_sentence(label: str) -> str:
    """The budget label (``training_over_seeds.budget_label``, summary.json's "budget") as the first
    sentence, "" where the runs converged."""
    return (f"**{label[0].upper() + label[1:]}**: most runs ended on their epoch budget with their training accuracy "
            "still able to rise, so the accuracies below are the budget's, not the protocol's." if label else "")


def _dictionary_sentence(d: pd.DataFrame, honest: bool) -> str:
    """The dictionary's frame-level precision and recall over seeds (dictionary_tuned.csv): at the τ chosen
    on the tuning part against the paper's τ, on the scoring part; the paper's τ alone without a split."""
    chosen, paper = d[d.tau_rule.str.startswith("chosen")], d[~d.tau_rule.str.startswith("chosen")]
    tau = int(paper.tau.iloc[0])
    arm = lambda t, c: (len(t), t[c].min(), t[c].max())
    if not honest:
        return (f"The dictionary at the paper's τ = {tau} on every frame (no honest split): precision "
                f"{wording.span(*arm(paper, 'precision')[1:])}, recall {wording.span(*arm(paper, 'recall')[1:])} over seeds.")
    parts = [wording.pair_order(f"{c} at the chosen τ {wording.span(*arm(chosen, c)[1:])}", arm(chosen, c),
                           f"at τ = {tau} {wording.span(*arm(paper, c)[1:])}", arm(paper, c)) for c in ("precision", "recall")]
    return (f"The dictionary on the scoring part, τ chosen on the tuning part ({sorted(set(chosen.tau.astype(int)))}) "
            f"against the paper's τ = L + Δ = {tau}, frame level over seeds: " + "; ".join(parts) + ".")


def conclusion(out_dir) -> str:
    """Notebook 12's last cell, in Markdown (no paper claim of ``study.verdict`` is about this protocol):
    the budget label where fewer than half of the runs converged (summary.json's "budget"), the in-traversal test accuracy against the revisit accuracy of the same models (%, [min, max] over
    seeds, summary_table.csv), the paper's 98 %, and the dictionary at the chosen and the paper's τ
    (dictionary_tuned.csv, summary.json under ``out_dir``)."""
    out_dir = Path(out_dir)
    summary = pd.read_csv(out_dir / "summary_table.csv")
    info = json.loads((out_dir / "summary.json").read_text())
    name = verdict.dataset_name(out_dir.parent)
    lines = [_budget_sentence(info.get("budget", "")), _accuracy_sentence(summary, "random", name),
             _accuracy_sentence(summary, "blocked", name),
             _dictionary_sentence(pd.read_csv(out_dir / "dictionary_tuned.csv"), info["split"]["honest"])]
    return wording.heading(Path(out_dir).parent, "12_revisit_protocol") + "\n\n" + " ".join(x for x in lines if x)


# ----------------------------------------------------------------------------------- figures
def figure_accuracy(per_seed: pd.DataFrame, runs, revisit, queries, frames_per_spot: int):
    """Test accuracy per seed in the traversal and on the revisit (left), and the running mean of
    the revisit accuracy along the revisit (right)."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2), gridspec_kw={"width_ratios": [1, 2]})
    ax = axes[0]
    cols = [(s, c) for s in ("random", "blocked") for c in ("in_traversal_test_acc_%", "revisit_acc_%")]
    for k, (split, col) in enumerate(cols):
        v = per_seed[per_seed.split == split][col]
        ax.scatter(np.full(len(v), k), v, color="C0" if col.startswith("in") else "C3", zorder=3)
        ax.hlines(v.median(), k - 0.3, k + 0.3, color="k", lw=1.5)
    ax.set_xticks(range(4), ["random split\nin traversal", "random split\nrevisit", "blocked split\nin traversal",
                             "blocked split\nrevisit"], fontsize=8)
    ax.axhline(98, color="k", ls="--", lw=1, label="paper: 98 % (random split, all frames, real GreenHouse)")
    ax.set_xlabel("split of the training frames, frames scored")
    ax.set_ylabel("accuracy (%)"); ax.set_ylim(0, 102); ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.3), borderaxespad=0)
    ax.set_title(f"test accuracy per seed (bar: median), L = {frames_per_spot}", fontsize=10)
    ax = axes[1]
    win = max(5, len(queries) // 60)
    for split, ls in (("random", "-"), ("blocked", "--")):
        for r in runs[split]:
            ok = revisit[split, r["seed"]]["right"].astype(float)
            ax.plot(queries, 100 * np.convolve(ok, np.ones(win) / win, mode="same"), ls=ls, lw=1,
                    label=f"{split}, seed {r['seed']}")
    ax.set_xlabel("revisit frame (index in the sequence)")
    ax.set_ylabel(f"revisit accuracy (%), running mean of {win} frames")
    ax.set_ylim(0, 102); ax.grid(alpha=0.3); ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    ax.set_title("where along the revisit the places are recognised", fontsize=10)
    fig.tight_layout()
    return fig


def _rgb(path):
    """One frame file as (H, W, 3) uint8 RGB, for a figure."""
    return sequence.read_image(path)[..., ::-1]


def figure_examples(dataset, t: FirstTraversal, pred, right, examples: int, seed):
    """Up to ``examples`` revisit frames named right and as many named wrong, each beside a
    ground-truth partner and the middle frame of the spot the model named; None without any.

    pred, right: (Q,) a model's predicted spots and whether each is right (:func:`revisit_predictions`).
    """
    import matplotlib.pyplot as plt

    paths = sequence.list_frames(dataset)
    pick = []
    for good, idx in ((True, np.flatnonzero(right)), (False, np.flatnonzero(~right))):    # spread along the revisit
        if len(idx):
            pick += [(q, good) for q in idx[np.linspace(0, len(idx) - 1, min(examples, len(idx))).astype(int)]]
    if not pick:
        return None
    fig, axes = plt.subplots(len(pick), 3, figsize=(8, 2.1 * len(pick)), squeeze=False)
    for row, (q, good) in zip(axes, pick):
        f = int(t.queries[q]); partners = np.flatnonzero(t.GT[f, :t.n_ref]); c = int(pred[q])
        mate = int(partners[len(partners) // 2])
        named = int(np.flatnonzero(t.y == c)[len(np.flatnonzero(t.y == c)) // 2])
        for ax, (i, title) in zip(row, [(f, f"revisit frame {f}"), (mate, f"its partner {mate} (spot {t.y[mate]})"),
                                         (named, f"named spot {c} (frame {named}) {'right' if good else 'WRONG'}")]):
            ax.imshow(_rgb(paths[i])); ax.axis("off")
            ax.set_title(title, fontsize=8, color="k" if good or i != named else "C3")
    fig.suptitle(f"seed {seed}, random-split model: revisit frames named right (top) and wrong (bottom)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return fig


def figure_tau(tuned: Tuned):
    """Frame-level precision and recall of the dictionary per τ (and the tuning part's F1), the
    chosen τ dotted, the paper's τ dashed; the legend beside the axes."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.2))
    for seed, c in tuned.curve.groupby("seed"):
        line, = ax.plot(c.tau, c.score_precision, "-o", ms=3, label=f"seed {seed}: precision ({tuned.scored})")
        ax.plot(c.tau, c.score_recall, "--", color=line.get_color(), label=f"seed {seed}: recall ({tuned.scored})")
        if tuned.note is None:
            ax.plot(c.tau, c.tune_f1, ":", color=line.get_color(), lw=1, label=f"seed {seed}: F1 (tuning part)")
    for k, tau in enumerate(tuned.table[tuned.table.tau_rule.str.startswith("chosen")].tau.unique()):
        ax.axvline(tau, color="k", lw=0.8, ls=":", label="τ chosen on the tuning part" if k == 0 else None)
    ax.axvline(tuned.tau_paper, color="k", ls="--", lw=1.2, label=f"paper's τ = L + Δ = {tuned.tau_paper}")
    ax.set_xlabel("threshold τ (detections of one spot)"); ax.set_ylabel("frame-level precision / recall / F1")
    ax.set_ylim(-0.02, 1.02); ax.grid(alpha=0.3); ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    ax.set_title("dictionary detector: dotted verticals = τ chosen on the tuning part" if tuned.note is None else
                 "dictionary detector on every frame: no honest split, no τ chosen", fontsize=10)
    fig.tight_layout()
    return fig
