"""Shared fixtures: small sequence folders made on the fly (nothing downloaded)."""
import contextlib
import io
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "greenhouse"
# Hang guards, not time limits: far above what any test takes on the slowest, busiest machine, so no
# test's outcome depends on the machine's speed; they only end a test that would hang. A papermill
# kernel gets KERNEL_START_S to answer (papermill's default 60 s was missed on a loaded 2-core machine).
HANG_S = 3600
KERNEL_START_S = 600


@pytest.fixture(scope="session")
def real_trajectory():
    """The real GreenHouse trajectory from ../shared/greenhouse (skipped where absent)."""
    path = SHARED / "CameraTrajectory.txt"
    if not path.is_file():
        pytest.skip(f"real GreenHouse trajectory not found at {path}")
    return path


def run_cli(args, process: bool = False, timeout: int = HANG_S) -> subprocess.CompletedProcess:
    """``python -m greenloop ARGS`` -> a CompletedProcess with its exit status and what it printed.
    process: run it as a user types it, in a new interpreter (TensorFlow's logs quieted); otherwise
    in this process, with no interpreter start and no second TensorFlow import. The tests that check
    a command run it once as a process and their other calls in this one."""
    args = [str(a) for a in args]
    if process:
        env = dict(os.environ, PYTHONPATH=str(ROOT), TF_CPP_MIN_LOG_LEVEL="3")
        return subprocess.run([sys.executable, "-m", "greenloop", *args], capture_output=True, text=True, env=env,
                              timeout=timeout)
    from greenloop.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(args)
        except SystemExit as e:                 # argparse's usage errors and --help
            code = e.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def execute_notebook(src, out, **kw):
    """``papermill.execute_notebook(src, out, **kw)`` on the greenloop kernel, without a progress bar,
    with the hang guards (KERNEL_START_S for the kernel to answer, HANG_S per cell) unless kw says
    otherwise. Returns the executed notebook (nbformat)."""
    import papermill

    kw = {"kernel_name": "greenloop", "progress_bar": False, "start_timeout": KERNEL_START_S,
          "execution_timeout": HANG_S, **kw}
    return papermill.execute_notebook(str(src), str(out), **kw)


@pytest.fixture(scope="session")
def shared_cache(tmp_path_factory, request):
    """A model cache folder that every xdist worker of this session shares: util.cache's file locks
    make the first worker train a key and the others load it (a module fixture runs once per worker)."""
    base = tmp_path_factory.getbasetemp()
    worker = hasattr(request.config, "workerinput")       # an xdist worker: the session's folder is one up
    folder = (base.parent if worker else base) / "shared-models"
    folder.mkdir(exist_ok=True)
    return folder


def write_frames(folder: Path, n: int, size=(40, 30), ext=".png", seed=0) -> Path:
    """n colour frames of size (w, h) under folder/rgb, numbered 0..n-1."""
    rng = np.random.default_rng(seed)
    (folder / "rgb").mkdir(parents=True, exist_ok=True)
    for i in range(n):
        img = rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8)
        cv2.imwrite(str(folder / "rgb" / f"{i}{ext}"), img)
    return folder


def revisit_example():
    """40 frames, spots of 10; frames 30..39 revisit frames 0..9 (spot 0). Returns (pred, ref, gt):
    a loop-aware classifier's labels (the revisit is spot 0) with one error at frame 15."""
    n = 40
    ref = np.arange(n) // 10
    gt = np.zeros((n, n), bool)
    for k in range(10):
        gt[k, 30 + k] = gt[30 + k, k] = True
    pred = ref.copy()
    pred[30:] = 0
    pred[15] = 2
    return pred, ref, gt


@pytest.fixture(scope="session")
def tiny_sequence(tmp_path_factory):
    """A 200-frame, 160x120 synthetic greenhouse sequence (rgb, depth, trajectory, camera)."""
    from greenloop.datasets import synthetic
    folder = tmp_path_factory.mktemp("seq") / "tiny-greenhouse"
    return synthetic.make_greenhouse(folder, n_frames=200, size=(160, 120), seed=0, progress=False)


@pytest.fixture(scope="session")
def tiny_days_sequence(tmp_path_factory):
    """The greenhouse over two days on tiny parameters (``--tiny --days 2``: two aisles, 160x120 every
    0.25 m; day-00 sun, day-01 overcast, aisle 1 driven the other way on day-01): 178 frames."""
    from greenloop.datasets.synthetic import daysmake
    folder = tmp_path_factory.mktemp("seq") / "tiny-days"
    return daysmake.make_greenhouse_days(folder, n_days=2, tiny=True, workers=1, progress=False)


def pose_loops_as_pairs(poses, threshold=0.5, exclude=10) -> np.ndarray:
    """The Eq. 5 loops of some poses as ground_truth.csv rows (i, j, tolerance), i < j: each run
    of consecutive partners j of a frame i becomes one row (its centre, half its length), so the
    file exercises tolerances and reads back to exactly the pose ground truth."""
    from greenloop import groundtruth
    gt = np.triu(groundtruth.loop_matrix(poses, threshold, exclude), 1)
    rows = []
    for i in np.flatnonzero(gt.any(1)):
        js = np.flatnonzero(gt[i])
        for run in np.split(js, np.flatnonzero(np.diff(js) > 1) + 1):
            if len(run) % 2 == 0:                         # an even run: its first frame on its own
                rows.append((i, run[0], 0))
                run = run[1:]
            rows.append((i, run[len(run) // 2], len(run) // 2))
    return np.asarray(rows, dtype=np.int64).reshape(-1, 3)


@pytest.fixture(scope="session")
def tiny_pairs_sequence(tiny_sequence, tmp_path_factory):
    """tiny_sequence's 200 frames (160x120) with NO poses and NO depth: its ground truth only as
    loop pairs in ground_truth.csv (the pose loops, |i - j| > 10, with tolerances)."""
    import shutil

    from greenloop.datasets import sequence
    folder = tmp_path_factory.mktemp("seq") / "tiny-pairs"
    shutil.copytree(tiny_sequence / "rgb", folder / "rgb")
    _, poses = sequence.read_trajectory(tiny_sequence)
    sequence.write_loop_pairs(folder / sequence.GROUND_TRUTH_NAME, pose_loops_as_pairs(poses))
    return folder


@pytest.fixture(scope="session")
def tiny_end_loop_sequence(tiny_sequence, tmp_path_factory):
    """A user's sequence whose only revisit lies at its end: tiny_sequence's frames 0..179 as jpg
    (no poses, no depth), then frames 0..19 seen again, darker and shifted by 2 px, as frames
    180..199; ground_truth.csv pairs each with its first visit (tolerance 1)."""
    folder = tmp_path_factory.mktemp("seq") / "tiny-end-loop"
    (folder / "rgb").mkdir(parents=True)
    for i in range(200):
        img = cv2.imread(str(tiny_sequence / "rgb" / f"{i if i < 180 else i - 180}.png"))
        if i >= 180:
            img = np.roll((img * 0.8).astype(np.uint8), 2, axis=1)
        cv2.imwrite(str(folder / "rgb" / f"{i}.jpg"), img)
    from greenloop.datasets import sequence
    sequence.write_loop_pairs(folder / sequence.GROUND_TRUTH_NAME, [(180 + k, k, 1) for k in range(20)])
    return folder


@pytest.fixture(scope="session")
def tiny_near_loop_sequence(tiny_sequence, tmp_path_factory):
    """A user's two-traversal sequence whose revisits all lie inside the default 150-frame
    exclusion window, in the traversals layout (no poses, no depth): traversals/first/ holds
    tiny_sequence's frames 0..99 as jpg, traversals/second/ the same places again, darker and
    shifted by 2 px (stream frames 100..199); sequence.yaml says frame k of each is one place,
    tolerance 1 (closest loop 99 frames apart, farthest 101) and sets no exclude."""
    folder = tmp_path_factory.mktemp("seq") / "tiny-near-loop"
    for name in ("first", "second"):
        (folder / "traversals" / name).mkdir(parents=True)
    for i in range(200):
        img = cv2.imread(str(tiny_sequence / "rgb" / f"{i % 100}.png"))
        if i >= 100:
            img = np.roll((img * 0.8).astype(np.uint8), 2, axis=1)
        cv2.imwrite(str(folder / "traversals" / ("first", "second")[i // 100] / f"{i % 100}.jpg"), img)
    (folder / "sequence.yaml").write_text("traversals: [first, second]\nground_truth: aligned\ntolerance: 1\n")
    return folder
