"""What it takes to add a dataset, a descriptor and a detector (docs/ARCHITECTURE.md, "Where new
work goes"): a folder with its sequence.yaml; one module and one registry line; one module and one
registry line, each taken from the document as written. Then notebook 13's leaderboard rows all
three, and `python -m greenloop detect` streams the toy dataset through the toy detector and the
toy descriptor, closing exactly the loops their score matrices declare."""
import re
import sys
import types
from pathlib import Path

import cv2
import numpy as np
import yaml

from greenloop import features
from greenloop.cli import main
from greenloop.datasets import sequence
from greenloop.experiments import leaderboard as experiment
from greenloop.methods import registry
from greenloop.methods.greenloop_seq import seqmatch
from tests.test_detectors import _clear_threshold, _example, _walk_folder

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "ARCHITECTURE.md").read_text()


def _section(title: str) -> str:
    return DOC[DOC.index(f"## {title}"):].split("\n## ", 1)[0]


def _toy_dataset(folder: Path) -> Path:
    """The documented toy: 60 frames (40-59 revisit 0-19), ground_truth.csv and the yaml block."""
    _walk_folder(folder)
    (folder / "sequence.yaml").write_text(re.search(r"```yaml\n(.*?)```", _section("Adding a dataset"), re.S).group(1))
    return folder


def _toy_detector(monkeypatch):
    """The documented detector module, and its one line in ENTRIES (undone after the test)."""
    code, line = re.findall(r"```python\n(.*?)```", _section("Adding a detector"), re.S)[:2]
    module = types.ModuleType("greenloop.methods.toy.entry")
    exec(compile(code, "ARCHITECTURE.md", "exec"), module.__dict__)
    monkeypatch.setitem(sys.modules, module.__name__, module)
    entry = eval(line.strip().rstrip(","), {"toy": module})
    monkeypatch.setattr(registry, "ENTRIES", registry.ENTRIES + (entry,))
    monkeypatch.setitem(registry.REGISTRY, entry.name, entry)
    return entry


def _detect(argv, capsys) -> list[int]:
    assert main(argv) == 0
    return [int(line.split("\t")[0]) for line in capsys.readouterr().out.splitlines() if line[:1].isdigit()]


def test_a_toy_dataset_descriptor_and_detector_run_through_the_leaderboard_and_detect(tmp_path, monkeypatch, capsys):
    from greenloop.util import cache
    monkeypatch.setattr(cache, "CACHE_DIR", tmp_path / "models")
    folder = _toy_dataset(tmp_path / "toy")
    seq = sequence.open(folder)
    assert seq.exclude == 10 and seq.frame_step == 1 and seq.protocol.targets == "generic" and seq.n_frames == 60
    _example(monkeypatch)                                       # the descriptor: hue-histogram
    toy = _toy_detector(monkeypatch)
    for name in [n for n in registry.REGISTRY if n not in ("single-frame", "toy")]:   # keep the run to seconds
        monkeypatch.delitem(registry.REGISTRY, name)
    params = dict(seq_lens=[3], contrast_windows=[0], velocities=[1.0], threshold_rule="f1", fps_frames=5,
                  timing_repeats=3, cnn_backbones=[], random_control="pixels-patchnorm", vocab_size=16, whiten_dims=[4])
    data, split = experiment.prepare(folder, 1, 0.5, yaml.safe_load((folder / "sequence.yaml").read_text())["exclude"],
                                     0.5, None, params)
    tuned = experiment.tune(data)
    timed = experiment.stream_and_time(data, tuned, experiment.decide(data))
    board = experiment.board(data, split, tuned, timed).board.set_index("method")
    for row in ("toy", "hue-histogram (single frame)"):
        assert np.isfinite(board.loc[row, ["R@1_%", "AUC-PR_%", "R@100P_%"]].astype(float)).all(), row
        assert board.loc[row, "fps_min"] > 0
    assert timed.stream_check["toy"]["equal"]                        # checked=True: its stream is its matrix

    S = tuned.S["toy"]
    thr = _clear_threshold(S, data.exclude, 30)
    expected = seqmatch.matrix_events(S, thr, data.exclude, 60)
    assert expected and _detect(["detect", str(folder), "--method", "toy", "--threshold", repr(thr)], capsys) == expected
    S = tuned.S["hue-histogram (single frame)"]
    thr = _clear_threshold(S, data.exclude, 30)
    assert _detect(["detect", str(folder), "--method", "single-frame", "--descriptor", "hue-histogram",
                    "--threshold", repr(thr)], capsys) == seqmatch.matrix_events(S, thr, data.exclude, 60)
    assert toy.cli_knobs["seq_len"] == 3 and "hue-histogram" in features.names()
