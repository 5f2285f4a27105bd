"""The experiments of notebooks 00-06 (greenloop.experiments), on tiny inputs made here: hand-worked
values, or equality with the stage functions they compose. No GPU, no network; seconds."""
import numpy as np
import pandas as pd
import pytest

from conftest import revisit_example
from greenloop import evaluate, groundtruth
from greenloop.methods.dictionary import cnn, dictionary, shift, spots
from greenloop.experiments import (confusion_matrix, dataset, dictionary_threshold, shift_robustness,
                                   speed_claim, spot_grouping, training_over_seeds as tos)
from greenloop import report


def _toy(n=120, L=30, seed=0):
    rng = np.random.default_rng(seed)
    y = spots.group(n, L)
    X = (rng.random((n, 8, 8, 1)) * 0.2 + y[:, None, None, None] / (y.max() + 1)).astype(np.float32)
    return X, y


# ------------------------------------------------------------ 02: training over seeds, leakage
def test_leakage_controls_match_the_training_set_sizes():
    X, y = _toy(n=240, L=60)
    rows = tos.leakage_controls(X, y, [0], gaps=(0, 10), epochs=1, cache=False, progress=False)
    by = rows.set_index(["control", "gap"])
    assert set(by.index) == {("blocked", 0), ("random, same n_train", 0), ("blocked", 10),
                             ("random, same n_train", 10), ("blocked, centred", 5)}
    for g in (0, 10):
        assert by.loc[("blocked", g), "n_train"] == by.loc[("random, same n_train", g), "n_train"]
    assert by.loc[("blocked", 0), "n_train"] == 240 - 48 and by.loc[("blocked", 10), "n_train"] < 240 - 48
    assert (rows.converged == (rows["final_train_acc_%"] >= 95)).all() and rows["test_acc_%"].between(0, 100).all()


def _fake_run_seeds(asked):
    def fake(X, y_, seeds, progress=True, **kw):
        out = []
        for s in seeds:
            tr, te = cnn.split_indices(y_, s, split=kw.get("split", "random"), gap=kw.get("gap", 5),
                                       block=kw.get("block", "random"), train_size=kw.get("train_size"))
            asked.append((kw.get("split"), kw.get("train_size"), len(tr)))
            out.append({"seed": s, "split": {"train": tr, "test": te}, "test_accuracy": 1 / 3,
                        "history": {"accuracy": [1.0]}})
        return out
    return fake


def test_leakage_control_matches_size_within_the_random_split(monkeypatch):
    """Nordland's case: at gap 0 the blocked split of 7152 frames in spots of 60 keeps 5722
    training frames, one more than the random 80/20 split has; the matched random run then keeps
    all 5721 of its own instead of failing. Accuracies come back unrounded (1/3 -> 33.33...)."""
    y = spots.group(7152, 60)
    monkeypatch.setattr(cnn, "run_seeds", _fake_run_seeds([]))
    rows = tos.leakage_controls(np.zeros((7152, 1, 1, 1), np.float32), y, [0], gaps=[0])
    blocked, matched = (rows[rows.control == c].iloc[0] for c in ("blocked", "random, same n_train"))
    assert blocked["n_train"] == 5722 and matched["n_train"] == 5721
    assert blocked["test_acc_%"] == pytest.approx(100 / 3) and list(rows.columns) == [
        "control", "gap", "seed", "n_train", "n_test", "test_acc_%", "final_train_acc_%", "converged"]


def _run(seed, test_acc, train_acc, val_acc=(0.5,), n_train=8, n_test=2, seconds=1.25):
    """A run_seeds dict without a model: what the summaries over seeds read."""
    return {"seed": seed, "test_accuracy": test_acc, "split": {"train": np.arange(n_train), "test": np.arange(n_test)},
            "history": {"accuracy": [0.1, train_acc], "val_accuracy": list(val_acc), "seconds": seconds}}


def test_converged_and_first_epoch():
    assert tos.converged({"accuracy": [0.2, 0.95]}, 0.95) and not tos.converged({"accuracy": [0.99, 0.94]}, 0.95)
    assert tos.converged({"accuracy": [0.2, 0.6], "stopped_early": True}, 0.95)
    assert not tos.converged({"accuracy": [0.2, 0.6], "stopped_early": False}, 0.95)
    h = {"val_accuracy": [0.5, 0.97, 0.98, 0.99]}
    assert tos.first_epoch(h, 0.98) == 3 and tos.first_epoch(h, 0.5) == 1 and tos.first_epoch(h, 0.995) is None


def test_runs_by_split_trains_each_split_with_the_same_arguments(monkeypatch):
    asked = []
    monkeypatch.setattr(cnn, "run_seeds", lambda X, y, seeds, **kw: asked.append((list(seeds), kw)) or [kw["split"]])
    runs = tos.runs_by_split(np.zeros((4, 1, 1, 1)), np.zeros(4, int), [0, 1], epochs=3, gap=2)
    assert runs == {"random": ["random"], "blocked": ["blocked"]}
    assert asked == [([0, 1], {"split": "random", "epochs": 3, "gap": 2}), ([0, 1], {"split": "blocked", "epochs": 3, "gap": 2})]


def test_per_seed_and_seed_summary():
    runs = {"random": [_run(0, 0.9, 0.99, val_acc=(0.5, 0.98, 0.97, 0.99)), _run(1, 0.7, 0.5, val_acc=(0.2, 0.3, 0.4, 0.6))],
            "blocked": [_run(0, 0.4, 0.96, n_train=6, seconds=2.0)]}
    per_seed = tos.per_seed(runs, target_accuracy=0.98, converged_at=0.95, after_epoch=2)
    assert list(zip(per_seed.split, per_seed.seed)) == [("random", 0), ("random", 1), ("blocked", 0)]
    assert list(per_seed.columns) == ["split", "seed", "n_train", "n_test", "test_acc_%", "epoch_to_98%",
                                      "min_val_acc_after_ep2_%", "final_train_acc_%", "converged", "train_seconds"]
    r0, r1, r2 = (per_seed.iloc[k] for k in range(3))
    assert r0["epoch_to_98%"] == 2 and r0["min_val_acc_after_ep2_%"] == pytest.approx(97.0) and r0["converged"]
    assert np.isnan(r1["epoch_to_98%"]) and r1["min_val_acc_after_ep2_%"] == pytest.approx(40.0) and not r1["converged"]
    assert r2["n_train"] == 6 and r2["min_val_acc_after_ep2_%"] == 50.0   # a 1-epoch run: its last epoch
    summ = tos.seed_summary(per_seed)
    assert list(summ.columns) == ["split", "seeds", "converged_seeds", "mean", "std", "median", "worst", "best",
                                  "median_of_converged"]
    assert list(summ.split) == ["blocked", "random"]
    rnd = summ.set_index("split").loc["random"]
    assert (rnd.seeds, rnd.converged_seeds, rnd["mean"], rnd["worst"], rnd["best"]) == (2, 1, 80.0, 70.0, 90.0)
    assert rnd["std"] == pytest.approx(np.std([90, 70], ddof=1)) and rnd.median_of_converged == 90.0


def _control_rows():
    rows = []
    for gap, seed, blocked, matched, centred in ((0, 0, 60.0, 80.0, 70.0), (0, 1, 50.0, 90.0, 55.0), (5, 0, 40.0, 45.0, None)):
        for control, acc in zip(tos.LEAKAGE_CONTROLS, (blocked, matched, centred)):
            if acc is not None:
                rows.append({"control": control, "gap": gap, "seed": seed, "n_train": 100 - 2 * gap + seed,
                             "test_acc_%": acc, "converged": acc > 52})
    return pd.DataFrame(rows)


def test_summarise_controls_gives_the_asked_statistics_only():
    runs = _control_rows()
    s = tos.summarise_controls(runs, by=["control", "gap"], stats=("mean", "std", "median"))
    assert list(s.columns) == ["control", "gap", "seeds", "converged_seeds", "n_train_median", "acc_mean_%", "acc_std_%",
                               "acc_median_%", "acc_median_converged_%"]
    assert list(zip(s.control, s.gap)) == [("blocked", 0), ("random, same n_train", 0), ("blocked, centred", 0),
                                           ("blocked", 5), ("random, same n_train", 5)]
    b0 = s.iloc[0]
    assert (b0.seeds, b0.converged_seeds, b0.n_train_median, b0["acc_mean_%"], b0["acc_median_converged_%"]) == (2, 1, 100, 55.0, 60.0)
    assert b0["acc_std_%"] == np.std([60, 50], ddof=1) and s.iloc[3]["acc_std_%"] == 0.0   # unrounded; one seed: 0
    assert np.isnan(s.iloc[3]["acc_median_converged_%"])
    t = tos.summarise_controls(runs, by=["gap", "control"])
    assert list(t.columns)[5:] == ["acc_median_%", "acc_min_%", "acc_max_%", "acc_median_converged_%"]
    assert (t.iloc[0]["acc_min_%"], t.iloc[0]["acc_max_%"]) == (50.0, 60.0)
    with pytest.raises(ValueError, match="p90"):
        tos.summarise_controls(runs, by=["gap"], stats=("p90",))


def test_memory_points_pairs_runs_of_one_seed_and_gap():
    m = tos.memory_points(_control_rows())
    assert list(m.columns) == ["memory_points_median", "memory_points_min", "memory_points_max"]
    assert list(m.index) == [("blocked", 0), ("blocked", 5), ("blocked, centred", 0)]
    assert tuple(m.loc[("blocked", 0)]) == (30.0, 20.0, 40.0)        # 80 - 60, 90 - 50
    assert tuple(m.loc[("blocked", 5)]) == (5.0, 5.0, 5.0)
    assert tuple(m.loc[("blocked, centred", 0)]) == (22.5, 10.0, 35.0)
    said = tos.memory_statement(m, 0, 40, 2).splitlines()
    assert len(said) == 2 and "30.0 points (median; 20.0 to 40.0 over 2 seeds)" in said[0] and "centred" in said[1]
    assert "anywhere" in tos.memory_statement(m, 5, 40, 1) and tos.memory_statement(m, 7, 40, 1) == ""


# ------------------------------------------------------------ 01: spot grouping (Table 1)
def test_accuracy_over_seeds_by_hand():
    runs = [_run(0, 0.90, 0.99), _run(1, 0.80, 0.50), _run(2, 0.70, 0.96)]
    s = spot_grouping.accuracy_over_seeds(runs, converged_at=0.95)
    assert list(s) == ["seeds", "acc_mean_%", "acc_std_%", "acc_median_%", "acc_min_%", "acc_max_%",
                       "final_train_acc_min_%", "converged_seeds", "acc_median_converged_%", "epochs_min", "epochs_max",
                       "budget_limited"]
    assert s["seeds"] == 3 and s["acc_mean_%"] == pytest.approx(80.0) and s["acc_std_%"] == pytest.approx(10.0)
    assert (s["acc_median_%"], s["acc_min_%"], s["acc_max_%"]) == pytest.approx((80.0, 70.0, 90.0))
    assert s["final_train_acc_min_%"] == 50.0 and s["converged_seeds"] == 2 and s["acc_median_converged_%"] == pytest.approx(80.0)
    one = spot_grouping.accuracy_over_seeds([_run(0, 0.5, 0.2)], converged_at=0.95)
    assert one["acc_std_%"] == 0.0 and one["converged_seeds"] == 0 and np.isnan(one["acc_median_converged_%"])
    assert (s["epochs_min"], s["epochs_max"], s["budget_limited"], one["budget_limited"]) == (2, 2, False, True)
    # a seed whose training accuracy stopped rising before the cap converged, fit or not; one that ran
    # into the cap while below converged_at did not: two of three such runs are budget-limited
    stopped = _run(3, 0.4, 0.6)
    stopped["history"] = dict(stopped["history"], accuracy=[0.1, 0.6, 0.6], stopped_early=True)
    capped = [_run(4, 0.4, 0.6), _run(5, 0.4, 0.6)]
    for r in capped:
        r["history"]["stopped_early"] = False
    t = spot_grouping.accuracy_over_seeds([stopped] + capped, converged_at=0.95)
    assert (t["converged_seeds"], t["epochs_min"], t["epochs_max"], t["budget_limited"]) == (1, 2, 3, True)
    assert not spot_grouping.accuracy_over_seeds([stopped, stopped, capped[0]], converged_at=0.95)["budget_limited"]


def test_table1_groups_every_L_with_its_seeds(monkeypatch):
    asked = []
    monkeypatch.setattr(cnn, "run_seeds", lambda X, y, seeds, **kw: asked.append((int(y.max()) + 1, list(seeds), kw))
                        or [_run(s, 0.5 + 0.1 * s, 0.99) for s in seeds])
    t, runs = spot_grouping.table1(np.zeros((130, 1, 1, 1)), [50, 60, 70], 60, [0, 1], [2], epochs=3)
    assert asked == [(3, [2], {"epochs": 3}), (3, [0, 1], {"epochs": 3}), (2, [2], {"epochs": 3})]
    assert t.spots.tolist() == [3, 3, 2] and t.last_spot_frames.tolist() == [30, 10, 60]
    assert t["paper_acc_%"].tolist() == [97, 98, 97] and t["acc_mean_%"].tolist() == pytest.approx([70.0, 55.0, 70.0])
    rows = spot_grouping.paper_rows(t)
    assert rows[2] == ("accuracy, L = 60 (%)", 98, "55.00 ± 7.07, median 55.00 (min 50.00, 2 seeds, 2 converged)")
    assert rows[3] == ("spots, L = 60", 38, 3) and len(rows) == 6 and list(runs) == [50, 60, 70]


def test_table1_figure_names_its_budget_limited_rows():
    import matplotlib
    matplotlib.use("Agg")
    runs = {50: [_run(0, 0.5, 0.4), _run(1, 0.6, 0.3)], 60: [_run(0, 0.9, 0.99), _run(1, 0.8, 0.99)]}
    t = pd.DataFrame([dict(frames_per_spot=L, **spot_grouping.accuracy_over_seeds(rs)) for L, rs in runs.items()])
    fig = spot_grouping.figure_table1(runs, t, 0.95)
    ax = fig.axes[0]
    assert "budget-limited at L = 50:" in ax.get_title() and "2 epochs" in ax.get_title()
    assert [a.get_text() for a in ax.texts] == ["budget-limited"] and ax.texts[0].xy == (50, 50.0)
    # L = 50's seeds did not converge: hollow (white face), L = 60's did: filled; no line joins the means
    import matplotlib.colors as mc
    dots = [c for c in ax.collections if c.get_offsets().shape[0] and c.get_label() != "_nolegend_"
            and c.get_offsets()[0][0] in (50 - 1.2, 60 - 1.2)]
    face = {round(float(c.get_offsets()[0][0])): mc.to_hex(c.get_facecolor()[0]) for c in dots}
    assert face == {49: "#ffffff", 59: mc.to_hex("tab:blue")}
    assert {h.get_label() for h in ax.get_legend().legend_handles} >= {"one seed, converged",
                                                                       "one seed, did not converge (hollow)"}
    assert not [ln for ln in ax.lines if ln.get_linestyle() not in ("None", "")
                and len(set(np.asarray(ln.get_xdata(), float))) > 1]


def test_controls_by_grouping_runs_one_gap_per_grouping(monkeypatch):
    asked = []

    def fake(X, y, seeds, gaps, centre_gap, converged_at, progress, **kw):
        asked.append((int(y.max()), list(gaps), centre_gap, converged_at, kw))
        return pd.DataFrame([{"control": "blocked", "gap": gaps[0], "seed": s} for s in seeds])
    monkeypatch.setattr(tos, "leakage_controls", fake)
    rows = spot_grouping.controls_by_grouping(np.zeros((60, 1, 1, 1), np.float32), [20, 30], [0, 1], gap=5,
                                              converged_at=0.9, epochs=3)
    assert asked == [(2, [5], 5, 0.9, {"epochs": 3}), (1, [5], 5, 0.9, {"epochs": 3})]
    assert list(zip(rows.frames_per_spot, rows.seed)) == [(20, 0), (20, 1), (30, 0), (30, 1)]
    assert list(rows.columns) == ["control", "gap", "seed", "frames_per_spot"]


# ------------------------------------------------------------ 03: confusion matrix
def _error_runs():
    labels = np.array([0, 0, 1, 1, 2, 2])
    gt = np.zeros((6, 6), bool)
    gt[0, 5] = gt[5, 0] = True          # frame 5 (spot 2) revisits frame 0 (spot 0)
    runs = {"random": [{"seed": 0, "split": {"test": np.array([5, 4, 2])}, "test_pred": np.array([0, 1, 1])},
                       {"seed": 1, "split": {"test": np.array([5, 4, 2])}, "test_pred": np.array([2, 2, 1])}],
            "blocked": [{"seed": 0, "split": {"test": np.array([0, 3])}, "test_pred": np.array([1, 1])}]}
    return labels, gt, runs


def test_errors_per_seed_tallies_every_run():
    labels, gt, runs = _error_runs()
    rows = confusion_matrix.errors_per_seed(runs, labels, gt)
    assert list(rows.columns) == ["split", "seed", "test_frames", "misclassified", "accuracy_%", "errors_on_adjacent_spot",
                                  "adjacent_share_%", "errors_on_same_place_other_time"]
    assert list(zip(rows.split, rows.seed)) == [("random", 0), ("random", 1), ("blocked", 0)]
    # 5 -> spot 0 (two spots away, same place), 4 -> spot 1 (adjacent); 2 right; unrounded: 100/3 %
    assert rows.iloc[0, 2:].tolist() == pytest.approx([3, 2, 100 * (1 - 2 / 3), 1, 50.0, 1])
    assert rows.iloc[1, 2:4].tolist() == [3, 0] and rows.iloc[1]["accuracy_%"] == 100.0
    assert np.isnan(rows.iloc[1]["adjacent_share_%"]) and rows.iloc[2, 2:].tolist() == [2, 1, 50.0, 1, 100.0, 0]
    assert confusion_matrix.errors_per_seed(runs, labels)["errors_on_same_place_other_time"].isna().all()
    written = report.rounded(rows, columns={"accuracy_%": 2, "adjacent_share_%": 1})
    assert written["accuracy_%"].iloc[0] == 33.33


def test_first_seed_tables_and_paper_rows():
    labels, gt, runs = _error_runs()
    tables, matrices = confusion_matrix.first_seed_tables(runs, labels, 3)
    assert matrices["random"].tolist() == [[0, 0, 0], [0, 1, 0], [1, 1, 0]]        # frames 5, 4, 2 (spots 2, 2, 1) -> 0, 1, 1
    assert matrices["blocked"].tolist() == [[0, 1, 0], [0, 1, 0], [0, 0, 0]]
    assert tables["random"].equals(evaluate.per_spot(labels[[5, 4, 2]], np.array([0, 1, 1]), 3))
    rows = confusion_matrix.paper_rows(confusion_matrix.errors_per_seed(runs, labels, gt), tables, 3, has_gt=True)
    by = {q: v for q, _, v, *_ in rows}
    assert by["misclassified, mean over seeds (random split)"] == "1.0 (min 0, max 2)"
    assert by["share of errors on an adjacent spot, random split (%)"] == "50.0"       # 1 of the 2 errors
    assert by["share of errors naming the same place at another time, random split (%)"] == "50.0"
    assert by["classes with precision = recall = 1 (blocked split)"] == "0 of 3" and len(rows) == 12


# ------------------------------------------------------------ 04: shift robustness
def _dots():
    """8 frames of 8x8: frame i has one bright pixel at row 3, column i, and is labelled i; the
    "model" names the column of the brightest pixel (0 for a blank frame)."""
    X = np.zeros((8, 8, 8, 1), np.float32)
    X[np.arange(8), 3, np.arange(8)] = 1
    return X, np.arange(8)


def _column(model, X):
    assert model == "dots"
    return X[..., 0].max(1).argmax(1)


def _runs():
    return [{"seed": 0, "model": "dots", "test_accuracy": 1.0, "split": {"train": np.arange(6), "test": np.array([6, 7])}},
            {"seed": 1, "model": "dots", "test_accuracy": 0.5, "split": {"train": np.arange(1, 7), "test": np.array([0, 7])}}]


def test_accuracy_and_frame_sets():
    X, y = _dots()
    assert shift_robustness.accuracy(_column, "dots", X, y) == 100.0
    assert shift_robustness.accuracy(_column, "dots", shift.shift(X, -1), y) == 12.5     # only frame 0: blank, read as 0
    sets = shift_robustness.frame_sets({"train": np.array([1, 2]), "test": np.array([0])}, 3)
    assert list(sets) == list(shift_robustness.FRAME_SETS)
    assert [s.tolist() for s in sets.values()] == [[0, 1, 2], [1, 2], [0]]


def test_paper_scores_all_frames_and_test_only():
    X, y = _dots()
    t = shift_robustness.paper_scores(_column, _runs(), shift.shift(X, -1), y)
    assert t.to_dict("records") == [
        {"seed": 0, "original_test_%": 100.0, "shift1_all_frames_%": 12.5, "shift1_test_only_%": 0.0},
        {"seed": 1, "original_test_%": 50.0, "shift1_all_frames_%": 12.5, "shift1_test_only_%": 50.0}]


def test_perturbation_grid_by_direction():
    X, y = _dots()
    grid = shift_robustness.perturbation_grid(_column, _runs()[1:], X, y, shifts=[1, 2], rotations=[180])  # test 0, 7
    got = grid.set_index(["perturbation", "amount"])["heldout_%"]
    assert len(grid) == 4 * 2 + 2 and (grid.seed == 1).all()
    assert got["shift right", 1] == 0.0                  # 0 -> column 1, 7 falls off (blank: 0)
    assert got["shift left", 1] == 50.0                  # 0 falls off and reads as 0; 7 -> 6
    assert got["shift up", 2] == got["shift down", 1] == 100.0   # the column does not move
    assert got["rotation", 180] == got["rotation", -180] == 0.0  # column c -> 7 - c
    every = grid.set_index(["perturbation", "amount"])["all_frames_%"]
    assert every["shift left", 1] == 12.5 and every["shift up", 2] == 100.0     # of 8 frames, only frame 0 reads 0


def _memoriser(model, X):
    """A planted classifier that memorises its training frames: the label of the nearest training frame
    (model: {"X": (M, H, W, 1), "y": (M,)}); it knows nothing of a frame it did not see."""
    d = ((X[:, None] - model["X"][None]) ** 2).sum(axis=(2, 3, 4))
    return model["y"][d.argmin(1)]


def test_a_memorising_model_scores_high_on_all_frames_and_low_held_out():
    yy, xx = np.mgrid[:32, :32]
    centres = np.array([(6 + 6 * (k % 4), 8 + 8 * (k // 4)) for k in range(10)])[:, :, None, None]  # 6 px apart
    X = np.exp(-((xx - centres[:, 0]) ** 2 + (yy - centres[:, 1]) ** 2) / 8.0)[..., None].astype(np.float32)  # one class each
    y = np.arange(10)
    train, test = np.arange(8), np.array([8, 9])
    runs = [{"seed": 0, "model": {"X": X[train], "y": y[train]}, "split": {"train": train, "test": test}}]
    grid = shift_robustness.perturbation_grid(_memoriser, runs, X, y, shifts=[1], rotations=[])
    assert (grid["all_frames_%"] == 80.0).all() and (grid["heldout_%"] == 0.0).all()   # 8 of 10 remembered
    s = shift_robustness.perturbation_summary(grid)
    assert (s.all_frames_minus_heldout_points == 80.0).all() and (s.heldout_mean == 0.0).all()
    table3 = shift_robustness.paper_scores(_memoriser, [dict(runs[0], test_accuracy=0.0)], shift.shift(X, dx=1), y)
    cmp = shift_robustness.comparison(table3, 10, np.zeros(10), np.zeros(10), 256).set_index("quantity")
    judged = cmp.loc["accuracy, held-out test frames shifted 1 px right (%)"]
    assert judged["note"].startswith("judged") and judged.iloc[1].startswith("0.00")
    assert cmp.loc["accuracy, all frames shifted 1 px right (%)"].iloc[1].startswith("80.00")


def test_perturbation_summary_over_runs():
    X, y = _dots()
    s = shift_robustness.perturbation_summary(shift_robustness.perturbation_grid(_column, _runs(), X, y, [1], [180]))
    assert list(s.columns) == ["perturbation", "amount", "heldout_mean", "heldout_std", "heldout_min", "all_frames_mean",
                               "all_frames_std", "all_frames_min", "all_frames_minus_heldout_points"]
    assert list(zip(s.perturbation, s.amount))[:2] == [("rotation", -180), ("rotation", 180)] and len(s) == 6
    left = s[(s.perturbation == "shift left") & (s.amount == 1)].iloc[0]      # seed 0: 0 %, seed 1: 50 %
    assert (left["heldout_mean"], left["heldout_std"], left["heldout_min"]) == (25.0, np.std([0, 50], ddof=1), 0.0)
    assert left["all_frames_mean"] == 12.5 and left["all_frames_minus_heldout_points"] == -12.5


def test_frame_set_scores_subtracts_the_same_runs_test_frames():
    X, y = _dots()
    per_seed, summary = shift_robustness.frame_set_scores(_column, _runs(), X, shift.shift(X, -1), y)
    assert len(per_seed) == 6 and list(per_seed.frames[:3]) == list(shift_robustness.FRAME_SETS)
    assert (per_seed["unshifted_%"] == 100).all()
    # seed 0: all 1/8, train (0..5) 1/6, test (6, 7) 0; seed 1: all 1/8, train (1..6) 0, test (0, 7) 1/2
    assert per_seed["shift1_%"].tolist() == pytest.approx([12.5, 100 / 6, 0.0, 12.5, 0.0, 50.0])
    assert per_seed["shift1_vs_test_only_points"].tolist() == pytest.approx([12.5, 100 / 6, 0.0, -37.5, -50.0, 0.0])
    assert list(summary.columns) == ["frames", "n_frames", "unshifted_%", "shift1_%", "shift1_vs_test_only_points"]
    assert list(summary.frames) == list(shift_robustness.FRAME_SETS)
    assert summary["n_frames"].tolist() == [8, 6, 2] and summary["shift1_%"].tolist() == pytest.approx([12.5, 100 / 12, 25.0])
    assert report.rounded(summary, 2)["shift1_vs_test_only_points"].tolist() == [-12.5, -16.67, 0.0]


def test_control_scores_and_the_one_shift_table():
    X, y = _dots()
    full = (X * 255).astype(np.uint8)                    # native = CNN size: every full-res shift is exact
    controls, identical = shift_robustness.control_scores(_column, _runs(), X, full, y, shifts=[1])
    assert identical == [True] * 4
    assert list(controls.columns) == ["direction", "shift_px", "input", "accuracy_mean_%", "accuracy_std_%",
                                      "changed_pixels_per_frame", "mean_abs_change_per_pixel"]
    assert len(controls) == 4 * len(shift.CONTROLS)
    c = controls.set_index(["direction", "input"])
    left = c.loc[("left", shift.CONTROLS[0])]
    assert (left["accuracy_mean_%"], left["accuracy_std_%"]) == (25.0, np.std([0, 50], ddof=1))
    assert left.changed_pixels_per_frame == 15 / 8 and left.mean_abs_change_per_pixel == pytest.approx(15 / 64 / 8)  # 7 x 2 + 1
    written = report.rounded(controls, columns=shift_robustness.CONTROL_DECIMALS).set_index(["direction", "input"])
    assert written.loc[("left", shift.CONTROLS[0]), "changed_pixels_per_frame"] == 1.9
    assert c.loc[("up", shift.CONTROLS[1]), "accuracy_mean_%"] == 100.0
    # right, replicate border: frame 0's pixel is copied into column 0 too and the first maximum wins -> right
    # (seed 1); the zero border moves it to column 1; frame 7 falls off either way
    assert c.loc[("right", shift.CONTROLS[0]), "accuracy_mean_%"] == 0.0
    assert c.loc[("right", shift.CONTROLS[1]), "accuracy_mean_%"] == 25.0
    wide = shift_robustness.controls_by_direction(controls, 1, no_shift=75.0)
    assert list(wide.columns) == ["direction", "no shift", *shift.CONTROLS, "lost_to_shift_points", "won_back_by_replicate_points"]
    assert list(wide.direction) == list(shift.DIRECTIONS)
    said = shift_robustness.controls_statement(wide, 1).splitlines()
    assert said[0].startswith("1 px right: 75.0 points lost") and "+25.0 points, leaving it 50.0 points below" in said[0]
    wide = wide.set_index("direction")
    assert (wide.loc["right", "lost_to_shift_points"], wide.loc["right", "won_back_by_replicate_points"]) == (75.0, 25.0)
    assert (wide.loc["left", "lost_to_shift_points"], wide.loc["left", "won_back_by_replicate_points"]) == (50.0, 0.0)


# ------------------------------------------------------------ 05: the dictionary's threshold


def test_tau_sweep_scores_every_threshold():
    pred, ref, gt = revisit_example()
    rows = dictionary_threshold.tau_sweep(pred, ref, gt, [3, 12, 25], exclude=5)
    assert list(rows[0]) == ["tau", "true_events", "false_events", "true_frames", "false_frames", "revisit_recall_%",
                             "first_delay_frames"]
    # tau 3: spots 0, 1, 2 fire on their first traversal (frames 2-9, 12-19 but 15, 21-29 flagged false);
    # the revisit is flagged from its first frame
    assert tuple(rows[0].values()) == (3, 0, 3, 10, 8 + 7 + 9, 100.0, 0)
    assert tuple(rows[1].values()) == (12, 1, 0, 9, 0, 90.0, 1)        # spot 0 reaches 12 at frame 31
    assert tuple(rows[2].values()) == (25, 0, 0, 0, 0, 0.0, None)      # no spot reaches 25


def test_variants_scores_events_and_sweep(monkeypatch):
    pred, ref, gt = revisit_example()
    trained = []
    monkeypatch.setattr(cnn, "run_seeds", lambda X, y, seeds, **kw: trained.append((y.tolist(), list(seeds), kw))
                        or [{"seed": seeds[0], "model": "aware"}])
    monkeypatch.setattr(cnn, "predict", lambda model, X: pred if model == "aware" else ref)
    variants = dictionary_threshold.variant_predictions(np.zeros((40, 1, 1, 1)), gt, 10, {"seed": 7, "model": "paper"},
                                                        epochs=2)
    assert trained == [(spots.by_place(10, gt).tolist(), [7], {"epochs": 2})]
    assert list(variants) == list(dictionary_threshold.VARIANTS)
    assert variants[dictionary_threshold.VARIANTS[1]][1].tolist() == spots.by_place(10, gt).tolist()
    scores = dictionary_threshold.variant_scores(variants, gt, 12, exclude=5)
    aware = scores[dictionary_threshold.VARIANTS[1]]
    direct = dictionary.score_closures(pred, spots.by_place(10, gt), gt, 12, 5)
    assert {k: v for k, v in aware.items() if k != "flags"} == {k: v for k, v in direct.items() if k != "flags"}
    ev = dictionary_threshold.events(scores)
    assert list(ev.columns) == ["variant", "frame", "spot", "count", "true"]
    assert len(ev) == sum(s["events"] for s in scores.values())
    assert "flags" not in dictionary_threshold.scores_summary(scores)[dictionary_threshold.VARIANTS[0]]
    sw = dictionary_threshold.sweep(variants, gt, [3, 12], exclude=5)
    assert list(sw.columns)[0] == "variant" and len(sw) == 4
    direct = dictionary_threshold.tau_sweep(ref, ref, gt, [3, 12], 5)
    assert sw.iloc[:2, 1:6].to_dict("records") == [{k: r[k] for k in list(r)[:5]} for r in direct]


def test_the_detector_over_seeds_gives_each_seeds_precision_recall_and_convergence(monkeypatch):
    pred, ref, gt = revisit_example()               # the loop-aware model: pred; the paper's: its labels exactly
    fit, short = {"accuracy": [0.5, 0.99]}, {"accuracy": [0.3, 0.6]}
    monkeypatch.setattr(cnn, "run_seeds", lambda X, y, seeds, **kw: [
        {"seed": seeds[0], "model": "aware", "history": fit if seeds[0] == 7 else short}])
    monkeypatch.setattr(cnn, "predict", lambda model, X: pred if model == "aware" else ref)
    runs = [{"seed": s, "model": "paper", "history": h} for s, h in ((7, fit), (8, short))]
    per_seed, first = dictionary_threshold.over_seeds(np.zeros((40, 1, 1, 1)), gt, 10, runs, 12, exclude=5)
    assert per_seed[["seed", "variant"]].values.tolist() == [[s, v] for s in (7, 8) for v in dictionary_threshold.VARIANTS]
    assert per_seed.converged.tolist() == [True, True, False, False] and per_seed.epochs.tolist() == [2] * 4
    direct = dictionary.score_closures(pred, spots.by_place(10, gt), gt, 12, 5)
    aware = per_seed[per_seed.variant == dictionary_threshold.VARIANTS[1]].iloc[0]
    assert aware["precision_%"] == 100 * direct["precision"] and aware["recall_%"] == 90.0    # 9 of 10 revisit frames
    paper = per_seed[per_seed.variant == dictionary_threshold.VARIANTS[0]]
    assert paper["precision_%"].isna().all() and (paper["recall_%"] == 0).all()   # spots by index: the revisit is new
    assert first[dictionary_threshold.VARIANTS[1]][0] is pred
    s = dictionary_threshold.seed_summary(per_seed.assign(**{"recall_%": [0.0, 90.0, 0.0, 50.0]})).set_index("variant")
    row = s.loc[dictionary_threshold.VARIANTS[1]]
    assert (row.seeds, row.converged_seeds) == (2, 1)
    assert (row["recall_median_%"], row["recall_min_%"], row["recall_max_%"], row["recall_median_converged_%"]) == (
        70.0, 50.0, 90.0, 90.0)


# ------------------------------------------------------------ 00: the dataset
def test_dataset_summary_rows(tmp_path):
    from greenloop.datasets import sequence
    poses = np.repeat(np.eye(4)[None], 30, axis=0)
    poses[:, 0, 3] = np.r_[np.arange(15), np.arange(15)[::-1]] * 0.1   # out and back: 2.8 m, loops near the turn
    gt = groundtruth.loop_matrix(poses, 0.5, 5)
    info = {"kind": "synthetic", "ground_truth": "poses"}
    for k in range(30):
        (tmp_path / "rgb").mkdir(exist_ok=True)
        (tmp_path / "rgb" / f"{k}.png").write_bytes(b"")
    t = dataset.summary(tmp_path, info, poses, gt)
    pairs = groundtruth.loop_pairs(gt)
    assert t.iloc[0].to_dict() == {"sequence": f"synthetic ({tmp_path})", "frames": 30, "ground_truth": "poses",
                                   "path_m": pytest.approx(2.8), "loop_pairs": len(pairs),
                                   "revisit_frames": int(groundtruth.revisit_frames(gt).sum()),
                                   "first_revisit_frame": int(pairs[:, 1].min())}
    none = dataset.summary(tmp_path, info, None, None).iloc[0]
    assert none.path_m is None and none.loop_pairs is None and none.first_revisit_frame is None
    gps = tmp_path / "gps-only"                      # no poses, a positions file: its track's length
    (gps / "rgb").mkdir(parents=True)
    for k in range(4):
        (gps / "rgb" / f"{k}.png").write_bytes(b"")
    (gps / "positions.csv").write_text("frame,x,y\n0,0,0\n1,3,4\n2,3,0\n3,0,0\n")
    assert dataset.summary(gps, {"kind": "user", "ground_truth": "pairs"}, None, None).iloc[0].path_m == pytest.approx(12)
    traj = tmp_path / "CameraTrajectory.txt"
    sequence.write_trajectory(traj, np.arange(30), poses)
    assert dataset.find_reference(str(tmp_path / "missing.txt")) is None and dataset.find_reference(str(traj)) == traj
    row, ref_poses, ref_pairs = dataset.reference(traj, 0.5, 5)
    assert row["sequence"] == f"real GreenHouse ({traj})" and row["frames"] == 30 and row["path_m"] == pytest.approx(2.8)
    read = groundtruth.loop_pairs(groundtruth.loop_matrix(sequence.read_trajectory(traj)[1], 0.5, 5))
    assert ref_pairs.tolist() == read.tolist() and row["loop_pairs"] == len(read) > 0 and ref_poses.shape == (30, 4, 4)
    both = dataset.summary(tmp_path, info, poses, gt, row)
    assert len(both) == 2 and both.iloc[1].to_dict() == row


def test_speed_claim_is_the_benchs_table(monkeypatch):
    from greenloop.speed import bench
    monkeypatch.setattr(speed_claim, "Detector", lambda model, threshold, backend: backend)
    monkeypatch.setattr(speed_claim.sequence, "list_frames", lambda d: ["a.png"] * 500)
    monkeypatch.setattr(speed_claim.sequence, "read_image", lambda p: np.zeros((6, 8, 3), np.uint8))
    asked = {}
    monkeypatch.setattr(bench, "bench_windows", lambda m, raw, dets, rounds: asked.setdefault("w", (len(raw), dets, rounds)) and
                        {"reference": {"frames_per_s": 10.0, "median_ms": 100.0},
                         "numpy": {"frames_per_s": 50.0, "median_ms": 20.0}, "tflite": {"frames_per_s": 40.0, "median_ms": 25.0},
                         "gray_pass_floor": {"frames_per_s": 1000.0, "median_ms": 1.0}})
    monkeypatch.setattr(bench, "bench_single", lambda m, raw, dets, n_ref, n_ours: asked.setdefault("s", (n_ref, n_ours)) and
                        {b: {"median_ms": 1.0, "p99_ms": 2.0} for b in ("reference", "numpy", "tflite")})
    monkeypatch.setattr(bench, "raw_agreement", lambda m, dets, raw, X: {"numpy": len(raw), "tflite": len(raw) - 1})
    table, timings, shape = speed_claim.stream_comparison("model", "folder", None, window=70, repeats=200)
    assert asked == {"w": (210, {"numpy": "numpy", "tflite": "tflite"}, 20), "s": (50, 1000)} and shape == (6, 8, 3)
    assert table["window_speed-up"].tolist() == [1.0, 5.0, 4.0, 100.0]
    assert table.labels_equal.tolist() == ["210/210", "210/210", "209/210", ""] and set(timings) == {"windows", "single", "labels_equal"}


# ------------------------------------------------------------ rounding where a table is written
def test_write_table_rounds_only_what_it_is_asked_to(tmp_path):
    df = pd.DataFrame({"name": ["a", "b"], "acc_%": [100 / 3, 12.346], "n": [3, 4], "s": [1.26, None]})
    r = report.rounded(df, 2, {"s": 1})
    assert r["acc_%"].tolist() == [33.33, 12.35] and r["s"].iloc[0] == 1.3 and np.isnan(r["s"].iloc[1])
    assert report.rounded(df)["acc_%"].iloc[0] == 100 / 3 and df["acc_%"].iloc[0] == 100 / 3   # no copy rounded in place
    assert report.rounded(df, columns={"acc_%": 0})["acc_%"].tolist() == [33.0, 12.0]
    assert report.records(df, 1)[0] == {"name": "a", "acc_%": 33.3, "n": 3, "s": 1.3}
    with pytest.raises(ValueError, match="not in the table"):
        report.rounded(df, 2, {"missing": 1})
    report.write_table(df, tmp_path / "t", decimals=1)
    assert (tmp_path / "t.csv").read_text().splitlines()[1] == "a,33.3,3,1.3"
    assert "33.3" in (tmp_path / "t.md").read_text() and "33.33" not in (tmp_path / "t.md").read_text()


def test_budget_label_stands_on_tables_and_figures_of_unconverged_runs():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fitted, stuck = _run(0, 0.9, 0.99), _run(1, 0.3, 0.4)
    assert tos.budget_label([fitted, stuck]) == ""                                 # half converged
    assert tos.budget_label([fitted, stuck, stuck]) == "budget-limited: 1 of 3 seeds converged"
    assert tos.budget_label({"random": [fitted], "blocked": [stuck, stuck]}) == "budget-limited: 1 of 3 seeds converged"
    fig, ax = plt.subplots(); ax.set_title("Table 3")
    assert [t.get_text() for t in tos.label_budget(fig, [stuck]).texts] == ["budget-limited: 0 of 1 seeds converged"]
    assert tos.label_budget(fig, [fitted]) is fig and len(fig.texts) == 1                        # nothing added
    plt.close("all")
