"""Loop-closure metrics: a similarity matrix or a detector's decisions against ground-truth loops.

Arrays in, fractions out; ``greenloop.evaluate`` (the package doc) says what is measured, exactly.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from sklearn.metrics import average_precision_score, precision_recall_curve, roc_curve

from greenloop.groundtruth import DEFAULT_EXCLUDE, far_in_time
from greenloop.util.checks import positive_int

_NO_LOOPS = ("the ground truth has no loops among the counted pairs (|i - j| > exclude={exclude}"
             "{q}): use a larger pose threshold (greenloop.groundtruth.for_sequence), a larger "
             "tolerance in ground_truth.csv, a smaller exclude, or other query frames; the "
             "sequence may not revisit any place")


# ----------------------------------------------------------------------------------- checks
def _check_exclude(exclude) -> int:
    return positive_int("exclude", exclude, 0, unit="frames")


def _check_gt(GT, name: str = "GT") -> np.ndarray:
    G = np.asarray(GT)
    if G.ndim != 2 or G.shape[0] != G.shape[1]:
        raise ValueError(f"{name} must be a square (N, N) loop matrix from "
                         f"greenloop.groundtruth.for_sequence, got shape {G.shape}")
    if G.dtype != bool:
        if not np.issubdtype(G.dtype, np.number) or not np.all(np.isin(G, (0, 1))):
            raise ValueError(f"{name} must be boolean (or 0/1), got dtype {G.dtype}")
        G = G.astype(bool)
    if not np.array_equal(G, G.T):
        raise ValueError(f"{name} must be symmetric, as greenloop.groundtruth.for_sequence returns; "
                         f"for a one-triangle matrix pass `gt | gt.T`")
    return G


def _check_pair(S, GT):
    S = np.asarray(S)
    G = np.asarray(GT)
    if S.ndim != 2 or G.ndim != 2 or S.shape != G.shape or S.shape[0] != S.shape[1]:
        raise ValueError(f"S and GT must be square matrices of the same size (N, N): S has shape "
                         f"{S.shape}, GT has shape {G.shape}; compute both from the same frames")
    if not np.issubdtype(S.dtype, np.number) or np.iscomplexobj(S):
        raise ValueError(f"S must be a real numeric similarity matrix, got dtype {S.dtype}")
    G = _check_gt(G)
    return S, G


def _check_queries(queries, n: int):
    if queries is None:
        return None
    q = np.asarray(queries)
    if q.shape != (n,) or q.dtype != bool:
        raise ValueError(f"queries must be a (N,) bool mask of query frames with N={n}, got "
                         f"shape {q.shape} dtype {q.dtype} (see split_mask)")
    return q


def pair_mask(n: int, exclude: int = DEFAULT_EXCLUDE, queries=None) -> np.ndarray:
    """The counted pairs: (n, n) bool, True at [i, j] iff i < j, j - i > exclude and
    (queries is None or queries[j]). ``S[pair_mask(...)]`` lists them in row-major order,
    the order used by :func:`pair_samples` and by a (P,) ``predicted`` in :func:`operating_point`.
    """
    exclude = _check_exclude(exclude)
    q = _check_queries(queries, n)
    m = np.triu(far_in_time(n, exclude), 1)            # i < j and j - i > exclude
    if q is not None:
        m &= q[None, :]
    return m


# ------------------------------------------------------------------------------ scores
def pair_samples(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None):
    """Labels and scores of the counted pairs, ready for scikit-learn metrics.

    S: (N, N) similarity matrix, higher = more similar; S[i, j], i < j, is used (earlier frame
       as database row, later frame as query column).
    GT: (N, N) bool symmetric ground truth from :mod:`greenloop.groundtruth`.
    exclude: pairs with |i - j| <= exclude frames are left out even where GT is True.
    queries: optional (N,) bool; only pairs whose later frame j is in it count (module doc).
    Returns (y_true (P,) bool, y_score (P,) float) over pairs i < j, j - i > exclude, each
    unordered pair once, in row-major order.
    Raises ValueError if the shapes differ, S has NaN, or no counted pair is a loop.
    """
    S, G = _check_pair(S, GT)
    m = pair_mask(S.shape[0], exclude, queries)
    y_true, y_score = G[m], S[m]
    if y_score.size == 0:
        raise ValueError(f"no pairs to score: N={S.shape[0]} frames with exclude={exclude} "
                         f"(and the query mask) leave no pair with j - i > exclude")
    if not np.all(np.isfinite(y_score)):
        raise ValueError("S contains NaN or inf among the counted pairs; fix the similarity")
    if not y_true.any():
        raise ValueError(_NO_LOOPS.format(exclude=exclude,
                                          q="" if queries is None else ", in the query mask"))
    return y_true, y_score


def pr_curve(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None):
    """Precision-recall curve over the counted pairs (sklearn.metrics.precision_recall_curve).

    Arguments as in :func:`pair_samples`. Returns (precision, recall, thresholds) exactly as
    scikit-learn does: thresholds (T,) are the distinct scores in increasing order; precision
    and recall have T + 1 entries, the last being precision 1, recall 0 (no threshold).
    Declaring pairs with S >= thresholds[k] loops gives precision[k], recall[k].
    """
    y_true, y_score = pair_samples(S, GT, exclude, queries)
    return precision_recall_curve(y_true, y_score)


def average_precision(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """Average precision over the counted pairs (sklearn.metrics.average_precision_score).

    Step-wise: AP = sum_n (R_n - R_{n-1}) P_n over the distinct thresholds, highest first;
    NOT the trapezoidal area under the PR curve. Arguments as in :func:`pair_samples`.
    Returns a float in [0, 1]; a random score gives about the fraction of loop pairs.
    """
    y_true, y_score = pair_samples(S, GT, exclude, queries)
    return float(average_precision_score(y_true, y_score))


def recall_at_precision(S, GT, precision: float = 0.95, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """The largest pair recall reached with precision >= ``precision`` (0 < precision <= 1).

    Arguments otherwise as in :func:`pair_samples`. Thresholds are the distinct scores, so tied
    pairs are declared together. Returns a float in [0, 1] (0.0 when no threshold reaches it).
    """
    if not 0 < precision <= 1:
        raise ValueError(f"precision must be in (0, 1], got {precision}")
    p, r, _ = pr_curve(S, GT, exclude, queries)
    ok = p >= precision
    return float(r[ok].max()) if ok.any() else 0.0


def recall_at_100_precision(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """The largest recall reached with precision exactly 1 (no false loop declared):
    :func:`recall_at_precision` at 1. 0.0 if the top-scored pair (or any pair tied with it) is
    not a loop."""
    return recall_at_precision(S, GT, 1.0, exclude, queries)


def recall_at_k(S, GT, k: int = 1, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """Place-recognition recall@k (per query, not per pair): ``per_query(...)[f"R@{k}"]``.

    A query is a frame j with at least one ground-truth loop partner among its candidates (the
    earlier frames i with j - i > exclude, and queries[j] if given); it succeeds if any of its top
    k candidates, ranked by S[i, j] high to low (ties: the earlier frame first), is a loop.
    S: (N, N) similarity, higher = more similar (column j = query). GT: (N, N) bool symmetric.
    k: integer >= 1. Returns the fraction of queries that succeed, a float in [0, 1]. Raises
    ValueError if no frame is a query (no loops).
    """
    positive_int("k", k)
    m = best_matches(S, GT, exclude, queries, k=k)
    if not m.has_partner.any():
        raise ValueError(_NO_LOOPS.format(exclude=exclude,
                                          q="" if queries is None else ", in the query mask"))
    return float(np.mean(m.hit_rank[m.has_partner] < k))


# ------------------------------------------------------------- per-query metrics (the field's)
class Matches(NamedTuple):
    """Each query's ranked candidates, reduced to what the per-query metrics read. (Q,) arrays,
    one entry per query frame with at least one candidate, in increasing frame order:

    query: frame index j; match: its best candidate i (largest score; ties: smallest i);
    score: that score; correct: the best candidate is a ground-truth partner; has_partner: some
    candidate is; hit_rank: 0-based rank of the best-ranked partner among the candidates (score
    high to low, ties: smaller i first), or ``k`` when that rank is >= k or there is no partner.
    k: the cap of hit_rank (R@K is defined for K <= k).
    """
    query: np.ndarray
    match: np.ndarray
    score: np.ndarray
    correct: np.ndarray
    has_partner: np.ndarray
    hit_rank: np.ndarray
    k: int


def candidate_mask(n: int, exclude: int = DEFAULT_EXCLUDE, queries=None, reference=None) -> np.ndarray:
    """(n, n) bool: [i, j] True iff database frame i is a candidate of query frame j.

    Two database modes. Loop closure (``reference`` None, the default): every earlier frame
    outside the exclusion window, i < j and j - i > exclude (:func:`pair_mask`). Place
    recognition (``reference`` a (n,) bool mask, e.g. the first traversal): the candidates of
    query j are the reference frames, queries are the frames outside it; exclude is not used.
    queries: optional (n,) bool mask restricting the query frames in either mode.
    """
    if reference is None:
        return pair_mask(n, exclude, queries)
    ref = np.asarray(reference)
    if ref.shape != (n,) or ref.dtype != bool:
        raise ValueError(f"reference must be a (N,) bool mask of database frames with N={n}, got "
                         f"shape {ref.shape} dtype {ref.dtype}")
    if ref.all() or not ref.any():
        raise ValueError("reference must mark some frames (the database) and leave others (the "
                         "queries): place recognition needs both")
    m = ref[:, None] & ~ref[None, :]
    q = _check_queries(queries, n)
    return m if q is None else m & q[None, :]


def matches(query, match, score, correct, has_partner, hit_rank, k: int) -> Matches:
    """A validated :class:`Matches` from arrays a caller ranked itself (e.g. an index's top-k
    lists, with no (N, N) matrix). All (Q,): query/match/hit_rank int, score float (finite),
    correct/has_partner bool (correct implies has_partner); 0 <= hit_rank <= k, and hit_rank == 0
    wherever correct. Returns the Matches; ValueError naming the field that is off."""
    k = positive_int("k", k)
    q, mt, hr = (np.asarray(a, dtype=np.int64) for a in (query, match, hit_rank))
    sc = np.asarray(score, dtype=np.float64)
    ok, hp = np.asarray(correct), np.asarray(has_partner)
    if len({a.shape for a in (q, mt, hr, sc, ok, hp)}) != 1 or q.ndim != 1:
        raise ValueError("query, match, score, correct, has_partner and hit_rank must be (Q,) "
                         "arrays of one length")
    if ok.dtype != bool or hp.dtype != bool:
        raise ValueError("correct and has_partner must be bool arrays")
    if not np.all(np.isfinite(sc)):
        raise ValueError("score has NaN or inf values: fix the similarity")
    if np.any(ok & ~hp) or np.any((hr < 0) | (hr > k)) or np.any(hr[ok] != 0):
        raise ValueError("inconsistent matches: a correct best match needs a partner and hit_rank "
                         "0, and hit_rank must lie in [0, k]")
    return Matches(q, mt, sc, ok, hp, hr, k)


def best_matches(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None, reference=None, k: int = 10) -> Matches:
    """Each query's best candidate and the rank of its best-ranked partner, from a score matrix.

    S: (N, N) float, higher = more similar, row = database frame, column = query. GT: (N, N)
    bool symmetric ground truth. exclude, queries, reference: the database mode
    (:func:`candidate_mask`). k: cap of hit_rank. Returns :class:`Matches` over the query frames
    with at least one candidate (those without a partner included: they count as false
    positives when they fire). Memory O(N Q); an index's top-k lists use :func:`matches`.
    """
    S, G = _check_pair(S, GT)
    n = S.shape[0]
    cand = candidate_mask(n, exclude, queries, reference)
    js = np.flatnonzero(cand.any(0))
    if not len(js):
        raise ValueError(f"no query frame has a candidate: N={n} frames, exclude={exclude} "
                         f"(and the query / reference masks) leave no database frame to match")
    Sq, cq = np.asarray(S[:, js], dtype=np.float64), cand[:, js]
    if not np.all(np.isfinite(Sq[cq])):
        raise ValueError("S contains NaN or inf among the candidate pairs; fix the similarity")
    Sm = np.where(cq, Sq, -np.inf)
    best = Sm.argmax(0)                                           # first maximum: smallest i
    cols = np.arange(len(js))
    tq = G[:, js] & cq
    has = tq.any(0)
    top = np.where(tq, Sq, -np.inf).max(0)                        # best partner's score
    rows = np.arange(n)[:, None]
    first = np.where(tq & (Sq == top), rows, n).min(0)
    ahead = (cq & ((Sq > top) | ((Sq == top) & (rows < first)))).sum(0)
    hit = np.where(has, np.minimum(ahead, k), k)
    return matches(js, best, Sm[best, cols], G[best, js] & cq[best, cols], has, hit, k)


def query_pr_curve(m: Matches):
    """The per-query precision-recall curve: each query's best match, ranked by its score.

    Declaring every query whose best score >= t: TP = declared and correct, FP = declared and not
    correct (a wrong best match, or a query without a partner that fires); recall = TP / (queries
    with a partner), precision = TP / declared. m: :class:`Matches`. Returns (precision,
    recall, thresholds), each (T,) over the T distinct scores in decreasing order (ties are
    declared together); no (P=1, R=0) anchor is added. ValueError if no query has a partner.
    """
    revisits = int(m.has_partner.sum())
    if not revisits:
        raise ValueError("no query has a ground-truth partner among its candidates: recall is "
                         "undefined (the sequence may not revisit any place outside the window)")
    order = np.argsort(-m.score, kind="stable")
    s, hit = m.score[order], m.correct[order]
    last = np.r_[s[1:] != s[:-1], True]
    tp = np.cumsum(hit)[last]
    declared = (np.arange(len(s)) + 1)[last]
    return tp / declared, tp / revisits, s[last]


def _recall_at(precision, recall, level: float) -> float:
    ok = precision >= level - 1e-12
    return float(recall[ok].max()) if ok.any() else 0.0


def query_metrics(m: Matches, ks=(1, 5, 10)) -> dict:
    """The field's per-query metrics of one method, as fractions in [0, 1].

    m: :class:`Matches`; ks: the K of Recall@K (each <= m.k). Returns {"R@K": fraction of the
    queries with a partner whose best-ranked partner is in the top K, for each K; "AUC-PR": the
    step-wise area sum_n (R_n - R_{n-1}) P_n of :func:`query_pr_curve` (R_0 = 0), not the
    trapezoid; "R@100P" / "R@95P": the largest recall with precision >= 1 / 0.95 (0.0 when
    none); "queries": Q; "revisits": queries with a partner}.
    """
    ks = [positive_int("K", K) for K in ks]
    if any(K > m.k for K in ks):
        raise ValueError(f"R@K needs K <= k={m.k} (the cap the matches were ranked with); got {ks}")
    p, r, _ = query_pr_curve(m)
    hp = m.has_partner
    out = {f"R@{K}": float(np.mean(m.hit_rank[hp] < K)) for K in ks}
    out["AUC-PR"] = float(np.sum(np.diff(np.r_[0.0, r]) * p))
    out["R@100P"], out["R@95P"] = _recall_at(p, r, 1.0), _recall_at(p, r, 0.95)
    out["queries"], out["revisits"] = int(len(m.query)), int(hp.sum())
    return out


def per_query(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None, reference=None, ks=(1, 5, 10)) -> dict:
    """:func:`query_metrics` of a score matrix: ``query_metrics(best_matches(S, GT, exclude,
    queries, reference, k=max(ks)), ks)``. Arguments as in :func:`best_matches`."""
    return query_metrics(best_matches(S, GT, exclude, queries, reference, k=max(ks)), ks)


def query_chance(GT, exclude: int = DEFAULT_EXCLUDE, queries=None, reference=None, ks=(1, 5, 10)) -> dict:
    """What a random score gets on :func:`query_metrics`' keys (fractions), for a chance row.

    With c_j candidates and t_j partners at query j: R@K = mean over queries with a partner of
    1 - C(c_j - t_j, K) / C(c_j, K) (exact). A random best match is correct with p_j = t_j / c_j,
    independently, in a random order of the Q queries, so the expected step-wise area is exact:
    AUC-PR = [H_Q sum p + ((sum p)^2 - sum p^2) (Q - H_Q) / (Q - 1)] / (Q revisits), H_Q the
    harmonic number (the expected AP of a random ranking, times the recall it ends at). R@100P
    is the expected run of correct queries at the top, approximated by pbar / (1 - pbar) /
    revisits with pbar = sum p / Q (capped at the final recall sum p / revisits); R@95P is the
    final recall where pbar >= 0.95, else R@100P. Arguments as in :func:`best_matches`.
    """
    G = _check_gt(GT)
    cand = candidate_mask(G.shape[0], exclude, queries, reference)
    has_cand = cand.any(0)
    c = cand.sum(0)[has_cand].astype(np.float64)
    t = (G & cand).sum(0)[has_cand].astype(np.float64)
    rev = t > 0
    if not rev.any():
        raise ValueError(_NO_LOOPS.format(exclude=exclude, q="" if queries is None else ", in the query mask"))
    out = {}
    for K in (positive_int("K", K) for K in ks):
        miss = np.ones(rev.sum())
        for r in range(K):                      # C(c - t, K) / C(c, K) as a product
            miss *= np.clip((c[rev] - t[rev] - r) / np.maximum(c[rev] - r, 1), 0, 1)
        out[f"R@{K}"] = float(np.mean(1 - miss))
    p = t / c
    pbar, final = float(p.mean()), float(p.sum() / rev.sum())
    Q, sp, h = len(c), float(p.sum()), float(np.sum(1.0 / np.arange(1, len(c) + 1)))
    pairs = (sp ** 2 - float(np.sum(p ** 2))) * ((Q - h) / (Q - 1) if Q > 1 else 0.0)
    out["AUC-PR"] = (h * sp + pairs) / (Q * rev.sum())
    out["R@100P"] = min(final, pbar / (1 - pbar) / rev.sum()) if pbar < 1 else final
    out["R@95P"] = final if pbar >= 0.95 else out["R@100P"]
    out["queries"], out["revisits"] = int(len(c)), int(rev.sum())
    return out


# -------------------------------------------------------------- mean per-class accuracy
def mean_per_class_accuracy(S, GT, threshold: float, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """Mean per-class accuracy (MPCA) of declaring every counted pair with S >= threshold a loop.

    The two classes are the counted pairs (:func:`pair_samples`) that are loops and those that
    are not; MPCA = (recall on loop pairs + recall on non-loop pairs) / 2, scikit-learn's
    balanced accuracy. 0.5 is chance, 1 is perfect. The ResNet/Inception/ZCA paper reports it
    (Table III) without stating its threshold; pick one with :func:`mpca_threshold` on a tuning
    part and score it here on another. S, GT, exclude, queries as in :func:`pair_samples`;
    threshold in the units of S. Returns a float in [0, 1].
    """
    y_true, y_score = pair_samples(S, GT, exclude, queries)
    declared = y_score >= threshold
    return float((declared[y_true].mean() + (~declared[~y_true]).mean()) / 2)


def mpca_threshold(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """The threshold on S that maximises :func:`mean_per_class_accuracy` over the counted pairs
    (the point of the ROC curve furthest above the diagonal, max TPR - FPR). Arguments as in
    :func:`pair_samples`; call it with the tuning part's ``queries``. Returns a float in S's units
    (``inf`` would declare nothing; it is never returned, since declaring the top pair is at
    least as good)."""
    y_true, y_score = pair_samples(S, GT, exclude, queries)
    fpr, tpr, thr = roc_curve(y_true, y_score)
    k = int(np.argmax(tpr - fpr))
    return float(thr[k]) if np.isfinite(thr[k]) else float(thr[1])


# -------------------------------------------------------------------- decision detectors
def operating_point(predicted, GT, exclude: int = DEFAULT_EXCLUDE, queries=None) -> dict:
    """Precision and recall of a detector that outputs loop decisions, not scores.

    predicted: either an (N, N) bool matrix of declared loop pairs (a pair i < j counts as
        declared if predicted[i, j] or predicted[j, i], so a detector may fill either triangle,
        e.g. row = query, column = matched earlier frame), or a (P,) bool vector aligned with
        the counted pairs of :func:`pair_samples` (row-major order of :func:`pair_mask`).
    GT, exclude, queries: as in :func:`pair_samples`; only counted pairs are scored.
    Returns dict(precision, recall, tp, fp, fn, ignored): counts over counted pairs;
    precision = tp / (tp + fp) (NaN if nothing was declared: undefined, not 1), recall =
    tp / (tp + fn); ``ignored`` = declared pairs not counted (within ``exclude`` frames or
    outside ``queries``), reported so that they are not silently lost.
    The point can be drawn on the axes of :func:`pr_curve` (x = recall, y = precision).
    """
    G = _check_gt(GT)
    n = G.shape[0]
    m = pair_mask(n, exclude, queries)
    P = np.asarray(predicted)
    if P.dtype != bool:
        raise ValueError(f"predicted must be boolean decisions, got dtype {P.dtype}")
    if P.ndim == 2:
        if P.shape != G.shape:
            raise ValueError(f"predicted and GT must have the same shape: predicted has shape "
                             f"{P.shape}, GT has shape {G.shape}")
        declared = np.triu(P | P.T, 1)
        ignored = int((declared & ~m).sum())
        pred = declared[m]
    elif P.ndim == 1:
        n_pairs = int(m.sum())
        if P.shape[0] != n_pairs:
            raise ValueError(f"a 1-D predicted must have one entry per counted pair: expected "
                             f"shape ({n_pairs},) for N={n}, exclude={exclude}, got {P.shape}")
        pred, ignored = P, 0
    else:
        raise ValueError(f"predicted must be (N, N) or (P,) bool, got shape {P.shape}")
    y = G[m]
    if not y.any():
        raise ValueError(_NO_LOOPS.format(exclude=exclude,
                                          q="" if queries is None else ", in the query mask"))
    tp = int(np.sum(pred & y))
    fp = int(np.sum(pred & ~y))
    fn = int(np.sum(~pred & y))
    precision = tp / (tp + fp) if tp + fp else float("nan")
    return dict(precision=float(precision), recall=tp / (tp + fn), tp=tp, fp=fp, fn=fn,
                ignored=ignored)


def closure_counts(declared, correct, revisit, at=None) -> dict:
    """Count per-query closures: the one tally of ``seqmatch.closures`` (a score matrix at a
    threshold) and ``dictionary.query_closures`` (a detector's declared pairs).

    declared, correct, revisit: (Q,) bool per query: a closure is declared at it, the declared
    closure is a ground-truth loop (a subset of declared), it has a loop partner. at: (Q,) the
    frame index of each query (default 0..Q-1), for the delay.
    Returns dict(declared, false, correct, revisits, precision (NaN if none declared), recall
    (correct / revisits, NaN without revisits), f1 (0 without a correct closure), first_delay
    (frames from the first revisit query to the first correct closure; None if never)).
    """
    dec, ok, rev = (np.asarray(a, dtype=bool) for a in (declared, correct, revisit))
    at = np.arange(len(dec)) if at is None else np.asarray(at)
    ok = dec & ok
    correct_ = int(ok.sum())
    n_dec, n_rev = int(dec.sum()), int(rev.sum())
    precision = correct_ / n_dec if n_dec else float("nan")
    recall = correct_ / n_rev if n_rev else float("nan")
    f1 = 2 * precision * recall / (precision + recall) if correct_ else 0.0
    first_rev = at[rev][0] if n_rev else None
    hits = at[ok]
    delay = int(hits[0] - first_rev) if len(hits) and first_rev is not None else None
    return dict(declared=n_dec, false=n_dec - correct_, correct=correct_, revisits=n_rev,
                precision=precision, recall=recall, f1=f1, first_delay=delay)


def false_closure_runs(S, GT, threshold: float, exclude: int = DEFAULT_EXCLUDE, queries=None, frames=None,
                       poses=None) -> list[dict]:
    """Where the false closures of a score matrix at a threshold lie: ``seqmatch.closures``' rule
    (each query's best candidate, :func:`best_matches`, declared when it scores >= threshold, false
    when it is no ground-truth loop), the false ones grouped into runs of consecutive query frames.

    S, GT, exclude, queries: as :func:`best_matches` (loop-closure mode). frames: (N,) int, each
    frame's number as the reader knows it (default 0..N-1; e.g. the original frame of a subsampled
    stream). poses: optional (N, 4, 4) camera-to-world matrices (metres), one per frame of S.
    Returns one dict per run, in stream order: first_query, last_query, first_match, last_match
    (``frames`` numbers), closures (false closures in the run), with_partner (of those, queries that
    have a ground-truth partner among their candidates), offset_frames (median over them of the
    match's distance, in ``frames`` numbers, to the query's nearest partner; NaN when none has one),
    max_score, and with poses distance_m (median distance of query's and match's camera centres)
    and angle_deg (median angle between their optical axes, +z, degrees; as
    ``groundtruth.loop_matrix_metric`` reads them).
    """
    m = best_matches(S, GT, exclude, queries)
    n = np.asarray(S).shape[0]
    f = np.arange(n) if frames is None else np.asarray(frames)
    if f.shape != (n,):
        raise ValueError(f"frames must be (N,) with N={n}, got shape {f.shape}")
    bad = np.flatnonzero((m.score >= threshold) & ~m.correct)
    G, cand = np.asarray(GT, dtype=bool), candidate_mask(n, exclude, queries)
    runs = np.split(bad, np.flatnonzero(np.diff(m.query[bad]) != 1) + 1) if len(bad) else []
    P = None if poses is None else np.asarray(poses, dtype=np.float64)
    out = []
    for r in runs:
        q, i, hp = m.query[r], m.match[r], m.has_partner[r]
        offsets = [np.abs(f[np.flatnonzero(G[:, j] & cand[:, j])] - f[b]).min() for j, b in zip(q[hp], i[hp])]
        row = dict(first_query=int(f[q[0]]), last_query=int(f[q[-1]]), first_match=int(f[i[0]]),
                   last_match=int(f[i[-1]]), closures=len(r), with_partner=len(offsets),
                   offset_frames=float(np.median(offsets)) if offsets else float("nan"),
                   max_score=float(m.score[r].max()))
        if P is not None:
            t, z = P[:, :3, 3], P[:, :3, 2]
            row["distance_m"] = float(np.median(np.linalg.norm(t[q] - t[i], axis=1)))
            row["angle_deg"] = float(np.median(np.degrees(np.arccos(np.clip((z[q] * z[i]).sum(1), -1.0, 1.0)))))
        out.append(row)
    return out


# ------------------------------------------------- the notebooks' scoring protocol (07-11)
def pair_metrics(S, GT, exclude: int = DEFAULT_EXCLUDE, queries=None, tag: str = "") -> dict:
    """AP and recall at 100 % precision of one similarity matrix, in % (unrounded).

    S, GT, exclude, queries: as in :func:`pair_samples`. tag: inserted in the keys, e.g. "_RGB".
    Returns {f"AP{tag}_%": float, f"R@100P{tag}_%": float}, the columns of the notebooks' tables.
    """
    return {f"AP{tag}_%": 100 * average_precision(S, GT, exclude, queries=queries),
            f"R@100P{tag}_%": 100 * recall_at_100_precision(S, GT, exclude, queries=queries)}


def chance_level(GT, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """The fraction of counted pairs that are loops: the AP a random score gets on average.

    GT: (N, N) bool ground truth; exclude, queries: as in :func:`pair_samples`. Returns a float in
    (0, 1] (a fraction, not %). ValueError as :func:`pair_samples` (no loop among the pairs).
    """
    G = _check_gt(GT)
    n = G.shape[0]
    return float(pair_samples(np.zeros((n, n), np.float32), G, exclude, queries)[0].mean())


def revisit_queries(GT, exclude: int = DEFAULT_EXCLUDE, queries=None, reference=None) -> np.ndarray:
    """(N,) bool: the queries with a loop partner among their candidates: frame j with some
    GT[i, j], i < j - exclude (:func:`pair_mask`, loop closure), or with i a ``reference`` frame
    (place recognition); within ``queries`` when given (:func:`candidate_mask`). These are the
    queries R@K and the recall of :func:`query_metrics` rest on (its "revisits"). GT: (N, N)
    bool; exclude: frames; queries, reference: (N,) bool or None."""
    G = _check_gt(GT)
    return (G & candidate_mask(G.shape[0], exclude, queries, reference)).any(0)


def precision_at_recall(S, GT, recall: float, exclude: int = DEFAULT_EXCLUDE, queries=None) -> float:
    """The best precision at a recall of at least ``recall`` (a fraction in [0, 1]).

    S, GT, exclude, queries: as in :func:`pr_curve`. Returns max precision over the points of the
    PR curve whose recall >= ``recall`` (the curve's last point has recall 0, so recall=0 always
    finds one; recall above the largest reached raises ValueError from the empty max).
    """
    p, r, _ = pr_curve(S, GT, exclude, queries=queries)
    return float(p[r >= recall].max())


def interpolated_precision(precision, recall, grid) -> np.ndarray:
    """Interpolated precision of a PR curve on a recall grid: the max precision at recall >= g.

    precision, recall: (T,) the curve's points (e.g. from :func:`pr_curve`). grid: (G,) recall
    values in [0, 1]. Returns (G,) float: max precision[recall >= g], 0.0 where no point reaches g.
    """
    p, r = np.asarray(precision), np.asarray(recall)
    return np.array([p[r >= g].max() if np.any(r >= g) else 0.0 for g in grid])


def overlap_recall(precision, recall, ref_precision, ref_recall, grid, tol: float) -> float:
    """The recall up to which a PR curve stays with a reference curve (Qi 2024 Figure 7's "overlap").

    precision, recall and ref_precision, ref_recall: (T,) and (T_ref,) the two curves' points.
    grid: (G,) increasing recall values; tol: largest allowed difference of interpolated precision
    (:func:`interpolated_precision`, a fraction). Returns grid[k - 1] for the first grid point k
    where the two differ by more than tol, 1.0 when they never do, 0.0 when they differ already
    at grid[0] (notebook 11 used to index grid[-1] there and report a full overlap).
    """
    P = interpolated_precision(precision, recall, grid)
    P_ref = interpolated_precision(ref_precision, ref_recall, grid)
    off = np.abs(P - P_ref) > tol
    if not off.any():
        return 1.0
    k = int(np.argmax(off))
    return float(np.asarray(grid)[k - 1]) if k > 0 else 0.0


def relative_rates(accuracy, seconds, ref_accuracy, ref_seconds):
    """Qi 2024's optimisation rates of a method against a reference method, in %.

    accuracy, seconds: the method's accuracy (AP, any unit) and time (any unit), scalars, arrays or
    pandas Series; ref_accuracy, ref_seconds: the reference's, in the same units (broadcast).
    Returns (R_a, R_t): R_a = 100 (a - a_ref) / a_ref (accuracy change, + = better) and
    R_t = 100 (t_ref - t) / t_ref (time saved, + = faster), of the inputs' type, unrounded.
    """
    R_a = 100 * (accuracy - ref_accuracy) / ref_accuracy
    R_t = 100 * (ref_seconds - seconds) / ref_seconds
    return R_a, R_t


def loss_per_time_saved(R_a, R_t) -> np.ndarray:
    """Accuracy lost per 1 % of time saved, -R_a / R_t (Qi 2024 Table 6), NaN where no time is saved.

    R_a, R_t: (K,) rates in % from :func:`relative_rates`. Returns (K,) float: -R_a / R_t where
    R_t > 0, NaN elsewhere (a slower method has no such trade).
    """
    R_a, R_t = np.asarray(R_a, dtype=float), np.asarray(R_t, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(R_t > 0, -R_a / R_t, np.nan)
