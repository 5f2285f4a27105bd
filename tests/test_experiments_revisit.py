"""Notebook 12's protocol (greenloop.experiments.revisit_protocol): the first traversal's places,
named on the revisit; the dictionary's τ chosen on one part of the revisits, scored on the other."""
import numpy as np
import pandas as pd
import pytest

from greenloop import evaluate, groundtruth
from greenloop.datasets import sequence
from greenloop.experiments import revisit_protocol as rp
from greenloop.methods.dictionary import cnn, dictionary, spots


def test_first_traversal_is_the_spots_before_the_first_revisit(tiny_sequence):
    t = rp.first_traversal(tiny_sequence, 20, 0.5, 20)
    GT = groundtruth.for_sequence(tiny_sequence, threshold=0.5, exclude=20)
    n_ref = spots.first_revisit(GT)
    assert t.X.shape == (200, 32, 32, 1) and np.array_equal(t.X, sequence.load_frames(tiny_sequence))
    assert np.array_equal(t.GT, GT) and t.n_ref == n_ref and np.array_equal(t.y, spots.group(n_ref, 20))
    queries, ok = spots.revisit_targets(t.y, GT, n_ref)
    assert np.array_equal(t.queries, queries) and np.array_equal(t.acceptable, ok) and (t.queries >= n_ref).all()
    assert t.text.startswith(f"first traversal: frames 0..{n_ref - 1} ({int(t.y.max()) + 1} spots of 20); {len(queries)} ")
    fixed = rp.first_traversal(tiny_sequence, 20, 0.5, 20, first_traversal_end=100)
    assert fixed.n_ref == 100 and len(fixed.y) == 100 and (fixed.queries >= 100).all()


def test_revisit_predictions_scores_the_same_models_on_the_revisit(monkeypatch):
    """Two spots learnt on the first traversal; four revisit frames, each acceptable in one spot."""
    trained = []

    def fake_run_seeds(X, y_, seeds, progress=True, **kw):
        trained.append((len(X), kw["split"], kw["gap"], progress))
        return [{"seed": s, "model": (kw["split"], s), "split": {"train": np.arange(8)}, "test_accuracy": 0.755,
                 "history": {"accuracy": [0.5, 0.98765]}} for s in seeds]

    # the "random" models name revisit frames by their value, the "blocked" ones all as spot 0
    monkeypatch.setattr(cnn, "run_seeds", fake_run_seeds)
    monkeypatch.setattr(cnn, "predict", lambda model, X: (X[:, 0, 0, 0].astype(np.int64) if model[0] == "random"
                                                          else np.zeros(len(X), np.int64)))
    X_first = np.zeros((10, 1, 1, 1), np.float32)
    X_rev = np.array([0, 1, 1, 0], np.float32).reshape(4, 1, 1, 1)
    acceptable = np.array([[True, False], [False, True], [True, False], [False, True]])
    runs, per_seed, rev = rp.revisit_predictions(X_first, np.repeat([0, 1], 5), X_rev, acceptable, [3, 4], gap=2)
    assert trained == [(10, "random", 2, False), (10, "blocked", 2, False)] and list(runs) == ["random", "blocked"]
    assert per_seed[["split", "seed", "revisit_acc_%"]].values.tolist() == \
        [["random", 3, 50.0], ["random", 4, 50.0], ["blocked", 3, 50.0], ["blocked", 4, 50.0]]
    row = per_seed.iloc[0].to_dict()
    assert list(row) == ["split", "seed", "n_train", "epochs", "final_train_acc_%", "converged", "in_traversal_test_acc_%",
                         "revisit_acc_%", "revisit_frames"]
    assert (row["epochs"], row["converged"]) == (2, True)              # 98.765 % >= 95 %: fits its training frames
    # unrounded: 98.765 %, not 98.77 %
    assert row["final_train_acc_%"] == pytest.approx(98.765) and row["in_traversal_test_acc_%"] == pytest.approx(75.5)
    assert (row["n_train"], row["revisit_frames"]) == (8, 4)
    assert rev["random", 3]["pred"].tolist() == [0, 1, 1, 0] and rev["random", 3]["right"].tolist() == [True, True, False, False]
    assert rev["blocked", 4]["right"].tolist() == [True, False, True, False]
    with pytest.raises(ValueError, match="acceptable"):
        rp.revisit_predictions(X_first, np.repeat([0, 1], 5), X_rev, acceptable[:3], [0])


def test_accuracy_summary_by_hand():
    per_seed = pd.DataFrame({"split": ["random"] * 3 + ["blocked"] * 2, "seed": [0, 1, 2, 0, 1],
                             "in_traversal_test_acc_%": [90.0, 96.0, 99.0, 70.0, 80.0],
                             "revisit_acc_%": [10.0, 20.0, 60.0, 5.0, 5.0]})
    s = rp.accuracy_summary(per_seed).set_index(["split", "scored_on"])
    assert list(s.columns) == ["seeds", "mean", "std", "median", "min", "max"] and len(s) == 4
    r = s.loc[("random", "revisit_acc_%")]
    # mean 30, sample std sqrt(((-20)^2 + (-10)^2 + 30^2) / 2) = sqrt(700)
    assert (r.seeds, r["mean"], r["median"], r["min"], r["max"]) == (3, 30.0, 20.0, 10.0, 60.0)
    assert r["std"] == pytest.approx(np.sqrt(700))
    b = s.loc[("blocked", "in_traversal_test_acc_%")]
    assert (b.seeds, b["mean"], b["median"]) == (2, 75.0, 75.0) and b["std"] == pytest.approx(np.sqrt(50))


def _stream():
    """The stream of test_dictionary's query-mask test: frames 6..11 revisit frames 0..5."""
    n = 12
    gt = np.zeros((n, n), bool)
    for k in range(6):
        gt[k, 6 + k] = gt[6 + k, k] = True
    ref = np.r_[np.repeat([0, 1], 3), -np.ones(6, int)]
    pred = np.r_[np.repeat([0, 1], 3), np.repeat([0, 1], 3)]
    return pred, ref, gt


def test_tune_and_score_chooses_tau_on_one_part_and_scores_it_on_the_other():
    pred, ref, gt = _stream()
    n = len(pred)
    tune, score = np.arange(n) < 9, np.arange(n) >= 9
    rules, curve = rp.tune_and_score(pred, ref, gt, [2, 3, 4, 7], tune, score, 5, exclude=2)
    chosen, paper = rules
    # tau 4 is the best F1 on frames < 9; on frames 9..11 it flags all three revisit frames, rightly
    assert chosen == {"tau_rule": "chosen on the tuning part", "tau": 4, "precision": 1.0, "recall": 1.0,
                      "flagged_frames": 3, "false_frames": 0, "events": 1, "false_events": 0, "first_delay_frames": 0}
    # the paper's tau 5: spot 1 reaches 5 detections at frame 10, one frame into the scored revisit (recall 2/3, unrounded)
    assert paper["recall"] == 2 / 3 and paper == {"tau_rule": "paper: L + Δ", "tau": 5, "precision": 1.0, "recall": 2 / 3,
                                                  "flagged_frames": 2, "false_frames": 0, "events": 1, "false_events": 0,
                                                  "first_delay_frames": 1}
    assert [c["tau"] for c in curve] == [2, 3, 4, 7]
    assert [c["tune_f1"] for c in curve] == pytest.approx([0.6, 0.75, 1.0, 0.0])   # F1 on frames < 9
    assert [c["score_recall"] for c in curve] == [1.0, 1.0, 1.0, 0.0] and np.isnan(curve[-1]["score_precision"])
    # no honest split: nothing chosen, the paper's tau on every frame (flags 7, 8, 10, 11)
    rules, curve = rp.tune_and_score(pred, ref, gt, [2, 3, 4, 7], None, None, 5, exclude=2)
    assert [(r["tau_rule"], r["tau"], r["flagged_frames"], r["recall"], r["events"], r["first_delay_frames"])
            for r in rules] == [("paper: L + Δ, every frame (no honest split)", 5, 4, 2 / 3, 2, 1)]
    assert all(np.isnan(c["tune_f1"]) for c in curve)
    with pytest.raises(ValueError, match="both"):
        rp.tune_and_score(pred, ref, gt, [2], tune, None, 5, exclude=2)


def _traversal(n=120, first=60, L=10):
    """Frames first.. n-1 revisit frames 0 .. n-first-1; spots of L frames in the first traversal."""
    gt = np.zeros((n, n), bool)
    k = np.arange(n - first)
    gt[k, k + first] = gt[k + first, k] = True
    y = spots.group(first, L)
    queries, ok = spots.revisit_targets(y, gt, first)
    X = np.arange(n, dtype=np.float32).reshape(n, 1, 1, 1)
    return rp.FirstTraversal(X, gt, first, y, queries, ok, "")


def test_dictionary_scores_is_tune_and_score_on_each_model_on_the_honest_split(monkeypatch):
    t = _traversal()
    # model s names frame i the spot of frame i mod 60, except that model 1 misses every third frame
    truth = (np.arange(120) % 60) // 10
    preds = {0: truth, 1: np.where(np.arange(120) % 3 == 0, 5 - truth, truth)}
    monkeypatch.setattr(cnn, "predict", lambda model, X: preds[model])
    tuned = rp.dictionary_scores(t, [{"seed": 7, "model": 0}, {"seed": 8, "model": 1}], [5, 10, 15, 20], 0.5, 10, 10, 5)
    tune, score, note = evaluate.honest_split(120, 0.5, t.GT, 10)
    assert note is None and tuned.note is None and tuned.scored == "scoring part"
    assert tuned.tau_paper == dictionary.threshold(10, 0.1, 10)["tau"] == 20
    ref = np.r_[t.y, -np.ones(60, np.int64)]
    expected = []
    for seed, model in ((7, 0), (8, 1)):
        rules, _ = rp.tune_and_score(preds[model], ref, t.GT, [5, 10, 15, 20], tune, score, 20, 5)
        expected += [{"seed": seed, **r} for r in rules]
    assert tuned.table.to_dict("records") == pd.DataFrame(expected).to_dict("records")
    assert tuned.table.tau_rule.tolist() == ["chosen on the tuning part", "paper: L + Δ"] * 2
    assert len(tuned.curve) == 2 * 4 and tuned.curve.seed.tolist() == [7] * 4 + [8] * 4
    cut = int(np.flatnonzero(tune)[-1]) + 1
    assert tuned.text.startswith(f"tuning part: frames < {cut}; scoring part: frames >= {int(np.flatnonzero(score)[0])}")


def test_dictionary_scores_without_an_honest_split_scores_the_papers_tau_on_every_frame(monkeypatch):
    t = _traversal(n=70, first=62, L=10)          # 8 revisit frames, all within L = 10 of each other
    monkeypatch.setattr(cnn, "predict", lambda model, X: (np.arange(70) % 62) // 10 % 6)
    tuned = rp.dictionary_scores(t, [{"seed": 0, "model": None}], [5, 10], 0.5, 10, 10, 5)
    assert tuned.note.startswith("**No honest tuning/evaluation split:**") and "τ chosen on a tuning part" in tuned.note
    assert tuned.scored == "whole sequence, no split" and tuned.text == ""
    assert tuned.table.tau_rule.tolist() == ["paper: L + Δ, every frame (no honest split)"]
    assert tuned.curve.tune_f1.isna().all()


def test_paper_vs_run_rows_by_hand():
    per_seed = pd.DataFrame({"split": ["random", "random", "blocked", "blocked"], "seed": [0, 1, 0, 1],
                             "in_traversal_test_acc_%": [98.0, 100.0, 60.0, 70.0], "revisit_acc_%": [10.0, 30.0, 5.0, 5.0]})
    table = pd.DataFrame([{"seed": 0, "tau_rule": "chosen on the tuning part", "tau": 15, "precision": 0.5, "recall": 0.25},
                          {"seed": 0, "tau_rule": "paper: L + Δ", "tau": 70, "precision": 1.0, "recall": 0.125},
                          {"seed": 1, "tau_rule": "chosen on the tuning part", "tau": 10, "precision": 0.7, "recall": 0.75},
                          {"seed": 1, "tau_rule": "paper: L + Δ", "tau": 70, "precision": 0.0, "recall": 0.0}])
    tuned = rp.Tuned(table, pd.DataFrame(), 70, None, "scoring part", "")
    cmp = rp.paper_vs_run(per_seed, tuned, 60).set_index("quantity")["this run"]
    # random: mean 99, sample std sqrt(2) = 1.41, median 99
    assert cmp["test accuracy, random 80/20 split, L = 60 (%)"] == "99.00 ± 1.41 (median 99.00, 2 seeds)"
    assert cmp["revisit accuracy, blocked-split models (%)"] == "5.00 ± 0.00 (median 5.00, 2 seeds)"
    assert cmp["dictionary τ"] == "chosen on the tuning part: [10, 15]"
    assert cmp["dictionary precision / recall on the scoring part, chosen τ"] == "0.600 / 0.500 (mean of 2 seeds)"
    assert cmp["dictionary precision / recall on the scoring part, τ = 70"] == "0.500 / 0.062 (mean of 2 seeds)"
    no_split = rp.Tuned(table[table.tau_rule == "paper: L + Δ"], pd.DataFrame(), 70, "note", "whole sequence, no split", "")
    cmp = rp.paper_vs_run(per_seed, no_split, 60).set_index("quantity")["this run"]
    assert cmp["dictionary τ"] == rp.NOT_AVAILABLE and "dictionary precision / recall on the whole sequence, no split, τ = 70" in cmp
