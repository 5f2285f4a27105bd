"""Recordings as robots make them (greenloop.datasets.recording, .odometry): ROS 1 and ROS 2 bags
written here by rosbags, a video written by OpenCV, TUM and KITTI odometry files, read back; and
``detect`` on a bag and a video declaring a planted revisit."""
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from greenloop.datasets import odometry, recording, sequence
from tests.conftest import run_cli

CAM, PNG, ODOM, ODOM2 = "/cam/image_raw", "/cam/image_raw/compressed", "/odom", "/wheel/odom"


def _frames(n: int, seed: int = 0, size=(10, 8)) -> list[np.ndarray]:
    """n random (h, w, 3) uint8 BGR frames."""
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8) for _ in range(n)]


def _poses(n: int, seed: int = 1) -> np.ndarray:
    """n random (4, 4) poses."""
    rng = np.random.default_rng(seed)
    P = np.tile(np.eye(4), (n, 1, 1))
    P[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    P[:, :3, 3] = rng.normal(0, 5, (n, 3))
    return P


def _header(ts, ros1: bool, sec: float, frame_id: str = "cam"):
    stamp = ts.types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(round((sec % 1) * 1e9)))
    extra = {"seq": 0} if ros1 else {}
    return ts.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id, **extra)


def _messages(ts, ros1: bool, frames, stamps, png_frames, odom_poses, odom_stamps):
    """[(topic, msgtype, stamp s, message)] of one recording: raw bgr8 frames, PNG-compressed frames
    and two Odometry topics (the second a copy)."""
    T = ts.types
    out = []
    for img, t in zip(frames, stamps):
        h, w = img.shape[:2]
        out.append((CAM, "sensor_msgs/msg/Image", t, T["sensor_msgs/msg/Image"](
            header=_header(ts, ros1, t), height=h, width=w, encoding="bgr8", is_bigendian=0, step=3 * w,
            data=img.reshape(-1).copy())))
    for img, t in zip(png_frames, stamps):
        data = np.frombuffer(cv2.imencode(".png", img)[1].tobytes(), np.uint8)
        out.append((PNG, "sensor_msgs/msg/CompressedImage", t, T["sensor_msgs/msg/CompressedImage"](
            header=_header(ts, ros1, t), format="bgr8; png compressed bgr8", data=data)))
    for topic in (ODOM, ODOM2):
        for P, t in zip(odom_poses, odom_stamps):
            q = Rotation.from_matrix(P[:3, :3]).as_quat()
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=P[0, 3], y=P[1, 3], z=P[2, 3]),
                                               orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))
            cov = np.zeros(36)
            twist = T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                                                 angular=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0))
            out.append((topic, "nav_msgs/msg/Odometry", t, T["nav_msgs/msg/Odometry"](
                header=_header(ts, ros1, t, "odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov))))
    return sorted(out, key=lambda m: m[2])


def write_bag(path: Path, ros1: bool, frames, stamps, png_frames=(), odom=(np.zeros((0, 4, 4)), ())) -> Path:
    """A ROS 1 .bag (ros1) or ROS 2 bag folder at ``path`` holding the messages of :func:`_messages`;
    the log time of each message is its header stamp plus 1 ms."""
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    msgs = _messages(ts, ros1, frames, stamps, png_frames, *odom)
    writer = Writer1(path) if ros1 else Writer2(path, version=9)
    with writer as w:
        conns = {}
        for topic, msgtype, t, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
            data = ts.serialize_ros1(msg, msgtype) if ros1 else ts.serialize_cdr(msg, msgtype)
            w.write(conns[topic], int(round(t * 1e9)) + 1_000_000, data)
    return path


@pytest.fixture(scope="module", params=["ros1", "ros2"])
def bag(request, tmp_path_factory):
    """(bag path, raw frames, png frames, frame stamps, odometry poses, odometry stamps)."""
    frames, pngs = _frames(7, 0), _frames(7, 5)
    stamps = 100.0 + 0.25 * np.arange(7)
    poses, ostamps = _poses(12), 100.0 + 0.1 * np.arange(12) + 0.05
    ros1 = request.param == "ros1"
    path = tmp_path_factory.mktemp("bag") / ("rec.bag" if ros1 else "rec")
    return write_bag(path, ros1, frames, stamps, pngs, (poses, ostamps)), frames, pngs, stamps, poses, ostamps


def test_a_bag_reads_back_exactly_raw_and_compressed_frames_and_odometry(bag):
    path, frames, pngs, stamps, poses, ostamps = bag
    src = recording.open_frames(path, CAM)
    assert src.kind == "bag" and src.topic == CAM and len(src) == 7
    got = src.read(range(7))
    assert all(g.dtype == np.uint8 and np.array_equal(g, f) for g, f in zip(got, frames))
    np.testing.assert_allclose(src.stamps, stamps, atol=1e-9)       # the header stamps, not the log times
    assert src.names == [f"{t:.6f}" for t in stamps]
    assert [np.array_equal(a, b) for a, b in zip(src.read([5, 1, 5]), [frames[5], frames[1], frames[5]])] == [True] * 3
    view = src[1::3]                                                 # frames 1, 4
    assert len(view) == 2 and view.names == [src.names[1], src.names[4]]
    assert np.array_equal(view.read([1])[0], frames[4])
    png = recording.open_frames(path, PNG).read()
    assert all(np.array_equal(g, f) for g, f in zip(png, pngs))       # PNG is lossless
    t, P = odometry.read_odometry(path, ODOM)
    np.testing.assert_allclose(t, ostamps, atol=1e-9)
    np.testing.assert_allclose(P, poses, atol=1e-9)


def test_a_bag_without_the_topic_lists_its_image_topics_with_their_counts(bag):
    path = bag[0]
    for topic in (None, "/nope"):
        with pytest.raises(ValueError) as e:
            recording.open_frames(path, topic)
        msg = str(e.value)
        assert f"{CAM} (Image, 7 messages)" in msg and f"{PNG} (CompressedImage, 7 messages)" in msg
        assert "--topic" in msg and ODOM not in msg
    with pytest.raises(ValueError, match=rf"{ODOM} \(Odometry, 12 messages\).*{ODOM2}"):
        odometry.read_odometry(path)


def test_a_bag_with_one_image_topic_needs_no_topic_and_a_folder_takes_none(tmp_path):
    frames = _frames(3, 2)
    path = write_bag(tmp_path / "one.bag", True, frames, [1.0, 2.0, 3.0])
    src = recording.open_frames(path)
    assert src.topic == CAM and src.frame_rate == pytest.approx(1.0)
    assert all(np.array_equal(a, b) for a, b in zip(src.read(), frames))
    with pytest.raises(ValueError, match="no odometry topic"):
        odometry.read_odometry(path)
    (tmp_path / "imgs").mkdir()
    cv2.imwrite(str(tmp_path / "imgs" / "0.png"), frames[0])
    with pytest.raises(ValueError, match="drop it"):
        recording.open_frames(tmp_path / "imgs", CAM)


def test_an_image_folder_reads_its_files_in_order_as_sequence_does(tiny_sequence):
    src = recording.open_frames(tiny_sequence)
    paths = sequence.list_frames(tiny_sequence)
    assert src.kind == "folder" and len(src) == len(paths) and src.names == [p.name for p in paths]
    assert src.stamps is None and src.sequence is sequence.open(tiny_sequence)
    got = src[::50].read()
    assert all(np.array_equal(g, cv2.imread(str(p))) for g, p in zip(got, paths[::50]))


def write_video(path: Path, frames, fps: float = 2.0) -> Path:
    """An MJPG .avi of (h, w, 3) uint8 BGR frames."""
    h, w = frames[0].shape[:2]
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    assert out.isOpened()
    for f in frames:
        out.write(f)
    out.release()
    return path


def _numbered(n: int) -> list[np.ndarray]:
    """n 32 x 48 frames whose index k is written in blocks: 8 bits, each an 8 x 6 block (0 or 255)."""
    out = []
    for k in range(n):
        img = np.zeros((32, 48, 3), np.uint8)
        for b in range(8):
            if k >> b & 1:
                img[(b // 4) * 16:(b // 4) * 16 + 16, (b % 4) * 12:(b % 4) * 12 + 12] = 255
        out.append(img)
    return out


def _index_of(img: np.ndarray) -> int:
    """The frame index :func:`_numbered` wrote, read from each block's mean."""
    g = img.mean(2)
    return sum(1 << b for b in range(8) if g[(b // 4) * 16 + 4:(b // 4) * 16 + 12, (b % 4) * 12 + 3:(b % 4) * 12 + 9].mean() > 128)


def test_a_video_reads_back_in_order_forward_and_after_a_seek(tmp_path):
    frames = _numbered(150)
    src = recording.open_frames(write_video(tmp_path / "v.avi", frames, fps=5))
    assert src.kind == "video" and len(src) == 150 and src.frame_rate == pytest.approx(5)
    np.testing.assert_allclose(src.stamps, np.arange(150) / 5)
    window = src.read(range(0, 20))
    assert [_index_of(f) for f in window] == list(range(20))
    assert max(np.abs(f.astype(int) - g).mean() for f, g in zip(window, frames)) < 8     # MJPG is lossy
    assert [_index_of(f) for f in src.read([140, 3, 141, 100])] == [140, 3, 141, 100]   # seeks back and far
    assert [_index_of(f) for f in src[::7].read()] == list(range(0, 150, 7))


def test_odometry_files_read_back_and_associate_interpolates_on_the_geodesic(tmp_path):
    poses, t = _poses(5), np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    sequence.write_trajectory(tmp_path / "odom.tum", t, poses)
    ts, P = odometry.read_odometry(tmp_path / "odom.tum")
    np.testing.assert_allclose(ts, t)
    np.testing.assert_allclose(P, poses, atol=1e-8)
    (tmp_path / "odom.kitti").write_text("".join(" ".join(f"{v:.12g}" for v in p[:3].ravel()) + "\n" for p in poses))
    ts, P = odometry.read_odometry(tmp_path / "odom.kitti")
    np.testing.assert_array_equal(ts, np.arange(5))
    np.testing.assert_allclose(P, poses, atol=1e-10)
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    with pytest.raises(ValueError, match="TUM .* KITTI"):
        odometry.read_odometry(tmp_path / "bad.txt")
    out, ok = odometry.associate([0.5, 0.75, -0.1, 2.05, 3.0], t, poses, max_dt=0.3)
    assert ok.tolist() == [True, True, True, True, False] and np.isnan(out[4]).all()
    np.testing.assert_allclose(out[0], poses[1], atol=1e-12)
    np.testing.assert_allclose(out[2], poses[0])
    np.testing.assert_allclose(out[3], poses[4])
    mid = Rotation.from_matrix(poses[1, :3, :3]) * Rotation.from_rotvec(
        0.5 * (Rotation.from_matrix(poses[1, :3, :3]).inv() * Rotation.from_matrix(poses[2, :3, :3])).as_rotvec())
    np.testing.assert_allclose(out[1, :3, :3], mid.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(out[1, :3, 3], (poses[1, :3, 3] + poses[2, :3, 3]) / 2)
    a0 = Rotation.from_matrix(out[1, :3, :3]).inv() * Rotation.from_matrix(poses[1, :3, :3])   # half way, both sides
    a1 = Rotation.from_matrix(out[1, :3, :3]).inv() * Rotation.from_matrix(poses[2, :3, :3])
    assert a0.magnitude() == pytest.approx(a1.magnitude())


def _revisit(tiny_sequence) -> list[np.ndarray]:
    """80 frames of the synthetic greenhouse, then its frames 0..39 again: a planted revisit."""
    paths = sequence.list_frames(tiny_sequence)
    return [cv2.imread(str(paths[k])) for k in list(range(80)) + list(range(40))]


def _closures(out: str) -> list[tuple[int, int]]:
    rows = [line.split("\t") for line in out.splitlines() if line[:1].isdigit()]
    return [(int(r[0]), int(r[1])) for r in rows]


def test_detect_on_a_bag_and_a_video_declares_the_planted_revisit(tiny_sequence, tmp_path):
    frames = _revisit(tiny_sequence)
    stamps = 1000.0 + 0.5 * np.arange(len(frames))                  # 2 frames/s: 10 s exclude 20 frames
    bag_path = write_bag(tmp_path / "field.bag", True, frames, stamps, frames[:3])
    video = write_video(tmp_path / "field.avi", frames, fps=2)
    r = run_cli(["detect", bag_path])
    assert r.returncode == 2 and f"{CAM} (Image, 120 messages)" in r.stderr + r.stdout
    for args in (["detect", bag_path, "--topic", CAM], ["detect", video]):
        r = run_cli(args)
        assert r.returncode == 0, r.stderr
        assert "exclude 20 (frame rate)" in r.stdout and "120 frames from" in r.stdout
        found = _closures(r.stdout)
        assert found and all(f >= 80 and m == f - 80 for f, m in found), r.stdout


def test_a_bag_whose_driver_left_header_stamps_unset_is_timed_by_its_log_times(tmp_path):
    path = write_bag(tmp_path / "unset.bag", True, _frames(3, 4), [0.0, 1.0, 2.0])   # frame 0's stamp is 0
    src = recording.open_frames(path)
    np.testing.assert_allclose(src.stamps, [0.001, 1.001, 2.001], atol=1e-9)        # write_bag logs at stamp + 1 ms
    assert src.names[1] == "1.001000"
