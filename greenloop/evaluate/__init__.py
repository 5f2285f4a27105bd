"""Scoring: loop closures against ground-truth loops, and the spot classifier's predictions.

Three rooms: ``metrics`` (arrays in, fractions out), ``split`` (the honest tuning/evaluation split)
and ``spot_errors`` (the spot classifier's errors); every public name is read as ``evaluate.NAME``.

Loop closures: a similarity matrix or a detector's decisions against the ground truth (below).
The spot classifier (main paper Tables 2 and 4): :func:`per_spot` (precision, recall, F1 per
spot), :func:`spot_errors` (misclassified and adjacent-spot errors), :func:`same_place_errors`.

What is measured, exactly
-------------------------
The ground truth is a symmetric (N, N) bool matrix from :mod:`greenloop.groundtruth`, the one
place that defines when two frames are a loop: get a sequence's with
:func:`greenloop.groundtruth.for_sequence` (its poses by Qi 2024 Eq. 5 where it has them, its
``ground_truth.csv`` loop pairs otherwise), or from poses with ``loop_matrix`` /
``loop_matrix_metric``. Here every **unordered pair of frames
(i, j), i < j, with j - i > exclude** (default 150 frames, Qi 2024) is one sample, labelled by
``GT[i, j]`` and scored by ``S[i, j]`` (row = earlier/database frame, column = later/query
frame; higher = more similar). Pairs within ``exclude`` frames never count, whatever GT says.
"AP" is scikit-learn's ``average_precision_score`` over those pairs: the **step-wise** sum
``AP = sum_n (R_n - R_{n-1}) P_n`` over the distinct score thresholds, highest first (P_n, R_n
the precision and recall of declaring every pair scored >= the n-th threshold a loop). It is
*not* the trapezoidal area under the PR curve (``sklearn.metrics.auc(recall, precision)``),
which interpolates linearly and is optimistic. Pair AP is this study's secondary column,
named "pair AP" wherever it appears.

The field's metrics are per query (:func:`best_matches`, :func:`query_metrics`,
:func:`per_query`, :func:`query_chance`): each query frame's candidates are ranked by score;
Recall@K is the share of queries with a partner whose best-ranked partner is among the top K;
the precision-recall curve ranks each query's *best* match by its score (a wrong best match,
or a query without a partner that fires, is a false positive), and AUC-PR, R@100P and R@95P are
read off it. Two database modes (:func:`candidate_mask`): loop closure (every earlier frame
outside the exclusion window; the default) and place recognition (a reference traversal).
Numbers from tools that use another definition or another ground truth (other thresholds,
``exclude``, or pairs counted twice) are not comparable.

Honest tuning
-------------
Any tuned knob (median-filter size, PCA dimension, a detector's threshold) is tuned on one part
of the sequence and scored on another, never picked by its score on the evaluation ground
truth. :func:`split_mask` gives two disjoint sets of *query* frames; every pair-based function
takes ``queries=``: a (N,) bool mask, and pair (i, j), i < j, counts only when the later frame
j is in the mask (the earlier frame i may be anywhere). Tune with ``queries=tune``, report with
``queries=eval``. Where the revisit frames all lie within the gap of each other (one short loop
at the very end of a sequence), no such split exists: :func:`split_mask` raises
:class:`NoHonestSplit`, and only untuned numbers (over every query) can be reported.
"""
from __future__ import annotations

from greenloop.evaluate.metrics import (
    pair_mask, pair_samples, pr_curve, average_precision, recall_at_precision,
    recall_at_100_precision, recall_at_k, Matches, candidate_mask, matches,
    best_matches, query_pr_curve, query_metrics, per_query, query_chance,
    mean_per_class_accuracy, mpca_threshold, operating_point, closure_counts, false_closure_runs, pair_metrics,
    chance_level, revisit_queries, precision_at_recall, interpolated_precision, overlap_recall,
    relative_rates, loss_per_time_saved,
)
from greenloop.evaluate.split import (
    NoHonestSplit, split_mask, honest_split, split_summary,
)
from greenloop.evaluate.spot_errors import (
    per_spot, spot_errors, same_place_errors,
)

__all__ = [
    "pair_mask", "pair_samples", "pr_curve", "average_precision", "recall_at_precision",
    "recall_at_100_precision",
    "recall_at_k", "Matches", "candidate_mask", "matches", "best_matches", "query_pr_curve",
    "query_metrics", "per_query", "query_chance", "operating_point", "split_mask", "NoHonestSplit", "mean_per_class_accuracy",
    "mpca_threshold", "closure_counts", "false_closure_runs", "pair_metrics", "chance_level",
    "revisit_queries",
    "precision_at_recall", "interpolated_precision", "overlap_recall", "relative_rates",
    "loss_per_time_saved", "honest_split", "split_summary", "per_spot", "spot_errors", "same_place_errors",
]
