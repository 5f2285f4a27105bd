"""`python -m greenloop.speed.bench --quick` end to end on the tiny sequence: it runs, writes its
files, and the backends it times give Keras's labels. Correctness only; the figures it prints are
not asserted (they depend on the machine and its load)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("keras")

from greenloop.speed import bench  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def test_bench_quick_writes_figures_and_backends_agree(tiny_sequence, tmp_path):
    out = tmp_path / "bench"
    env = dict(os.environ, PYTHONPATH=str(ROOT), GREENLOOP_CACHE=str(tmp_path / "models"))
    r = subprocess.run([sys.executable, "-m", "greenloop.speed.bench", "--quick", "--dataset", str(tiny_sequence),
                        "--out", str(out)], capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads((out / "bench.json").read_text())
    assert res["data"]["random_frames"] is False and res["data"]["n_frames"] == 200
    # every window pipeline, the floor and the single-frame paths were timed
    for k in ("reference", "gray_pass_floor", "numpy", "tflite", "tflite-int8"):
        assert res["windows"][k]["n"] > 0 and res["windows"][k]["median_ms"] > 0
    for k in ("reference", "numpy", "tflite"):
        assert res["single"][k]["p99_ms"] >= res["single"][k]["median_ms"] > 0
    for k in ("numpy", "tflite"):
        a = res["agreement"][k]
        assert a["frames"] == 200 and a["same_labels"] == 200
    assert res["training"]["plain"]["epoch_seconds"] and res["training"]["fast"]["epoch_seconds"]
    assert res["accuracy_200_epochs"] is None  # --quick skips the 200-epoch comparison
    table = (out / "bench.md").read_text()
    assert "floor: one cvtColor pass" in table and "labels equal to Keras (tflite)" in table


def test_same_distribution_tells_apart_what_differs():
    rng = np.random.default_rng(0)
    plain = 0.93 + 0.02 * rng.standard_normal(10)
    shifted = bench.same_distribution(plain, plain - 0.3)
    assert shifted["mann_whitney_p"] < 0.001 and shifted["mean_difference_points"] == pytest.approx(-30)
    same = bench.same_distribution(plain, 0.93 + 0.02 * rng.standard_normal(10))
    assert same["mann_whitney_p"] > 0.05
