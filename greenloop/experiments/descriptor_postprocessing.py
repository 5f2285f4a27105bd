"""Notebook 08's study: descriptor post-processing (Zhang 2017, the ZCA paper) tuned honestly.

Four variants of each descriptor (raw, L2, PCA-whitened, ZCA; :func:`whitened_variants`), each with
and without a median filter of its similarity matrix (:func:`median_scores`), every knob (the
whitening dimension, the filter size, the MPCA threshold) picked on a tuning part of the query
frames and scored on the evaluation part (``evaluate.honest_split``, :func:`tune_then_score`), and a
second split with the parts' roles swapped (:func:`swapped_split`). :func:`postprocessing`,
:func:`second_split`, :func:`split_spread` and :func:`paper_rows` give the notebook's tables,
unrounded (AP and recall in %, MPCA a fraction; :data:`DECIMALS` is how the notebook shows them).
The building blocks are ``similarity`` (whitening, median filter, S = 1 - D / max D) and
``evaluate`` (AP, MPCA, the split).
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from greenloop import similarity
from greenloop.study import verdict, wording
from greenloop.evaluate import (average_precision, mean_per_class_accuracy, mpca_threshold,
                                pr_curve, recall_at_100_precision)
from greenloop import report
from greenloop.experiments.leaderboard import rows as lb

__all__ = [
    "DECIMALS", "NOT_AVAILABLE", "tune_then_score", "whitened_variants", "median_scores",
    "swapped_split", "Scored", "postprocessing", "second_split", "split_spread", "PAIRED", "paired", "paper_rows",
    "conclusion",
    "figure_tuning", "figure_ap_by_variant", "figure_pr_raw_vs_whitened", "figure_similarity",
]

# decimals the notebook shows and writes each column with (pandas DataFrame.round)
DECIMALS = {"AP_tune_%": 2, "AP_eval_%": 2, "R@100P_eval_%": 2, "AP_all_%": 2, "R@100P_all_%": 2,
            "MPCA_threshold": 4, "MPCA_eval": 3, "min": 2, "max": 2, "spread": 2}
NOT_AVAILABLE = ("not available: no honest tuning/evaluation split (every revisit frame lies within the gap "
                 "of the others)")


# ----------------------------------------------------------- tuning on one part, scoring on the other
def tune_then_score(candidates, GT, exclude: int, tune, evaluate) -> dict:
    """Pick a knob's value by AP on the tuning queries and score the pick on the evaluation queries.

    candidates: {value: S}, one (N, N) similarity matrix per candidate value of the knob (a
        whitening dimension, a median-filter size, ...). GT, exclude: as in ``evaluate.pair_samples``.
    tune, evaluate: (N,) bool query masks from ``evaluate.split_mask`` (swap them for the second split).
    Returns dict(value, AP_tune, AP_eval, R@100P_eval, AP_tune_all): the picked value (the first
    of equal tuning APs), its AP on the tuning queries and its AP and recall at 100 % precision on
    the evaluation queries, in [0, 1], and {value: AP on the tuning queries} of every candidate
    (the tuning curve). The evaluation ground truth never influences the pick.
    """
    if not candidates:
        raise ValueError("candidates is empty: give at least one {value: S}")
    tuned = {v: average_precision(S, GT, exclude, queries=tune) for v, S in candidates.items()}
    best = max(tuned, key=tuned.get)
    S = candidates[best]
    return {"value": best, "AP_tune": tuned[best],
            "AP_eval": average_precision(S, GT, exclude, queries=evaluate),
            "R@100P_eval": recall_at_100_precision(S, GT, exclude, queries=evaluate),
            "AP_tune_all": tuned}


def whitened_variants(X, GT, exclude: int, tune, evaluate, pca_dim: int = 500,
                      dims=(8, 16, 32, 64, 128, 256, 500), eps: float = 1e-5):
    """Zhang 2017's post-processing variants of one descriptor, whitening fitted on the tuning part.

    X: (N, D) raw descriptors. GT, exclude: as ``evaluate.pair_samples``. tune, evaluate: (N,) bool
    query masks of ``evaluate.split_mask``, or both None where no honest split exists. pca_dim: the
    paper's PCA dimension; dims: the candidate dimensions of the tuned variants; eps: whitening ε.
    Returns (variants, curves). variants: {name: (S (N, N) float, whitening note)} with "raw"
    (1 - D / max D of X), "L2" (of the L2-normalised X), "PCA-whitened, paper dim" (fitted on the
    tuning frames, on every frame without a split) and, with a split, "PCA-whitened, tuned dim"
    and "ZCA, tuned dim" (dimension picked by :func:`tune_then_score`). curves: {"pca dim" |
    "zca dim": {kept dim: AP on the tuning queries in [0, 1]}}, empty without a split.
    """
    Xn = similarity.l2_normalise(X)
    variants = {"raw": (similarity.distance_similarity(X, normalise=False), "-"),
                "L2": (similarity.distance_similarity(Xn), "-")}
    (k, Y), = similarity.whitening_candidates(Xn, [pca_dim], "pca", eps, fit=tune).items()
    variants["PCA-whitened, paper dim"] = (similarity.distance_similarity(Y), f"dim {k} (paper {pca_dim})"
                                           + ("" if tune is not None else ", fitted on every frame"))
    curves = {}
    if tune is None:
        return variants, curves                       # a tuned dimension needs a tuning part
    for kind, name in (("pca", "PCA-whitened, tuned dim"), ("zca", "ZCA, tuned dim")):
        cands = similarity.whitened_similarities(Xn, dims, kind, eps, fit=tune)
        r = tune_then_score(cands, GT, exclude, tune, evaluate)
        curves[f"{kind} dim"] = r["AP_tune_all"]
        variants[name] = (cands[r["value"]], f"dim {r['value']} (picked on tuning part)")
    return variants, curves


def _mpca(S, GT, exclude, tune, evaluate) -> dict:
    """MPCA threshold picked on the tuning queries, MPCA on the evaluation queries (a fraction)."""
    thr = mpca_threshold(S, GT, exclude, queries=tune)
    return {"MPCA_threshold": thr,
            "MPCA_eval": mean_per_class_accuracy(S, GT, thr, exclude, queries=evaluate)}


def median_scores(S, GT, exclude: int, tune, evaluate, sizes=(1, 3, 5, 9, 15)):
    """One variant's rows of notebook 08's table: unfiltered and with the median size tuned.

    S: (N, N) similarity of the variant. GT, exclude: as ``evaluate.pair_samples``. tune, evaluate: (N,)
    bool query masks of ``evaluate.split_mask``, or both None where no honest split exists. sizes:
    candidate median-filter sizes in frames (1: no filter, :func:`similarity.median_candidates`).
    Returns (rows, curve). With a split: two rows (median_filter "none" at size 1, then
    "median (tuned)" at the picked size) with AP_tune_%, AP_eval_%, R@100P_eval_% (in %, unrounded) and the MPCA threshold (tuned) and MPCA on the evaluation part; curve = {size: AP on
    the tuning queries}. Without: one unfiltered row scored on every query (AP_all_%,
    R@100P_all_%, NaN where a tuning part is needed) and curve None.
    """
    if tune is None:
        return [{"median_filter": "none", "size": 1, "AP_tune_%": np.nan,
                 "AP_all_%": 100 * average_precision(S, GT, exclude),
                 "R@100P_all_%": 100 * recall_at_100_precision(S, GT, exclude),
                 "MPCA_threshold": np.nan, "MPCA_eval": np.nan}], None
    fs = similarity.median_candidates(S, sizes)
    r = tune_then_score(fs, GT, exclude, tune, evaluate)
    rows = []
    for filt, s in (("none", 1), ("median (tuned)", r["value"])):
        Sf = fs[s]
        rows.append({"median_filter": filt, "size": s, "AP_tune_%": 100 * r["AP_tune_all"][s],
                     "AP_eval_%": 100 * average_precision(Sf, GT, exclude, queries=evaluate),
                     "R@100P_eval_%": 100 * recall_at_100_precision(Sf, GT, exclude, queries=evaluate),
                     **_mpca(Sf, GT, exclude, tune, evaluate)})
    return rows, r["AP_tune_all"]


def swapped_split(X, S_l2, GT, exclude: int, tune, evaluate, dims=(8, 16, 32, 64, 128, 256, 500),
                  sizes=(1, 3, 5, 9, 15), eps: float = 1e-5) -> list:
    """Notebook 08's second split: each knob tuned on either part and scored on the other.

    X: (N, D) raw descriptors (L2-normalised here; the PCA whitening is refitted on each tuning
    part). S_l2: (N, N) similarity of the L2 variant, whose median-filter size is the second knob.
    GT, exclude: as ``evaluate.pair_samples``; tune, evaluate: (N,) bool masks of ``evaluate.split_mask``.
    dims, sizes, eps: as :func:`whitened_variants` and :func:`median_scores`.
    Returns a list of 4 dicts (split A = tune early/score late, then B = swapped; per split the
    PCA-whitening dimension, then the median size): knob, split, picked, AP_tune_%, AP_eval_%,
    R@100P_eval_% (in %, unrounded).
    """
    Xn = similarity.l2_normalise(X)
    medians = similarity.median_candidates(S_l2, sizes)
    rows = []
    for split, (tq, eq) in {"A: tune early, score late": (tune, evaluate),
                            "B: tune late, score early": (evaluate, tune)}.items():
        for knob, cands in (("PCA-whitening dim", similarity.whitened_similarities(Xn, dims, "pca", eps, fit=tq)),
                            ("median size, L2", medians)):
            r = tune_then_score(cands, GT, exclude, tq, eq)
            rows.append({"knob": knob, "split": split, "picked": r["value"],
                         "AP_tune_%": 100 * r["AP_tune"], "AP_eval_%": 100 * r["AP_eval"],
                         "R@100P_eval_%": 100 * r["R@100P_eval"]})
    return rows


# ---------------------------------------------------------------------- the notebook's tables
class Scored(NamedTuple):
    """Notebook 08's main tables. table: one row per (backbone, variant, median filter) with
    backbone, weights, label, variant, whitening and :func:`median_scores`' columns. tuning: one
    row per (backbone, knob, candidate value): backbone, label, knob, value, AP_tune_% (a one-row
    ``status`` table without a split). variants: {backbone: :func:`whitened_variants`' variants}."""
    table: pd.DataFrame
    tuning: pd.DataFrame
    variants: dict


def _tuning_rows(b: str, label: str, knob: str, curve: dict) -> list:
    return [{"backbone": b, "label": label, "knob": knob, "value": v, "AP_tune_%": 100 * a} for v, a in curve.items()]


def postprocessing(feats: dict, infos: dict, GT, exclude: int, tune, evaluate, pca_dim: int = 500,
                   dims=(8, 16, 32, 64, 128, 256, 500), eps: float = 1e-5, sizes=(1, 3, 5, 9, 15)) -> Scored:
    """Every backbone's variants, unfiltered and median-filtered, scored (unrounded).

    feats: {backbone: (N, D) descriptors}; infos: {backbone: features info (weights, label)}.
    GT, exclude, tune, evaluate, pca_dim, dims, eps: as :func:`whitened_variants`; sizes: as
    :func:`median_scores`. Tuning rows: the whitening curves of every backbone first, then the
    median-size curves ("median size, <variant>").
    """
    tuning, variants, rows = [], {}, []
    for b, X in feats.items():
        variants[b], curves = whitened_variants(X, GT, exclude, tune, evaluate, pca_dim, dims, eps)
        for knob, curve in curves.items():
            tuning += _tuning_rows(b, infos[b].label, knob, curve)
    for b in feats:
        for v, (S, knob) in variants[b].items():
            scored, curve = median_scores(S, GT, exclude, tune, evaluate, sizes)
            if curve is not None:
                tuning += _tuning_rows(b, infos[b].label, f"median size, {v}", curve)
            rows += [{"backbone": b, "weights": infos[b].weights, "label": infos[b].label, "variant": v,
                      "whitening": knob, **r} for r in scored]
    tuning = pd.DataFrame(tuning) if tune is not None else pd.DataFrame([{"status": NOT_AVAILABLE}])
    return Scored(pd.DataFrame(rows), tuning, variants)


def second_split(feats: dict, infos: dict, variants: dict, GT, exclude: int, tune, evaluate,
                 dims=(8, 16, 32, 64, 128, 256, 500), sizes=(1, 3, 5, 9, 15), eps: float = 1e-5) -> pd.DataFrame:
    """:func:`swapped_split` of every backbone (its L2 variant's matrix from ``variants``): one row
    per (backbone, split, knob) with backbone, label and the swapped_split columns; a one-row
    ``status`` table (:data:`NOT_AVAILABLE`) where no honest split exists (tune is None)."""
    if tune is None:
        return pd.DataFrame([{"status": NOT_AVAILABLE}])
    return pd.DataFrame([{"backbone": b, "label": infos[b].label, **r} for b, X in feats.items()
                         for r in swapped_split(X, variants[b]["L2"][0], GT, exclude, tune, evaluate, dims, sizes, eps)])


def split_spread(swap: pd.DataFrame) -> pd.DataFrame:
    """min, max and spread = max - min (points) of AP_eval_% of each (label, knob) over the two
    splits of :func:`second_split`; the status table itself where that has none. Give it the
    second split as shown (rounded) for a spread that is the difference of the values shown."""
    if "status" in swap:
        return swap.copy()
    t = swap.groupby(["label", "knob"])["AP_eval_%"].agg(["min", "max"])
    return t.assign(spread=t["max"] - t["min"]).reset_index()


# the paired comparisons of paired.csv (each a minus b): Zhang 2017's whitening against raw, the ZCA paper's median
# filter against the unfiltered ZCA matrix; the median-filtered ZCA arm is named MEDIAN_ARM
MEDIAN_ARM = "ZCA, tuned dim + median (tuned)"
PAIRED = {"PCA-whitened, paper dim minus raw": ("PCA-whitened, paper dim", "raw"),
          "PCA-whitened, tuned dim minus raw": ("PCA-whitened, tuned dim", "raw"),
          "ZCA + median filter (tuned) minus ZCA": (MEDIAN_ARM, "ZCA, tuned dim")}


def paired(table: pd.DataFrame, variants: dict, GT, exclude: int, evaluate, block: int = 10) -> pd.DataFrame:
    """Every backbone's comparisons of :data:`PAIRED` (those its variants hold: the tuned ones need a
    split), by the leaderboard's paired block bootstrap over the same evaluation queries
    (``leaderboard.rows.paired_table``: per-query R@1 and AUC-PR, loop closure).

    table: :attr:`Scored.table` (each backbone's picked median size); variants: :attr:`Scored.variants`;
    GT, exclude: as ``evaluate.pair_samples``; evaluate: (N,) bool evaluation queries, or None (every
    query, no honest split); block: queries per bootstrap run. Returns a DataFrame: backbone, weights,
    label, then ``leaderboard.rows.PAIRED_COLUMNS``."""
    out = []
    for b, v in variants.items():
        S = {k: m for k, (m, _) in v.items()}
        rows = table[(table.backbone == b) & (table.variant == "ZCA, tuned dim") & (table.median_filter != "none")]
        if len(rows):
            size = int(rows["size"].iloc[0])
            S[MEDIAN_ARM] = similarity.median_candidates(S["ZCA, tuned dim"], [size])[size]
        pairs = [(c, a, o) for c, (a, o) in PAIRED.items() if a in S and o in S]
        first = table[table.backbone == b].iloc[0]
        out.append(lb.paired_table(S, pairs, GT, exclude, evaluate, block).assign(
            backbone=b, weights=first.weights, label=first.label))
    t = pd.concat(out, ignore_index=True) if out else pd.DataFrame(columns=lb.PAIRED_COLUMNS + ["backbone"])
    return t[["backbone", "weights", "label"] + lb.PAIRED_COLUMNS]


# ---------------------------------------------------------------------- this run vs the papers
def _backbone_rows(t: pd.DataFrame, b: str, label: str, split_ok: bool) -> list:
    AP = "AP_eval_%" if split_ok else "AP_all_%"
    raw, pca = t.loc[(b, "raw", "none"), AP], t.loc[(b, "PCA-whitened, paper dim", "none"), AP]
    rows = [(f"PCA whitening vs raw features, {b}: AP {'eval' if split_ok else 'over every query'} (%)",
             "CNN-Aug beats raw (qualitative, New College / City Centre)", f"{raw:.2f} -> {pca:.2f}",
             f"{label}; Zhang 2017 reports PR curves only" + ("" if split_ok else "; no honest split: whitening fitted on every frame"))]
    if split_ok:
        z0, z = t.loc[(b, "ZCA, tuned dim", "none"), "AP_eval_%"], t.loc[(b, "ZCA, tuned dim", "median (tuned)")]
        zca = f"{z0:.2f} -> {z['AP_eval_%']:.2f} (size {int(z['size'])})"
    rows.append((f"median filter on ZCA similarity, {b}: AP eval (%)", "removes salt-and-pepper noise (qualitative)",
                 zca if split_ok else NOT_AVAILABLE, label))
    return rows


def paper_rows(table: pd.DataFrame, variants: dict, infos: dict, pca_dim: int, eps: float, split_ok: bool,
               paper_t3: dict) -> pd.DataFrame:
    """The paper-vs-run table (``report.paper_vs_run``): the picked PCA dimensions and ε, per
    backbone PCA whitening against raw and the median filter on ZCA, Table III's MPCA rows of
    paper_t3 = {backbone: (City Centre, New College)} and the best pretrained network by MPCA.
    table: :attr:`Scored.table`; variants: :attr:`Scored.variants` (its backbones in order);
    split_ok: whether an honest split exists (else the tuned cells read :data:`NOT_AVAILABLE`)."""
    t = table.set_index(["backbone", "variant", "median_filter"])
    done = list(variants)
    rows = [("PCA output dimension", pca_dim,
             "; ".join(f"{b}: {variants[b]['PCA-whitened, tuned dim'][1].split(' (')[0]}" for b in done)
             if split_ok else NOT_AVAILABLE, "picked by AP on the tuning part; paper's 500 scored as 'PCA-whitened, paper dim'"),
            ("whitening ε", 1e-5, eps)]
    for b in done:
        rows += _backbone_rows(t, b, infos[b].label, split_ok)
    for b, (cc, nc) in paper_t3.items():
        if b in done:
            r = t.loc[(b, "ZCA, tuned dim", "median (tuned)")] if split_ok else None
            rows.append((f"MPCA, ZCA + median filter, {b}", f"{cc} (City Centre) / {nc} (New College)",
                         f"{r['MPCA_eval']:.3f} (AP {r['AP_eval_%']:.2f} %)" if split_ok else NOT_AVAILABLE,
                         f"{infos[b].label}{'; the paper ran Inception-v4' if b == 'inceptionv3' else ''}; other datasets, "
                         f"threshold picked on the tuning part"))
    zm = table[(table.variant == "ZCA, tuned dim") & (table.median_filter != "none") & table.weights.str.startswith("imagenet")]
    zm = zm.sort_values("MPCA_eval", ascending=False)
    rows.append(("best pretrained network with ZCA + median filter, by MPCA", "ResNet50 (of ResNet50/101/152, Inception-v4)",
                 f"{zm.iloc[0].label}: MPCA {zm.iloc[0]['MPCA_eval']:.3f}" if len(zm) else
                 ("no pretrained network in this run" if split_ok else NOT_AVAILABLE),
                 "only networks with ImageNet weights count; random-init rows rank nothing"))
    return report.paper_vs_run(rows)


def _gap_text(name: str, diff: float, spread_row) -> str:
    """How a difference of ``diff`` points (one split) stands against the spread of its knob's pick over
    the two splits (a row of :func:`split_spread`, or None): never an order (two splits are no seed range)."""
    if spread_row is None:
        return f"{name} {diff:+.2f} points (one split): not resolved by the split"
    within = abs(diff) <= spread_row["spread"]
    return (f"{name} {diff:+.2f} points, {'within' if within else 'beyond'} the {wording.num(spread_row['spread'])}-point "
            f"spread of its knob's pick over the two splits (AP {wording.span(spread_row['min'], spread_row['max'], unit=' %')})"
            + ("" if within else ", but two splits are too few to call an order") + ": not resolved by the two splits")


def _variant_sentence(t: pd.DataFrame, label: str, ap: str, dataset: str) -> str:
    """The variants' APs (%) of one network (rows of postprocessing.csv), unfiltered unless said."""
    a = t.set_index(["variant", "median_filter"])[ap]
    names = [("raw", "none", "raw"), ("L2", "none", "L2"), ("PCA-whitened, paper dim", "none", "PCA-whitened at the paper's dim"),
             ("PCA-whitened, tuned dim", "none", "at the tuned dim"), ("ZCA, tuned dim", "none", "ZCA at the tuned dim"),
             ("ZCA, tuned dim", "median (tuned)", "ZCA + the tuned median filter")]
    parts = [f"{words} {wording.num(a[(v, m)])}" for v, m, words in names if (v, m) in a.index]
    part = "evaluation part" if ap == "AP_eval_%" else "every query (no honest split, untuned rows only)"
    return f"On {dataset}, {label} reaches AP (%, {part}): " + ", ".join(parts) + "."


def conclusion(out_dir) -> str:
    """Notebook 08's last cell, in Markdown: the verdicts on Zhang 2017's whitening and the ZCA paper's
    median filter for this dataset, then the AP (%) of each variant of the network with ImageNet weights
    (else the first network, said to be random-init) and how each gain stands against the spread of its
    knob's pick over the two splits (postprocessing.csv and split_spread.csv under ``out_dir``)."""
    out_dir = Path(out_dir)
    t = pd.read_csv(out_dir / "postprocessing.csv")
    pre = t[t.weights.str.startswith("imagenet")]
    net = (pre if len(pre) else t).backbone.iloc[0]
    rows, ap = t[t.backbone == net], "AP_eval_%" if "AP_eval_%" in t else "AP_all_%"
    lines = ([] if len(pre) else ["No network here has ImageNet weights: what follows is about untrained features."])
    lines.append(_variant_sentence(rows, rows.label.iloc[0], ap, verdict.dataset_name(out_dir.parent)))
    spread = pd.read_csv(out_dir / "split_spread.csv")
    if ap == "AP_eval_%" and "spread" in spread:
        a = rows.set_index(["variant", "median_filter"])[ap]
        by = spread[spread.label == rows.label.iloc[0]].set_index("knob")
        knob = lambda k: by.loc[k] if k in by.index else None
        lines.append("Gains on the one split: " + _gap_text(
            "whitening at the tuned dim over raw", a[("PCA-whitened, tuned dim", "none")] - a[("raw", "none")],
            knob("PCA-whitening dim")) + "; " + _gap_text(
            "the median filter on ZCA", a[("ZCA, tuned dim", "median (tuned)")] - a[("ZCA, tuned dim", "none")],
            knob("median size, L2")) + " (the filter size's spread is read on the L2 variant).")
    else:
        lines.append(f"No honest tuning/evaluation split here: {wording.NOT_A_RANKING}.")
    lines.append(_paired_sentence(out_dir, rows.backbone.iloc[0]))
    return wording.heading(Path(out_dir).parent, "08_descriptor_postprocessing") + "\n\n" + " ".join(l for l in lines if l)


def _paired_sentence(out_dir: Path, backbone: str) -> str:
    """The paired comparisons of one backbone (paired.csv under ``out_dir``, :func:`paired`) in words,
    per-query AUC-PR: what answers the papers' orders; "" where the folder has no paired.csv."""
    path = out_dir / "paired.csv"
    if not path.is_file():
        return ""
    t = pd.read_csv(path)
    t = t[t.backbone == backbone]
    parts = [lb.paired_sentence(t, c) for c in PAIRED]
    parts = [p for p in parts if p]
    return ("Paired over the same queries (per-query AUC-PR, a minus b): " + "; ".join(parts) + ".") if parts else ""


# -------------------------------------------------------------------------------- figures
def figure_tuning(tuning: pd.DataFrame, infos: dict):
    """AP on the tuning part against the whitening dimension (PCA, ZCA) and the median size (L2
    variant), ★ at each pick, one line per backbone of ``tuning``. Returns the figure."""
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(13, 4))
    for b in dict.fromkeys(tuning.backbone):
        for ax, kind, ls, name in ((axes[0], "pca dim", "-", "PCA"), (axes[0], "zca dim", "--", "ZCA"),
                                   (axes[1], "median size, L2", "-", "L2")):
            t = tuning[(tuning.backbone == b) & (tuning.knob == kind)]
            line, = ax.plot(t.value, t["AP_tune_%"], ls, marker="o", label=f"{infos[b].label}, {name}")
            bi = t["AP_tune_%"].idxmax()
            ax.plot(t.value[bi], t["AP_tune_%"][bi], "*", ms=14, color=line.get_color())
    axes[0].set_xscale("log", base=2); axes[0].set_xlabel("whitening dimension"); axes[0].set_ylabel("AP on the TUNING part (%)")
    axes[0].set_title("whitening dimension (★ = picked)")
    axes[1].set_xlabel("median filter size (frames)"); axes[1].set_ylabel("AP on the TUNING part (%)")
    axes[1].set_title("median filter size, L2 variant (★ = picked)")
    for ax in axes:
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2, borderaxespad=0)
    return fig


def figure_ap_by_variant(table: pd.DataFrame, infos: dict, split_ok: bool, scored_on: str):
    """One panel per backbone: AP of each variant without and (with a split) with the tuned median
    filter, on the evaluation part (every query without a split). Returns the figure."""
    import matplotlib.pyplot as plt
    done = list(dict.fromkeys(table.backbone))
    AP = "AP_eval_%" if split_ok else "AP_all_%"
    fig, axes = plt.subplots(1, len(done), figsize=(4.5 * len(done), 4), squeeze=False, sharey=True)
    for ax, b in zip(axes[0], done):
        t = table[table.backbone == b].set_index(["variant", "median_filter"])[AP]
        order = list(dict.fromkeys(table[table.backbone == b].variant))
        x = np.arange(len(order))
        ax.bar(x - 0.2, [t[(v, "none")] for v in order], 0.4, label="no filter")
        if split_ok:
            ax.bar(x + 0.2, [t[(v, "median (tuned)")] for v in order], 0.4, label="median filter (size tuned)")
        ax.set_xticks(x); ax.set_xticklabels(order, rotation=30, ha="right", fontsize=8); ax.set_title(infos[b].label, fontsize=9)
        ax.set_xlabel("descriptor variant", fontsize=8)
    axes[0][0].set_ylabel(f"AP on the {scored_on} (%)")
    axes[0][-1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    fig.tight_layout()
    return fig


def figure_pr_raw_vs_whitened(variants: dict, table: pd.DataFrame, infos: dict, GT, exclude: int, queries,
                              scored_on: str):
    """Zhang 2017 Fig. 5: per backbone the PR curves of the raw and the L2 + PCA-whitened (paper
    dimension) descriptor on the queries (None: every query). Returns the figure."""
    import matplotlib.pyplot as plt
    done = list(variants)
    AP = "AP_eval_%" if queries is not None else "AP_all_%"
    fig, axes = plt.subplots(1, len(done), figsize=(3.6 * len(done), 3.6), squeeze=False, sharey=True)
    for ax, b in zip(axes[0], done):
        for v, ls in (("raw", "--"), ("PCA-whitened, paper dim", "-")):
            p, r, _ = pr_curve(variants[b][v][0], GT, exclude, queries=queries)
            ap = table[(table.backbone == b) & (table.variant == v) & (table.median_filter == "none")][AP].iloc[0]
            ax.plot(r, p, ls, label=f"{'raw' if v == 'raw' else 'L2 + PCA-whitened'}: AP {ap:.1f} %")
        ax.set_title(infos[b].label, fontsize=8); ax.set_xlabel("recall"); ax.set_xlim(0, 1); ax.set_ylim(0, 1.02)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), borderaxespad=0)
    axes[0][0].set_ylabel(f"precision ({scored_on.lower()})")
    fig.suptitle("Zhang 2017 Fig. 5 layout: raw vs L2 + PCA-whitened descriptors, S = 1 - D / max D", fontsize=10)
    fig.tight_layout()
    return fig


def figure_similarity(variants: dict, infos: dict, GT, show, frame_step: int):
    """Zhang 2017 Fig. 4: for each backbone in ``show`` the ground truth, the raw and the L2 +
    PCA-whitened similarity matrix S = 1 - D / max D side by side. Returns the figure."""
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(show), 3, figsize=(11, 3.4 * len(show)), squeeze=False)
    for row, b in zip(axes, show):
        S_pca, note = variants[b]["PCA-whitened, paper dim"]
        panels = [("ground truth", np.asarray(GT, float), "gray_r"), (f"{infos[b].label}: raw", variants[b]["raw"][0], "viridis"),
                  (f"L2 + PCA-whitened ({note})", S_pca, "viridis")]
        for ax, (title, A, cmap) in zip(row, panels):
            im = ax.imshow(A, cmap=cmap, interpolation="nearest", vmin=0, vmax=1)
            ax.set_title(title, fontsize=8)
            ax.set_xlabel(f"query frame (x{frame_step} = original index)"); ax.set_ylabel("database frame")
            fig.colorbar(im, ax=ax, fraction=0.046, label="loop (1) / no loop (0)" if cmap == "gray_r" else "S = 1 - D / max D")
    fig.suptitle("Zhang 2017 Fig. 4 layout: similarity matrices beside the ground truth", fontsize=10)
    fig.tight_layout()
    return fig
