"""The field's per-query metrics (greenloop.evaluate: best_matches, query_metrics, query_chance):
hand-worked examples, a naive reimplementation, scikit-learn where the definitions coincide, and
a Monte-Carlo check of the chance levels."""
import numpy as np
import pytest
from sklearn.metrics import average_precision_score

from greenloop import evaluate as ev

# 8 frames, exclude = 2: query j's candidates are i < j - 2.
#   j=3: {0: .2}                      no partner                best 0 (a false positive if it fires)
#   j=4: {0: .9 +, 1: .1}             partner 0                 best 0, correct
#   j=5: {0: .8, 1: .7 +, 2: .1}      partner 1                 best 0, wrong; partner at rank 1
#   j=6: {0: .3, 1: .3, 2: .6 +, 3: .2}  partner 2              best 2, correct
#   j=7: {0: .5, 1..4: .1}            no partner                best 0
N, EX = 8, 2
SCORES = {3: [.2], 4: [.9, .1], 5: [.8, .7, .1], 6: [.3, .3, .6, .2], 7: [.5, .1, .1, .1, .1]}
LOOPS = [(0, 4), (1, 5), (2, 6)]


def example():
    S = np.zeros((N, N))
    for j, col in SCORES.items():
        S[:len(col), j] = col
    G = np.zeros((N, N), bool)
    for i, j in LOOPS:
        G[i, j] = G[j, i] = True
    return S, G


def test_best_matches_hand_example():
    S, G = example()
    m = ev.best_matches(S, G, EX, k=3)
    assert m.query.tolist() == [3, 4, 5, 6, 7]
    assert m.match.tolist() == [0, 0, 0, 2, 0]
    assert m.correct.tolist() == [False, True, False, True, False]
    assert m.has_partner.tolist() == [False, True, True, True, False]
    assert m.hit_rank.tolist() == [3, 0, 1, 0, 3]
    assert m.score.tolist() == pytest.approx([.2, .9, .8, .6, .5])


def test_query_metrics_hand_example():
    S, G = example()
    got = ev.per_query(S, G, EX, ks=(1, 2))
    # ranked best matches: .9 +, .8 -, .6 +, .5 -, .2 -  over 3 revisits
    # P = 1, 1/2, 2/3, 2/4, 2/5; R = 1/3, 1/3, 2/3, 2/3, 2/3
    assert got["R@1"] == pytest.approx(2 / 3)
    assert got["R@2"] == pytest.approx(1.0)
    assert got["AUC-PR"] == pytest.approx(1 / 3 + (1 / 3) * (2 / 3))
    assert got["R@100P"] == pytest.approx(1 / 3)
    assert got["R@95P"] == pytest.approx(1 / 3)
    assert (got["queries"], got["revisits"]) == (5, 3)
    p, r, t = ev.query_pr_curve(ev.best_matches(S, G, EX))
    assert p.tolist() == pytest.approx([1, 1 / 2, 2 / 3, 2 / 4, 2 / 5])
    assert r.tolist() == pytest.approx([1 / 3, 1 / 3, 2 / 3, 2 / 3, 2 / 3])
    assert t.tolist() == pytest.approx([.9, .8, .6, .5, .2])


def test_a_partnerless_query_that_fires_first_costs_r_at_100p():
    S, G = example()
    S[0, 7] = 0.95                         # query 7 has no partner and now scores highest
    got = ev.per_query(S, G, EX, ks=(1,))
    assert got["R@100P"] == 0.0
    assert got["R@1"] == pytest.approx(2 / 3)   # R@K reads only queries with a partner


def test_ties_are_declared_together():
    S, G = example()
    S[0, 5] = 0.9                          # query 5's wrong best match ties query 4's right one
    p, r, t = ev.query_pr_curve(ev.best_matches(S, G, EX))
    assert t[0] == pytest.approx(0.9) and p[0] == pytest.approx(1 / 2) and r[0] == pytest.approx(1 / 3)
    assert ev.per_query(S, G, EX, ks=(1,))["R@100P"] == 0.0


def test_place_recognition_mode():
    # reference = frames 0..2, queries 3..5, query 3+k revisits k; exclude plays no part
    n = 6
    S = np.zeros((n, n))
    S[:3, 3] = [.9, .1, .2]      # right
    S[:3, 4] = [.8, .3, .1]      # wrong (partner 1 at rank 1)
    S[:3, 5] = [.1, .2, .7]      # right
    G = np.zeros((n, n), bool)
    for k in range(3):
        G[k, 3 + k] = G[3 + k, k] = True
    ref = np.arange(n) < 3
    m = ev.best_matches(S, G, exclude=100, reference=ref, k=2)
    assert m.query.tolist() == [3, 4, 5] and m.hit_rank.tolist() == [0, 1, 0]
    got = ev.query_metrics(m, ks=(1, 2))
    assert got["R@1"] == pytest.approx(2 / 3) and got["R@2"] == 1.0
    assert got["AUC-PR"] == pytest.approx(1 / 3 + 0 + (1 / 3) * (2 / 3))
    with pytest.raises(ValueError, match="reference"):
        ev.candidate_mask(n, reference=np.ones(n, bool))


def naive_hit_rank(S, G, exclude, k):
    out = {}
    for j in range(len(S)):
        cand = [i for i in range(j) if j - i > exclude]
        if not cand:
            continue
        ranked = sorted(cand, key=lambda i: (-S[i, j], i))
        hits = [r for r, i in enumerate(ranked) if G[i, j]]
        out[j] = (ranked[0], min(hits[0], k) if hits else k)
    return out


@pytest.mark.parametrize("seed", range(3))
def test_best_matches_equal_a_naive_ranking_with_ties(seed):
    rng = np.random.default_rng(seed)
    n, exclude, k = 40, 5, 4
    S = np.round(rng.random((n, n)), 1)
    G = rng.random((n, n)) < 0.1
    G = G | G.T
    m = ev.best_matches(S, G, exclude, k=k)
    naive = naive_hit_rank(S, G, exclude, k)
    assert m.query.tolist() == sorted(naive)
    assert list(zip(m.match.tolist(), m.hit_rank.tolist())) == [naive[j] for j in m.query]


def test_auc_pr_equals_sklearn_scaled_when_every_query_has_a_partner():
    # with every query a revisit, the per-query curve is sklearn's PR of (correct, score) with
    # recall rescaled by correct / queries: AUC-PR = AP * n_correct / Q
    rng = np.random.default_rng(7)
    n, exclude = 60, 4
    S = rng.random((n, n))
    G = rng.random((n, n)) < 0.2
    G = G | G.T
    rev = ev.revisit_queries(G, exclude)
    m = ev.best_matches(S, G, exclude, queries=rev)
    assert m.has_partner.all() and 0 < m.correct.sum() < len(m.query)
    ap = average_precision_score(m.correct, m.score)
    assert ev.query_metrics(m, ks=(1,))["AUC-PR"] == pytest.approx(ap * m.correct.sum() / len(m.query))


def test_matches_rejects_inconsistent_records():
    with pytest.raises(ValueError, match="inconsistent"):
        ev.matches([3], [0], [.5], [True], [False], [0], k=1)      # correct without a partner
    with pytest.raises(ValueError, match="inconsistent"):
        ev.matches([3], [0], [.5], [True], [True], [1], k=1)       # correct but rank 1
    with pytest.raises(ValueError, match="K <= k"):
        ev.query_metrics(ev.matches([3], [0], [.5], [True], [True], [0], k=1), ks=(5,))


def test_chance_levels_match_random_scores():
    S, G = example()
    exact = ev.query_chance(G, EX, ks=(1, 2))
    # by hand: partners 1 of 2, 1 of 3, 1 of 4 candidates -> R@1 = mean(1/2, 1/3, 1/4)
    assert exact["R@1"] == pytest.approx((1 / 2 + 1 / 3 + 1 / 4) / 3)
    assert exact["R@2"] == pytest.approx((1 + 2 / 3 + 1 / 2) / 3)
    rng = np.random.default_rng(0)
    n, exclude = 50, 3
    G = rng.random((n, n)) < 0.1
    G = G | G.T
    chance = ev.query_chance(G, exclude, ks=(1, 5))
    runs = [ev.per_query(rng.random((n, n)), G, exclude, ks=(1, 5)) for _ in range(300)]
    for key in ("R@1", "R@5", "AUC-PR"):
        mc = np.mean([r[key] for r in runs])
        assert mc == pytest.approx(chance[key], rel=0.08), key
