"""datasets.sequence.open: one Sequence per folder, read once; what it holds; its protocol (sequence.yaml's
``protocol``) deciding the detector's target set and target streams."""
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import write_frames
from greenloop import exclusion, groundtruth
from greenloop.datasets import description, sequence
from greenloop.experiments import leaderboard as ex
from greenloop.methods.interface import Data
from greenloop.study import params as study_params, targets


def _poses(n: int) -> np.ndarray:
    """n camera-to-world poses along x, 1 m apart, then back: frame n - 1 - k at frame k's place."""
    x = np.r_[np.arange(n // 2), np.arange(n - n // 2)[::-1]].astype(float)
    P = np.tile(np.eye(4), (n, 1, 1))
    P[:, 0, 3] = x
    return P


@pytest.fixture
def rgbd(tmp_path):
    """12 frames of 40x30 with depth, poses, a camera file and a sequence.yaml of two traversals."""
    f = write_frames(tmp_path / "rec", 12, size=(40, 30))
    (f / "depth").mkdir()
    for i in range(12):
        cv2.imwrite(str(f / "depth" / f"{i}.png"), np.full((30, 40), 5000 * (i + 1), np.uint16))
    sequence.write_trajectory(f / "CameraTrajectory.txt", np.arange(12), _poses(12))
    (f / "camera.yaml").write_text("Camera.fx: 50.0\nCamera.fy: 51.0\nCamera.cx: 20.0\nCamera.cy: 15.0\n"
                                   "Camera.width: 40\nCamera.height: 30\n")
    (f / "sequence.yaml").write_text("exclude: 3\nframe_step: 2\ntolerance: 1\ntraversals: {out: [0, 6], back: [6, 12]}\n")
    return f


def _walks(root: Path, names=("first", "second", "third"), n: int = 6, text: str = "") -> Path:
    """A traversals/ folder: len(names) walks of n frames (frame k of each one place), aligned ground truth."""
    rng = np.random.default_rng(0)
    places = rng.integers(0, 256, (n, 24, 32, 3), dtype=np.uint8)
    for t, name in enumerate(names):
        (root / "traversals" / name).mkdir(parents=True)
        for k in range(n):
            cv2.imwrite(str(root / "traversals" / name / f"{k}.png"), (places[k] * (1 - 0.2 * t)).astype(np.uint8))
    (root / "sequence.yaml").write_text(f"traversals: [{', '.join(names)}]\nground_truth: aligned\ntolerance: 1\n" + text)
    return root


# ------------------------------------------------------------------------------ read once
def test_open_reads_each_part_once_and_returns_the_same_object(rgbd, monkeypatch):
    calls = {"images": 0, "description": 0, "trajectory": 0}
    images, read, traj = sequence._images, description.read, sequence._read_trajectory_file

    def count(name, fn):
        def wrapped(*a, **k):
            calls[name] += 1
            return fn(*a, **k)
        return wrapped
    monkeypatch.setattr(sequence, "_images", count("images", images))
    monkeypatch.setattr(description, "read", count("description", read))
    monkeypatch.setattr(sequence, "_read_trajectory_file", count("trajectory", traj))
    seq = sequence.open(rgbd)
    assert sequence.open(rgbd) is seq and sequence.open(str(rgbd)) is seq and sequence.open(seq) is seq
    for _ in range(3):                      # every stage's reads go through the one object
        sequence.list_frames(rgbd), sequence.traversals(rgbd), sequence.read_description(rgbd)
        sequence.folder_info(rgbd), sequence.layout(rgbd), sequence.ground_truth_source(rgbd)
        groundtruth.for_sequence(rgbd, exclude=2), exclusion.exclusion(rgbd), study_params.sequence_parameters(rgbd)
    assert calls == {"images": 1, "description": 1, "trajectory": 1}


def test_an_edited_folder_is_read_again(rgbd):
    seq = sequence.open(rgbd)
    assert seq.frame_step == 2 and seq.n_frames == 12
    (rgbd / "sequence.yaml").write_text((rgbd / "sequence.yaml").read_text().replace("frame_step: 2", "frame_step: 3"))
    again = sequence.open(rgbd)                     # the same size, written at once: the text differs
    assert again is not seq and again.frame_step == 3 and seq.frame_step == 2
    write_frames(rgbd, 13, size=(40, 30))          # frame 12 added
    assert sequence.open(rgbd).n_frames == 13 and sequence.open(rgbd) is sequence.open(rgbd)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        sequence.open(rgbd / "missing")
    other = sequence.open(f"{rgbd}/")              # another spelling: its own object, named as given
    assert str(other) == f"{rgbd}/" and other.path == rgbd and other.n_frames == 13


def test_an_edited_ground_truth_file_is_read_again(tmp_path):
    f = write_frames(tmp_path / "pairs", 40, size=(8, 6))
    sequence.write_loop_pairs(f / "ground_truth.csv", [(0, 30, 0)])
    assert sequence.open(f).loop_pairs().tolist() == [[0, 30, 0]]
    sequence.write_loop_pairs(f / "ground_truth.csv", [(0, 31, 0), (1, 32, 0)])
    assert sequence.open(f).loop_pairs().tolist() == [[0, 31, 0], [1, 32, 0]]
    assert groundtruth.for_sequence(f, exclude=5)[1, 32]


# ------------------------------------------------------------------------------ what it holds
def test_every_attribute_of_a_small_folder(rgbd):
    seq = sequence.open(rgbd)
    assert (seq.path, seq.name, os.fspath(seq), str(seq), Path(seq)) == (rgbd, "rec", str(rgbd), str(rgbd), rgbd)
    assert [p.name for p in seq.frame_paths] == [f"{k}.png" for k in range(12)] and seq.n_frames == 12
    assert (seq.width, seq.height, seq.layout) == (40, 30, "rgb")
    assert seq.traversals == [sequence.Traversal("out", 0, 6), sequence.Traversal("back", 6, 12)]
    assert seq.traversal_index().tolist() == [0] * 6 + [1] * 6 and seq.reference_frames().sum() == 6
    assert (seq.frame_step, seq.exclude, seq.tolerance) == (2, 3, 1)
    assert seq.description == sequence.read_description(rgbd) and seq.description["protocol"] is None
    assert seq.has_depth and seq.has_trajectory and seq.has_camera
    assert seq.ground_truth.kind == "poses" and seq.ground_truth.path == rgbd / "CameraTrajectory.txt"
    assert seq.protocol == sequence.Protocol("generic", ())
    assert len(seq.fingerprint) == 12 and seq.fingerprint == sequence.fingerprint(rgbd)
    X = seq.frames(size=(20, 15), step=2)
    assert X.shape == (6, 15, 20, 1) and X.dtype == np.float32 and np.array_equal(X, sequence.load_frames(rgbd, (20, 15), step=2))
    D = seq.depth(limit=3)
    assert D.shape == (3, 30, 40) and D.dtype == np.float32 and D[:, 0, 0].tolist() == [1.0, 2.0, 3.0]   # metres
    ids, P = seq.poses()
    assert ids.tolist() == list(range(12)) and P.shape == (12, 4, 4) and P[11, 0, 3] == 0.0
    P[:] = 0                                                        # a copy: the kept poses are untouched
    assert seq.poses()[1][11, 0, 3] == 0.0 and seq.poses()[1][5, 0, 3] == 5.0
    assert seq.camera()["fx"] == 50.0 and seq.camera() == sequence.read_camera(rgbd)
    assert seq.info() == sequence.folder_info(rgbd) and seq.info()["traversals"] == "out 0-5, back 6-11"


def test_a_sequence_gives_what_its_path_gives_to_every_function(rgbd, tiny_near_loop_sequence):
    for folder in (rgbd, tiny_near_loop_sequence):
        seq = sequence.open(folder)
        for fn in (sequence.list_frames, sequence.traversals, sequence.layout, sequence.folder_info,
                   sequence.read_description, sequence.ground_truth_source, sequence.ground_truth_kind,
                   sequence.fingerprint, exclusion.exclusion, study_params.sequence_parameters):
            assert fn(seq) == fn(str(folder)), fn.__name__
        for fn in (sequence.traversal_index, sequence.reference_frames, groundtruth.for_sequence):
            assert np.array_equal(fn(seq), fn(str(folder))), fn.__name__
    walks = sequence.open(tiny_near_loop_sequence)
    assert walks.layout == "traversals" and walks.ground_truth.format == "aligned"
    assert np.array_equal(walks.loop_pairs(), sequence.read_loop_pairs(tiny_near_loop_sequence, 200))


# ------------------------------------------------------------------------------ the protocol
STREAMS = ("protocol:\n  targets: gardenspoint\n  target_streams:\n"
           "    - traversals: [second, third]\n"
           "    - name: first and last\n      traversals: [first, third]\n      tolerance: 0\n")


def test_the_protocol_decides_the_target_set_and_the_target_streams(tmp_path, monkeypatch):
    f = _walks(tmp_path / "walks", text=STREAMS)
    p = sequence.open(f).protocol
    assert p.targets == "gardenspoint" and [s.name for s in p.streams] == ["second -> third", "first and last"]
    assert p.streams[0].traversals == (sequence.Traversal("second", 6, 12), sequence.Traversal("third", 12, 18))
    assert [s.tolerance for s in p.streams] == [sequence.TARGET_TOLERANCE, 0]
    rows = [{"method": "greenloop-seq", "mode": "place recognition", "R@1_%": 95.0, "R@100P_%": 40.0}]
    judged = {r["target"]: r["met"] for r in targets.detector_targets(rows, p.targets)}
    assert judged["R@1 (%), place recognition"] is True and judged["R@100P (%), place recognition"] is False
    # the leaderboard's target streams are these, every frame (describing skipped here)
    monkeypatch.setattr(ex, "_every_frame", lambda d, reg: d._replace(frame_step=1, frames=np.arange(18)))
    data = Data(sequence.open(f), 2, np.arange(0, 18, 2), np.zeros((9, 9), bool), 1, None, None,
                {"exclude": 1, "seq_lens": [2], "fps_frames": 4}, {}, {}, {})
    protos = ex.target_protocols(data, 0.5)
    assert list(protos) == ["second -> third", "first and last"]
    d, s = protos["first and last"]
    assert d.frames.tolist() == list(range(6)) + list(range(12, 18)) and s.reference.tolist() == [True] * 6 + [False] * 6
    assert (d.GT[:6, 6:] == np.eye(6, dtype=bool)).all() and not d.GT[:6, :6].any()      # tolerance 0
    d, _ = protos["second -> third"]
    k = np.arange(6)
    assert (d.GT[:6, 6:] == (np.abs(k[:, None] - k[None, :]) <= 2)).all()               # the default +- 2


def test_a_folder_without_protocol_gets_the_generic_targets_and_no_stream(tmp_path, tiny_sequence):
    f = _walks(tmp_path / "walks")
    for folder in (f, tiny_sequence):
        assert sequence.open(folder).protocol == sequence.Protocol("generic", ())
    rows = [{"method": "greenloop-seq", "mode": "loop closure", "R@1_%": 80.0}]
    assert targets.detector_targets(rows, sequence.open(f).protocol.targets)[0]["target"].startswith(
        "R@1 not below the best row")
    data = Data(sequence.open(f), 1, np.arange(18), np.zeros((18, 18), bool), 1, None, None, {}, {}, {}, {})
    assert ex.target_protocols(data, 0.5) == {}
    (f / "sequence.yaml").write_text((f / "sequence.yaml").read_text() + "protocol: {targets: nordland}\n")
    assert sequence.open(f).protocol == sequence.Protocol("nordland", ())     # a set, no stream of its own


@pytest.mark.parametrize("text, match", [
    ("protocol: nordland\n", r"protocol must be a mapping.*protocol: \{targets:"),
    ("protocol: {targets: kitti}\n", r"protocol: targets must be one of generic, nordland, gardenspoint, got 'kitti'"),
    ("protocol: {target: nordland}\n", r"protocol: unknown key\(s\) \['target'\]; the keys are targets, target_streams"),
    ("protocol: {target_streams: {traversals: [first, second]}}\n", r"target_streams must be a list"),
    ("protocol: {target_streams: [{traversals: [first]}]}\n", r"target_streams\[0\]: traversals must name at least two"),
    ("protocol: {target_streams: [{traversals: [first, second], tolerance: -1}]}\n",
     r"target_streams\[0\]: tolerance must be an integer >= 0"),
    ("protocol: {target_streams: [{traversals: [first, second], step: 2}]}\n", r"target_streams\[0\]: unknown key\(s\) \['step'\]"),
])
def test_a_malformed_protocol_names_the_key_and_the_fix(tmp_path, text, match):
    f = _walks(tmp_path / "walks", text=text)
    with pytest.raises(ValueError, match=match):
        sequence.open(f)
    with pytest.raises(ValueError, match="sequence.yaml: protocol"):
        sequence.read_description(f)


@pytest.mark.parametrize("streams, match", [
    ("[{traversals: [first, dusk]}]", r"target_streams\[0\]: traversals \['dusk'\] are not traversals of .* \(it has first, "
                                      r"second, third\): fix the names"),
    ("[{traversals: [third, first]}]", r"target_streams\[0\]: traversal third \[12, 18\) must be .*\(stream order, no overlap\)"),
    ("[{traversals: {a: [0, 6], b: [6, 10]}}]", r"target_streams\[0\]: traversals \['a', 'b'\] must be of one length"),
    ("[{traversals: {a: [0, 6], b: [12, 19]}}]", r"traversal b \[12, 19\) must be a non-empty range of the 18 frames"),
])
def test_a_stream_that_does_not_fit_the_sequence_fails_at_open(tmp_path, streams, match):
    f = _walks(tmp_path / "walks", text=f"protocol: {{targets: gardenspoint, target_streams: {streams}}}\n")
    with pytest.raises(ValueError, match=match):
        sequence.open(f)
