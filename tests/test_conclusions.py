"""The conclusions notebooks 00-06 generate in their last cell, on planted tables: the wording follows the
numbers (an order only where the seed ranges separate it, "not resolved" where they overlap), and names
the dataset the results folder ran on."""
import json

import pandas as pd
import pytest

from greenloop.experiments import (confusion_matrix, dataset, dictionary_threshold, shift_robustness,
                                   speed_claim, spot_grouping, training_over_seeds)
from greenloop.study import wording


def _folder(tmp_path, stem, tables: dict, parameters=None, data="data/nordland"):
    """results/<stem>/ under tmp_path with a manifest naming ``data`` and the planted ``tables``
    ({file name: DataFrame (csv) or dict (json)}). Returns the notebook's folder."""
    out = tmp_path / "results" / stem
    out.mkdir(parents=True)
    (out / "manifest.json").write_text(json.dumps({"dataset": data, "parameters": parameters or {}}))
    for name, t in tables.items():
        if isinstance(t, pd.DataFrame):
            t.to_csv(out / name, index=False)
        else:
            (out / name).write_text(json.dumps(t))
    return out


def test_order_states_an_order_only_where_the_ranges_separate_it():
    five = {"a": (5, 90, 95), "b": (5, 80, 89), "c": (5, 70, 79)}
    assert wording.order(five) == "resolved: a > b > c (the ranges do not overlap)"
    assert wording.order({**five, "c": (5, 85, 88)}).startswith("resolved for the first only: a")
    assert wording.order({**five, "b": (5, 80, 91)}) == "not resolved: the ranges overlap"
    few = wording.order({**five, "b": (3, 80, 89)})          # apart, but 3 seeds in an arm
    assert few.startswith("not resolved") and "fewer than 5 seeds" in few
    assert wording.sign(0.5, 3, 5) == "above zero in every seed" and wording.sign(-3, -1, 5) == "below zero in every seed"
    assert wording.sign(0.5, 3, 3) == "above zero in each of 3 seeds, too few to resolve the sign, 5 needed"
    assert wording.sign(-0.2, 2, 5).startswith("sign not resolved")
    assert wording.span(10, 10) == "10" and wording.between(36, 36) == "36" and wording.count(1, "seed") == "1 seed"


def _table1(ranges, seeds=5, converged=5):
    """Table 1 with L = 50, 60, 70 and the given (min, max) accuracy per L (%)."""
    return pd.DataFrame([{"frames_per_spot": L, "spots": 1, "last_spot_frames": 1, "seeds": seeds,
                          "acc_mean_%": (lo + hi) / 2, "acc_std_%": 1.0, "acc_median_%": (lo + hi) / 2,
                          "acc_min_%": lo, "acc_max_%": hi, "final_train_acc_min_%": 99, "converged_seeds": converged,
                          "acc_median_converged_%": (lo + hi) / 2, "paper_acc_%": p, "paper_spots": 1}
                         for L, (lo, hi), p in zip((50, 60, 70), ranges, (97, 98, 97))])


def _controls(ranges):
    return pd.DataFrame([{"frames_per_spot": L, "control": "blocked", "seeds": 3, "converged_seeds": 3,
                          "n_train_median": 10, "acc_median_%": (lo + hi) / 2, "acc_min_%": lo, "acc_max_%": hi,
                          "acc_median_converged_%": (lo + hi) / 2} for L, (lo, hi) in zip((50, 60, 70), ranges)])


def test_spot_grouping_orders_L_only_when_the_seed_ranges_separate(tmp_path):
    apart = _table1([(80, 85), (97, 99), (86, 90)])
    c = _folder(tmp_path / "a", "01_spot_grouping", {"table1.csv": apart, "table1_controls.csv": _controls(
        [(10, 20), (15, 25), (30, 40)])}, {"control_epochs": 40})
    text = spot_grouping.conclusion(c)
    assert text.startswith("### Conclusion on Nordland") and "**holds**" in text
    assert "the order of L is resolved: L = 60 > L = 70 > L = 50" in text
    assert "blocked: L = 50 [10, 20], L = 60 [15, 25], L = 70 [30, 40] (not resolved: L = 70's range" in text
    overlap = _folder(tmp_path / "b", "01_spot_grouping", {"table1.csv": _table1([(80, 95), (90, 96), (85, 93)])})
    text = spot_grouping.conclusion(overlap)
    assert "the order of L is not resolved: the ranges overlap" in text and "L = 60 >" not in text
    budget = _folder(tmp_path / "c", "01_spot_grouping", {"table1.csv": _table1([(80, 95)] * 3, converged=1)})
    assert "measure the training budget" in spot_grouping.conclusion(budget)


def _per_seed(random, blocked):
    rows = [{"split": s, "seed": i, "n_train": 8, "n_test": 2, "test_acc_%": a, "epoch_to_98%": None,
             "min_val_acc_after_ep45_%": a - 1, "final_train_acc_%": 99, "converged": True, "train_seconds": 1}
            for s, accs in (("random", random), ("blocked", blocked)) for i, a in enumerate(accs)]
    return pd.DataFrame(rows)


def _leakage(lo, hi, seeds=5):
    return pd.DataFrame([{"control": "blocked", "gap": 5, "seeds": seeds, "memory_points_median": (lo + hi) / 2,
                          "memory_points_min": lo, "memory_points_max": hi}])


def test_training_over_seeds_words_the_splits_and_the_memory_by_their_spread(tmp_path):
    out = _folder(tmp_path / "a", "02_training_over_seeds", {
        "per_seed.csv": _per_seed([90, 91, 92, 93, 95], [40, 45, 50, 55, 60]), "leakage_summary.csv": _leakage(2, 9)},
        {"gap": 5, "sweep_epochs": 40})
    text = training_over_seeds.conclusion(out)
    assert "resolved: the random split > the blocked split" in text
    assert "No random-split seed reached 98 % validation accuracy" in text
    assert "5.5 points (median; per seed 2 to 9, above zero in every seed)" in text
    out = _folder(tmp_path / "b", "02_training_over_seeds", {
        "per_seed.csv": _per_seed([50, 60, 70, 80, 90], [40, 45, 50, 55, 65]), "leakage_summary.csv": _leakage(-1, 4)},
        {"gap": 5, "sweep_epochs": 40})
    text = training_over_seeds.conclusion(out)
    assert "their order is not resolved: the ranges overlap" in text and "split >" not in text
    assert "sign not resolved" in text
    out = _folder(tmp_path / "c", "02_training_over_seeds", {
        "per_seed.csv": _per_seed([90, 91, 92], [40, 45, 50]), "leakage_summary.csv": _leakage(2, 9, seeds=3)},
        {"gap": 5, "sweep_epochs": 40})
    text = training_over_seeds.conclusion(out)                 # apart, but 3 seeds: neither order nor sign resolved
    assert "their order is not resolved" in text and "above zero in each of 3 seeds, too few" in text


def _errors(shares, misclassified=10):
    return pd.DataFrame([{"split": "random", "seed": i, "test_frames": 100, "misclassified": misclassified,
                          "accuracy_%": 100 - misclassified, "errors_on_adjacent_spot": s * misclassified / 100,
                          "adjacent_share_%": s, "errors_on_same_place_other_time": 2} for i, s in enumerate(shares)])


@pytest.mark.parametrize("shares, words", [([60, 70, 80], "more than half in every seed"),
                                           ([10, 30, 40], "less than half in every seed"),
                                           ([40, 60, 70], "whether 'most' holds is not resolved")])
def test_confusion_matrix_weighs_the_adjacent_errors_against_most(tmp_path, shares, words):
    text = confusion_matrix.conclusion(_folder(tmp_path, "03_confusion_matrix", {"errors_per_seed.csv": _errors(shares)}))
    assert words in text and "20 % of them" in text             # 2 of 10 errors on a revisited place, every seed


def _table3(all_frames, test_only):
    return pd.DataFrame({"seed": range(len(all_frames)), "original_test_%": 90.0,
                         "shift1_all_frames_%": all_frames, "shift1_test_only_%": test_only})


def test_shift_robustness_says_whether_the_training_frames_lift_the_shifted_accuracy(tmp_path):
    lifted = shift_robustness.conclusion(_folder(tmp_path / "a", "04_shift_robustness",
                                                 {"table3.csv": _table3([80, 82, 84, 81, 83], [70, 71, 72, 71, 72])}))
    assert "by +10.8 points (per seed +10 to +12, above zero in every seed): the paper's protocol flatters" in lifted
    assert "the paper: 92 %" in lifted and "costs 18.8 points (per seed 18 to 20, above zero in every seed)" in lifted
    few = shift_robustness.conclusion(_folder(tmp_path / "c", "04_shift_robustness",
                                              {"table3.csv": _table3([80, 82, 84], [70, 71, 72])}))
    assert "above zero in each of 3 seeds, too few" in few and "flatters" not in few
    mixed = shift_robustness.conclusion(_folder(tmp_path / "b", "04_shift_robustness",
                                                {"table3.csv": _table3([70, 72, 69], [71, 70, 70])}))
    assert "sign not resolved" in mixed and "flatters" not in mixed


def _sweep(true_events):
    return pd.DataFrame([{"variant": dictionary_threshold.VARIANTS[0], "tau": t, "true_events": e, "false_events": 9 - i,
                          "true_frames": e, "false_frames": 1, "revisit_recall_%": 0, "first_delay_frames": None}
                         for i, (t, e) in enumerate(zip((60, 65, 70), true_events))])


def _scores(revisits):
    one = {"true_events": 1, "false_events": 2, "revisit_frames": revisits, "revisits_detected": revisits // 2}
    return {"derived": {"frames_per_spot": 60, "error_rate": 0.2, "margin": 10, "expected_correct": 48.0, "tau": 70},
            "scores": {v: one for v in dictionary_threshold.VARIANTS}}


def test_dictionary_threshold_reads_the_sweep_and_the_scores(tmp_path):
    text = dictionary_threshold.conclusion(_folder(tmp_path / "a", "05_dictionary_threshold",
                                                   {"summary.json": _scores(40), "tau_sweep.csv": _sweep([2, 2, 0])}))
    assert "ε = 0.2 gives (1 − ε)·L = 48" in text and "at most 2 true closure events (at τ = 60, 65)" in text
    assert "flag 50 % of the 40 revisit frames" in text and "number 9 at τ = 60 and 7 at τ = 70" in text
    text = dictionary_threshold.conclusion(_folder(tmp_path / "b", "05_dictionary_threshold",
                                                   {"summary.json": _scores(0), "tau_sweep.csv": _sweep([0, 0, 0])}))
    assert "never declare a true closure event" in text and "no closure can be true" in text


def test_dictionary_threshold_gives_the_spread_over_seeds_and_their_convergence(tmp_path):
    summary = pd.DataFrame([{"variant": v, "seeds": 5, "converged_seeds": c, "precision_median_%": p, "precision_min_%": p - 10,
                             "precision_max_%": p + 5, "recall_median_%": 20.0, "recall_min_%": 10.0, "recall_max_%": 30.0}
                            for v, c, p in zip(dictionary_threshold.VARIANTS, (2, 5), (60.0, 90.0))])
    out = _folder(tmp_path, "05_dictionary_threshold", {"summary.json": _scores(40), "tau_sweep.csv": _sweep([2, 2, 0]),
                                                        "seeds_summary.csv": summary})
    text = dictionary_threshold.conclusion(out)
    assert "closure precision 60 % [50, 65] of the flagged frames, recall 20 % [10, 30] of the revisit frames " \
           "(2 of 5 seeds converged, budget-limited)" in text
    assert "precision 90 % [80, 95]" in text and "(5 of 5 seeds converged)" in text and "one seed" not in text


def _speed(median_s, p95_s):
    return {"window_frames": 70, "median_window_s": median_s, "p95_window_s": p95_s, "frames_per_s": 70 / median_s,
            "median_ms_per_frame": 1e3 * median_s / 70, "p95_ms_per_frame": 1e3 * p95_s / 70, "repeats": 10,
            "cpu": "planted CPU"}


@pytest.mark.parametrize("median_s, p95_s, words", [(0.05, 0.07, "both lie above the paper's figure"),
                                                    (0.07, 0.09, "the paper's figure lies between them: not resolved"),
                                                    (0.09, 0.1, "both lie below the paper's figure")])
def test_speed_claim_places_920_frames_per_second_against_the_median_and_p95_window(tmp_path, median_s, p95_s, words):
    text = speed_claim.conclusion(_folder(tmp_path, "06_speed", {"summary.json": _speed(median_s, p95_s)}))
    assert words in text and "planted CPU" in text


def test_speed_claim_meets_a_speed_up_target_only_against_the_slow_windows(tmp_path):
    table = pd.DataFrame([{"pipeline": "reference: cv2", "window_frames_per_s": 1000, "single_median_ms": 40,
                           "single_p99_ms": 50, "window_speed-up": 1.0},
                          {"pipeline": "greenloop.methods.dictionary.stream (tflite)", "window_frames_per_s": 12000,
                           "single_median_ms": 0.2, "single_p99_ms": 0.5, "window_speed-up": 12.0}])
    windows = {"reference": {"median_ms": 60.0, "p99_ms": 70.0}, "tflite": {"median_ms": 5.0, "p99_ms": 8.0}}
    text = speed_claim.conclusion(_folder(tmp_path, "06_speed", {"summary.json": _speed(0.05, 0.06),
                                                                 "stream.csv": table, "stream.json": {"windows": windows}}))
    assert "12x at the medians, 7.5x against its p99 window (target 10x: not resolved" in text
    assert "(targets 0.3 and 1 ms: met)" in text


def test_dataset_says_what_the_sequence_holds(tmp_path):
    row = {"sequence": "x", "frames": 600, "ground_truth": "pairs", "path_m": None, "loop_pairs": 0,
           "revisit_frames": 0, "first_revisit_frame": None}
    cmp = pd.DataFrame({"quantity": ["frames", "spots of 50 frames"], "paper": [2260, ""], "this run": [600, 12]})
    text = dataset.conclusion(_folder(tmp_path, "00_dataset", {"dataset.csv": pd.DataFrame([row]),
                                                               "paper_vs_run.csv": cmp}, data="data/gardenspoint"))
    assert text.startswith("### Conclusion on Gardens Point")
    assert "The Gardens Point sequence holds 600 frames" in text and "12 spots of 50 frames." in text
    assert "leaves no loop pair outside the exclusion window" in text
