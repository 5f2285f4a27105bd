"""Notebook 11's study: Qi 2024's multi-probe LSH against brute force (Tables 5-6, Figure 7).

Every frame is matched incrementally (``greenloop.methods.lsh.lsh.incremental_match``) by each matcher of
:func:`table6_variants`, once per hyperplane seed (:func:`match_runs`); :func:`table6` averages the
runs, :func:`figure7_curves` / :func:`figure7_overlap` give Figure 7's PR curves over the scanned
pairs and how far each stays with brute force's, :func:`paper_rows` the paper-vs-run rows. The
hashing, probing and matching themselves live in :mod:`greenloop.methods.lsh.lsh`; the scores in
:mod:`greenloop.evaluate`. Tables come back unrounded (percentages in %, times in ms / s).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from greenloop import evaluate, report, similarity
from greenloop.methods.lsh import lsh
from greenloop.speed import scale
from greenloop.study import verdict, wording

__all__ = [
    "scanned_matrix", "best_match_matrix", "table6_variants", "query_matches", "run_scores",
    "compare_variants", "scanned_pr_curve", "Runs", "match_runs", "table6", "FIGURE7_STYLES",
    "figure7_curves", "figure7_overlap", "figure_7", "figure_scaling", "figure_times", "paper_rows", "summary_lines", "conclusion",
]


# ------------------------------------------------- score matrices and per-run scores of one match
def _incremental(result: lsh.MatchResult, need_candidates: bool = False) -> int:
    if not isinstance(result, lsh.MatchResult) or result.params.get("mode") != "incremental":
        raise ValueError("expected a MatchResult of lsh.incremental_match (query t = frame t)")
    if need_candidates and result.candidates is None:
        raise ValueError("this result kept no candidates: run incremental_match(..., "
                         "keep_candidates=True)")
    return len(result.best)


def scanned_matrix(S, result: lsh.MatchResult, floor: float = -2.0) -> np.ndarray:
    """The similarity matrix restricted to the pairs a method actually scanned.

    S: (N, N) cosine similarities of the same frames (``similarity.cosine_matrix(X)``), read at
    [i, j] with i the stored frame and j the query. result: from ``lsh.incremental_match(X, ...,
    keep_candidates=True)``. Returns (N, N) float32: S[i, j] where query j scanned frame i,
    ``floor`` (below every cosine) elsewhere, so pairs a method never looked at rank last, tied.
    For brute force this equals S on every pair i < j - exclude.
    """
    n = _incremental(result, need_candidates=True)
    S = np.asarray(S)
    if S.shape != (n, n):
        raise ValueError(f"S must be ({n}, {n}) for {n} queries, got shape {S.shape}")
    out = np.full((n, n), floor, np.float32)
    for j, cand in enumerate(result.candidates):
        rows = np.arange(result.n_stored[j]) if cand is None else cand
        out[rows, j] = S[rows, j]
    return out


def best_match_matrix(result: lsh.MatchResult, floor: float = -2.0) -> np.ndarray:
    """Only each query's best match: (N, N) float32 with [best_j, j] = score_j, ``floor``
    elsewhere (queries without a match add nothing). result: from :func:`greenloop.methods.lsh.lsh.incremental_match`."""
    n = _incremental(result)
    out = np.full((n, n), floor, np.float32)
    ok = result.best >= 0
    out[result.best[ok], np.flatnonzero(ok)] = result.score[ok]
    return out


def table6_variants(centre: bool = True, centre_frames: int = 1) -> list:
    """The matchers of Table 6: [(name, method, centre_frames)] for :func:`greenloop.methods.lsh.lsh.incremental_match`.

    Brute force, scikit-learn, SWP and QDP with hyperplanes through the origin (the paper); with
    centre, SWP and QDP again with hyperplanes through the mean of the first ``centre_frames``
    frames (beyond the paper; notebook 11 uses exclude + 1, in frames of the sequence).
    """
    out = [("brute force", "brute", 0), ("NearestNeighbors (sklearn)", "sklearn", 0),
           ("SWP-RHLSH", "swp", 0), ("QDP-RHLSH", "qdp", 0)]
    if centre:
        out += [("SWP-RHLSH, centred", "swp", centre_frames), ("QDP-RHLSH, centred", "qdp", centre_frames)]
    return out


def query_matches(result: lsh.MatchResult, GT, exclude: int, floor: float = -2.0):
    """The per-query :class:`greenloop.evaluate.Matches` of one incremental run (loop-closure mode).

    result: from :func:`greenloop.methods.lsh.lsh.incremental_match`. GT: (N, N) bool ground truth; exclude: band in
    frames (the run's). Queries: every frame with a stored candidate (j - i > exclude for some
    i). match/score: the method's best scanned frame and its cosine; a query that scanned nothing
    has no match and gets score ``floor`` (below every cosine: it fires only at the lowest
    threshold) and correct False. has_partner: a GT partner among ALL its candidates (the same
    denominator for every method). Only the best match is known, so k = 1 (R@1 only).
    """
    n = _incremental(result)
    G = np.asarray(GT, dtype=bool)
    if G.shape != (n, n):
        raise ValueError(f"GT must be ({n}, {n}) for {n} queries, got shape {G.shape}")
    js = np.flatnonzero(result.n_stored > 0)
    has = (G & evaluate.candidate_mask(n, exclude))[:, js].any(0)
    found = result.best[js] >= 0
    match = np.where(found, result.best[js], 0)
    score = np.where(found, result.score[js], floor)
    correct = found & G[match, js]
    return evaluate.matches(js, match, score, correct, has, np.where(correct, 0, 1), 1)


def run_scores(r: lsh.MatchResult, S, brute: lsh.MatchResult, GT, exclude: int) -> dict:
    """The scores of one incremental run (notebook 11's Table 6 columns).

    r, brute: :func:`greenloop.methods.lsh.lsh.incremental_match` results (keep_candidates=True) of the method and of brute
    force on the same N frames. S: (N, N) cosine matrix of the frames. GT: (N, N) bool ground
    truth; exclude: band in frames. Returns the per-query metrics of :func:`query_matches`
    (``evaluate.query_metrics``, loop-closure mode): R@1_%, AUC-PR_%, R@100P_%, R@95P_%; then
    AP_pairs_% (pair AP of :func:`scanned_matrix`, secondary), NN_agree_% (same best match as
    brute force), scanned_% (candidates / stored), probes_per_query, N1_at_end (NaN for
    brute/sklearn), ms_per_query, probe_ms_per_query (ms) and total_s (s); unrounded.
    """
    t, hashed = r.timed, r.method in ("swp", "qdp")
    q = evaluate.query_metrics(query_matches(r, GT, exclude), ks=(1,))
    return {"R@1_%": 100 * q["R@1"], "AUC-PR_%": 100 * q["AUC-PR"], "R@100P_%": 100 * q["R@100P"],
            "R@95P_%": 100 * q["R@95P"],
            "AP_pairs_%": 100 * evaluate.average_precision(scanned_matrix(S, r), GT, exclude),
            "NN_agree_%": 100 * np.mean(r.best[t] == brute.best[t]),
            "scanned_%": 100 * np.mean(r.n_candidates[t] / r.n_stored[t]),
            "probes_per_query": float(r.n_probes[t].mean()) if hashed else np.nan,
            "N1_at_end": int(r.n_buckets[-1]) if hashed else np.nan,
            "ms_per_query": r.ms_per_query, "probe_ms_per_query": 1e3 * float(r.probe_seconds[t].mean()),
            "total_s": float(r.seconds.sum())}


def compare_variants(per_seed, reference: str = "brute force"):
    """Table 6: every matcher's scores averaged over hyperplane seeds, against the reference's.

    per_seed: a pandas DataFrame, one row per run: backbone, weights, label, variant, seed and the
    columns of :func:`run_scores`. reference: the variant each backbone's rates are taken against.
    Returns a DataFrame, one row per (backbone, weights, label, variant) in first-seen order: the
    means, AP_pairs_sd (population sd over seeds, after AP_pairs_%) and ms_sd, then R_a_% and
    R_t_% (:func:`greenloop.evaluate.relative_rates` of AP_pairs_% and ms_per_query against the
    reference row of the same backbone) and loss_per_1%_time (-R_a / R_t, NaN unless R_t > 0).
    """
    keys = ["backbone", "weights", "label", "variant"]
    metrics = [c for c in per_seed.columns if c not in keys + ["seed"]]
    table = per_seed.groupby(keys, sort=False)[metrics].mean().reset_index()
    spread = per_seed.groupby(keys, sort=False)[["AP_pairs_%", "ms_per_query"]].std(ddof=0).reset_index()
    table.insert(table.columns.get_loc("AP_pairs_%") + 1, "AP_pairs_sd", spread["AP_pairs_%"].values)
    table["ms_sd"] = spread["ms_per_query"].values
    ref = table[table.variant == reference].set_index("backbone")
    table["R_a_%"], table["R_t_%"] = evaluate.relative_rates(
        table["AP_pairs_%"], table["ms_per_query"],
        table.backbone.map(ref["AP_pairs_%"]), table.backbone.map(ref["ms_per_query"]))
    table["loss_per_1%_time"] = evaluate.loss_per_time_saved(table["R_a_%"], table["R_t_%"])
    return table


def scanned_pr_curve(S, result: lsh.MatchResult, GT, exclude: int, floor: float = -2.0):
    """Figure 7's PR curve of one incremental run, over the pairs the method scanned.

    S, result, floor: as :func:`scanned_matrix`; GT, exclude: as ``evaluate.pr_curve``.
    Returns (precision, recall), each (T,): ``evaluate.pr_curve`` of the scanned matrix without
    the point where the never-scanned pairs (scored ``floor``) are declared loops, so the curve
    ends at the largest recall the method reaches.
    """
    p, r, th = evaluate.pr_curve(scanned_matrix(S, result, floor), GT, exclude)
    keep = np.append(th > floor, True)
    return p[keep], r[keep]


# ------------------------------------------------------------- the notebook's runs and tables
class Runs(NamedTuple):
    """Every incremental run of :func:`match_runs`.

    per_seed: DataFrame, one row per (backbone, variant, seed): backbone, weights, label, variant,
        seed and the columns of :func:`run_scores` (unrounded). runs: {(backbone, variant, seed):
        lsh.MatchResult}. S: {backbone: (N, N) float32 cosine matrix of its descriptors}.
        ap_full: {backbone: pair AP of S, in %}. per_query_full: {backbone: {R@1, AUC-PR, R@100P,
        R@95P: in %}} of S (``evaluate.per_query``, loop-closure mode).
    """
    per_seed: pd.DataFrame
    runs: dict
    S: dict
    ap_full: dict
    per_query_full: dict


def match_runs(feats: dict, infos: dict, GT, exclude: int, seeds, n_bits: int = 16, radius: int = 4,
               qdp_probes=(1000, 1500, 500), qdp_score: str = "margin", centre: bool = True) -> Runs:
    """Every matcher of :func:`table6_variants` on every backbone's descriptors, once per seed.

    feats: {backbone: (N, D) descriptors}; infos: {backbone: features info with weights, label}.
    GT: (N, N) bool ground truth; exclude: band in frames of the descriptors (the notebook's exclude_steps).
    seeds: hyperplane seeds (scikit-learn, seed-free and slow, runs with the first only).
    n_bits, radius, qdp_probes, qdp_score: as ``lsh.incremental_match``. centre: add the centred
    SWP / QDP rows (hyperplanes through the mean of the first exclude + 1 frames).
    """
    seeds = list(seeds)
    if not seeds:
        raise ValueError("seeds is empty: give at least one hyperplane seed, e.g. [0]")
    variants = table6_variants(centre, exclude + 1)
    rows, runs, S, ap_full, pq_full = [], {}, {}, {}, {}
    for b, X in feats.items():
        S[b] = similarity.cosine_matrix(X)
        ap_full[b] = 100 * evaluate.average_precision(S[b], GT, exclude)
        pq_full[b] = {k: 100 * v for k, v in evaluate.per_query(S[b], GT, exclude, ks=(1,)).items()
                      if k not in ("queries", "revisits")}
        for seed in seeds:
            for name, method, k in variants:
                if method == "sklearn" and seed != seeds[0]:
                    continue
                runs[b, name, seed] = lsh.incremental_match(
                    X, method, exclude=exclude, n_bits=n_bits, seed=seed, radius=radius,
                    qdp_probes=qdp_probes, qdp_score=qdp_score, centre_frames=k, keep_candidates=True)
            rows += [{"backbone": b, "weights": infos[b].weights, "label": infos[b].label, "variant": name,
                      "seed": seed, **run_scores(runs[b, name, seed], S[b], runs[b, "brute force", seed], GT, exclude)}
                     for name, _, _ in variants if (b, name, seed) in runs]
    return Runs(pd.DataFrame(rows), runs, S, ap_full, pq_full)


def table6(runs: Runs, n_bits: int = 16, radius: int = 4, qdp_probes=(1000, 1500, 500)) -> pd.DataFrame:
    """Table 6: :func:`compare_variants` of the runs, with a ``probing`` column (5th) naming each
    matcher's hash and probing. Unrounded. Raises RuntimeError if brute force's scanned-pair AP
    is not the AP of the full cosine matrix (the two are the same quantity by construction)."""
    table = compare_variants(runs.per_seed, reference="brute force")
    table.insert(4, "probing", table.variant.map({
        "brute force": "none", "NearestNeighbors (sklearn)": "none",
        "SWP-RHLSH": f"{n_bits} bits, m = {radius}",
        "QDP-RHLSH": f"{n_bits} bits, M = {qdp_probes[0]} / {qdp_probes[1]} (N1 < / >= {qdp_probes[2]})",
        "SWP-RHLSH, centred": f"{n_bits} bits, m = {radius}, centred",
        "QDP-RHLSH, centred": f"{n_bits} bits, M rule as above, centred"}))
    brute = table.loc[table.variant == "brute force", "AP_pairs_%"].values
    if not np.allclose(brute, list(runs.ap_full.values()), atol=1e-9):
        raise RuntimeError("brute force's scanned-pair AP differs from the AP of the full cosine matrix")
    return table


FIGURE7_STYLES = {"brute force": ("k", "-"), "SWP-RHLSH": ("tab:blue", "-"), "QDP-RHLSH": ("tab:orange", "-"),
                  "SWP-RHLSH, centred": ("tab:green", "--"), "QDP-RHLSH, centred": ("tab:red", "--")}
TIME_COLOURS = {**{k: c for k, (c, _) in FIGURE7_STYLES.items()}, "NearestNeighbors (sklearn)": "tab:gray"}


def figure7_curves(runs: Runs, GT, exclude: int, seed: int) -> dict:
    """Figure 7's PR curves of one seed: {(backbone, variant): (precision, recall)} of
    :func:`scanned_pr_curve`, for the variants of FIGURE7_STYLES that ran, backbone by backbone."""
    return {(b, name): scanned_pr_curve(runs.S[b], runs.runs[b, name, seed], GT, exclude)
            for b in runs.S for name in FIGURE7_STYLES if (b, name, seed) in runs.runs}


def figure7_overlap(curves: dict, infos: dict, seed: int, grid, tol: float) -> pd.DataFrame:
    """The recall up to which each curve of :func:`figure7_curves` stays with brute force's
    (``evaluate.overlap_recall`` on the recall grid, interpolated precision within tol).
    Returns one row per curve: backbone, label, variant, seed, overlap_recall, max_recall."""
    return pd.DataFrame([{"backbone": b, "label": infos[b].label, "variant": name, "seed": seed,
                          "overlap_recall": evaluate.overlap_recall(p, r, *curves[b, "brute force"], grid, tol),
                          "max_recall": float(r.max())} for (b, name), (p, r) in curves.items()])


def figure_7(curves: dict, table: pd.DataFrame, infos: dict, title: str, seed: int):
    """Figure 7: one panel per backbone, the PR curve of each matcher (legend: its pair AP and ms
    per query from ``table``). Returns the matplotlib figure."""
    import matplotlib.pyplot as plt
    backbones = list(dict.fromkeys(b for b, _ in curves))
    fig, axes = plt.subplots(1, len(backbones), figsize=(6 * len(backbones), 4.8), squeeze=False)
    for ax, b in zip(axes[0], backbones):
        for name, (colour, ls) in FIGURE7_STYLES.items():
            if (b, name) in curves:
                p, r = curves[b, name]
                row = table[(table.backbone == b) & (table.variant == name)].iloc[0]
                ax.plot(r, p, color=colour, ls=ls, lw=1.4,
                        label=f"{name}: AP {row['AP_pairs_%']:.1f} %, {row['ms_per_query']:.3f} ms/query")
        ax.set_xlabel("recall"); ax.set_ylabel("precision"); ax.set_xlim(0, 1); ax.set_ylim(0, 1.02)
        ax.set_title(f"{infos[b].label}, hyperplane seed {seed}", fontsize=10)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), borderaxespad=0)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def figure_scaling(scaling: pd.DataFrame):
    """Median and p99 search time against the number of stored frames, one line per method
    (``scale.read_results``' table). Returns the matplotlib figure."""
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    for ax, col in zip(axes, ["p50_ms", "p99_ms"]):
        for (method, t), marker in zip(scaling.groupby("method", sort=False), "osv^Dxp*"):
            ax.plot(t.stored, t[col], marker=marker, label=method)
        ax.set_xscale("log"); ax.set_yscale("log"); ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel("stored frames"); ax.set_title(f"{col[:3]} per-query search time (ms)", fontsize=9)
    axes[0].set_ylabel("ms per query (one thread)")
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    fig.suptitle(f"{int(scaling.dim.iloc[0])}-D descriptors of augmented Nordland frames (results/bench/scale.md)",
                 fontsize=9)
    return fig


def figure_times(per_seed: pd.DataFrame, main: str, paper6: dict):
    """Matching time of every matcher on the ``main`` descriptor (rows of :attr:`Runs.per_seed`): per
    query (left, ms) and per sequence (right, s), each bar the mean over hyperplane seeds with its
    [min, max] whisker (log scale), one colour per matcher (:data:`TIME_COLOURS`); on the right Qi 2024
    Table 6's seconds (paper6 = {variant: (AP %, s, ...)}) as dashed marks with a legend entry (the paper
    does not say per query or per sequence). Returns the matplotlib figure."""
    import matplotlib.pyplot as plt
    t = per_seed[per_seed.backbone == main]
    g = t.groupby("variant", sort=False)
    names = list(g.groups)
    fig, axes = plt.subplots(1, 2, figsize=(13, 0.9 + 0.45 * len(names)), sharey=True)
    y = np.arange(len(names))
    for ax, col, xlabel in zip(axes, ("ms_per_query", "total_s"), ("ms per query (one thread)", "s per sequence (every query)")):
        m, lo, hi = g[col].mean().to_numpy(), g[col].min().to_numpy(), g[col].max().to_numpy()
        ax.barh(y, m, xerr=[m - lo, hi - m], color=[TIME_COLOURS.get(n, "0.5") for n in names],
                error_kw=dict(ecolor="k", lw=1, capsize=3))
        ax.set_xscale("log"); ax.set_xlabel(xlabel); ax.grid(axis="x", alpha=0.3, which="both")
    marked = [(k, paper6[n][1]) for k, n in enumerate(names) if n in paper6]
    report.mark_paper(axes[1], [k for k, _ in marked], [v for _, v in marked],
                       "Qi 2024 Table 6 (s; per query or per sequence not stated)", horizontal=False)
    axes[0].set_yticks(y, names, fontsize=8); axes[0].invert_yaxis(); axes[0].set_ylabel("matcher")
    axes[1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    fig.suptitle(f"Matching time, {t.label.iloc[0]}: bars the mean over {t.seed.nunique()} hyperplane seeds, "
                 "whiskers their [min, max]", fontsize=10)
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------- this run vs the paper
def _table5_rows(t: pd.DataFrame, paper5, n_bits, radius, qdp_probes) -> list:
    bits, m, probes = paper5
    return [("hash length (bits)", bits, n_bits, "Table 5"),
            ("SWP perturbation size m", m, radius, "Table 5"),
            ("QDP probing count M", probes,
             f"{qdp_probes[0]} (N1 < {qdp_probes[2]}), {qdp_probes[1]} (N1 >= {qdp_probes[2]}); "
             f"N1 at the end: {int(t.loc['QDP-RHLSH', 'N1_at_end'])}", "Table 5; the paper's text states the reverse rule")]


def _table6_rows(t: pd.DataFrame, ov: pd.DataFrame, paper6: dict, note: str, n_seeds: int, tol: float, seed: int) -> list:
    rows = []
    for v, (ap_, sec, ra, rt, loss) in paper6.items():
        r = t.loc[v]
        rows += [(f"{v}: average accuracy rate / AP (%)", ap_, r["AP_pairs_%"],
                  f"{note}; AP over scanned pairs, mean of {n_seeds} hyperplane seeds", 2),
                 (f"{v}: average matching time", f"{sec} s", f"{r['ms_per_query']:.3f} ms per query ({r['total_s']:.3f} s per sequence)",
                  f"the paper does not say per query or per sequence; {report.cpu_model()}")]
        if ra is not None:
            rows += [(f"{v}: R_a accuracy change (%)", ra, r["R_a_%"], "vs brute force", 2),
                     (f"{v}: R_t time saved (%)", rt, r["R_t_%"], "vs brute force; negative = slower", 2),
                     (f"{v}: accuracy loss per 1 % time saved", loss,
                      "no time saved" if not r["R_t_%"] > 0 else r["loss_per_1%_time"], "-R_a / R_t", 3),
                     (f"{v}: PR curve overlaps brute force's up to recall", "~0.8 (Figure 7)" if v.startswith("SWP") else "~0.5 (Figure 7)",
                      ov.loc[v, "overlap_recall"], f"interpolated precision within {tol}; hyperplane seed {seed}")]
    return rows


def _scaling_rows(scaling: pd.DataFrame) -> list:
    big = scaling[scaling.stored == scaling.stored.max()].set_index("method")
    rows = []
    for m in ("SWP-RHLSH", "QDP-RHLSH"):
        won = scale.crossover(scaling, m)
        rows.append((f"stored frames from which {m} beats brute force (median search time)", None,
                     won if won is not None else f"never up to {int(scaling.stored.max()):,}",
                     f"make bench-scale, {int(scaling.dim.iloc[0])}-D augmented Nordland descriptors; beyond the paper"))
        rows.append((f"{m} at {int(scaling.stored.max()):,} stored frames: recall@1 vs the exact scan (%)", None,
                     float(big.loc[m, "recall@1_%"]),
                     f"scans {big.loc[m, 'scanned_%']:.1f} % of the stored frames; make bench-scale", 1))
    return rows


def paper_rows(table: pd.DataFrame, overlap: pd.DataFrame, scaling: pd.DataFrame, main: str, label: str,
               paper5, paper6: dict, n_bits: int, radius: int, qdp_probes, n_seeds: int, tol: float,
               seed: int) -> pd.DataFrame:
    """The paper-vs-run table of the ``main`` backbone (``report.paper_vs_run``): Table 5's
    parameters (paper5 = (bits, m, M rule) as the paper states them), Table 6's rows per matcher
    of paper6 = {variant: (AP %, seconds, R_a %, R_t %, loss per 1 %)} (None where the paper has
    none), the better choice, and the scaling benchmark's crossovers. table: :func:`table6` as
    shown (the cells copy its values to the stated decimals); overlap: :func:`figure7_overlap`;
    scaling: ``scale.read_results``' table; label: the main backbone's label."""
    t = table[table.backbone == main].set_index("variant")
    ov = overlap[overlap.backbone == main].set_index("variant")
    note = f"{label}; synthetic RGB frames (the paper: real GreenHouse RGB-D)"
    rows = _table5_rows(t, paper5, n_bits, radius, qdp_probes) + _table6_rows(t, ov, paper6, note, n_seeds, tol, seed)
    loss = t.loc[["SWP-RHLSH", "QDP-RHLSH"], "loss_per_1%_time"]
    rows.append(("better choice (smaller accuracy loss per 1 % time saved)", "SWP-RHLSH",
                 loss.idxmin() if loss.notna().any() else "neither saves time", "on this run's descriptors and machine"))
    return report.paper_vs_run(rows + _scaling_rows(scaling))


def _versus_brute(t: pd.DataFrame, n: int, value: str, sd: str, unit: str, words) -> list:
    """SWP and QDP against brute force on one column of table6.csv (``value`` with its sd over the n
    hyperplane seeds, rows by variant), ordered by ``study.verdict``'s rule for Table 6: mean ± sd
    ranges that do not overlap (:func:`greenloop.study.wording.pair_order` with min_n 1)."""
    arm = lambda r: (n, r[value] - r[sd], r[value] + r[sd])
    text = lambda v, r: f"{v} {r[value]:.4g} ± {r[sd]:.2g}{unit}"
    bf = t.loc["brute force"]
    return [wording.pair_order(text(v, t.loc[v]), arm(t.loc[v]), text("brute force", bf), arm(bf), "hyperplane seeds", 1, words)
            for v in ("SWP-RHLSH", "QDP-RHLSH") if v in t.index]


def _time_sentence(t: pd.DataFrame, n: int, dataset: str) -> str:
    """Per-query matching time (ms, mean ± sd over n hyperplane seeds) of SWP and QDP against brute
    force's, with the share of stored frames each scans. t: one descriptor's rows of table6.csv by variant."""
    scans = "; ".join(f"{v} scans {wording.num(t.loc[v, 'scanned_%'])} %" for v in ("SWP-RHLSH", "QDP-RHLSH") if v in t.index)
    return (f"On {dataset}, {t.label.iloc[0]} (mean ± sd over {n} hyperplane seeds), time per query: "
            + "; ".join(_versus_brute(t, n, "ms_per_query", "ms_sd", " ms", ("is slower than", "is faster than")))
            + f" ({scans} of the stored frames).")


def _accuracy_sentence(t: pd.DataFrame, n: int) -> str:
    """Pair AP (%, mean ± sd over seeds) of SWP and QDP against brute force's, and the per-query R@1."""
    r1 = ", ".join(f"{v} {wording.num(t.loc[v, 'R@1_%'])} %" for v in ("brute force", "SWP-RHLSH", "QDP-RHLSH") if v in t.index)
    return ("Pair AP: " + "; ".join(_versus_brute(t, n, "AP_pairs_%", "AP_pairs_sd", " %", ("lies above", "lies below")))
            + f" (paper: SWP -1.2 %, QDP -6.3 % of AP); R@1 {r1}.")


def _scaling_sentence(cmp: pd.Series) -> str:
    """The stored count from which each RHLSH variant's median search time drops below the exact
    scan's in ``make bench-scale`` (paper_vs_run.csv's cells); "" where the run has none."""
    rows = {m: cmp.get(f"stored frames from which {m} beats brute force (median search time)") for m in ("SWP-RHLSH", "QDP-RHLSH")}
    if all(v is None for v in rows.values()):
        return ""
    return ("In make bench-scale's benchmark (64-D descriptors, medians of one run), the search time drops below the "
            "exact scan's from " + ", ".join(f"{v} stored frames for {m}" for m, v in rows.items() if v is not None) + ".")


def conclusion(out_dir) -> str:
    """Notebook 11's last cell, in Markdown: the verdict on Qi 2024's Table 6 trade for this dataset, then,
    on the descriptor the verdict reads (the first with ImageNet weights, else the notebook's main one),
    the matching times with their spread over hyperplane seeds, the pair AP and R@1 (table6.csv,
    per_seed.csv, summary.json under ``out_dir``) and the scaling benchmark's crossovers (paper_vs_run.csv)."""
    out_dir = Path(out_dir)
    t = pd.read_csv(out_dir / "table6.csv")
    pre = t[t.weights.str.contains("imagenet")]
    main = pre.backbone.iloc[0] if len(pre) else json.loads((out_dir / "summary.json").read_text())["main"]
    seeds = pd.read_csv(out_dir / "per_seed.csv")
    n = int(seeds[(seeds.backbone == main) & (seeds.variant == "SWP-RHLSH")].seed.nunique())
    t = t[t.backbone == main].set_index("variant")
    cmp = pd.read_csv(out_dir / "paper_vs_run.csv").set_index("quantity")["this run"]
    lines = [_time_sentence(t, n, verdict.dataset_name(out_dir.parent)), _accuracy_sentence(t, n), _scaling_sentence(cmp)]
    return wording.heading(Path(out_dir).parent, "11_lsh_matching") + "\n\n" + " ".join(x for x in lines if x)


def summary_lines(table: pd.DataFrame, main: str, n_frames: int) -> list:
    """One sentence per RHLSH variant of the ``main`` backbone: share scanned, buckets, AP against
    brute force's, NN agreement and time per query (the notebook prints them)."""
    t = table[table.backbone == main].set_index("variant")
    bf = t.loc["brute force"]
    return [f"{v}: scans {r['scanned_%']:.1f} % of the stored frames ({r['N1_at_end']:.0f} non-empty buckets for "
            f"{n_frames} frames), AP {r['AP_pairs_%']:.2f} % vs {bf['AP_pairs_%']:.2f} % (R_a {r['R_a_%']:+.1f} %), same "
            f"match as brute force for {r['NN_agree_%']:.1f} % of the queries, {r['ms_per_query']:.3f} ms vs "
            f"{bf['ms_per_query']:.3f} ms per query" for v, r in t.iterrows() if "RHLSH" in v]
