"""Notebook 09's study: RGB against RGB-D descriptors (Qi 2024 Sec. 3.1.2, Tables 3 and 4).

Each CNN backbone describes every described frame's RGB image and its depth image (replicated to
three channels) and the two vectors are concatenated (``features.extract_rgbd``); the RGB half,
the depth half and the whole are scored with cosine similarity (``similarity.rgbd_matrices``,
``evaluate.pair_metrics``). :func:`rgbd_table` gives the table (unrounded; :data:`DECIMALS` is how
the notebook shows it), :func:`paper_rows` the paper-vs-run rows, the ``figure_*`` functions the
figures.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import evaluate, features, report, similarity
from greenloop.experiments.leaderboard import rows as lb
from greenloop.study import verdict, wording

__all__ = ["DECIMALS", "REFERENCE", "PAIRED", "split_backbones", "rgbd_table", "skipped_table", "paired", "paper_rows",
           "conclusion",
           "figure_pr_rgb_vs_rgbd", "figure_ap", "figure_similarity", "figure_skipped"]

# decimals the notebook shows and writes each column with (pandas DataFrame.round)
DECIMALS = {"AP_RGB_%": 2, "R@100P_RGB_%": 2, "AP_depth_%": 2, "R@100P_depth_%": 2, "AP_RGB-D_%": 2,
            "R@100P_RGB-D_%": 2, "extract_s_per_image_rgbd": 4, "R_a_%": 1, "R_t_%": 1}
REFERENCE = "ghostnet"          # Tables 3/4 take their rates R_a, R_t relative to GhostNet (RGB-D)
PAIRED = {"RGB-D minus RGB": ("RGB-D", "RGB")}      # paired.csv's comparisons (a minus b): Qi 2024's "depth adds to RGB"


def split_backbones(backbones) -> tuple[list, list]:
    """(cnn, skipped): the backbone specs ("name" or "name:random") that name a CNN of
    ``features.CNN_BACKBONES``, and the others (Tables 3/4 compare CNNs only)."""
    cnn = [b for b in backbones if features.parse(b).backbone in features.CNN_BACKBONES]
    return cnn, [b for b in backbones if b not in cnn]


def rgbd_table(dataset, backbones, GT, exclude: int, weights="auto", input_size=128, frame_step: int = 1,
               max_depth: float = features.DEPTH_MAX_M):
    """Tables 3/4: every CNN backbone's RGB, depth and RGB-D descriptor scored on one sequence.

    dataset: a sequence folder with depth/. backbones: CNN specs (:func:`split_backbones`).
    GT: (M, M) bool ground truth of the described frames; exclude: band in steps of frame_step.
    weights, input_size (square side; ignored by fixed-input networks), frame_step, max_depth
    (metres mapped to 255): as ``features.extract_rgbd``.
    Returns (table, S, infos): table one row per backbone (backbone, weights, label, dim_rgbd,
    input, AP_/R@100P_ of RGB, depth, RGB-D in %, extract_s_per_image_rgbd in s per RGB-D frame,
    R_a_% and R_t_% against :data:`REFERENCE`'s RGB-D row, NaN without it), unrounded;
    S {backbone: ``similarity.rgbd_matrices``}; infos {backbone: extraction info}.
    """
    rows, S, infos = [], {}, {}
    for b in backbones:
        d = features.get(b, weights, cnn_input_size=input_size, warn=False)
        with features.random_init_reported(d):
            X, inf = features.extract_rgbd(dataset, d, progress=False, step=frame_step, max_depth=max_depth,
                                           return_info=True)
        infos[b], S[b] = inf, similarity.rgbd_matrices(X)
        row = {"backbone": b, "weights": inf.weights, "label": inf.label, "dim_rgbd": X.shape[1],
               "input": "x".join(map(str, inf.input_size))}
        for k, Sk in S[b].items():
            row.update(evaluate.pair_metrics(Sk, GT, exclude, tag=f"_{k}"))
        rows.append({**row, "extract_s_per_image_rgbd": inf.seconds_per_image})
    features.clear_cache()
    table = pd.DataFrame(rows)
    table["R_a_%"] = table["R_t_%"] = np.nan
    if REFERENCE in S:
        ref = table.set_index("backbone").loc[REFERENCE]
        table["R_a_%"], table["R_t_%"] = evaluate.relative_rates(
            table["AP_RGB-D_%"], table["extract_s_per_image_rgbd"], ref["AP_RGB-D_%"], ref["extract_s_per_image_rgbd"])
    return table, S, infos


def paired(table: pd.DataFrame, S: dict, GT, exclude: int, block: int = 10) -> pd.DataFrame:
    """Each backbone's comparisons of :data:`PAIRED` by the leaderboard's paired block bootstrap over
    the same queries (``leaderboard.rows.paired_table``: per-query R@1 and AUC-PR, loop closure,
    every query). table: :func:`rgbd_table`'s table; S: its {backbone: {"RGB", "depth", "RGB-D": (M, M)}};
    GT: (M, M) bool; exclude: steps; block: queries per bootstrap run. Returns a DataFrame: backbone,
    weights, label, then ``leaderboard.rows.PAIRED_COLUMNS``."""
    pairs = [(c, a, b) for c, (a, b) in PAIRED.items()]
    out = [lb.paired_table(S[r.backbone], pairs, GT, exclude, None, block).assign(
        backbone=r.backbone, weights=r.weights, label=r.label) for r in table.itertuples()]
    t = pd.concat(out, ignore_index=True) if out else pd.DataFrame(columns=lb.PAIRED_COLUMNS + ["backbone", "weights", "label"])
    return t[["backbone", "weights", "label"] + lb.PAIRED_COLUMNS]


def skipped_table(backbones, weights="auto") -> pd.DataFrame:
    """The table of a sequence without depth/: per CNN backbone its weights, label and the status
    "skipped: the dataset has no depth/ folder"."""
    used = {b: features.get(b, weights, warn=False).resolved.label for b in backbones}
    return pd.DataFrame([{"backbone": b, "weights": used[b], "label": f"{b} ({used[b]})",
                          "status": "skipped: the dataset has no depth/ folder"} for b in backbones])


def paper_rows(table: pd.DataFrame, paper: dict, kind: str, dataset, has_depth: bool) -> pd.DataFrame:
    """Paper vs run (``report.paper_vs_run``). paper: {backbone: dict(t3=(AP %, s), t4=(AP %, s))},
    Tables 3 (TUM) and 4 (GreenHouse). table: :func:`rgbd_table`'s table as shown (its cells are
    copied). kind: the dataset's kind (``sequence.folder_info``). Without depth one "skipped" row."""
    if not has_depth:
        return report.paper_vs_run([("RGB-D experiment", "Tables 3 and 4", "skipped", f"{dataset} has no depth/ folder")])
    t, rows = table.set_index("backbone"), []
    for b, p in paper.items():
        if b not in t.index:
            continue
        lab = t.loc[b, "label"]
        rows += [(f"RGB-D AP, {b}: Table 4 GreenHouse (%)", p["t4"][0], t.loc[b, "AP_RGB-D_%"], f"{lab}; real GreenHouse vs {kind} data"),
                 (f"RGB-D AP, {b}: Table 3 TUM (%)", p["t3"][0], t.loc[b, "AP_RGB-D_%"], f"{lab}; TUM: a different dataset"),
                 (f"RGB-D extraction time per frame, {b} (s)", p["t4"][1], t.loc[b, "extract_s_per_image_rgbd"],
                  f"{lab}; input {t.loc[b, 'input']}, {report.cpu_model()}"),
                 (f"depth adds to RGB, {b}: AP RGB -> RGB-D (%)", "GhostNet TUM: 53.1 -> 59.4" if b == "ghostnet" else None,
                  f"{t.loc[b, 'AP_RGB_%']:.2f} -> {t.loc[b, 'AP_RGB-D_%']:.2f}", lab)]
    pre = table[table.weights.str.startswith("imagenet")].sort_values("AP_RGB-D_%", ascending=False)
    rows.append(("best pretrained RGB-D descriptor", "GhostNet (Tables 3 and 4)",
                 f"{pre.iloc[0].label}: {pre.iloc[0]['AP_RGB-D_%']} %" if len(pre) else "no pretrained network in this run",
                 "only networks with ImageNet weights count; random-init rows rank nothing"))
    return report.paper_vs_run(rows)


def conclusion(out_dir) -> str:
    """Notebook 09's last cell, in Markdown: the verdict on Qi 2024's "depth adds to RGB" for this
    dataset, then each network's AP (%) on RGB, on depth alone and on RGB-D (rgbd.csv under
    ``out_dir``): one AP each, so no order; a folder without depth says so."""
    out_dir = Path(out_dir)
    t, name = pd.read_csv(out_dir / "rgbd.csv"), verdict.dataset_name(out_dir.parent)
    if "AP_RGB-D_%" not in t:
        text = f"{name} has no depth/ folder: no RGB-D descriptor was described or compared here."
    else:
        parts = [f"{r.label} {wording.num(r['AP_RGB_%'])} -> {wording.num(r['AP_RGB-D_%'])} "
                 f"(depth alone {wording.num(r['AP_depth_%'])})" for _, r in t.iterrows()]
        text = (f"On {name}, AP RGB -> RGB-D (%): " + "; ".join(parts) + f": one AP per descriptor over one "
                f"sequence, {wording.NOT_A_RANKING}. Only rows with ImageNet weights bear on the paper's claim.")
        text += _paired_text(out_dir)
    return wording.heading(Path(out_dir).parent, "09_rgbd_features") + "\n\n" + text


def _paired_text(out_dir: Path) -> str:
    """Each network's paired comparisons (paired.csv under ``out_dir``, :func:`paired`) in words,
    per-query AUC-PR; "" where the folder has none."""
    path = out_dir / "paired.csv"
    if not path.is_file():
        return ""
    t = pd.read_csv(path)
    parts = [f"{label}: {lb.paired_sentence(t[t.label == label], c)}" for label in dict.fromkeys(t.label) for c in PAIRED]
    return " Paired over the same queries (per-query AUC-PR, a minus b), which orders the two: " + "; ".join(parts) + "."


def figure_pr_rgb_vs_rgbd(S: dict, table: pd.DataFrame, infos: dict, GT, exclude: int, title: str):
    """PR curves of every backbone's RGB (dotted) and RGB-D (solid) descriptor, one colour per
    backbone (``report.palette``), the legend beside the axes. Returns the figure."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(11, 6))
    colours = report.palette(S)
    for k, b in enumerate(S):
        for kind, ls in (("RGB", ":"), ("RGB-D", "-")):
            p, r, _ = evaluate.pr_curve(S[b][kind], GT, exclude)
            ax.plot(r, p, ls, color=colours[b], lw=1.4, label=f"{infos[b].label}, {kind}: AP {table.loc[k, f'AP_{kind}_%']:.1f} %")
    ax.set_xlabel("recall"); ax.set_ylabel("precision"); ax.set_xlim(0, 1); ax.set_ylim(0, 1.02)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0); ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def figure_ap(table: pd.DataFrame, paper: dict):
    """Each backbone's AP (%) on RGB, depth alone and RGB-D (:func:`rgbd_table`, grouped bars), and the
    paper's RGB-D AP of the same network (paper = {backbone: dict(t3=(AP %, s), t4=(AP %, s))}: Table 4,
    GreenHouse, dashed; Table 3, TUM, dotted) with their legend entries. One AP each: no whiskers."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(11, 4.5))
    x = np.arange(len(table))
    for k, (kind, colour) in enumerate((("RGB", "C0"), ("depth", "C2"), ("RGB-D", "C3"))):
        ax.bar(x + (k - 1) * 0.27, table[f"AP_{kind}_%"], 0.27, color=colour, label=f"{kind}, this run")
    at = [(k, paper[b]) for k, b in enumerate(table.backbone) if b in paper]
    report.mark_paper(ax, [k + 0.27 for k, _ in at], [p["t4"][0] for _, p in at], "paper, RGB-D, Table 4 (GreenHouse)", width=0.4)
    for n, (k, p) in enumerate(at):
        ax.plot([k + 0.07, k + 0.47], [p["t3"][0]] * 2, "k:", lw=1.6, label="paper, RGB-D, Table 3 (TUM)" if n == 0 else None)
    ax.set_xticks(x, table.label, rotation=25, ha="right", fontsize=8)
    ax.set_xlabel("network (weights)"); ax.set_ylabel("AP (%), pairs beyond the exclusion band"); ax.set_ylim(0, 100)
    ax.grid(axis="y", alpha=0.3); ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    ax.set_title("RGB, depth and RGB-D AP of each network (bars) beside the paper's RGB-D AP (lines)", fontsize=10)
    fig.tight_layout()
    return fig


def figure_similarity(S: dict, infos: dict, GT):
    """The ground truth beside every backbone's RGB-D cosine similarity matrix. Returns the figure."""
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(S) + 1, figsize=(3.2 * (len(S) + 1), 3.4))
    axes[0].imshow(GT, cmap="gray_r", interpolation="nearest"); axes[0].set_title("ground truth", fontsize=9)
    for ax, b in zip(axes[1:], S):
        ax.imshow(S[b]["RGB-D"], interpolation="nearest"); ax.set_title(f"{infos[b].label}, RGB-D", fontsize=8)
    for ax in axes:
        ax.set_xticks([]); ax.set_yticks([])
        ax.set_xlabel("query frame", fontsize=7); ax.set_ylabel("earlier frame", fontsize=7)
    fig.tight_layout()
    return fig


def figure_skipped(dataset):
    """A figure that says the RGB-D experiment was skipped (the sequence has no depth/)."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 1.5)); ax.axis("off")
    ax.text(0.5, 0.5, f"RGB-D experiment skipped:\n{dataset} has no depth/ folder", ha="center", va="center")
    return fig
