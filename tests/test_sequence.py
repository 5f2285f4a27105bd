import numpy as np
import pytest

from greenloop.datasets import sequence
from conftest import write_frames


def test_list_frames_numeric_order(tmp_path):
    write_frames(tmp_path, 12)
    names = [p.name for p in sequence.list_frames(tmp_path)]
    assert names[:3] == ["0.png", "1.png", "2.png"] and names[-2:] == ["10.png", "11.png"]


def test_list_frames_folder_of_images_and_jpg(tmp_path):
    write_frames(tmp_path, 3, ext=".jpg")
    flat = tmp_path / "rgb"
    assert [p.name for p in sequence.list_frames(flat)] == ["0.jpg", "1.jpg", "2.jpg"]


def test_load_frames_default_preprocessing(tmp_path):
    write_frames(tmp_path, 5, size=(64, 48))
    X = sequence.load_frames(tmp_path)
    assert X.shape == (5, 32, 32, 1) and X.dtype == np.float32
    assert 0.0 <= X.min() and X.max() <= 1.0 and X.std() > 0.01
    rgb = sequence.load_frames(tmp_path, size=(16, 8), gray=False, limit=2)
    assert rgb.shape == (2, 8, 16, 3)
    raw = sequence.load_frames(tmp_path, size=None, dtype=np.uint8)
    assert raw.shape == (5, 48, 64, 1) and raw.dtype == np.uint8


def test_load_frames_rgb_channel_order(tmp_path):
    import cv2
    (tmp_path / "rgb").mkdir()
    img = np.zeros((4, 4, 3), np.uint8)
    img[..., 2] = 255  # red in OpenCV's BGR
    cv2.imwrite(str(tmp_path / "rgb" / "0.png"), img)
    X = sequence.load_frames(tmp_path, size=None, gray=False)
    assert X[0, 0, 0].tolist() == [1.0, 0.0, 0.0]


def test_missing_empty_unreadable_mixed(tmp_path):
    with pytest.raises(FileNotFoundError, match="make data"):
        sequence.list_frames(tmp_path / "nope")
    (tmp_path / "empty" / "rgb").mkdir(parents=True)
    with pytest.raises(ValueError, match="no .png/.jpg images"):
        sequence.list_frames(tmp_path / "empty")
    write_frames(tmp_path / "bad", 2)
    (tmp_path / "bad" / "rgb" / "2.png").write_bytes(b"not an image")
    with pytest.raises(ValueError, match="cannot read image .*2.png"):
        sequence.load_frames(tmp_path / "bad")
    write_frames(tmp_path / "mixed", 2, size=(40, 30))
    write_frames(tmp_path / "mixed2", 1, size=(20, 30))
    (tmp_path / "mixed2" / "rgb" / "0.png").rename(tmp_path / "mixed" / "rgb" / "5.png")
    with pytest.raises(ValueError, match="mixed sizes"):
        sequence.load_frames(tmp_path / "mixed", size=None)
    assert sequence.load_frames(tmp_path / "mixed").shape == (3, 32, 32, 1)


def test_read_real_trajectory(real_trajectory):
    ids, poses = sequence.read_trajectory(real_trajectory)
    assert len(ids) == 2261 and ids[0] == 0 and ids[-1] == 2260
    assert poses.shape == (2261, 4, 4)
    assert np.allclose(poses[0], np.eye(4), atol=1e-6)
    R = poses[:, :3, :3]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-6)
    # the quaternion sign flips between frames 922 and 987 must not show up as a jump in rotation
    rel = np.einsum("nij,nik->njk", R[:-1], R[1:])
    angle = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert angle.max() < 10


def test_trajectory_round_trip_and_errors(tmp_path):
    rng = np.random.default_rng(1)
    from scipy.spatial.transform import Rotation
    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:, :3, :3] = Rotation.random(5, random_state=1).as_matrix()
    poses[:, :3, 3] = rng.normal(size=(5, 3))
    sequence.write_trajectory(tmp_path / "t.txt", np.arange(5), poses)
    ids, back = sequence.read_trajectory(tmp_path / "t.txt")
    assert ids.tolist() == [0, 1, 2, 3, 4] and np.allclose(back, poses, atol=1e-7)
    with pytest.raises(ValueError, match="5 poses but the sequence has 7 frames"):
        sequence.read_trajectory(tmp_path / "t.txt", n_frames=7)
    (tmp_path / "bad.txt").write_text("0 1 2 3 0 0 0 1\n1 1 2 oops 0 0 0 1\n")
    with pytest.raises(ValueError, match=r"bad.txt:2: expected 8 numbers"):
        sequence.read_trajectory(tmp_path / "bad.txt")
    with pytest.raises(FileNotFoundError, match="CameraTrajectory.txt"):
        sequence.read_trajectory(tmp_path)


def test_read_camera(real_trajectory, tmp_path):
    cam = sequence.read_camera(real_trajectory.parent / "D435i.yaml")
    assert cam["fx"] == pytest.approx(602.897) and cam["cy"] == pytest.approx(241.4)
    assert (cam["width"], cam["height"]) == (640, 480) and cam["depth_scale"] == 5000.0
    (tmp_path / "camera.yaml").write_text("Camera.fx: 1\n")
    with pytest.raises(ValueError, match="lacks"):
        sequence.read_camera(tmp_path)


def test_step_and_limit_select_frames(tmp_path):
    write_frames(tmp_path, 10, size=(8, 8))
    all_ = sequence.load_frames(tmp_path, size=None)
    assert np.array_equal(sequence.load_frames(tmp_path, size=None, step=3), all_[::3])
    assert np.array_equal(sequence.load_frames(tmp_path, size=None, step=3, limit=2), all_[[0, 3]])
    with pytest.raises(ValueError, match="step"):
        sequence.load_frames(tmp_path, step=0)
