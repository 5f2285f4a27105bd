"""Notebook 14's experiment (greenloop.experiments.loop_closing) on the tiny synthetic sequence: the
detectors' closures through the registry, true closures with GNC lowering the ATE below odometry
alone, injected false loops wrecking plain LM and not GNC, the per-traversal odometry, and the
draft notebook run by papermill on tiny parameters writing its tables."""
import json

import numpy as np
import pandas as pd
import pytest

from greenloop.datasets import sequence
from greenloop.experiments import loop_closing as lc
from greenloop.mapping import metrics
from greenloop.mapping import trajectory as tj
from greenloop.study import wording
from tests.test_notebooks import ROOT, TINY, _run

# the tiny sequence's detectors (notebook 13's tiny parameters, every frame described)
PARAMS = dict(seq_lens=TINY["seq_lens"], contrast_windows=TINY["contrast_windows"], velocities=[0.8, 1.0, 1.25],
              threshold_rule="f1", fps_frames=TINY["fps_frames"], weights=None, input_size=TINY["input_size"],
              frames_per_spot=TINY["frames_per_spot"], margin=10, seeds=[0], epochs=TINY["epochs"], batch_size=32,
              seq_descriptors=["pixels"], fast_descriptors=["pixels"])
SEEDS = [0, 1]


@pytest.fixture(scope="module")
def study(tiny_sequence):
    """(poses, detected, arm loops, true flags, labelled closures, runs) on the tiny sequence, the
    named default and SeqSLAM as the detectors (the dictionary runs in the notebook's test)."""
    poses = sequence.open(tiny_sequence).poses()[1]
    det = lc.run_detectors(tiny_sequence, PARAMS, 1, 0.5, TINY["exclude"], 0.5, ["greenloop-seq-grad", "seqslam"])
    closures = pd.concat([lc.ground_truth_closures(poses, det.data.frames, det.data.GT), det.closures])
    names = [lc.GROUND_TRUTH] + det.arms
    arm_loops, true, labelled = lc.arms(closures, poses, 0.5, names)
    return poses, det, arm_loops, true, labelled, lc.run_arms(poses, arm_loops, true, SEEDS)


def test_the_detectors_closures_come_through_the_registry_and_are_labelled_by_the_pose_rule(study):
    poses, det, arm_loops, true, labelled, _ = study
    assert det.arms == ["SeqSLAM (tuned)", "SeqSLAM (published)", "greenloop-seq-grad"]
    assert set(det.closures["arm"]) <= set(det.arms) and len(det.closures) > 0
    assert np.all(det.closures["query"] - det.closures["match"] > 20)             # outside the exclusion band
    gt = labelled[labelled.arm == lc.GROUND_TRUTH]
    assert gt["true"].all() and len(gt) == int(np.triu(det.data.GT, 1).any(0).sum())   # one per revisit query
    some = labelled.iloc[:5]
    err = [np.linalg.norm(tj.relative(poses[q], poses[m]) - np.eye(4)) for q, m in zip(some["query"], some["match"])]
    assert np.allclose(some["error"], err) and np.array_equal(some["true"], np.asarray(err) < 0.5)
    (loop,) = lc.loops(det.closures.iloc[:1], poses)                              # unverified: the identity
    assert np.array_equal(loop.T, np.eye(4)) and (loop.i, loop.j) == tuple(det.closures.iloc[0][["query", "match"]])
    assert np.allclose(arm_loops[lc.GROUND_TRUTH][0].T, tj.relative(poses[gt.iloc[0]["query"]], poses[gt.iloc[0]["match"]]))


def test_a_verified_closures_pose_becomes_its_loop_factor_in_the_graphs_convention(study):
    """verification's R, t are T_match^-1 T_query; the loop factor is T_query^-1 T_match; a row without
    a pose (too small to check) stays the identity."""
    poses = study[0]
    q, m = 150, 30
    T_mq = tj.relative(poses[m], poses[q])
    rows = pd.DataFrame([("x (verified)", q, m, 1.0, T_mq[:3, :3], T_mq[:3, 3], True, True),
                         ("x (verified)", q, m, 1.0, None, None, False, False)],
                        columns=["arm", "query", "match", "score", "R", "t", "metric", "verified"])
    posed, bare = lc.loops(rows, poses)
    assert np.allclose(posed.T, tj.relative(poses[q], poses[m])) and posed.metric
    assert np.array_equal(bare.T, np.eye(4))


def test_verification_keeps_a_subset_of_each_detectors_closures(study, tiny_sequence):
    """On the tiny sequence (160x120, below verification's 240 px) every closure the stage declares is
    one of the detector's and unverified (no pose); the arm is named '<detector> (verified)'."""
    det = study[1]
    grad = det.closures[det.closures.arm == "greenloop-seq-grad"]
    v = lc.verified(tiny_sequence, grad)
    assert set(v.arm) <= {"greenloop-seq-grad (verified)"}
    assert set(zip(v["query"], v["match"])) <= set(zip(grad["query"], grad["match"]))
    assert not v["verified"].any() and v["R"].isna().all()


def test_true_closures_with_gnc_lower_the_ate_below_odometry_alone(study):
    _, _, arm_loops, true, _, runs = study
    s = runs.per_seed.set_index(["arm", "back_end", "seed"])["ate_m"]
    for seed in SEEDS:
        odometry = s[lc.ODOMETRY, "none", seed]
        assert s[lc.GROUND_TRUTH, "gnc", seed] < 0.3 * odometry
        assert s["SeqSLAM (tuned)", "gnc", seed] < 0.5 * odometry                 # mostly true, identity factors
    table = lc.summary(runs.per_seed).set_index(["arm", "back_end"])
    assert table.loc[(lc.GROUND_TRUTH, "gnc"), "loop_factors"] == len(arm_loops[lc.GROUND_TRUTH])
    assert table.loc[(lc.ODOMETRY, "none"), "seeds"] == len(SEEDS)
    assert table.loc[("SeqSLAM (tuned)", "gnc"), "true_factors"] == true["SeqSLAM (tuned)"].sum()


def test_injected_false_loops_raise_plain_lms_ate_above_gncs(study):
    poses, _, arm_loops, true, _, _ = study
    name, loops = lc.curve_loops(arm_loops, true, "no such arm")
    assert name == lc.GROUND_TRUTH and len(loops) == int(np.sum(true[lc.GROUND_TRUTH]))
    curve = lc.robustness(poses, loops, [0], (0.0, 0.3), min_distance_m=3.0)
    c = curve.set_index(["fraction", "back_end"])
    assert c.loc[(0.3, "lm"), "ate_m"] > 5 * c.loc[(0.3, "gnc"), "ate_m"]
    assert c.loc[(0.3, "lm"), "ate_m"] > c.loc[(0.3, "lm"), "odometry_ate_m"]
    assert c.loc[(0.3, "gnc"), "ate_m"] == pytest.approx(c.loc[(0.0, "gnc"), "ate_m"], rel=1e-3)
    assert c.loc[(0.3, "gnc"), "false_kept"] == 0 and c.loc[(0.3, "lm"), "false_factors"] > 0
    table = lc.robustness_summary(curve).set_index(["fraction", "back_end"])
    assert table.loc[(0.3, "lm"), "seeds_above_odometry"] == 1 and table.loc[(0.3, "gnc"), "seeds_above_odometry"] == 0


def test_each_traversal_starts_at_its_true_pose_and_drifts_by_the_one_model():
    gt = tj.rectangle_route(6, 6, 0.2, laps=2)
    half = len(gt) // 2
    odo = lc.simulate(gt, 3, starts=(0, half))
    assert np.allclose(odo[0], gt[0]) and np.allclose(odo[half], gt[half])
    assert metrics.ate(gt[:half], odo[:half]) > 0.01
    assert np.array_equal(odo, lc.simulate(gt, 3, starts=(0, half))) and not np.allclose(odo, lc.simulate(gt, 4, (0, half)))
    assert np.allclose(lc.simulate(gt, 3, (0,), scale_error=0, slip=0, heading_bias=0, heading_noise=0), gt)
    first = tj.drift_poses(gt[:half], int(np.random.default_rng([3, 0]).integers(2**31)))
    assert np.allclose(odo[:half], first)


def test_the_draft_notebook_writes_its_tables_and_conclusion(tiny_sequence, tmp_path, monkeypatch):
    notebook = ROOT / "notebooks" / "drafts" / "14_loop_closing.ipynb"
    (tmp_path / "models").mkdir()
    params = dict(TINY, frame_step=1, odometry_seeds=[0, 1], seq_descriptors=["pixels"],
                  fast_descriptors=["pixels"], false_min_distance_m=3.0, verify=True)
    folder = _run(notebook, tiny_sequence, tmp_path, monkeypatch, params)
    table = pd.read_csv(folder / "ate_table.csv").set_index(["arm", "back_end"])
    odometry = table.loc[(lc.ODOMETRY, "none"), "ate_m_mean"]
    assert table.loc[(lc.GROUND_TRUTH, "gnc"), "ate_m_mean"] < 0.3 * odometry
    assert {"greenloop-seq-grad", "SeqSLAM (tuned)", "SeqSLAM (published)"} <= set(table.index.get_level_values(0))
    assert any(a.startswith("main paper") for a in table.index.get_level_values(0))    # the dictionary's arm
    assert len(pd.read_csv(folder / "per_seed.csv")) == 2 * len(table)            # every arm, every seed
    curve = pd.read_csv(folder / "robustness.csv")
    assert sorted(curve.fraction.unique()) == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    info = json.loads((folder / "summary.json").read_text())
    assert info["verify"] is True and info["curve_arm"] in info["arms"] and "greenloop-seq-grad (verified)" in info["arms"]
    text = lc.conclusion(folder)
    assert "Odometry alone" in text and "Unverified arms" in text and wording.num(odometry, 3) in text
    assert "The target (GNC with greenloop-seq-grad (verified)'s closures" in text
    assert (folder / "trajectories_gnc.png").is_file() and (folder / "robustness.png").is_file()
