"""greenloop.experiments.leaderboard.rows's paired comparisons: a metric's difference between two methods on the
same queries, bootstrapped in the same blocks as the rows' intervals (``spread``), and the table the
statement and the targets read."""
from collections import Counter

import numpy as np
import pandas as pd
import pytest

from greenloop import evaluate
from greenloop.experiments.leaderboard import rows as lb
from greenloop.methods.greenloop_seq import seqstream

Q, BLOCK = 300, 10


def _matches(correct, score):
    """(Q,) Matches of a method whose best match is right where ``correct`` (every query has a partner)."""
    ok = np.asarray(correct, dtype=bool)
    n = len(ok)
    return evaluate.matches(np.arange(n), np.zeros(n, int), score, ok, np.ones(n, bool), np.where(ok, 0, 1), k=1)


def _method(rng, rate: float, n: int = Q):
    """A method right on exactly ``rate`` of n queries (random positions); right matches score higher."""
    ok = np.zeros(n, bool)
    ok[rng.choice(n, int(round(rate * n)), replace=False)] = True
    return _matches(ok, rng.random(n) + 0.5 * ok)


def _unpaired(m, block=BLOCK):
    """Each method's own 95 % interval (what spread gives), in %: ((R@1 lo, hi), (AUC-PR lo, hi))."""
    lo, hi = 100 * np.percentile(lb.boot_metrics(m, block), [2.5, 97.5], axis=0)
    return tuple(zip(lo, hi))


def test_a_planted_difference_is_resolved_both_ways_round():
    rng = np.random.default_rng(0)
    a, b = _method(rng, 0.9), _method(rng, 0.5)
    d = lb.paired(a, b, BLOCK)
    assert d["R@1"]["difference"] == pytest.approx(40.0)               # 270 vs 150 of 300 queries
    assert d["R@1"]["resolved"] and 0 < d["R@1"]["lo"] < 40 < d["R@1"]["hi"]
    assert d["AUC-PR"]["resolved"] and d["AUC-PR"]["lo"] > 0
    back = lb.paired(b, a, BLOCK)                                        # b minus a: the mirror image
    assert back["R@1"]["difference"] == pytest.approx(-40.0) and back["R@1"]["resolved"]
    assert back["R@1"]["hi"] == pytest.approx(-d["R@1"]["lo"]) and back["R@1"]["lo"] == pytest.approx(-d["R@1"]["hi"])


def test_a_planted_null_is_not_resolved():
    rng = np.random.default_rng(1)
    a = _method(rng, 0.7)
    same = lb.paired(a, a, BLOCK)                                        # identical methods
    assert all(v == {"difference": 0.0, "lo": 0.0, "hi": 0.0, "resolved": False} for v in same.values())
    # the same (correct, score) pairs dealt to other queries: the same distribution, every metric equal
    perm = rng.permutation(Q)
    b = _matches(a.correct[perm], a.score[perm])
    d = lb.paired(a, b, BLOCK)
    for metric in lb.COMPARED:
        assert d[metric]["difference"] == pytest.approx(0.0, abs=1e-9), metric
        assert d[metric]["lo"] < 0 < d[metric]["hi"] and not d[metric]["resolved"], (metric, d[metric])


def test_methods_of_one_rate_are_rarely_resolved():
    """Forty pairs of independent methods each right on a query with probability 0.7 (their observed
    rates differ by chance): a 95 % interval resolves about two of them (more than seven: P < 0.001
    for a calibrated interval; a 50 % one would resolve about twenty)."""
    rng = np.random.default_rng(2)

    def coin():
        ok = rng.random(Q) < 0.7
        return _matches(ok, rng.random(Q) + 0.5 * ok)
    hits = [lb.paired(coin(), coin(), BLOCK)["R@1"] for _ in range(40)]
    assert np.std([h["difference"] for h in hits]) > 2                  # the null's own spread, not 0
    assert sum(h["resolved"] for h in hits) <= 7, hits


def test_pairing_resolves_what_the_rows_intervals_leave_overlapping():
    """b is a with 8 of its right queries (one in each of 8 blocks) made wrong: 4 points lower on
    every resample that holds one of them. The rows' own intervals (spread) overlap widely; the
    paired difference is resolved."""
    rng = np.random.default_rng(3)
    n = 200
    a = _method(rng, 0.8, n)
    flip = [blk * BLOCK + np.flatnonzero(a.correct[blk * BLOCK:(blk + 1) * BLOCK])[0] for blk in range(0, 16, 2)]
    b = _matches(np.where(np.isin(np.arange(n), flip), False, a.correct), a.score)
    (a_lo, a_hi), _ = _unpaired(a)
    (b_lo, b_hi), _ = _unpaired(b)
    assert a_lo < b_hi and b_lo < a_hi                                   # unpaired: not resolved
    d = lb.paired(a, b, BLOCK)
    assert d["R@1"]["difference"] == pytest.approx(4.0) and d["R@1"]["resolved"] and d["R@1"]["lo"] > 0
    assert d["AUC-PR"]["difference"] > 0


def test_paired_needs_the_same_queries():
    rng = np.random.default_rng(4)
    with pytest.raises(ValueError, match="same queries"):
        lb.paired(_method(rng, 0.5, 100), _method(rng, 0.5, 90))


@pytest.fixture(scope="module")
def revisit():
    """Two score matrices of one 120-frame stream (frames 80..119 revisit 0..39) and their queries."""
    n0, rep, ex = 80, 40, 20
    rng = np.random.default_rng(0)
    w = np.cumsum(rng.normal(size=(n0, 16)), 0).astype(np.float32) * 0.3
    X = np.concatenate([w, w[:rep] + rng.normal(scale=0.3, size=(rep, 16)).astype(np.float32)])
    GT = np.zeros((len(X), len(X)), bool)
    for k in range(rep):
        GT[max(k - 2, 0):k + 3, n0 + k] = True
    S = {"seq": seqstream.score_matrix(X, ex, 5, contrast_window=0),
         "single": seqstream.score_matrix(X, ex, 1, contrast_window=0)}
    S["noisy"] = S["single"] + rng.normal(scale=0.3, size=S["single"].shape).astype(np.float32)
    return S, GT | GT.T, ex, np.arange(len(X)) >= n0 - 10


def test_the_resamples_are_spreads(revisit, monkeypatch):
    """Every resample a paired comparison scores is one spread scores (block, n_boot, seed): each
    method is scored on spread's resamples, and on the whole query set once for the point."""
    S, GT, ex, q = revisit
    seen = []
    real = evaluate.query_metrics
    monkeypatch.setattr(evaluate, "query_metrics", lambda m, ks=(1, 5, 10): seen.append(tuple(m.query)) or real(m, ks))
    lb.spread(S["seq"], GT, ex, q, block=7, n_boot=50, seed=3)
    spread_calls, seen[:] = Counter(seen), []
    lb.comparisons(S, [("seq", "noisy")], GT, ex, q, block=7, n_boot=50, seed=3)
    whole = tuple(evaluate.best_matches(S["seq"], GT, ex, q, k=1).query)
    assert sum(spread_calls.values()) == 50 and whole not in spread_calls
    assert Counter(seen) == Counter({k: 2 * v for k, v in spread_calls.items()}) + Counter({whole: 2})
    seen[:] = []
    lb.comparisons(S, [("seq", "noisy")], GT, ex, q, block=8, n_boot=50, seed=3)     # other blocks: other resamples
    assert not set(seen) & set(spread_calls)


def test_the_rows_intervals_are_the_percentiles_of_the_same_resamples(revisit):
    S, GT, ex, q = revisit
    m = evaluate.best_matches(S["seq"], GT, ex, q, k=1)
    lo, hi = 100 * np.percentile(lb.boot_metrics(m, 5), [2.5, 97.5], axis=0)
    assert lb.spread(S["seq"], GT, ex, q, block=5) == {"R@1_lo_%": lo[0], "R@1_hi_%": hi[0],
                                                       "AUC-PR_lo_%": lo[1], "AUC-PR_hi_%": hi[1]}


def test_the_comparisons_table_is_the_paired_differences_as_written(revisit):
    S, GT, ex, q = revisit
    board = lb.table([{"method": k, "mode": "loop closure", **lb.metric_rows(S[k], GT, ex, q, block=5)[0]} for k in S]
                     + lb.chance_rows(GT, ex, q) + [{"method": "dictionary", "mode": "loop closure"}])
    pairs = lb.comparison_pairs(board, ["seq", "not on the board"])
    assert pairs == [("seq", "single"), ("seq", "noisy")]               # chance and the decision-only row: none
    t = lb.comparisons(S, pairs, GT, ex, q, block=5)
    assert list(t.columns) == lb.COMPARISON_COLUMNS and len(t) == 2 * len(lb.COMPARED)
    m = {k: evaluate.best_matches(S[k], GT, ex, q, k=1) for k in S}
    for _, r in t.iterrows():
        d = lb.paired(m[r.a], m[r.b], 5)[r.metric]
        assert (r.difference, r.lo, r.hi) == (round(d["difference"], 2), round(d["lo"], 2), round(d["hi"], 2))
        assert r.resolved == (r.lo > 0 or r.hi < 0)
        row = board.set_index("method").loc
        assert r.difference == pytest.approx(row[r.a, f"{r.metric}_%"] - row[r.b, f"{r.metric}_%"], abs=0.006)
    assert (t.queries == lb.query_counts(GT, ex, q)["queries"]).all()
    assert t.set_index(["b", "metric"]).loc[("noisy", "R@1"), "resolved"]


def _table(rows):
    return pd.DataFrame([dict(zip(lb.COMPARISON_COLUMNS, r + (50,))) for r in rows])


def test_the_statement_reads_higher_and_not_resolved_from_the_table_only():
    """The rows' intervals overlap (greenloop-seq [85, 95], pixels [60, 92]) but the table says
    resolved: "higher"; they separate for AUC-PR but the table says not resolved: "not resolved"."""
    spread = {"R@1_lo_%": 85.0, "R@1_hi_%": 95.0, "AUC-PR_lo_%": 70.0, "AUC-PR_hi_%": 90.0}
    board = lb.table([
        {"method": "greenloop-seq", "mode": "loop closure", "R@1_%": 90.0, "AUC-PR_%": 80.0, "R@100P_%": 40.0, **spread},
        {"method": "pixels (single frame)", "mode": "loop closure", "R@1_%": 70.0, "AUC-PR_%": 50.0, "R@100P_%": 0.0,
         "R@1_lo_%": 60.0, "R@1_hi_%": 92.0, "AUC-PR_lo_%": 40.0, "AUC-PR_hi_%": 60.0}])
    t = _table([("greenloop-seq", "pixels (single frame)", "R@1", 20.0, 2.5, 31.0, True),
                ("greenloop-seq", "pixels (single frame)", "AUC-PR", 30.0, -1.0, 45.0, False)])
    s = lb.statement(board, t, ["greenloop-seq"])
    assert "R@1 higher than it (difference 20.00 [2.50, 31.00])" in s
    assert "AUC-PR not resolved (difference 30.00 [-1.00, 45.00])" in s
    assert "R@1 above 1, below 0, not resolved against 0 of the 1 other rows" in s
    assert lb.targets(board, ["greenloop-seq"], t)["greenloop-seq"]["highest_R@1"] is True
    assert lb.targets(board, ["greenloop-seq"], t)["greenloop-seq"]["highest_AUC-PR"] is False
    assert lb.targets(board, ["greenloop-seq"])["greenloop-seq"]["highest_AUC-PR"] is True     # rows alone: intervals
    t.loc[0, ["difference", "lo", "hi"]] = [-20.0, -31.0, -2.5]
    assert "R@1 lower than it (difference -20.00 [-31.00, -2.50])" in lb.statement(board, t, ["greenloop-seq"])
    assert "R@1 not compared with it" in lb.statement(board, t.iloc[1:], ["greenloop-seq"])


def test_write_comparisons_writes_one_table_as_csv_and_markdown(tmp_path):
    t = _table([("a", "b", "R@1", 1.5, -0.5, 3.0, False)]).assign(protocol="leaderboard")
    csv, md = lb.write_comparisons(t, tmp_path, "the note")
    assert pd.read_csv(csv).equals(t) and "| a " in md.read_text() and md.read_text().rstrip().endswith("the note")


def _loop_scores(n=120, seed=0):
    """(GT, good, noise): n frames whose second half revisits the first (frame i + n/2 is frame i), a score
    matrix that ranks every revisit's partner first, and one of pure noise (M, M), symmetric."""
    rng = np.random.default_rng(seed)
    h = n // 2
    GT = np.zeros((n, n), bool)
    GT[np.arange(h), np.arange(h) + h] = GT[np.arange(h) + h, np.arange(h)] = True
    noise = rng.random((n, n))
    noise = (noise + noise.T) / 2
    return GT, np.where(GT, 2.0, noise), noise


def test_paired_table_resolves_a_planted_gap_and_calls_identical_scores_a_tie():
    GT, good, noise = _loop_scores()
    S = {"good": good, "noise": noise, "copy": noise.copy()}
    t = lb.paired_table(S, [("good minus noise", "good", "noise"), ("copy minus noise", "copy", "noise")], GT, 5, None, 10)
    assert list(t.columns) == lb.PAIRED_COLUMNS and len(t) == 2 * len(lb.COMPARED)
    gap = t[(t.comparison == "good minus noise") & (t.metric == "R@1")].iloc[0]
    assert gap.resolved and gap.low > 0 and gap.result == "good above noise" and gap.difference > 50
    assert gap.queries == 120 - 6 and gap.block == 10 and gap.blocks == 12      # queries with a candidate (j > 5)
    tie = t[t.comparison == "copy minus noise"]
    assert (tie.difference == 0).all() and (tie.low == 0).all() and (tie.high == 0).all()
    assert (~tie.resolved).all() and (tie.result == lb.TIE).all()
    back = lb.paired_table(S, [("noise minus good", "noise", "good")], GT, 5, None, 10)
    assert back.result.iloc[0] == "good above noise" and back.high.iloc[0] < 0
    assert "tie (the interval holds 0)" in lb.paired_sentence(t, "copy minus noise")
    assert "resolved: good above noise" in lb.paired_sentence(t, "good minus noise", "R@1")
    assert lb.paired_sentence(t, "absent") == "" and lb.paired_table(S, [], GT, 5, None).empty
