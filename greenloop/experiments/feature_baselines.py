"""Notebook 07's study: every whole-image descriptor on one sequence (Qi 2024 Table 2).

Each backbone's descriptors (``features.extract_all``) become a cosine similarity matrix, timed
as the best of three (:func:`similarity_matrices`, ``speed.timing.best_of``); :func:`table2`
scores them (AP, R@100P, R@1, R_a / R_t against SIFT-BoVW), :func:`ground_truth_sensitivity`
recomputes every AP under other ground-truth definitions, :func:`operating_points_table` lists
the main paper's dictionary detector (``dictionary.operating_points``) at each τ, and
:func:`paper_rows` sets this run beside Table 2. Tables come back unrounded (%, seconds);
:data:`DECIMALS` is how the notebook shows them.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from greenloop import evaluate, features, groundtruth, report, similarity
from greenloop.speed import timing
from greenloop.study import verdict, wording

__all__ = ["DECIMALS", "REFERENCE", "similarity_matrices", "table2", "layer_table", "chosen_layers",
           "layer_summary", "figure_layers",
           "ground_truth_sensitivity",
           "operating_points_table", "paper_rows", "conclusion", "figure_sensitivity", "figure_pr_curves",
           "figure_ap", "figure_similarity_matrices"]

# decimals the notebook shows and writes each column with (pandas DataFrame.round); the ground-truth
# sensitivity table (one column per descriptor label) shows 2, the operating points 4
DECIMALS = {"AP_%": 2, "R@100P_%": 2, "R@1_%": 2, "extract_s_per_image": 6, "match_s_MxM": 6, "R_a_%": 1, "R_t_%": 1,
            **{f"{m}_{p}_%": 2 for m in ("AP", "R@1", "AUC-PR") for p in ("tune", "eval", "all")}}
REFERENCE = "sift_bovw"         # Table 2 takes its rates R_a, R_t relative to SIFT-BoVW


def similarity_matrices(feats: dict, repeats: int = 3) -> tuple[dict, dict]:
    """(S, seconds): {backbone: (M, M) ``similarity.cosine_matrix`` of its (M, D) descriptors}
    and {backbone: wall time of that whole matrix, best of ``repeats``, in s}."""
    S, secs = {}, {}
    for b, X in feats.items():
        S[b], secs[b] = timing.best_of(similarity.cosine_matrix, X, repeats=repeats)
    return S, secs


def table2(S: dict, infos: dict, match_s: dict, GT, exclude: int) -> pd.DataFrame:
    """Table 2: one row per backbone of S (backbone, weights, label, dim, input, AP_%, R@100P_%,
    R@1_% in %, extract_s_per_image and match_s_MxM in s, R_a_% and R_t_% against
    :data:`REFERENCE`, NaN without it), unrounded. infos: {backbone: extraction info};
    match_s: :func:`similarity_matrices`' seconds; GT: (M, M) bool; exclude: band in steps."""
    table = pd.DataFrame([{"backbone": b, "weights": infos[b].weights, "label": infos[b].label, "dim": infos[b].dim,
                           "input": "native" if infos[b].input_size is None else "x".join(map(str, infos[b].input_size)),
                           **evaluate.pair_metrics(S[b], GT, exclude),
                           "R@1_%": 100 * evaluate.recall_at_k(S[b], GT, 1, exclude),
                           "extract_s_per_image": infos[b].seconds_per_image, "match_s_MxM": match_s[b]} for b in S])
    table["R_a_%"] = table["R_t_%"] = np.nan
    if REFERENCE in S:
        ref = table.set_index("backbone").loc[REFERENCE]
        table["R_a_%"], table["R_t_%"] = evaluate.relative_rates(
            table["AP_%"], table["extract_s_per_image"], ref["AP_%"], ref["extract_s_per_image"])
    return table


def layer_table(feats: dict, infos: dict, GT, exclude: int, tune=None, evalq=None) -> pd.DataFrame:
    """The layer study: one row per layer descriptor of ``feats`` ({"backbone@depth-pooling" entry:
    (M, D)}, greenloop.features.layers; infos: their ExtractInfo) with backbone, weights, depth,
    layer, pooling, dim, input, extract_s_per_image (the network's pass over every depth), and per
    query part the pair AP_%, the per-query R@1_% and AUC-PR_% (``evaluate.per_query``) of its
    cosine matrix: ``_tune`` on the tuning queries and ``_eval`` on the evaluation queries (tune,
    evalq: (M,) bool), or ``_all`` on every query where tune is None. chosen: each backbone's
    row with the highest tuning AUC-PR (the first on a tie; False everywhere without a split).
    Unrounded; GT (M, M) bool, exclude in steps."""
    parts = {"all": None} if tune is None else {"tune": tune, "eval": evalq}
    rows = []
    for spec, X in feats.items():
        n = features.parse(spec)
        S, i = similarity.cosine_matrix(X), infos[spec]
        row = {"spec": spec, "backbone": n.backbone + (":" + n.tag if n.tag else ""),
               "weights": i.weights, "depth": n.depth, "layer": i.layer.rsplit(", ", 1)[0], "pooling": n.pooling,
               "dim": i.dim, "input": "x".join(map(str, i.input_size)), "extract_s_per_image": i.seconds_per_image}
        for part, q in parts.items():
            m = evaluate.per_query(S, GT, exclude, queries=q, ks=(1,))
            row.update({f"AP_{part}_%": 100 * evaluate.average_precision(S, GT, exclude, queries=q),
                        f"R@1_{part}_%": 100 * m["R@1"], f"AUC-PR_{part}_%": 100 * m["AUC-PR"]})
        rows.append(row)
    t = pd.DataFrame(rows, columns=None if rows else ["spec", "backbone", "weights", "depth", "layer", "pooling", "dim"])
    t["chosen"] = False
    if tune is not None and len(t):
        t.loc[t.groupby("backbone", sort=False)["AUC-PR_tune_%"].idxmax().values, "chosen"] = True
    return t


def chosen_layers(layers_table: pd.DataFrame, feats: dict, infos: dict) -> tuple[dict, dict]:
    """The chosen rows of :func:`layer_table` as Table 2 entries: ({spec: (M, D)}, {spec: ExtractInfo})."""
    chosen = list(layers_table.spec[layers_table.chosen])
    return {s: feats[s] for s in chosen}, {s: infos[s] for s in chosen}


def layer_summary(layers_table: pd.DataFrame) -> str:
    """One line per network: the depth and pooling chosen on the tuning queries and its evaluation
    AUC-PR and R@1 beside the last map's global average (Table 2's descriptor), in %; without a
    split, the every-query figures of that last-map row and of the highest one (not a choice)."""
    part = "eval" if "AUC-PR_eval_%" in layers_table else "all"
    lines = [] if len(layers_table) else ["no network in layer_backbones: no layer study in this run"]
    for net, t in layers_table.groupby("backbone", sort=False):
        last = t[(t.depth == "last") & (t.pooling == "avg")]
        base = (f"last-avg {last[f'AUC-PR_{part}_%'].iloc[0]:.1f} / {last[f'R@1_{part}_%'].iloc[0]:.1f}"
                if len(last) else "no last-avg row")
        pick = t[t.chosen] if t.chosen.any() else t.loc[[t[f"AUC-PR_{part}_%"].idxmax()]]
        r = pick.iloc[0]
        how = "chosen on the tuning queries" if t.chosen.any() else "highest on every query, no split to choose on"
        lines.append(f"{net}: {r.depth}-{r.pooling} ({how}) AUC-PR / R@1 {r[f'AUC-PR_{part}_%']:.1f} / "
                     f"{r[f'R@1_{part}_%']:.1f} % on the {'evaluation' if part == 'eval' else 'every'} queries; {base}")
    return "\n".join(lines)


def ground_truth_sensitivity(dataset, frames, S: dict, infos: dict, exclude: int, exclude_steps: int,
                             thresholds=(0.3, 0.4, 0.5, 0.6, 0.7, 0.8), max_distance: float = 1.0,
                             max_angle: float = 30.0) -> pd.DataFrame:
    """Every AP (in %) under each ground truth of ``groundtruth.variants`` (Eq. 5 thresholds and
    the metric one; exclude in original frames, exclude_steps the band of ``frames``): one row per
    definition with ground_truth, loop_pairs, revisit_frames and one column per descriptor label
    (NaN where that ground truth has no loop). Empty where the folder's ground truth is loop pairs."""
    GTV = groundtruth.variants(dataset, frames, thresholds, exclude, max_distance, max_angle)
    return pd.DataFrame([{"ground_truth": name, "loop_pairs": len(groundtruth.loop_pairs(G)),
                          "revisit_frames": int(groundtruth.revisit_frames(G).sum()),
                          **{infos[b].label: 100 * evaluate.average_precision(S[b], G, exclude_steps) if G.any() else np.nan
                             for b in S}} for name, G in GTV.items()])


def operating_points_table(points: list, infos: dict) -> pd.DataFrame:
    """The dictionary's operating points (``dictionary.operating_points``' points): one row per
    tau with detector, tau, flagged_frames and ``evaluate.operating_point``'s columns, unrounded."""
    name = f"dictionary, spot_cnn ({infos['spot_cnn'].weights if 'spot_cnn' in infos else 'model'})"
    return pd.DataFrame([{"detector": name, "tau": p["tau"], "flagged_frames": p["flagged_frames"], **p["op"]}
                         for p in points])


def paper_rows(table: pd.DataFrame, ops: pd.DataFrame, paper: dict, frames_per_spot: int) -> pd.DataFrame:
    """Paper vs run (``report.paper_vs_run``): per backbone of paper = {backbone: (AP %, s, R_a %,
    R_t %)} (Table 2, TUM) this run's AP, extraction time, R_a and R_t, the best pretrained CNN, and
    the dictionary at the τ nearest L + 10. table, ops: :func:`table2` and
    :func:`operating_points_table` as shown (their cells are copied)."""
    note = "Qi 2024 Table 2 is on TUM RGB frames with ImageNet weights: a different dataset"
    t, rows = table.set_index("backbone"), []
    for b, (a, s, ra, rt) in paper.items():
        if b not in t.index:
            continue
        lab = t.loc[b, "label"]
        rows += [(f"AP / average accuracy rate, {b} (%)", a, t.loc[b, "AP_%"], f"{lab}; {note}"),
                 (f"extraction time per image, {b} (s)", s, t.loc[b, "extract_s_per_image"], f"{lab}; input {t.loc[b, 'input']}, {report.cpu_model()}"),
                 (f"R_a vs SIFT-BoVW, {b} (%)", ra, t.loc[b, "R_a_%"] if REFERENCE in t.index else "no sift_bovw row", lab),
                 (f"R_t vs SIFT-BoVW, {b} (%)", rt, t.loc[b, "R_t_%"] if REFERENCE in t.index else "no sift_bovw row", lab)]
    pre = table[table.weights.str.startswith("imagenet") & ~table.backbone.str.contains("@")]
    pre = pre.sort_values("AP_%", ascending=False)
    ranked = "; next: ".join(f"{r.label}: {r['AP_%']} %" for _, r in pre.head(2).iterrows())
    rows.append(("highest AP among the pretrained CNN descriptors", "GhostNet best (TUM)",
                 ranked or "no pretrained CNN in this run",
                 "the papers' whole-image descriptors with ImageNet weights here (no GhostNet weights on these "
                 "machines; the layer rows, chosen on the tuning queries, are left out); one AP over every pair, "
                 "no spread measured: not a ranking unless the gap is wide"))
    tp = ops.iloc[(ops.tau - (frames_per_spot + 10)).abs().argmin()]
    rows.append((f"dictionary detector at τ = {int(tp.tau)}: precision / recall", None,
                 f"{tp.precision:.3f} / {tp.recall:.3f}", "beyond the papers: the main paper never scores it against ground truth"))
    return report.paper_vs_run(rows)


def _descriptor_sentence(t: pd.DataFrame, chance: float, dataset: str) -> str:
    """Table 2's APs (%) on ``dataset``: the ImageNet rows, the range of the random-init rows, SIFT-BoVW
    and pixels, beside chance; single values, so no order."""
    whole = t[~t.backbone.str.contains("@")]
    pre = whole[whole.weights.str.startswith("imagenet")]
    rand = whole[whole.weights == "random init"]
    parts = [f"{r.label} {wording.num(r['AP_%'])} %" for _, r in pre.iterrows()]
    if len(rand):
        parts.append(f"the {len(rand)} random-init rows {wording.span(rand['AP_%'].min(), rand['AP_%'].max(), unit=' %')}")
    parts += [f"{b} {wording.num(whole.set_index('backbone').loc[b, 'AP_%'])} %" for b in ("sift_bovw", "pixels")
              if b in set(whole.backbone)]
    head = "the descriptors with ImageNet weights reach AP " if len(pre) else "no descriptor has ImageNet weights here; AP: "
    return (f"On {dataset} {head}" + ", ".join(parts) + f" (chance {wording.num(100 * chance)} %): one AP per "
            f"descriptor over one sequence: {wording.NOT_A_RANKING}.")


def _layer_sentence(t: pd.DataFrame) -> str:
    """The layer chosen per network on the tuning queries beside the last map's global average, per-query
    AUC-PR (%) on the evaluation queries; "" without a split or a layer network."""
    if not len(t) or "AUC-PR_eval_%" not in t or not t.chosen.any():
        return ""
    parts = []
    for net, g in t.groupby("backbone", sort=False):
        pick, last = g[g.chosen], g[(g.depth == "last") & (g.pooling == "avg")]
        if len(pick) and len(last):
            same = pick.index[0] == last.index[0]
            parts.append(f"{net} {pick.depth.iloc[0]}-{pick.pooling.iloc[0]} {wording.num(pick['AUC-PR_eval_%'].iloc[0])} %"
                         + ("" if same else f" (last-avg {wording.num(last['AUC-PR_eval_%'].iloc[0])} %)"))
    return ("Layer by layer, the map chosen on the tuning queries scores per-query AUC-PR " + "; ".join(parts)
            + f" on the evaluation queries: one deterministic run each, {wording.NOT_A_RANKING}.") if parts else ""


def _dictionary_sentence(ops: pd.DataFrame, tau: int) -> str:
    """The main paper's dictionary at the τ of ``ops`` nearest ``tau`` (L + Δ): declared pairs, right
    ones, precision and recall over the ground truth's pairs."""
    r = ops.iloc[(ops.tau - tau).abs().argmin()]
    declared = int(r.tp + r.fp)
    if declared == 0:
        return f"The main paper's dictionary at τ = {int(r.tau)} declares no pair (recall 0 of {int(r.fn)} loop pairs)."
    return (f"The main paper's dictionary at τ = {int(r.tau)} declares {declared} pairs, {int(r.tp)} of them loops: "
            f"precision {wording.num(r.precision)}, recall {wording.num(r.recall)} of {int(r.tp + r.fn)} loop pairs.")


def conclusion(out_dir) -> str:
    """Notebook 07's last cell, in Markdown: the verdict on Qi 2024's Table 2 ranking for this dataset,
    then what this run's tables (table2, layers, dictionary_operating_points, summary.json and manifest
    under ``out_dir``) say, with numbers; APs in %, one value per descriptor (no spread: no order)."""
    out_dir = Path(out_dir)
    t = pd.read_csv(out_dir / "table2.csv")
    chance = json.loads((out_dir / "summary.json").read_text())["chance_ap"]
    L = json.loads((out_dir / "manifest.json").read_text())["parameters"]["frames_per_spot"]
    lines = [_descriptor_sentence(t, chance, verdict.dataset_name(out_dir.parent)),
             _layer_sentence(pd.read_csv(out_dir / "layers.csv")),
             _dictionary_sentence(pd.read_csv(out_dir / "dictionary_operating_points.csv"), L + 10)]
    return wording.heading(Path(out_dir).parent, "07_feature_baselines") + "\n\n" + " ".join(x for x in lines if x)


# -------------------------------------------------------------------------------- figures
def figure_sensitivity(sensitivity: pd.DataFrame, labels):
    """AP of every descriptor label against the Eq. 5 threshold, the metric ground truth as ★ at
    the right. sensitivity: :func:`ground_truth_sensitivity`'s table. Returns the figure."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(9, 4.8))
    colours = report.palette(labels)
    eq5 = sensitivity[sensitivity.ground_truth.str.startswith("Eq. 5")]
    thr = [float(t.split("<")[1]) for t in eq5.ground_truth]
    metric = sensitivity[~sensitivity.ground_truth.str.startswith("Eq. 5")]
    for lab in labels:
        line, = ax.plot(thr, eq5[lab], marker="o", ms=3, lw=1, label=lab, color=colours[lab])
        ax.scatter([max(thr) + 0.12] * len(metric), metric[lab], marker="*", s=60, color=line.get_color())
    ax.set_xticks(thr + [max(thr) + 0.12], [f"{t:g}" for t in thr] + ["metric"])
    ax.set_xlabel("ground truth: Eq. 5 threshold (mixed units), and the metric variant (★)"); ax.set_ylabel("AP (%)")
    ax.grid(alpha=0.3); ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.set_title("AP of every descriptor under each ground-truth definition", fontsize=10)
    fig.tight_layout()
    return fig


def figure_pr_curves(S: dict, table: pd.DataFrame, ops: pd.DataFrame, GT, exclude: int, title: str):
    """Every descriptor's PR curve (legend: its AP from ``table``; one colour per descriptor,
    ``report.palette``) and the dictionary's operating points (``ops``, ★ per τ with a precision);
    the legend beside the axes. Returns the figure."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(11, 6))
    colours = report.palette(table.label)
    for k, b in enumerate(S):
        p, r, _ = evaluate.pr_curve(S[b], GT, exclude)
        ax.plot(r, p, color=colours[table.loc[k, "label"]], lw=1.4, label=f"{table.loc[k, 'label']}: AP {table.loc[k, 'AP_%']:.1f} %")
    ok = ops.dropna(subset=["precision"])
    ax.plot(ok.recall, ok.precision, "k*", ms=11, label=f"main paper's dictionary detector, τ ∈ {list(ok.tau)}")
    for _, o in ok.iterrows():
        ax.annotate(f"τ={o.tau}", (o.recall, o.precision), textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax.set_xlabel("recall"); ax.set_ylabel("precision"); ax.set_xlim(0, 1); ax.set_ylim(0, 1.02)
    ax.set_title(title, fontsize=9); ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    fig.tight_layout()
    return fig


def figure_ap(table: pd.DataFrame, paper: dict):
    """Every descriptor's AP (%) of ``table`` (:func:`table2`) as a bar, one colour per descriptor
    (``report.palette``, as in :func:`figure_pr_curves`), and Qi 2024 Table 2's AP of the paper's
    networks (paper = {backbone: (AP %, ...)}, TUM, ImageNet weights) as a dashed mark across the bar
    of the same backbone, with its legend entry. One AP per descriptor: no whiskers (no spread)."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(10, 1.2 + 0.28 * len(table)))
    colours = report.palette(table.label)
    y = np.arange(len(table))
    ax.barh(y, table["AP_%"], color=[colours[lab] for lab in table.label])
    marked = [(k, paper[b][0]) for k, b in enumerate(table.backbone) if b in paper]
    report.mark_paper(ax, [k for k, _ in marked], [v for _, v in marked],
                       "Qi 2024 Table 2 (TUM, ImageNet weights)", horizontal=False)
    ax.set_yticks(y, table.label, fontsize=7); ax.invert_yaxis()
    ax.set_xlabel("AP (%), every pair more than the exclusion band apart"); ax.set_ylabel("descriptor (weights)")
    ax.set_xlim(0, 100); ax.grid(axis="x", alpha=0.3)
    if marked:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    ax.set_title("AP of every descriptor here (bars) beside the paper's (dashed, another dataset)", fontsize=10)
    fig.tight_layout()
    return fig


def figure_similarity_matrices(S: dict, infos: dict, GT, gt_name: str):
    """The ground truth beside every descriptor's cosine similarity matrix, four panels a row.
    Returns the figure."""
    import matplotlib.pyplot as plt
    n = len(S) + 1
    cols = min(4, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), squeeze=False)
    axes = axes.ravel()
    axes[0].imshow(GT, cmap="gray_r", interpolation="nearest"); axes[0].set_title(f"ground truth ({gt_name})", fontsize=9)
    for ax, b in zip(axes[1:], S):
        ax.imshow(S[b], cmap="viridis", interpolation="nearest"); ax.set_title(infos[b].label, fontsize=8)
    for ax in axes:
        ax.set_xticks([]); ax.set_yticks([])
        ax.set_xlabel("query frame (described index)", fontsize=7); ax.set_ylabel("earlier frame", fontsize=7)
    for ax in axes[n:]:
        ax.axis("off")
    fig.suptitle("cosine similarity matrices beside the ground truth (row = earlier frame, column = query)", fontsize=10)
    fig.tight_layout()
    return fig


def figure_layers(layers_table: pd.DataFrame):
    """One panel per network of the layer study: per-query AUC-PR (evaluation part, or every query
    without a split) of each depth (x) and pooling (bars); the rows chosen on the tuning part
    outlined. layers_table: :func:`layer_table`'s. Returns the figure."""
    import matplotlib.pyplot as plt
    part = "eval" if "AUC-PR_eval_%" in layers_table else "all"
    nets = list(dict.fromkeys(layers_table.backbone))
    if not nets:
        fig, ax = plt.subplots(figsize=(4, 1.2))
        ax.text(0.5, 0.5, "no network in layer_backbones", ha="center", va="center"); ax.axis("off")
        return fig
    fig, axes = plt.subplots(1, len(nets), figsize=(3.6 * len(nets), 3.4), squeeze=False, sharey=True)
    for ax, net in zip(axes[0], nets):
        t = layers_table[layers_table.backbone == net]
        depths, pools = list(dict.fromkeys(t.depth)), list(dict.fromkeys(t.pooling))
        w = 0.8 / len(pools)
        for k, p in enumerate(pools):
            r = t[t.pooling == p].set_index("depth").reindex(depths)
            bars = ax.bar(np.arange(len(depths)) + (k - (len(pools) - 1) / 2) * w, r[f"AUC-PR_{part}_%"], w, label=p)
            for bar, chosen in zip(bars, r.chosen.fillna(False)):
                if chosen:
                    bar.set_edgecolor("black"); bar.set_linewidth(2)
        ax.set_xticks(range(len(depths)), depths); ax.set_xlabel("depth of the map read")
        ax.set_title(f"{net} ({t.weights.iloc[0]})", fontsize=9); ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel(f"per-query AUC-PR, {'evaluation queries' if part == 'eval' else 'every query'} (%)")
    axes[0][-1].legend(title="pooling", fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    fig.suptitle("Descriptors layer by layer (outlined: chosen on the tuning queries)", fontsize=10)
    fig.tight_layout()
    return fig
