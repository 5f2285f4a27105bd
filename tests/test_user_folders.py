"""Recordings nobody working on greenloop made (tests/user_folders.py: cut from Gardens Point,
Nordland and the synthetic generator; short, loop pairs only, GPS only, no revisit), met as a new
user meets them: what make would pass each notebook, which notebooks it would skip and why, and
`detect` with no flags. (`make quick` itself on such folders: the closing notes.)"""
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from greenloop import evaluate, exclusion, groundtruth
from greenloop.study import params
from greenloop.cli import main as cli_main
from tests import user_folders

from conftest import run_cli

ROOT = Path(__file__).resolve().parents[1]
QUICK = ROOT / "params" / "quick.yaml"


def _make_params(folder, stem, results):
    """What make's rule does before one notebook under `make quick`: (the YAML papermill gets or
    None, the skip reason or None, what it printed)."""
    nb = ROOT / "notebooks" / f"{stem}.ipynb"
    out, run = results / f".tmp-{stem}.ipynb", results / f".tmp-{stem}.yaml"
    rc = cli_main(["notebook-params", str(nb), str(folder), str(results), "--out", str(out), "--params-out", str(run),
                      "--", "-f", str(QUICK)])
    assert rc == 0
    skipped = (results / stem / "skipped.md").read_text() if out.exists() else None
    return (yaml.safe_load(run.read_text()) if run.exists() else None), skipped


def _detect(folder, *flags):
    r = run_cli(["detect", folder, *flags], process=True)
    assert r.returncode == 0, r.stderr
    return r


@pytest.fixture(scope="module")
def gardenspoint_short(tmp_path_factory):
    try:
        return user_folders.gardenspoint_pairs(tmp_path_factory.mktemp("u") / "gp", n=60)
    except FileNotFoundError as e:
        pytest.skip(str(e))


def test_a_short_recording_driven_twice_runs_every_notebook(gardenspoint_short, tmp_path):
    """120 frames (Gardens Point day then night, 60 places), loop pairs only: the exclusion leaves
    the revisits 58..62 frames apart (the paper's 150 would hide them all), quick's step 8 is
    refined for 07 (60 = 4 mod 8), and 13 runs (it picks its own step)."""
    e = exclusion.exclusion(gardenspoint_short)
    assert e.frames == 29 and e.source == "ground truth"
    run07, skip07 = _make_params(gardenspoint_short, "07_feature_baselines", tmp_path)
    assert skip07 is None and run07["exclude"] == 29 and run07["frame_step"] in (1, 2, 3, 4, 5, 6)
    run13, skip13 = _make_params(gardenspoint_short, "13_leaderboard", tmp_path)
    assert skip13 is None and run13["frame_step"] == 8 and run13["exclude"] == 29
    r = _detect(gardenspoint_short)
    assert "# exclude 29 (ground truth)" in r.stdout and "warning" not in r.stderr


def test_nordland_cut_and_a_gps_only_survey(tmp_path, tiny_sequence):
    try:
        nl = user_folders.nordland_short(tmp_path / "nl", n=40)
    except FileNotFoundError as e:
        pytest.skip(str(e))
    assert exclusion.exclusion(nl).frames == 19
    assert _make_params(nl, "08_descriptor_postprocessing", tmp_path / "r1")[1] is None
    gps = user_folders.synthetic_gps(tmp_path / "gps", tiny_sequence)
    e = exclusion.exclusion(gps)
    assert e.source == "ground truth" and e.frames < exclusion.DEFAULT_EXCLUDE
    assert "the camera leaves a place within" in e.rule
    run, skipped = _make_params(gps, "11_lsh_matching", tmp_path / "r2")
    assert skipped is None and run["exclude"] == e.frames


def test_a_drive_that_never_comes_back(tmp_path, tiny_sequence):
    """No ground truth: the notebooks that score loops are skipped with the reason in skipped.md
    and the manifest; `detect` runs with the fraction rule and declares nothing."""
    f = user_folders.no_revisit(tmp_path / "once", tiny_sequence, n=100)
    run, skipped = _make_params(f, "07_feature_baselines", tmp_path / "r")
    assert run is None and "has no ground truth" in skipped
    manifest = json.loads((tmp_path / "r" / "07_feature_baselines" / "manifest.json").read_text())
    assert manifest["skipped"].startswith("07_feature_baselines scores loop closures")
    assert _make_params(f, "04_shift_robustness", tmp_path / "r")[1] is None           # scores no loops: runs
    run05, skipped05 = _make_params(f, "05_dictionary_threshold", tmp_path / "r")      # counts closure events
    assert run05 is None and "has no ground truth" in skipped05
    r = _detect(f)
    assert "# exclude 20 (fraction)" in r.stdout and "summary: 100 frames, 0 closures" in r.stdout


def _closures(folder, *flags):
    """`detect` with no flags (or ``flags``) on a folder with ground truth: (revisit frames, closures
    declared, closures whose match is a ground-truth partner), revisit frames as the stream sees them (a
    partner among the candidates, exclusion.exclusion's band)."""
    e = exclusion.exclusion(folder).frames
    G = groundtruth.for_sequence(folder, exclude=e)
    rows = [line.split("\t") for line in _detect(folder, *flags).stdout.splitlines() if line[:1].isdigit()]
    return int(evaluate.revisit_queries(G, e).sum()), len(rows), sum(bool(G[int(r[1]), int(r[0])]) for r in rows)


@pytest.mark.parametrize("n, start", [(40, 300), (80, 1000)])
def test_a_short_nordland_cut_closes_half_its_revisit(tmp_path, n, start):
    """A threshold that carries to short recordings: the named default on a Nordland cut (n summer frames, the same n in winter; 80 and
    160 frames) finds at least half of the revisit frames, >= 90 % of its closures correct. Calibrated
    against every candidate ("zscore", 2.8) it found 3 of 42 and 40 of 82: the matched place's own
    rows inflated the std of so few candidates."""
    try:
        f = user_folders.nordland_short(tmp_path / "nl", n=n, start=start)
    except FileNotFoundError as e:
        pytest.skip(str(e))
    revisits, declared, correct = _closures(f)
    assert correct >= revisits / 2 and correct >= 0.9 * declared, (revisits, declared, correct)


def test_a_short_gardens_point_cut_fires_and_is_right(gardenspoint_short):
    """Gardens Point day then night (60 + 60 frames): the named default's appearance matches
    (--no-verify) are closures and every one is right; it does not reach half the revisit frames (the
    night matches stand lower over the null than the synthetic sequence's aliased places, which one
    threshold must also keep out: tools/calib_measure.py). Verified (the default), the night pairs do not
    hold by geometry (results/verification/summary.md: 1 % of night loop pairs accepted), so it declares
    nothing false and nothing at all: the recall the verification issue still has to win back."""
    revisits, declared, correct = _closures(gardenspoint_short, "--no-verify")
    assert revisits == 62 and declared >= 6 and correct == declared, (revisits, declared, correct)
    revisits, declared, correct = _closures(gardenspoint_short)
    assert correct == declared <= 2, (revisits, declared, correct)


def test_a_gps_only_survey_with_early_revisits_skips_or_runs_notebook_12(tmp_path, shared_cache, monkeypatch):
    """A drone survey flown twice with a gps.csv only (156 frames, neighbouring strips within the GPS
    radius: revisits 1..155 frames apart) revisits its start at frame 16: the first traversal holds one
    spot of quick's L = 60 frames, and the CNN of one class stopped make in notebook 12 with
    `n_classes must be >= 2`. make skips it with the reason and the fix; so it does where L = 8 makes 2
    spots but the blocked split's gap of 5 frames leaves no training frame; with L = 8 and gap 1 it runs."""
    from test_notebooks import _params, _run

    f = user_folders.gps_survey(tmp_path / "survey")
    e = exclusion.exclusion(f)
    assert params.loop_distances(f) == (1, 155) and e.frames == 7
    run, skipped = _make_params(f, "12_revisit_protocol", tmp_path / "r")
    assert run is None and "frames 0..15" in skipped and "holds 1 spot of frames_per_spot=60" in skipped
    assert "frames_per_spot <= 8" in skipped
    for other in ("00_dataset", "01_spot_grouping", "02_training_over_seeds", "03_confusion_matrix",
                  "04_shift_robustness", "05_dictionary_threshold", "13_leaderboard"):   # their spots: every frame's
        assert _make_params(f, other, tmp_path / "r")[1] is None, other
    nb = ROOT / "notebooks" / "12_revisit_protocol.ipynb"
    reason = params.skip_reason(nb, f, dict(params.notebook_defaults(nb), frames_per_spot=8, exclude=e.frames))
    assert "the blocked split leaves no training frame" in reason and "gap of 5" in reason
    assert params.skip_reason(nb, f, dict(params.notebook_defaults(nb), frames_per_spot=8, gap=1, exclude=e.frames)) is None
    results = tmp_path / "nb"
    results.mkdir()
    (results / "models").symlink_to(shared_cache, target_is_directory=True)
    folder = _run(nb, f, results, monkeypatch, dict(_params(nb.stem), frames_per_spot=8, gap=1, exclude=e.frames))
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["first_traversal_end"] == 16 and summary["spots"] == 2 and summary["revisit_frames"] > 0
