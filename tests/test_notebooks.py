"""Every notebook, executed by papermill on tiny parameters, must run and write its results."""
import json
import os
from pathlib import Path

import pandas as pd
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
TINY = yaml.safe_load((ROOT / "params" / "tiny.yaml").read_text())


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    return tmp_path_factory.mktemp("results")


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_and_writes_results(notebook, tiny_sequence, results, tmp_path_factory, monkeypatch):
    import papermill

    monkeypatch.setenv("PYTHONPATH", str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    monkeypatch.setenv("GREENLOOP_CACHE", str(results / "models"))
    monkeypatch.setenv("TF_CPP_MIN_LOG_LEVEL", "2")
    out = results / notebook.name
    papermill.execute_notebook(str(notebook), str(out), kernel_name="greenloop", cwd=str(ROOT),
                               parameters=dict(TINY, dataset=str(tiny_sequence), results_dir=str(results)),
                               execution_timeout=600, progress_bar=False)
    folder = results / notebook.stem
    assert (folder / "manifest.json").is_file()
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["dataset"] == str(tiny_sequence)
    assert list(folder.glob("*.md")), "the notebook wrote no table"
    assert list(folder.glob("*.png")), "the notebook saved no figure"
    if (folder / "paper_vs_run.csv").is_file():
        table = pd.read_csv(folder / "paper_vs_run.csv")
        assert list(table.columns[:3]) == ["quantity", "paper", "this run"]
        assert table["this run"].notna().all()
    CHECKS.get(notebook.stem, lambda f: None)(folder)


def _check_01(folder):
    t = pd.read_csv(folder / "table1.csv")
    assert t.frames_per_spot.tolist() == TINY["frames_per_spot_list"]
    assert t.spots.tolist() == [-(-200 // L) for L in TINY["frames_per_spot_list"]]
    assert t["acc_mean_%"].between(0, 100).all()


def _check_02(folder):
    t = pd.read_csv(folder / "per_seed.csv")
    assert sorted(t.split.unique()) == ["blocked", "random"]
    assert len(t) == 2 * len(TINY["seeds"])


def _check_03(folder):
    t = pd.read_csv(folder / "table2.csv")
    assert len(t) == -(-200 // TINY["frames_per_spot"])
    e = pd.read_csv(folder / "errors_per_seed.csv")
    assert (e.test_frames == 40).all()


def _check_05(folder):
    s = json.loads((folder / "summary.json").read_text())
    assert s["derived"]["tau"] == TINY["frames_per_spot"] + 10
    t = pd.read_csv(folder / "tau_sweep.csv")
    assert sorted(t.tau.unique()) == TINY["tau_list"]


def _check_06(folder):
    s = json.loads((folder / "summary.json").read_text())
    assert s["repeats"] == TINY["repeats"] and s["frames_per_s"] > 0


def _feature_backbones():
    return list(TINY["backbones"])


def _check_07(folder):
    t = pd.read_csv(folder / "table2.csv")
    assert t.backbone.tolist() == _feature_backbones()          # one row per backbone, in order
    assert {"weights", "label"} <= set(t.columns)
    assert (t.label == t.backbone + " (" + t.weights + ")").all()
    assert t["AP_%"].between(0, 100).all() and t["R@100P_%"].between(0, 100).all()
    assert (t.extract_s_per_image > 0).all() and (t.match_s_MxM > 0).all()
    cnns = t[t.backbone.isin(["vgg19", "resnet50", "resnet101", "resnet152", "efficientnetb0", "ghostnet",
                              "mobilenetv3small"])]
    assert (cnns.weights == "random init").all()                 # tiny runs weights=None: never "imagenet"
    if "sift_bovw" in t.backbone.values:
        assert t.set_index("backbone").loc["sift_bovw", "R_a_%"] == 0
    ops = pd.read_csv(folder / "dictionary_operating_points.csv")
    assert ops.tau.tolist() == TINY["tau_list"]
    assert ops.recall.between(0, 1).all()


def _check_08(folder):
    t = pd.read_csv(folder / "postprocessing.csv")
    done = [b for b in _feature_backbones() if b != "spot_cnn"]
    assert sorted(t.backbone.unique()) == sorted(done)
    assert {"weights", "label"} <= set(t.columns)
    assert {"raw", "L2", "ZCA, tuned dim"} <= set(t.variant)
    assert t["AP_eval_%"].between(0, 100).all() and t["AP_tune_%"].between(0, 100).all()
    assert set(t["size"]) <= set(TINY["median_sizes"])
    tuning = pd.read_csv(folder / "tuning.csv")
    assert (tuning.knob == "pca dim").any() and tuning.knob.str.startswith("median size").any()
    m = json.loads((folder / "manifest.json").read_text())
    assert m["parameters"]["tune_frames"] > 0 and m["parameters"]["eval_frames"] > 0


def _check_09(folder):
    t = pd.read_csv(folder / "rgbd.csv")
    cnns = [b for b in _feature_backbones() if b not in ("sift_bovw", "pixels", "spot_cnn")]
    assert t.backbone.tolist() == cnns
    assert (t.weights == "random init").all()
    for c in ("AP_RGB_%", "AP_depth_%", "AP_RGB-D_%"):
        assert t[c].between(0, 100).all()
    d = pd.read_csv(folder / "paper_vs_run.csv")
    assert len(d) > 0


def _check_10(folder):
    sup = pd.read_csv(folder / "supervisions.csv")
    trained = sup[sup.train_pairs > 0]
    assert trained.supervision.tolist() == ["softmax", "contrastive", "multitask"]
    assert (trained.weights == "trained here").all() and (trained.label.str.endswith("(trained here)")).all()
    assert (trained.train_pairs == TINY["siamese_epochs"] * TINY["siamese_pairs"]).all()
    assert (trained.dim == 128).all() and (trained.train_s > 0).all()
    assert set(sup.weights) == {"trained here", "random init", "none"}      # + untrained and pixels rows
    assert sup["AP_%"].between(0, 100).all() and sup["R@100P_%"].between(0, 100).all()
    fus = pd.read_csv(folder / "fusions.csv")
    assert fus[fus.fusion == "mid"].layer.tolist() == TINY["mid_layers"]
    assert {"early", "late", "RGB only", "late (rgb stream)", "late (depth stream)"} <= set(fus.fusion)
    assert (fus.weights == "trained here").all() and fus["AP_%"].between(0, 100).all()
    t2 = pd.read_csv(folder / "table2_mid_level_layers.csv")
    assert t2.quantity.str.endswith(tuple(TINY["mid_layers"])).all() and len(t2) == len(TINY["mid_layers"])
    assert pd.to_numeric(t2["this run"]).between(0, 1).all() and t2.paper.notna().all()
    t = pd.read_csv(folder / "timing.csv")
    assert (t.s_per_image_batched > 0).all() and (t.s_per_image_one_at_a_time > 0).all()
    s = json.loads((folder / "summary.json").read_text())
    assert s["labelled_frames_near_heldout"] == 0 and s["last_train_frame"] < s["first_heldout_frame"]
    assert s["networks_trained"] == 3 + 2 + len(TINY["mid_layers"])


CHECKS = {"01_spot_grouping": _check_01, "02_training_over_seeds": _check_02,
          "03_confusion_matrix": _check_03, "05_dictionary_threshold": _check_05, "06_speed": _check_06,
          "07_feature_baselines": _check_07, "08_descriptor_postprocessing": _check_08,
          "09_rgbd_features": _check_09, "10_siamese_rgbd": _check_10}


def test_10_siamese_rgbd_without_depth(tiny_sequence, tmp_path, monkeypatch):
    """On a folder without depth/ notebook 10 says it skips the fusions, and still writes its tables,
    figures and manifest."""
    import shutil

    import papermill

    seq = tmp_path / "no-depth"
    shutil.copytree(tiny_sequence, seq, ignore=shutil.ignore_patterns("depth"))
    monkeypatch.setenv("PYTHONPATH", str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    monkeypatch.setenv("GREENLOOP_CACHE", str(tmp_path / "models"))
    monkeypatch.setenv("TF_CPP_MIN_LOG_LEVEL", "2")
    out = tmp_path / "10.ipynb"
    papermill.execute_notebook(str(ROOT / "notebooks" / "10_siamese_rgbd.ipynb"), str(out), kernel_name="greenloop",
                               cwd=str(ROOT), parameters=dict(TINY, dataset=str(seq), results_dir=str(tmp_path),
                                                              supervisions=["multitask"]),
                               execution_timeout=600, progress_bar=False)
    folder = tmp_path / "10_siamese_rgbd"
    text = out.read_text()
    assert "has no depth/ folder: the RGB-D fusion section is SKIPPED" in text
    assert json.loads((folder / "manifest.json").read_text())["parameters"]["has_depth"] is False
    assert (folder / "figure8_supervisions.png").is_file() and (folder / "figure9_skipped.png").is_file()
    assert pd.read_csv(folder / "fusions.csv").status.str.startswith("skipped").all()
    assert (pd.read_csv(folder / "table2_mid_level_layers.csv")["this run"] == "skipped").all()
    sup = pd.read_csv(folder / "supervisions.csv")
    assert sup[sup.train_pairs > 0].supervision.tolist() == ["multitask"] and sup["AP_%"].between(0, 100).all()
    assert json.loads((folder / "summary.json").read_text())["networks_trained"] == 1
