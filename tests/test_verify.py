"""make verify (greenloop.study.verify): a rerun's tables against the committed ones, cell by cell,
timing aside, trained models' numbers within the committed seed spread."""
import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from greenloop.cli import main as cli_main
from greenloop.study import verify

ROOT = Path(__file__).resolve().parents[1]


def tree(folder: Path) -> Path:
    """A tiny results folder: a deterministic table with a timing column, a long table with a timing
    row, a per-seed table and its summary with mean/std/min/max."""
    nb = folder / "01_x"
    nb.mkdir(parents=True)
    pd.DataFrame({"backbone": ["pixels", "vgg19", "sift"], "AP_%": [40.12, 39.0, 70.7], "dim": [1024, 512, 500],
                  "extract_s_per_image": [0.001, 0.03, 0.025]}).to_csv(nb / "table2.csv", index=False)
    pd.DataFrame({"quantity": ["spots", "frames per second"], "paper": [38, 920], "this run": ["38", "2228"],
                  "note": ["", "this run: AMD EPYC (2 cores)"]}).to_csv(nb / "paper_vs_run.csv", index=False)
    nb = folder / "02_y"
    nb.mkdir()
    pd.DataFrame({"split": ["random"] * 3 + ["blocked"] * 3, "seed": [0, 1, 2] * 2, "n_test": [226] * 6,
                  "test_acc_%": [90.0, 93.5, 96.0, 40.0, 50.0, 55.0]}).to_csv(nb / "per_seed.csv", index=False)
    pd.DataFrame({"split": ["random", "blocked"], "seeds": [3, 3], "acc_mean_%": [93.17, 48.33],
                  "acc_std_%": [3.01, 7.64], "acc_min_%": [90.0, 40.0], "acc_max_%": [96.0, 55.0]}
                 ).to_csv(nb / "summary.csv", index=False)
    return folder


def plant(folder: Path, table: str, row: int, column: str, value) -> None:
    df = pd.read_csv(folder / table, dtype=str, keep_default_na=False)
    df.loc[row, column] = str(value)
    df.to_csv(folder / table, index=False)


@pytest.fixture
def ref_rerun(tmp_path):
    ref = tree(tmp_path / "ref")
    return ref, Path(shutil.copytree(ref, tmp_path / "rerun"))


def test_an_identical_copy_reproduces_and_names_the_skipped_timing(ref_rerun, capsys):
    ref, rerun = ref_rerun
    assert cli_main(["verify", str(ref), str(rerun)]) == 0
    out = capsys.readouterr().out
    assert "01_x/table2.csv: reproduced" in out and "timing columns skipped: extract_s_per_image" in out
    assert "timing rows skipped: 'frames per second'" in out and "4 reproduced" in out


def test_a_difference_in_a_plain_cell_fails_and_names_the_cell(ref_rerun, capsys):
    ref, rerun = ref_rerun
    plant(rerun, "01_x/table2.csv", 1, "AP_%", 39.01)
    assert cli_main(["verify", str(ref), str(rerun)]) == 1
    out = capsys.readouterr().out
    assert "01_x/table2.csv: differs" in out
    assert "row 2 (backbone='vgg19') AP_%: reference '39.0', rerun '39.01'" in out and "NOT REPRODUCED" in out


def test_integers_and_text_are_exact_floats_within_the_tolerance(ref_rerun):
    ref, rerun = ref_rerun
    plant(rerun, "01_x/table2.csv", 0, "AP_%", 40.12 * (1 + 1e-9))         # float noise: equal
    assert verify.compare_tables(ref / "01_x/table2.csv", rerun / "01_x/table2.csv").status == "reproduced"
    plant(rerun, "01_x/table2.csv", 0, "dim", 1025)
    res = verify.compare_tables(ref / "01_x/table2.csv", rerun / "01_x/table2.csv")
    assert res.status == "differs" and "dim" in res.differences[0]
    plant(rerun, "01_x/paper_vs_run.csv", 0, "note", "changed")
    assert verify.compare_tables(ref / "01_x/paper_vs_run.csv", rerun / "01_x/paper_vs_run.csv").status == "differs"


def test_a_difference_in_timing_is_ignored(ref_rerun, capsys):
    ref, rerun = ref_rerun
    plant(rerun, "01_x/table2.csv", 1, "extract_s_per_image", 0.5)
    plant(rerun, "01_x/paper_vs_run.csv", 1, "this run", "1900")           # the frames-per-second row
    plant(rerun, "01_x/paper_vs_run.csv", 1, "note", "this run: Intel Xeon (2 cores)")
    assert cli_main(["verify", str(ref), str(rerun)]) == 0
    assert "differs" not in capsys.readouterr().out


def test_a_missing_table_fails_and_a_new_one_does_not(ref_rerun, capsys):
    ref, rerun = ref_rerun
    (rerun / "02_y" / "extra.csv").write_text("a\n1\n")
    assert cli_main(["verify", str(ref), str(rerun)]) == 0
    assert "02_y/extra.csv: new" in capsys.readouterr().out
    (rerun / "02_y" / "summary.csv").unlink()
    assert cli_main(["verify", str(ref), str(rerun)]) == 1
    assert "02_y/summary.csv: missing" in capsys.readouterr().out


def test_a_retrained_seed_may_move_inside_the_committed_spread_not_outside(ref_rerun, capsys):
    ref, rerun = ref_rerun
    plant(rerun, "02_y/per_seed.csv", 0, "test_acc_%", 95.0)      # random split's seeds span 90..96
    plant(rerun, "02_y/summary.csv", 0, "acc_mean_%", 94.0)       # inside [min, max] 90..96
    plant(rerun, "02_y/summary.csv", 0, "acc_std_%", 2.0)         # inside one std of 3.01
    assert cli_main(["verify", str(ref), str(rerun)]) == 0
    assert "02_y/per_seed.csv: reproduced\n    1 cells within the committed seed spread" in capsys.readouterr().out

    plant(rerun, "02_y/per_seed.csv", 3, "test_acc_%", 60.0)      # blocked split's seeds span 40..55
    plant(rerun, "02_y/summary.csv", 1, "acc_max_%", 60.0)
    assert cli_main(["verify", str(ref), str(rerun)]) == 1
    out = capsys.readouterr().out
    assert ("row 4 (split='blocked') test_acc_%: reference '40.0', rerun '60.0' (outside the committed range "
            "over 3 seeds 40..55)") in out
    assert "row 2 (split='blocked') acc_max_%: reference '55.0', rerun '60.0' (outside the committed band 40..55)" in out
    plant(rerun, "02_y/per_seed.csv", 3, "test_acc_%", 95.0)      # inside the other split's spread only
    assert verify.compare_tables(ref / "02_y/per_seed.csv", rerun / "02_y/per_seed.csv").status == "differs"
    plant(rerun, "02_y/per_seed.csv", 3, "n_test", 225)           # constant over seeds: exact
    res = verify.compare_tables(ref / "02_y/per_seed.csv", rerun / "02_y/per_seed.csv")
    assert any("n_test" in d for d in res.differences)


def test_the_spread_rule_on_committed_tables(tmp_path):
    """The committed 02 tables: a seed moved inside the random split's spread reproduces, a worst
    seed below it does not; 13's frame rates and the cpu column are timing."""
    src = ROOT / "results"
    for t in ("02_training_over_seeds/per_seed.csv", "02_training_over_seeds/seed_summary.csv",
              "13_leaderboard/timing.csv"):
        for side in ("ref", "rerun"):
            (tmp_path / side / t).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(src / t, tmp_path / side / t)
    ref, rerun = tmp_path / "ref", tmp_path / "rerun"
    per_seed = pd.read_csv(ref / "02_training_over_seeds/per_seed.csv")
    rand = per_seed[per_seed.split == "random"]["test_acc_%"]
    i = int(rand.idxmax())
    plant(rerun, "02_training_over_seeds/per_seed.csv", i, "test_acc_%", round((rand.min() + rand.max()) / 2, 2))
    plant(rerun, "13_leaderboard/timing.csv", 0, "fps_median", 1.0)
    plant(rerun, "13_leaderboard/timing.csv", 0, "cpu", "another CPU")
    results = {r.table: r for r in verify.compare_folders(ref, rerun)}
    assert all(r.status == "reproduced" for r in results.values()), [r.line() for r in results.values()]
    assert {"fps_median", "cpu", "decode_ms"} <= set(results["13_leaderboard/timing.csv"].skipped_columns)
    plant(rerun, "02_training_over_seeds/seed_summary.csv", 1, "worst", rand.min() - 1)
    res = verify.compare_tables(ref / "02_training_over_seeds/seed_summary.csv",
                                rerun / "02_training_over_seeds/seed_summary.csv")
    assert res.status == "differs" and "worst" in res.differences[0] and "outside the committed band" in res.differences[0]


@pytest.mark.parametrize("name, timing", [
    ("train_s", True), ("decode_ms", True), ("window_frames_per_s", True), ("fps_median", True),
    ("insert_us", True), ("window_speed-up", True), ("R_t_%", True), ("loss_per_1%_time", True), ("cpu", True),
    ("extraction time per image, vgg19 (s)", True), ("frames/s (slowest repeat)", True), ("loaded_from_cache", True),
    ("frames per second", True), ("seconds per 70-frame window", True), ("train_seconds", True),
    ("AP_%", False), ("R_a_%", False), ("frames_timed", False), ("frames of sequence", False),
    ("frame step of the rows (1 = Nordland's full rate)", False), ("errors_on_same_place_other_time", False),
    ("share of errors naming the same place at another time (%)", False), ("seeds", False),
    ("first -> second -> last third of the epochs", False), ("bytes_per_frame", False)])
def test_the_timing_rule(name, timing):
    assert verify.is_timing(name) is timing


def test_the_reference_is_the_committed_folder_of_the_reruns_dataset(tmp_path, capsys):
    ref = tree(tmp_path / "results")
    (tmp_path / "results" / "01_x" / "manifest.json").write_text(json.dumps({"dataset": "data/synthetic-greenhouse"}))
    nordland = tree(tmp_path / "results" / "nordland")
    (nordland / "01_x" / "manifest.json").write_text(json.dumps({"dataset": "data/nordland"}))
    rerun = Path(shutil.copytree(nordland, tmp_path / "rerun"))
    (rerun / "01_x" / "manifest.json").write_text(json.dumps({"dataset": "/abs/data/nordland/"}))
    assert verify.resolve_reference(ref, rerun) == nordland
    assert verify.resolve_reference(nordland, rerun) == nordland
    (rerun / "01_x" / "manifest.json").write_text(json.dumps({"dataset": "data/my-run"}))
    assert cli_main(["verify", str(ref), str(rerun)]) == 2 and "my-run" in capsys.readouterr().err
