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


CHECKS = {"01_spot_grouping": _check_01, "02_training_over_seeds": _check_02,
          "03_confusion_matrix": _check_03, "05_dictionary_threshold": _check_05, "06_speed": _check_06}
