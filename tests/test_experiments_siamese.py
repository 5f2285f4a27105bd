"""Notebook 10's protocol (greenloop.experiments.siamese_rgbd): every table equals the stage
functions it composes, scored on the held-out part only; nothing is named best unless its seed
range lies above every other's."""
import matplotlib
import numpy as np
import pandas as pd
import pytest

from greenloop import evaluate, features, groundtruth
from greenloop.experiments import siamese_rgbd as sr
from greenloop.methods.siamese import siamese as sm

matplotlib.use("Agg")
W = 0.25            # small networks: the tests check structure and numbers, not accuracy
STEP = 2            # every 2nd frame of the tests' 200-frame sequence: 100 frames
SEEDS = [0, 1]


def _loop_gt(n=120, shift=90, length=30):
    """Frames shift .. shift+length-1 revisit frames 0 .. length-1 (i <-> i + shift)."""
    gt = np.zeros((n, n), bool)
    i = np.arange(length)
    gt[i, i + shift] = gt[i + shift, i] = True
    return gt


def test_score_descriptors_ranks_by_l2_distance():
    F = np.array([[0.0], [10.0], [20.0], [0.1], [10.1], [25.0]])
    gt = np.zeros((6, 6), bool)
    gt[0, 3] = gt[3, 0] = gt[1, 4] = gt[4, 1] = True        # the two closest far pairs are the loops
    S, ap, r100 = sr.score_descriptors(F, gt, 1)
    assert S[0, 3] == pytest.approx(1 - 0.1 / 25) and (ap, r100) == (100.0, 100.0)
    F[5] = 0.05                                # (0, 5) and (3, 5) now rank first, tied, and are no loops
    _, ap, r100 = sr.score_descriptors(F, gt, 1)
    assert ap == pytest.approx(100 * 2 / 4) and r100 == 0.0    # both loops come in at precision 2 / 4


def test_fit_and_score_row_and_the_references(tmp_path):
    gt, gap = _loop_gt(), 5
    train, held = evaluate.split_mask(120, 0.5, gt=gt, gap=gap)
    labels = sm.place_labels(train, gt, 20)
    X = np.random.default_rng(0).random((120, 32, 32, 3)).astype(np.float32)
    kw = dict(seed=0, epochs=1, n_pairs=20, batch_size=10, width=W, cache=tmp_path)
    row, S, model, hist = sr.fit_and_score("scnn softmax, RGB", X, labels, held, gap, gt, 0, kw, supervision="softmax")
    assert row["descriptor"] == "scnn softmax, RGB" and row["label"] == "scnn softmax, RGB (trained here)"
    assert (row["supervision"], row["fusion"], row["layer"], row["train_pairs"], row["epochs"]) == ("softmax", "none", "", 20, 1)
    _, ap, r100 = sr.score_descriptors(sm.describe(model, X), gt, 0, held)
    # unrounded: the row holds the scores themselves
    assert S.shape == (120, 120) and row["AP_%"] == ap and row["R@100P_%"] == r100 and row["train_s"] == hist["seconds"]
    assert not row["loaded_from_cache"] and row["seed"] == 0
    assert row["converged"] is sm.plateaued(hist["loss"]) is False          # one epoch: nothing levelled off
    assert hist["monitor"][-1] == pytest.approx(ap)        # the held-out AP watched after the last epoch
    again, *_ = sr.fit_and_score("scnn softmax, RGB", X, labels, held, gap, gt, 0, kw, supervision="softmax")
    assert again["loaded_from_cache"] and again["AP_%"] == row["AP_%"]
    rows, sims = sr.reference_scores(X, gt, 0, held, seeds=[0], width=W)
    assert [r["descriptor"] for r in rows] == ["scnn untrained, RGB", "pixels (32x32 gray)"]
    assert list(sims) == [("untrained", 0), ("pixels", None)]
    assert list(rows[0]) == list(row) and rows[0]["weights"] == "random init" and rows[0]["train_pairs"] == 0
    _, ap, _ = sr.score_descriptors(features.extract(np.rint(X * 255).astype(np.uint8), "pixels", progress=False), gt, 0, held)
    assert rows[1]["AP_%"] == ap


@pytest.fixture(scope="module")
def setup(tiny_sequence):
    return sr.setup(tiny_sequence, STEP, 20, 0.5, 20, 0.5, 5, 32, 10.0)


def test_setup_composes_the_stage_functions(setup, tiny_sequence):
    s = setup
    frames, ex, GT, summary = groundtruth.described_frames(tiny_sequence, STEP, 0.5, 20)
    assert np.array_equal(s.frames, frames) and s.exclude_steps == ex == 10 and np.array_equal(s.GT, GT)
    assert (s.gap, s.L) == (5 // STEP, 20 // STEP)                      # ORIGINAL frames in steps
    train, held, note = sm.training_split(len(frames), 0.5, GT, s.gap, s.L, frames)
    assert np.array_equal(s.train, train) and np.array_equal(s.held, held) and s.split_note == note
    assert np.array_equal(s.labels, sm.place_labels(train, GT, s.L)) and (s.labels[~train] == -1).all()
    assert s.has_depth and s.X.shape == (100, 32, 32, 4)
    assert np.array_equal(s.X, sm.load_inputs(tiny_sequence, (32, 32), step=STEP, depth=True, max_depth=10.0))
    assert s.chance == evaluate.chance_level(GT, ex, queries=held)
    assert summary in s.text and f"chance AP on the held-out part: {100 * s.chance:.2f} %" in s.text


@pytest.fixture(scope="module")
def kw(shared_cache):
    """The tests' training settings: one epoch of 20 pairs, a narrow trunk, the session's model cache."""
    return dict(epochs=1, n_pairs=20, batch_size=10, width=W, hard_fraction=0.5, cache=shared_cache)


@pytest.fixture(scope="module")
def trained(setup, kw):
    """One supervision and the four fusions (one mid-level layer), two seeds, one epoch of 20 pairs each."""
    sup = sr.supervisions(setup, ["softmax"], kw, SEEDS)
    fus = sr.fusions(setup, sup, "softmax", ["conv2"], "sum", kw, SEEDS)
    return sup, fus


def test_supervisions_table_is_each_network_scored_on_the_heldout_part(setup, trained):
    s, (sup, _) = setup, trained
    t = sup.table
    assert t.descriptor.tolist() == ["scnn softmax, RGB"] * 2 + ["scnn untrained, RGB"] * 2 + ["pixels (32x32 gray)"]
    assert t.seed.tolist()[:4] == SEEDS * 2 and np.isnan(t.seed.iloc[4])
    assert t.weights.tolist() == ["trained here"] * 2 + ["random init"] * 2 + ["none"]
    assert list(sup.sims) == [("softmax", 0), ("softmax", 1), ("untrained", 0), ("untrained", 1), ("pixels", None)]
    for k, seed in enumerate(SEEDS):
        _, ap, r100 = sr.score_descriptors(sm.describe(sup.models["softmax", seed], s.X[..., :3]), s.GT, s.exclude_steps, s.held)
        assert t.loc[k, "AP_%"] == ap and t.loc[k, "R@100P_%"] == r100 and t.loc[k, "train_pairs"] == 20
    assert t.loc[0, "AP_%"] != t.loc[1, "AP_%"]                      # two seeds, two networks
    assert [name for name, *_ in sup.trained] == ["scnn softmax, RGB, seed 0", "scnn softmax, RGB, seed 1"]
    summ = sr.seed_summary(t).set_index("descriptor")
    assert summ.seeds.tolist() == [2, 2, 1]
    assert summ.loc["scnn softmax, RGB", "AP_mean"] == pytest.approx(t["AP_%"][:2].mean())
    assert summ.loc["scnn softmax, RGB", "AP_std"] == pytest.approx(t["AP_%"][:2].std(ddof=1))
    assert summ.loc["scnn softmax, RGB", "AP_min"] == t["AP_%"][:2].min() and summ.loc["scnn softmax, RGB", "AP_max"] == t["AP_%"][:2].max()


def test_best_of_needs_five_seeds_and_separated_seed_ranges():
    def table(ap):
        return sr.seed_summary(pd.DataFrame({"descriptor": [d for d in ap for _ in ap[d]], "supervision": "x",
                                             "fusion": "none", "layer": "", "AP_%": [v for d in ap for v in ap[d]],
                                             "R@100P_%": 0.0, "train_s": 1.0}))
    summ = table({"a": [50, 52, 55, 58, 60], "b": [40, 41, 42, 44, 45], "c": [30, 35, 40, 50, 61]})
    assert sr.best_of(summ, ["a", "b"])[0] == "a"                  # [50, 60] above [40, 45], 5 seeds each
    best, text = sr.best_of(summ, ["a", "b", "c"])                 # c's 61 reaches into a's range
    assert best is None and "a 55.00 [50.00, 60.00]" in text and "c 43.20 [30.00, 61.00]" in text
    assert sr.best_of(summ, ["a"])[0] is None                      # nothing to be best against
    few, text = sr.best_of(table({"a": [50, 60], "b": [40, 45]}), ["a", "b"])   # separated, but 2 seeds each
    assert few is None and "fewer than 5 seeds per arm" in text


def test_the_budget_label_counts_each_trained_network_once():
    """Networks of other rows (RGB only, the late networks' single streams) and untrained rows are not
    counted; the label stands where fewer than half converged."""
    t = pd.DataFrame({"descriptor": ["e", "e", "l", "l", "l r", "l r", "RGB only", "u"],
                      "fusion": ["early", "early", "late", "late", "late (rgb stream)", "late (rgb stream)", "RGB only", "none"],
                      "epochs": [30, 30, 30, 30, 30, 30, 30, 0], "converged": [True, False, False, False, True, True, True, None]})
    assert sr.converged_networks(t) == (1, 4)
    assert sr.budget_label(t) == "budget-limited: 1 of 4 networks converged"
    assert sr.budget_label(t.assign(converged=t.converged.replace({False: True}))) == ""      # 4 of 4
    assert sr.converged_networks(t, t) == (2, 8) and sr.budget_label(t.drop(columns="converged")) == ""
    import matplotlib.pyplot as plt
    fig = plt.figure()
    assert [x.get_text() for x in sr.label_budget(fig, t).texts] == [sr.budget_label(t)]   # above the figure, once
    plt.close(fig)


def test_levelling_gives_the_gain_per_third_of_the_epochs_over_distinct_networks():
    a = {"monitor": [10, 20, 30, 40, 50, 60]}              # thirds 15, 35, 55: +20 then +20
    b = {"monitor": [10, 40, 50, 50, 50, 40]}              # thirds 25, 50, 45: +25 then -5
    text = sr._levelling([a, b, dict(a), {"monitor": [1, 2]}])   # a twice (two tables) counts once; 2 epochs: ignored
    assert text == "+22.5 then +7.5 points over 2 networks (1 still gaining in the last third)"
    assert sr._levelling([{"monitor": [1.0]}]).startswith("n/a")


def test_fusions_table_rgb_only_each_fusion_and_each_late_stream(setup, trained):
    s, (sup, fus) = setup, trained
    t = fus.table
    assert t.fusion.tolist() == [f for f in ["RGB only", "early", "mid", "late", "late (rgb stream)", "late (depth stream)"]
                                 for _ in SEEDS]
    assert t.seed.tolist() == SEEDS * 6 and t.layer.tolist()[4] == "conv2" and t.descriptor.tolist()[0] == "RGB only (softmax)"
    rgb = t.iloc[0].drop(["descriptor", "fusion"])
    assert rgb.equals(sup.table.iloc[0].drop(["descriptor", "fusion"]))          # the softmax RGB row, unchanged
    for stream in ("rgb", "depth"):
        for seed in SEEDS:
            _, ap, r100 = sr.score_descriptors(sm.describe(fus.models["late", seed], s.X, stream=stream), s.GT,
                                               s.exclude_steps, s.held)
            row = t[(t.fusion == f"late ({stream} stream)") & (t.seed == seed)].iloc[0]
            assert row["AP_%"] == ap and row["R@100P_%"] == r100
            assert row.label == f"scnn late fusion, {stream} stream alone (trained here)"
    _, ap, _ = sr.score_descriptors(sm.describe(fus.models["mid conv2", 1], s.X), s.GT, s.exclude_steps, s.held)
    assert t.loc[5, "AP_%"] == ap
    assert [n for n, *_ in fus.trained] == [f"{n}, seed {k}" for n in ("scnn early fusion", "scnn mid-level fusion at conv2",
                                                                      "scnn late fusion") for k in SEEDS]
    skipped = sr.fusions(s._replace(has_depth=False), sup, "softmax", ["conv2"], "sum", {}, SEEDS)
    assert skipped.table.status.str.startswith("skipped").all() and len(skipped.table) == 3 and not skipped.trained
    assert sr.seed_summary(skipped.table) is skipped.table


def test_the_arms_the_paper_ranks_get_their_own_seeds(setup, trained, kw):
    """ranking_seeds train early, the paper's layer (conv2) and late fusion on more seeds than the other
    mid-level layers; the table keeps Figure 9's order (early, each layer, late). (The networks of
    ``trained`` come from the cache: only conv1 is trained here.)"""
    sup, _ = trained
    fus = sr.fusions(setup, sup, "softmax", ["conv1", "conv2"], "sum", kw, [0], ranking_seeds=SEEDS)
    t = fus.table[fus.table.fusion.isin(["early", "mid", "late"])]
    assert list(zip(t.fusion, t.layer.fillna(""), t.seed)) == (
        [("early", "", k) for k in SEEDS] + [("mid", "conv1", 0)] + [("mid", "conv2", k) for k in SEEDS]
        + [("late", "", k) for k in SEEDS])
    assert t.loaded_from_cache.tolist() == [True, True, False, True, True, True, True]
    assert sr.seed_summary(fus.table).set_index("descriptor").seeds.to_dict()["scnn mid-level fusion at conv1"] == 1
    assert (fus.table[fus.table.fusion == "RGB only"].seed.tolist()) == SEEDS


def test_timing_paper_vs_run_conclusion_and_summary(setup, trained, tiny_sequence, tmp_path):
    s, (sup, fus) = setup, trained
    tim, n_native = sr.timing(s, sup, fus, tiny_sequence, "softmax", ["conv2"], 4, vocab_size=16)
    assert tim.descriptor.tolist() == ["scnn softmax, RGB", "scnn early fusion", "scnn mid-level fusion at conv2",
                                       "scnn late fusion", "sift_bovw (SIFT + 16-word quantisation)"]
    assert (tim.s_per_image_batched > 0).all() and (tim.s_per_image_one_at_a_time > 0).all() and n_native == 64
    cmp, t2, t3 = sr.paper_vs_run(s, sup, fus, tim, ["softmax"], ["conv2"], "sum", tiny_sequence)
    run, notes = cmp.set_index("quantity")["this run"], cmp.set_index("quantity")["note"]
    for q in ("best supervision", "best mid-level layer (Table 2)"):      # one candidate is never "best"
        assert run[q] == sr.UNRESOLVED
    fsum = sr.seed_summary(fus.table)
    best, text = sr.best_of(fsum, ["scnn early fusion", "scnn mid-level fusion at conv2", "scnn late fusion"])
    assert run["best fusion"] == (best or sr.UNRESOLVED) and text in notes["best fusion"]
    ssum = sr.seed_summary(sup.table).set_index("descriptor")
    above = ssum.loc["scnn softmax, RGB", "AP_min"] > ssum.loc[["scnn untrained, RGB", "pixels (32x32 gray)"], "AP_max"].max()
    assert run["each supervision above the untrained network and raw pixels"] == (
        f"softmax: {'above both' if above else 'not separated'}")
    first, last = (np.mean([sup.hists["softmax", k]["monitor"][e] for k in SEEDS]) for e in (0, -1))
    assert run["held-out AP after the first -> the last epoch, per supervision (%)"].startswith(f"softmax {first:.2f} -> {last:.2f} (loss ")
    p = [evaluate.precision_at_recall(fus.sims["late", k], s.GT, 0.82, s.exclude_steps, queries=s.held) for k in SEEDS]
    assert run["precision at 82 % recall, late fusion"] == f"{np.mean(p):.3f} [{min(p):.3f}, {max(p):.3f}]"
    mid = fus.table[fus.table.fusion == "mid"]["AP_%"]
    assert t2["this run"].tolist() == [round(mid.mean() / 100, 4)] and t2.paper.tolist() == [0.8111]
    assert len(t3) == len(tim) + 3
    out = tmp_path / "res" / "10_siamese_rgbd"                   # the conclusion reads the tables as written
    out.mkdir(parents=True)
    for name, t in (("supervisions", sr.seed_summary(sup.table)), ("fusions", fsum), ("paper_vs_run", cmp), ("timing", tim)):
        t.to_csv(out / f"{name}.csv", index=False)
    (out / "summary.json").write_text(f'{{"chance_ap": {s.chance}}}')
    text = sr.conclusion(out)
    assert text.startswith("### Conclusion on res") and "Xu 2022, Fig. 8" in text and "Xu 2022, Fig. 9" in text
    assert "softmax [" in text and ("every seed above both" in text) == above      # the supervision against the controls
    assert "conv2 first (Table 2): not resolved" in text                           # one layer, 2 seeds: never an order
    assert f"{tim.s_per_image_one_at_a_time.iloc[0]:.5f}" in text and "not a ranking" in text
    summary = sr.summary(s, sup.table, fus.table, tim, STEP, sup.trained + fus.trained)
    assert summary["networks_trained"] == 4 * len(SEEDS) and summary["labelled_frames_near_heldout"] == 0
    assert summary["last_train_frame"] < summary["first_heldout_frame"] and summary["frames"] == 100
    assert summary["training_seconds_total"] == pytest.approx(sum(t[1] for t in sup.trained + fus.trained))


def test_figures_draw_every_curve(setup, trained, tiny_sequence):
    s, (sup, fus) = setup, trained
    fig = sr.figure_supervisions(s, sup, ["softmax"], tiny_sequence)
    # every seed of softmax and of the untrained network, pixels, chance, the paper's point
    assert len(fig.axes[0].lines) == 2 * len(SEEDS) + 1 + 1 + 1
    fig, name = sr.figure_fusions(s, fus, ["conv2"], "sum", "softmax", tiny_sequence)
    # every seed of RGB only, the late depth stream, early, mid conv2 and late; chance and the paper's point
    assert name == "figure9_fusions" and len(fig.axes[0].lines) == 5 * len(SEEDS) + 1 + 1
    assert len(fig.axes[1].lines) == len(SEEDS) + 1
    k, n = sr.converged_networks(sr.ranked_fusions(fus.table, ["conv2"]))
    assert n == 3 * len(SEEDS) and fig._suptitle.get_text().startswith(f"early, mid-level at conv2 and late fusion: {k} of {n}")
    assert sr.figure_fusions(s._replace(has_depth=False), fus, ["conv2"], "sum", "softmax", tiny_sequence)[1] == "figure9_skipped"
    fig = sr.figure_convergence(sup, fus, ["conv2"], True)
    # per seed: the loss and the held-out AP of the supervision (+ untrained, pixels), and of 3 fusions
    assert [len(ax.lines) for ax in fig.axes] == [len(SEEDS), len(SEEDS) + 2, 3 * len(SEEDS)]
