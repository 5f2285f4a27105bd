"""Notebook 05's study: the paper's frequency-count dictionary at its threshold τ = L + Δ and over
a sweep of τ, scored against the ground truth, with the paper's spot labels (by frame index)
beside loop-aware ones (by place).

Every table comes back unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from greenloop.experiments import training_over_seeds as tos
from greenloop.groundtruth import DEFAULT_EXCLUDE
from greenloop.methods.dictionary import cnn, dictionary, spots
from greenloop.study import wording

PAPER_TAU = 70          # the paper's τ = L + Δ = 60 + 10 detections

VARIANTS = ("paper (spots by frame index)", "loop-aware (spots by place)")


def variant_runs(X: np.ndarray, gt: np.ndarray, frames_per_spot: int, paper_run: dict, **train_kw) -> dict:
    """The CNN run behind each of ``VARIANTS`` for one seed: {variant: (run, reference (N,) int64 the
    labels the CNN was trained on)}.

    X: (N, H, W, C) frames; gt: (N, N) bool loop matrix; frames_per_spot: L; paper_run: one
    ``cnn.run_seeds`` dict trained on ``spots.group(N, L)`` (the paper's labels). The loop-aware
    CNN is trained here (or loaded from the cache) on ``spots.by_place(L, gt)`` with paper_run's seed;
    train_kw go to ``cnn.train`` (epochs, batch_size, stop_patience, ...)."""
    y, y_place = spots.group(len(X), frames_per_spot), spots.by_place(frames_per_spot, gt)
    aware = cnn.run_seeds(X, y_place, [paper_run["seed"]], **train_kw)[0]
    return {VARIANTS[0]: (paper_run, y), VARIANTS[1]: (aware, y_place)}


def variant_predictions(X: np.ndarray, gt: np.ndarray, frames_per_spot: int, paper_run: dict,
                        **train_kw) -> dict:
    """Every frame's predicted spot under each of ``VARIANTS`` (:func:`variant_runs`' models):
    {variant: (pred (N,) int64 predicted spots, reference (N,) int64 the labels the CNN was trained on)}."""
    return {v: (cnn.predict(r["model"], X), ref)
            for v, (r, ref) in variant_runs(X, gt, frames_per_spot, paper_run, **train_kw).items()}


def _seed_row(variant: str, run: dict, s: dict, converged_at: float) -> dict:
    """One seed and variant of :func:`over_seeds`: its training (epochs, final training accuracy,
    converged by ``training_over_seeds.converged``) and ``dictionary.score_closures``' dict ``s``, in %."""
    h = run["history"]
    events = s["true_events"] + s["false_events"]
    return {"seed": run["seed"], "variant": variant, "epochs": len(h["accuracy"]),
            "final_train_acc_%": 100 * h["accuracy"][-1], "stopped_early": bool(h.get("stopped_early", False)),
            "converged": tos.converged(h, converged_at), "flagged_frames": s["true_frames"] + s["false_frames"],
            "true_frames": s["true_frames"], "events": events, "true_events": s["true_events"],
            "precision_%": 100 * s["precision"],
            "event_precision_%": 100 * s["true_events"] / events if events else np.nan,
            "revisit_frames": s["revisit_frames"],
            "recall_%": 100 * s["revisits_detected"] / s["revisit_frames"] if s["revisit_frames"] else np.nan}


def over_seeds(X: np.ndarray, gt: np.ndarray, frames_per_spot: int, runs: list[dict], tau: int,
               exclude: int = DEFAULT_EXCLUDE, converged_at: float = 0.95, **train_kw):
    """The detector at τ with every seed's CNN, per variant: closure precision and recall with their
    spread over seeds and each seed's convergence (the rule of notebooks 01/02, ``training_over_seeds.converged``).

    X, gt, frames_per_spot: as :func:`variant_runs`; runs: ``cnn.run_seeds``' dicts on the paper's
    labels, one per seed; tau: detections; exclude: frames; converged_at: a fraction; train_kw: the
    loop-aware CNN's training (as the paper's). Returns (per_seed, first): per_seed a DataFrame, one
    row per seed and variant: seed, variant, epochs, final_train_acc_%, stopped_early, converged,
    flagged_frames, true_frames, events, true_events, precision_% (true / flagged frames),
    event_precision_% (true / declared closure events; NaN where none), revisit_frames, recall_%
    (revisit frames flagged true / revisit frames; NaN without revisits); first: the first seed's
    :func:`variant_predictions` dict (the figures draw it)."""
    rows, first = [], None
    for run in runs:
        both = variant_runs(X, gt, frames_per_spot, run, **train_kw)
        preds = {v: (cnn.predict(r["model"], X), ref) for v, (r, ref) in both.items()}
        first = first or preds
        for v, (pred, ref) in preds.items():
            rows.append(_seed_row(v, both[v][0], dictionary.score_closures(pred, ref, gt, tau, exclude), converged_at))
    return pd.DataFrame(rows), first


SEED_STATS = ("precision_%", "event_precision_%", "recall_%")


def seed_summary(per_seed: pd.DataFrame) -> pd.DataFrame:
    """:func:`over_seeds`' table per variant (in ``VARIANTS`` order): seeds, converged_seeds, then for
    each of ``SEED_STATS`` its median, min and max over the seeds (``<stat>_median`` ...) and its median
    over the converged seeds (``<stat>_median_converged``, NaN where none converged), in %."""
    out = []
    for v, d in per_seed.groupby("variant", sort=False):
        row = {"variant": v, "seeds": len(d), "converged_seeds": int(d.converged.sum())}
        for c in SEED_STATS:
            k = c.removesuffix("_%")
            row.update({f"{k}_median_%": d[c].median(), f"{k}_min_%": d[c].min(), f"{k}_max_%": d[c].max(),
                        f"{k}_median_converged_%": d[d.converged][c].median() if d.converged.any() else np.nan})
        out.append(row)
    return pd.DataFrame(out)


def spread_text(summary: pd.DataFrame, variant: str, stat: str) -> str:
    """One cell of :func:`seed_summary`'s table: "median [min, max] (k of n seeds converged)" of ``stat``
    (a SEED_STATS name without _%: 'precision', 'event_precision', 'recall') for ``variant``."""
    r = summary.set_index("variant").loc[variant]
    return (f"{r[stat + '_median_%']:.1f} [{r[stat + '_min_%']:.1f}, {r[stat + '_max_%']:.1f}]"
            f" ({r['converged_seeds']} of {r['seeds']} seeds converged)")


def variant_scores(variants: dict, gt: np.ndarray, tau: int, exclude: int = DEFAULT_EXCLUDE) -> dict:
    """``dictionary.score_closures`` of each variant at τ: {variant: its dict}; variants:
    :func:`variant_predictions`' dict, gt: (N, N) bool, tau: detections, exclude: frames."""
    return {name: dictionary.score_closures(pred, ref, gt, tau, exclude) for name, (pred, ref) in variants.items()}


def events(scores: dict) -> pd.DataFrame:
    """Every closure event of :func:`variant_scores`: one row per event (variant, frame, spot,
    count, true), in variant then frame order."""
    return pd.DataFrame([dict(variant=name, **e) for name, s in scores.items() for e in s["event_list"]])


def events_view(events: pd.DataFrame, tau: int):
    """What the notebook shows of :func:`events`' table: the table, or a one-line Markdown note when no
    variant declared a closure at τ (an empty table says nothing)."""
    from IPython.display import Markdown

    return events if len(events) else Markdown(f"No variant declares a closure event at τ = {tau}.")


def scores_summary(scores: dict) -> dict:
    """:func:`variant_scores` without the per-frame flags, for summary.json: {variant: dict}."""
    return {name: {k: v for k, v in s.items() if k != "flags"} for name, s in scores.items()}


def tau_sweep(pred, reference_labels, gt, taus, exclude: int = DEFAULT_EXCLUDE) -> list[dict]:
    """The detector scored at every threshold of a sweep (``dictionary.score_closures`` per tau).

    pred, reference_labels, gt, exclude: as in ``dictionary.score_closures``; taus: thresholds
    (ints >= 1). Returns one dict per tau: tau, true_events, false_events, true_frames,
    false_frames, revisit_recall_% (revisit frames flagged true / revisit frames, in %; 0
    without revisits), first_delay_frames (frames from the start of the first revisit run with a
    true closure to that closure, None when none has one).
    """
    rows = []
    for t in taus:
        s = dictionary.score_closures(pred, reference_labels, gt, t, exclude)
        d = [x for x in s["delays"] if x is not None]
        rows.append({"tau": t, "true_events": s["true_events"], "false_events": s["false_events"],
                     "true_frames": s["true_frames"], "false_frames": s["false_frames"],
                     "revisit_recall_%": 100 * s["revisits_detected"] / max(1, s["revisit_frames"]),
                     "first_delay_frames": d[0] if d else None})
    return rows


def sweep(variants: dict, gt: np.ndarray, taus, exclude: int = DEFAULT_EXCLUDE) -> pd.DataFrame:
    """The τ sweep of every variant: :func:`tau_sweep`'s rows with a first column 'variant';
    variants: :func:`variant_predictions`' dict."""
    return pd.DataFrame([{"variant": name, **row} for name, (pred, ref) in variants.items()
                         for row in tau_sweep(pred, ref, gt, taus, exclude)])


def figure_timeline(variants: dict, scores: dict, tau: int, revisit: np.ndarray):
    """Every spot's count D(c) (detections) over the stream per variant, with this run's τ (dotted),
    the paper's τ = 70 (dashed), the ground-truth revisit frames (green) and each closure event (blue
    true, red false); revisit: (N,) bool."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(scores), 1, figsize=(14, 6), sharex=True)
    for ax, (name, s) in zip(axes, scores.items()):
        pred, ref = variants[name]
        ax.plot(dictionary.counts(pred, int(ref.max() + 1)), lw=0.6, color="grey", alpha=0.5)
        ax.axhline(tau, color="k", ls=":", label=f"this run: τ = {tau}")
        ax.axhline(PAPER_TAU, color="r", ls="--", lw=1, label=f"paper: τ = {PAPER_TAU}")
        ax.fill_between(np.arange(len(revisit)), 0, max(tau, PAPER_TAU) * 1.6, where=revisit, color="tab:green", alpha=0.15,
                        label="ground-truth revisit frames")
        for e in s["event_list"]:
            ax.axvline(e["frame"], color="tab:blue" if e["true"] else "tab:red", lw=1)
        ax.plot([], [], color="tab:blue", lw=1, label="true closure event")
        ax.plot([], [], color="tab:red", lw=1, label="false closure event")
        ax.set_title(f"{name}: {s['true_events']} true / {s['false_events']} false closure events, "
                     f"{s['true_frames']} true / {s['false_frames']} false flagged frames")
        ax.set_ylabel("D(c), every spot"); ax.set_ylim(0, max(tau, PAPER_TAU) * 1.6)
    axes[0].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1)); axes[-1].set_xlabel("frame (capture order)")
    fig.tight_layout()
    return fig


def figure_path(centres: np.ndarray, variants: dict, scores: dict, tau: int, revisit: np.ndarray):
    """The declared closures on the path (top view), one panel per variant: each event's frame
    joined to the middle frame of the spot it recognised (blue true, red false).

    centres: (N, 3) camera centres in metres (x right, z forward); revisit: (N,) bool."""
    import matplotlib.pyplot as plt

    t = centres
    fig, axes = plt.subplots(1, len(scores), figsize=(6.5 * len(scores), 5.5), squeeze=False)
    for ax, (name, s) in zip(axes[0], scores.items()):
        ref = variants[name][1]
        ax.plot(t[:, 0], t[:, 2], color="0.8", lw=1, zorder=1)
        ax.scatter(t[revisit, 0], t[revisit, 2], s=2, color="tab:green", alpha=0.4, label="ground-truth revisit frames", zorder=2)
        for e in s["event_list"]:
            f, spot = e["frame"], np.flatnonzero(ref == e["spot"])
            colour = "tab:blue" if e["true"] else "tab:red"
            ax.plot(*t[f, [0, 2]], "o", color=colour, ms=5, zorder=4)
            ax.plot(t[[f, spot[len(spot) // 2]], 0], t[[f, spot[len(spot) // 2]], 2], color=colour, lw=0.8, ls="--", zorder=3)
        ax.plot([], [], "o--", color="tab:blue", label="true closure: frame → the spot it recognised")
        ax.plot([], [], "o--", color="tab:red", label="false closure")
        ax.set_aspect("equal"); ax.set_xlabel("x (m)"); ax.set_ylabel("z (m)")
        ax.set_title(f"{name}, τ = {tau}: {s['true_events']} true / {s['false_events']} false", fontsize=10)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
    fig.suptitle("Declared closures on the path (top view)")
    fig.tight_layout()
    return fig


def figure_sweep(sweep: pd.DataFrame, tau: int):
    """True and false closure frames (counts) against τ, one panel per variant of :func:`sweep`'s
    table, with this run's τ = L + Δ dotted and the paper's τ = 70 dashed. Returns the figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, sweep.variant.nunique(), figsize=(13, 4), sharey=False, squeeze=False)
    for ax, (name, g) in zip(axes[0], sweep.groupby("variant", sort=False)):
        ax.plot(g.tau, g.true_frames, "o-", label="true closure frames")
        ax.plot(g.tau, g.false_frames, "s-", color="tab:red", label="false closure frames")
        ax.axvline(tau, color="k", ls=":", label=f"this run: τ = L + Δ = {tau}")
        ax.axvline(PAPER_TAU, color="r", ls="--", lw=1, label=f"paper: τ = {PAPER_TAU}")
        ax.set_xlabel("τ (detections)"); ax.set_ylabel("frames flagged as a closure"); ax.set_title(name)
    axes[0, -1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    return fig


def _threshold(derived: dict, name: str) -> str:
    """The derivation of τ with the error rate measured (the paper's ε = 0.10, τ = 70)."""
    return (f"On {name}, the worst seed's error rate ε = {wording.num(derived['error_rate'], 3)} gives "
            f"(1 − ε)·L = {wording.num(derived['expected_correct'], 1)} expected correct detections of a spot of "
            f"L = {derived['frames_per_spot']} and τ = L + Δ = {derived['tau']} (the paper: ε = 0.10, 54, τ = {PAPER_TAU}).")


LABELS = dict(zip(VARIANTS, ("the paper's labels (spots by frame index)", "the loop-aware labels (spots by place)")))


def _at_tau(scores: dict, tau: int) -> str:
    """Closure events and the revisit frames flagged at τ, per variant (one seed: no spread)."""
    revisits = next(iter(scores.values()))["revisit_frames"]
    if not revisits:
        return (f"The ground truth holds no revisit frame outside the exclusion window, so no closure can be true: at "
                f"τ = {tau} " + "; ".join(f"{LABELS.get(v, v)} declare {wording.count(s['false_events'], 'false closure event')}"
                                          for v, s in scores.items()) + ".")
    each = "; ".join(f"{LABELS.get(v, v)} declare {s['true_events']} true and {s['false_events']} false closure events "
                     f"and flag {wording.num(100 * s['revisits_detected'] / revisits, 1)} % of the {revisits} revisit "
                     f"frames" for v, s in scores.items())
    return (f"At τ = {tau}, {each} (one seed, so no spread; the loop-aware labels come from the ground truth that "
            f"scores them: an upper bound, not a detection result).")


def _over_seed_sentence(summary: pd.DataFrame, tau: int) -> str:
    """:func:`seed_summary`'s table in words: per variant the closure precision and recall at τ,
    median [min, max] over seeds, and how many seeds converged (budget-limited where fewer than half)."""
    def one(r):
        conv = f"{int(r.converged_seeds)} of {wording.count(r.seeds, 'seed')} converged"
        if wording.verdict.budget_limited(r.converged_seeds, r.seeds):
            conv += ", budget-limited"
        recall = (f"recall {wording.num(r['recall_median_%'], 1)} % {wording.span(r['recall_min_%'], r['recall_max_%'], 1)} "
                  f"of the revisit frames" if pd.notna(r["recall_median_%"]) else "no revisit frame to recall")
        precision = (f"closure precision {wording.num(r['precision_median_%'], 1)} % "
                     f"{wording.span(r['precision_min_%'], r['precision_max_%'], 1)} of the flagged frames"
                     if pd.notna(r["precision_max_%"]) else "no frame flagged")
        return f"{LABELS.get(r.variant, r.variant)}: {precision}, {recall} ({conv})"
    return (f"At τ = {tau}, median [min, max] over each seed's CNN: " + "; ".join(one(r) for _, r in summary.iterrows())
            + " (the loop-aware labels come from the ground truth that scores them: an upper bound, not a detection result).")


def _over_sweep(sweep: pd.DataFrame) -> str:
    """What the τ sweep of the paper's labels declares at its lowest and its highest τ, and at most."""
    g = sweep[sweep.variant == VARIANTS[0]].sort_values("tau")
    if not len(g):
        return ""
    lo, hi, most = g.iloc[0], g.iloc[-1], int(g.true_events.max())
    at = ", ".join(str(int(t)) for t in g[g.true_events == most].tau)
    true = "never declare a true closure event" if most == 0 else \
        f"declare at most {most} true closure events (at τ = {at})"
    return (f"Over τ from {int(lo.tau)} to {int(hi.tau)}, the paper's labels {true}; their false closure events number "
            f"{int(lo.false_events)} at τ = {int(lo.tau)} and {int(hi.false_events)} at τ = {int(hi.tau)}.")


def conclusion(out_dir) -> str:
    """Notebook 05's last cell (its claim, the dictionary as a detector, is concluded on in notebook 13):
    the τ derived with the measured error rate, the closures each variant declares at it, and what the
    τ sweep of the paper's labels declares. out_dir: the notebook's folder
    (``<results_dir>/05_dictionary_threshold``) holding summary.json and tau_sweep.csv. Returns Markdown."""
    out_dir = Path(out_dir)
    s = json.loads((out_dir / "summary.json").read_text())
    name = wording.verdict.dataset_name(out_dir.parent)
    tau = s["derived"]["tau"]
    seeds = out_dir / "seeds_summary.csv"
    at_tau = _over_seed_sentence(pd.read_csv(seeds), tau) if seeds.is_file() else _at_tau(s["scores"], tau)
    return wording.compose(out_dir.parent, "05_dictionary_threshold",
                           [_threshold(s["derived"], name), at_tau,
                            _over_sweep(pd.read_csv(out_dir / "tau_sweep.csv")),
                            "Whether the dictionary declares loop closures at the precision a detector needs is "
                            "concluded in notebook 13, on held-out evaluation queries."])
