"""Unit tests of greenloop.methods.lsh.lsh: hashing, SWP and QDP probe orders, incremental matching."""
import itertools
from math import comb

import numpy as np
import pytest

from greenloop import evaluate
from greenloop.experiments import lsh_matching
from greenloop.methods.lsh import lsh
from greenloop.similarity import cosine_matrix, l2_normalise

D, BITS = 48, 16


def unit(rng, n, d=D):
    return l2_normalise(rng.standard_normal((n, d)))


def hamming(a, b) -> int:
    return bin(int(a) ^ int(b)).count("1")


def neighbour_at_distance(q, H, r, rng, angle=0.35):
    """A unit vector near q whose code is exactly r bits from q's (rejection sampling)."""
    cq = lsh.codes(q[None], H)[0]
    for _ in range(20000):
        u = rng.standard_normal(q.size)
        u -= (u @ q) * q
        v = np.cos(angle) * q + np.sin(angle) * u / np.linalg.norm(u)
        if hamming(lsh.codes(v[None], H)[0], cq) == r:
            return v
    raise AssertionError(f"no neighbour at Hamming distance {r} found")


def positive_cone(n, d=D, seed=0):
    """Non-negative unit vectors around one direction (cosines ~0.95, like ReLU + GAP features)."""
    rng = np.random.default_rng(seed)
    return l2_normalise(np.abs(rng.random(d) + 0.15 * rng.standard_normal((n, d))))


# --------------------------------------------------------------------------- hashing
def test_hyperplanes_are_seeded_gaussian_and_codes_follow_the_signs():
    H = lsh.hyperplanes(D, BITS, seed=3)
    assert H.shape == (D, BITS) and H.dtype == np.float64
    assert np.array_equal(H, lsh.hyperplanes(D, BITS, seed=3))
    assert not np.array_equal(H, lsh.hyperplanes(D, BITS, seed=4))
    X = unit(np.random.default_rng(0), 50)
    c = lsh.codes(X, H)
    assert c.dtype == np.uint32 and c.shape == (50,)
    bits = (c[:, None] >> np.arange(BITS)) & 1
    assert np.array_equal(bits.astype(bool), X @ H >= 0)
    assert np.array_equal(lsh.codes(7.5 * X, H), c)                # scale does not matter


def test_offset_hyperplanes_split_descriptors_that_share_one_orthant():
    X = positive_cone(300, seed=1)
    H = lsh.hyperplanes(D, BITS, 0)
    through_origin = len(np.unique(lsh.codes(X, H)))
    through_mean = len(np.unique(lsh.codes(X, H, offset=X[:40].mean(0))))
    assert through_mean > 3 * through_origin


# ------------------------------------------------------------------------------- SWP
def test_swp_probes_every_code_within_the_radius_in_hamming_order():
    masks = lsh.hamming_masks(BITS, 4)
    assert masks.size == sum(comb(BITS, r) for r in range(5)) == 2517
    assert len(set(masks.tolist())) == masks.size
    weights = [bin(int(m)).count("1") for m in masks]
    assert weights == sorted(weights) and weights[0] == 0
    probes = lsh.probe_order_swp(0b1011, BITS, 4)
    assert probes[0] == 0b1011
    assert all(hamming(p, 0b1011) <= 4 for p in probes)


@pytest.mark.parametrize("r", [0, 1, 3, 4])
def test_swp_finds_the_exact_nearest_neighbour_inside_the_radius(r):
    rng = np.random.default_rng(10 + r)
    H = lsh.hyperplanes(D, BITS, 0)
    q = unit(rng, 1)[0]
    v = neighbour_at_distance(q, H, r, rng)
    db = np.vstack([unit(rng, 200), v])                           # v is row 200, the true NN
    exact = lsh.static_match(db, q[None], "brute").best[0]
    assert exact == 200
    found = lsh.static_match(db, q[None], "swp", n_bits=BITS, seed=0, radius=4)
    assert found.best[0] == 200
    assert np.isclose(found.score[0], q @ v, atol=1e-5)
    assert found.n_probes[0] == 2517 and found.n_candidates[0] < 201


def test_swp_misses_a_nearest_neighbour_outside_the_radius():
    rng = np.random.default_rng(7)
    H = lsh.hyperplanes(D, BITS, 0)
    q = unit(rng, 1)[0]
    v = neighbour_at_distance(q, H, 5, rng)
    db = np.vstack([unit(rng, 200), v])
    assert lsh.static_match(db, q[None], "brute").best[0] == 200
    assert lsh.static_match(db, q[None], "swp", radius=4).best[0] != 200
    assert lsh.static_match(db, q[None], "swp", radius=5).best[0] == 200


# ------------------------------------------------------------------------------- QDP
def test_qdp_order_starts_at_home_then_flips_the_smallest_margins_in_score_order():
    rng = np.random.default_rng(2)
    H = lsh.hyperplanes(D, BITS, 0)
    q = unit(rng, 1)[0]
    costs = lsh.qdp_costs(q, H)
    assert np.allclose(costs, np.abs(q @ H) / np.linalg.norm(H, axis=0))
    code = int(lsh.codes(q[None], H)[0])
    probes, scores = lsh.probe_order_qdp(code, costs, 1000)
    assert probes.size == 1001 and probes[0] == code and scores[0] == 0
    assert np.all(np.diff(scores) >= -1e-12)
    cheapest = np.argsort(costs)
    assert probes[1] == code ^ (1 << int(cheapest[0]))
    assert probes[2] == code ^ (1 << int(cheapest[1]))
    flips = probes[1:] ^ np.uint32(code)
    recomputed = [costs[[b for b in range(BITS) if f >> b & 1]].sum() for f in flips]
    assert np.allclose(recomputed, scores[1:])
    assert len(set(probes.tolist())) == probes.size


def test_perturbation_sets_are_exactly_the_cheapest_subsets():
    costs = np.random.default_rng(5).random(10)
    subsets = [s for r in range(1, 11) for s in itertools.combinations(range(10), r)]
    all_scores = np.sort([costs[list(s)].sum() for s in subsets])
    flips, scores = lsh.perturbation_sets(costs, 2000)              # capped at 2**10 - 1
    assert flips.size == 1023 and len(set(flips.tolist())) == 1023
    assert np.allclose(scores, all_scores)
    flips, scores = lsh.perturbation_sets(costs, 100)
    assert np.allclose(scores, all_scores[:100])


def test_compiled_heap_gives_the_python_heaps_sets_in_the_same_order():
    from greenloop.util import numba_kernels as kernels
    if not kernels.available():
        pytest.skip("numba is not installed: only the Python heap runs")
    rng = np.random.default_rng(6)
    for trial in range(40):
        k = int(rng.integers(1, 17))
        costs = rng.random(k) if trial % 2 else np.round(rng.random(k), 1)   # with ties
        n = int(rng.integers(0, 2000))
        fast = lsh.perturbation_sets(costs, n, compiled=True)
        slow = lsh.perturbation_sets(costs, n, compiled=False)
        assert np.array_equal(fast[0], slow[0]) and np.array_equal(fast[1], slow[1])


def test_log_odds_costs_rank_bits_like_margins():
    rng = np.random.default_rng(3)
    H = lsh.hyperplanes(D, BITS, 0)
    q = unit(rng, 1)[0]
    m, lo = lsh.qdp_costs(q, H), lsh.qdp_costs(q, H, "log_odds", theta=0.5)
    assert np.all(lo >= 0)
    proj = np.abs(q @ H)                                            # Eq. 1 uses |p_j . v|
    assert np.array_equal(np.argsort(lo), np.argsort(proj))


def test_qdp_probe_count_follows_table_5():
    assert lsh.qdp_n_probes(0) == 1000 and lsh.qdp_n_probes(499) == 1000
    assert lsh.qdp_n_probes(500) == 1500 and lsh.qdp_n_probes(10_000) == 1500
    assert lsh.qdp_n_probes(499, small=1500, large=1000) == 1500    # the text's reading


# ---------------------------------------------------------------------- incremental
def walk(n=150, d=D, seed=0):
    """A random walk on the sphere: consecutive frames are each other's nearest neighbours."""
    rng = np.random.default_rng(seed)
    steps = rng.standard_normal((n, d)) * 0.15
    steps[0] = rng.standard_normal(d)
    return l2_normalise(np.cumsum(steps, 0))


@pytest.mark.parametrize("method", lsh.METHODS)
def test_incremental_never_matches_recent_or_future_frames(method):
    X, ex = walk(), 10
    r = lsh.incremental_match(X, method, exclude=ex, keep_candidates=True)
    t = np.arange(len(X))
    assert np.all((r.best == lsh.NO_MATCH) | (r.best < t - ex))
    assert np.all(r.best[: ex + 1] == lsh.NO_MATCH) and np.all(r.n_stored == np.maximum(t - ex, 0))
    for j, cand in enumerate(r.candidates):
        if cand is not None:
            assert np.all(cand < j - ex)
    assert r.seconds.shape == (len(X),) and np.all(r.seconds >= r.probe_seconds)
    assert r.ms_per_query > 0
    S = cosine_matrix(X)
    ok = r.best >= 0
    assert np.allclose(r.score[ok], S[r.best[ok], t[ok]], atol=1e-5)


def test_incremental_brute_and_sklearn_equal_the_masked_cosine_matrix():
    X, ex = walk(seed=1), 10
    S = cosine_matrix(X).astype(np.float64)
    n = len(X)
    masked = np.where(evaluate.pair_mask(n, ex), S, -np.inf)        # rows i < j - ex per column j
    expect = np.where(np.arange(n) > ex, masked.argmax(0), lsh.NO_MATCH)
    for method in ("brute", "sklearn"):
        assert np.array_equal(lsh.incremental_match(X, method, exclude=ex).best, expect)


def test_scanned_matrix_of_brute_force_is_the_cosine_matrix_on_counted_pairs():
    X, ex = walk(seed=2), 10
    S = cosine_matrix(X)
    brute = lsh.incremental_match(X, "brute", exclude=ex, keep_candidates=True)
    m = evaluate.pair_mask(len(X), ex)
    assert np.array_equal(lsh_matching.scanned_matrix(S, brute)[m], S[m])
    swp = lsh.incremental_match(X, "swp", exclude=ex, radius=1, keep_candidates=True)
    Ss = lsh_matching.scanned_matrix(S, swp)
    assert (Ss[m] == -2).sum() > 0 and np.all((Ss[m] == S[m]) | (Ss[m] == -2))
    B = lsh_matching.best_match_matrix(swp)
    assert (B > -2).sum() == (swp.best >= 0).sum()


def test_centre_frames_move_only_the_buckets():
    X = positive_cone(120, seed=4)
    plain = lsh.incremental_match(X, "swp", exclude=10, radius=2)
    centred = lsh.incremental_match(X, "swp", exclude=10, radius=2, centre_frames=11)
    assert centred.n_buckets[-1] > plain.n_buckets[-1]
    assert centred.n_candidates.sum() < plain.n_candidates.sum()
    with pytest.raises(ValueError, match="centre_frames"):
        lsh.incremental_match(X, "swp", exclude=10, centre_frames=12)  # not causal


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, match", [
    (lambda: lsh.hyperplanes(D, 0), "n_bits"),
    (lambda: lsh.hyperplanes(D, 33), "n_bits"),
    (lambda: lsh.hamming_masks(16, -1), "radius"),
    (lambda: lsh.hamming_masks(16, 17), "radius"),
    (lambda: lsh.incremental_match(walk(20), "swp", radius=-1), "radius"),
    (lambda: lsh.codes(np.ones((4, D + 1)), lsh.hyperplanes(D)), "dims"),
    (lambda: lsh.codes(np.ones(D), lsh.hyperplanes(D)), r"\(N, D\)"),
    (lambda: lsh.codes(np.full((2, D), np.nan), lsh.hyperplanes(D)), "NaN"),
    (lambda: lsh.static_match(walk(20), np.ones((1, D + 2)), "swp"), "dims"),
    (lambda: lsh.incremental_match(np.ones(D), "swp"), r"\(N, D\)"),
    (lambda: lsh.incremental_match(walk(20), "kd_tree"), "method"),
    (lambda: lsh.incremental_match(walk(20), "swp", exclude=-1), "exclude"),
    (lambda: lsh.incremental_match(walk(20), "qdp", qdp_probes=(1000, 1500)), "qdp_probes"),
    (lambda: lsh.probe_order_swp(1 << 16, 16, 2), "code"),
    (lambda: lsh.perturbation_sets(np.array([0.1, -1.0]), 3), "costs"),
    (lambda: lsh.qdp_costs(np.ones(D), lsh.hyperplanes(D), "log_odds", theta=2.0), "theta"),
    (lambda: lsh_matching.scanned_matrix(np.zeros((20, 20)), lsh.incremental_match(walk(20), "swp")),
     "keep_candidates"),
])
def test_bad_input_raises_value_error(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_query_index_stops_at_the_time_budget_and_matches_static_match():
    rng = np.random.default_rng(8)
    db, Q = unit(rng, 300), unit(rng, 40)
    index = lsh.build_index(db, lsh.hyperplanes(D, BITS, 0))
    full = lsh.query_index(index, Q, "swp")
    assert np.array_equal(full.best, lsh.static_match(db, Q, "swp").best)
    short = lsh.query_index(index, Q, "qdp", max_seconds=1e-9)
    assert short.best.shape == (1,) and short.seconds.shape == (1,)
    nn = lsh.query_index(index, Q, "sklearn")
    assert np.array_equal(nn.best, lsh.query_index(index, Q, "brute").best)
    assert index.n_stored == 300                                    # queries store nothing


def test_no_query_pays_the_heap_compilation(monkeypatch):
    """The compiled heap is loaded before the first timed query (checked in order, not on a clock)."""
    lsh._heap_compiled.cache_clear()
    search, loaded = lsh._search, []

    def timed_search(*args):
        loaded.append(lsh._heap_compiled.cache_info().currsize)
        return search(*args)
    monkeypatch.setattr(lsh, "_search", timed_search)
    r = lsh.incremental_match(walk(60), "qdp", exclude=5)
    assert len(loaded) == len(r.seconds) == 60 and set(loaded) == {1}     # loaded (or None) before query 0


# ------------------------------------------------- Table 6, Figure 7, scaling (notebook 11)
def _revisit_sequence(noise=0.05, seed=0):
    """8 frames: 0..3 are four orthogonal unit vectors, 4..7 revisit them (GT[i, i + 4])."""
    rng = np.random.default_rng(seed)
    X = np.zeros((8, 16), np.float32)
    X[np.arange(8), np.arange(8) % 4] = 1.0
    X[4:] += noise * rng.standard_normal((4, 16)).astype(np.float32)
    gt = np.zeros((8, 8), bool)
    gt[np.arange(4), np.arange(4) + 4] = gt[np.arange(4) + 4, np.arange(4)] = True
    return X, gt


def test_table6_variants():
    assert [v[:2] for v in lsh_matching.table6_variants(False)] == [("brute force", "brute"), ("NearestNeighbors (sklearn)", "sklearn"),
                                                          ("SWP-RHLSH", "swp"), ("QDP-RHLSH", "qdp")]
    v = lsh_matching.table6_variants(True, 7)
    assert len(v) == 6 and v[4] == ("SWP-RHLSH, centred", "swp", 7) and v[5] == ("QDP-RHLSH, centred", "qdp", 7)
    assert all(k == 0 for _, _, k in v[:4])


def test_run_scores_of_brute_force_on_a_hand_made_revisit():
    X, gt = _revisit_sequence()
    S = cosine_matrix(X)
    brute = lsh.incremental_match(X, "brute", exclude=2, keep_candidates=True)
    assert brute.best[4:].tolist() == [0, 1, 2, 3]            # every revisit finds its place
    revisit = (gt & evaluate.pair_mask(8, 2)).any(0)
    assert np.flatnonzero(revisit).tolist() == [4, 5, 6, 7]
    sc = lsh_matching.run_scores(brute, S, brute, gt, 2)
    assert sc["R@1_%"] == 100.0 and sc["NN_agree_%"] == 100.0 and sc["scanned_%"] == 100.0
    assert sc["AUC-PR_%"] == 100.0 and sc["R@100P_%"] == 100.0 and sc["R@95P_%"] == 100.0
    assert sc["AP_pairs_%"] == pytest.approx(100 * evaluate.average_precision(S, gt, 2))
    assert np.isnan(sc["probes_per_query"]) and np.isnan(sc["N1_at_end"])
    swp = lsh.incremental_match(X, "swp", exclude=2, n_bits=8, radius=1, keep_candidates=True)
    sw = lsh_matching.run_scores(swp, S, brute, gt, 2)
    assert sw["N1_at_end"] == swp.n_buckets[-1] and sw["probes_per_query"] == pytest.approx(swp.n_probes[swp.timed].mean())
    assert sw["NN_agree_%"] == pytest.approx(100 * np.mean(swp.best[swp.timed] == brute.best[swp.timed]))


def test_query_matches_by_hand():
    import dataclasses
    X, gt = _revisit_sequence()
    brute = lsh.incremental_match(X, "brute", exclude=2, keep_candidates=True)
    m = lsh_matching.query_matches(brute, gt, 2)
    assert m.query.tolist() == [3, 4, 5, 6, 7] and m.has_partner.tolist() == [False, True, True, True, True]
    assert m.correct.tolist() == [False, True, True, True, True] and m.k == 1
    # query 5 scanned nothing: no match, score -2, below query 3's wrong match (cosine 0)
    best, score = brute.best.copy(), brute.score.copy()
    best[5], score[5] = lsh.NO_MATCH, -np.inf
    miss = dataclasses.replace(brute, best=best, score=score)
    q = evaluate.query_metrics(lsh_matching.query_matches(miss, gt, 2), ks=(1,))
    assert q["R@1"] == 0.75 and q["R@100P"] == 0.75 and q["AUC-PR"] == pytest.approx(0.75)
    assert q["queries"] == 5 and q["revisits"] == 4


def test_scanned_pr_curve_ends_at_the_recall_reached():
    X, gt = _revisit_sequence()
    S = cosine_matrix(X)
    brute = lsh.incremental_match(X, "brute", exclude=2, keep_candidates=True)
    p, r = lsh_matching.scanned_pr_curve(S, brute, gt, 2)
    p0, r0, _ = evaluate.pr_curve(S, gt, 2)
    assert np.array_equal(p, p0) and np.array_equal(r, r0)     # brute force scans every counted pair
    swp = lsh.incremental_match(X, "swp", exclude=2, n_bits=16, radius=0, keep_candidates=True)
    sm = lsh_matching.scanned_matrix(S, swp)
    m = evaluate.pair_mask(8, 2)
    loops_scanned = (gt & m & (sm > -2)).sum() / (gt & m).sum()
    p, r = lsh_matching.scanned_pr_curve(S, swp, gt, 2)
    assert r.max() == pytest.approx(loops_scanned) and len(p) == len(r) and r[-1] == 0.0


def test_compare_variants_averages_seeds_and_rates_against_brute_force():
    import pandas as pd
    base = {"backbone": "a", "weights": "w", "label": "a (w)"}
    per_seed = pd.DataFrame([dict(base, variant="brute force", seed=0, **{"AP_pairs_%": 40.0, "ms_per_query": 2.0}),
                             dict(base, variant="SWP-RHLSH", seed=0, **{"AP_pairs_%": 30.0, "ms_per_query": 1.0}),
                             dict(base, variant="brute force", seed=1, **{"AP_pairs_%": 40.0, "ms_per_query": 2.0}),
                             dict(base, variant="SWP-RHLSH", seed=1, **{"AP_pairs_%": 34.0, "ms_per_query": 3.0})])
    t = lsh_matching.compare_variants(per_seed)
    assert list(t.columns) == ["backbone", "weights", "label", "variant", "AP_pairs_%", "AP_pairs_sd", "ms_per_query",
                               "ms_sd", "R_a_%", "R_t_%", "loss_per_1%_time"]
    swp = t.set_index("variant").loc["SWP-RHLSH"]
    assert (swp["AP_pairs_%"], swp["AP_pairs_sd"], swp["ms_per_query"], swp["ms_sd"]) == (32.0, 2.0, 2.0, 1.0)
    assert swp["R_a_%"] == -20.0 and swp["R_t_%"] == 0.0 and np.isnan(swp["loss_per_1%_time"])
    per_seed.loc[3, "ms_per_query"] = 1.0                      # now half the time: R_t 50 %, loss 20 / 50
    swp = lsh_matching.compare_variants(per_seed).set_index("variant").loc["SWP-RHLSH"]
    assert swp["R_t_%"] == 50.0 and swp["loss_per_1%_time"] == pytest.approx(0.4)
    per_seed.insert(5, "R@1_%", 50.0)                           # per-query columns first: the sd stays beside AP_pairs
    assert list(lsh_matching.compare_variants(per_seed).columns[4:7]) == ["R@1_%", "AP_pairs_%", "AP_pairs_sd"]
