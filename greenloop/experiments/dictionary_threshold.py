"""Notebook 05's study: the paper's frequency-count dictionary at its threshold τ = L + Δ and over
a sweep of τ, scored against the ground truth, with the paper's spot labels (by frame index)
beside loop-aware ones (by place).

Every table comes back unrounded; ``report.write_table(..., decimals=...)`` rounds it.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from greenloop import cnn, dictionary, spots

VARIANTS = ("paper (spots by frame index)", "loop-aware (spots by place)")


def variant_predictions(X: np.ndarray, gt: np.ndarray, frames_per_spot: int, paper_run: dict,
                        **train_kw) -> dict:
    """Every frame's predicted spot under each of ``VARIANTS``.

    X: (N, H, W, C) frames; gt: (N, N) bool loop matrix; frames_per_spot: L; paper_run: one
    ``cnn.run_seeds`` dict trained on ``spots.group(N, L)`` (the paper's labels). The loop-aware
    CNN is trained here on ``spots.by_place(L, gt)`` with paper_run's seed; train_kw go to
    ``cnn.train`` (epochs, batch_size, ...). Returns {variant: (pred (N,) int64 predicted spots,
    reference (N,) int64 the labels the CNN was trained on)}.
    """
    y, y_place = spots.group(len(X), frames_per_spot), spots.by_place(frames_per_spot, gt)
    aware = cnn.run_seeds(X, y_place, [paper_run["seed"]], **train_kw)[0]
    return {VARIANTS[0]: (cnn.predict(paper_run["model"], X), y),
            VARIANTS[1]: (cnn.predict(aware["model"], X), y_place)}


def variant_scores(variants: dict, gt: np.ndarray, tau: int, exclude: int = 150) -> dict:
    """``dictionary.score_closures`` of each variant at τ: {variant: its dict}; variants:
    :func:`variant_predictions`' dict, gt: (N, N) bool, tau: detections, exclude: frames."""
    return {name: dictionary.score_closures(pred, ref, gt, tau, exclude) for name, (pred, ref) in variants.items()}


def events(scores: dict) -> pd.DataFrame:
    """Every closure event of :func:`variant_scores`: one row per event (variant, frame, spot,
    count, true), in variant then frame order."""
    return pd.DataFrame([dict(variant=name, **e) for name, s in scores.items() for e in s["event_list"]])


def scores_summary(scores: dict) -> dict:
    """:func:`variant_scores` without the per-frame flags, for summary.json: {variant: dict}."""
    return {name: {k: v for k, v in s.items() if k != "flags"} for name, s in scores.items()}


def tau_sweep(pred, reference_labels, gt, taus, exclude: int = 150) -> list[dict]:
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


def sweep(variants: dict, gt: np.ndarray, taus, exclude: int = 150) -> pd.DataFrame:
    """The τ sweep of every variant: :func:`tau_sweep`'s rows with a first column 'variant';
    variants: :func:`variant_predictions`' dict."""
    return pd.DataFrame([{"variant": name, **row} for name, (pred, ref) in variants.items()
                         for row in tau_sweep(pred, ref, gt, taus, exclude)])


def figure_timeline(variants: dict, scores: dict, tau: int, revisit: np.ndarray):
    """Every spot's count D(c) over the stream per variant, with τ, the ground-truth revisit
    frames (green) and each closure event (blue true, red false); revisit: (N,) bool."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(scores), 1, figsize=(14, 6), sharex=True)
    for ax, (name, s) in zip(axes, scores.items()):
        pred, ref = variants[name]
        ax.plot(dictionary.counts(pred, int(ref.max() + 1)), lw=0.6, color="grey", alpha=0.5)
        ax.axhline(tau, color="k", ls=":", label=f"τ = {tau}")
        ax.fill_between(np.arange(len(revisit)), 0, tau * 1.6, where=revisit, color="tab:green", alpha=0.15,
                        label="ground-truth revisit frames")
        for e in s["event_list"]:
            ax.axvline(e["frame"], color="tab:blue" if e["true"] else "tab:red", lw=1)
        ax.set_title(f"{name}: {s['true_events']} true / {s['false_events']} false closure events, "
                     f"{s['true_frames']} true / {s['false_frames']} false flagged frames")
        ax.set_ylabel("D(c), every spot"); ax.set_ylim(0, tau * 1.6)
    axes[0].legend(loc="upper left"); axes[-1].set_xlabel("frame (capture order)")
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
    """True and false closure frames against τ, one panel per variant of :func:`sweep`'s table,
    with the derived τ dotted."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, sweep.variant.nunique(), figsize=(13, 4), sharey=False)
    for ax, (name, g) in zip(np.atleast_1d(axes), sweep.groupby("variant", sort=False)):
        ax.plot(g.tau, g.true_frames, "o-", label="true closure frames")
        ax.plot(g.tau, g.false_frames, "s-", color="tab:red", label="false closure frames")
        ax.axvline(tau, color="k", ls=":"); ax.set_xlabel("τ"); ax.set_title(name); ax.legend()
    return fig
