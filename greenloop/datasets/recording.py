"""Recordings as robots make them: one frame source over an image folder, a ROS bag or a video.

:func:`open_frames` reads any of

* an image folder: a sequence folder or any folder of images ``greenloop.datasets.sequence``
  reads (rgb/, traversals/, reference/ + query/, images directly in it), frames in its order;
* a ROS 1 ``.bag`` file or a ROS 2 bag folder (its ``metadata.yaml``; a ``.db3`` / ``.mcap`` file
  of one names its folder), read with ``rosbags.highlevel.AnyReader``: the messages of one
  ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` topic (``topic``; needed when the bag
  has several image topics) decoded by ``rosbags.image``;
* a video file (VIDEO_SUFFIXES) through ``cv2.VideoCapture``,

as a :class:`FrameSource`: ``len(src)`` frames, ``src.names`` (one label a frame: its file name,
or its time stamp ``"%.6f"`` seconds), ``src.stamps`` ((N,) float64 seconds, or None where the
recording has no times), ``src.read(indices)`` -> a list of (H, W, 3) uint8 BGR frames (as a
camera delivers them, as ``cv2.imread`` decodes), ``src[a:b:k]`` a view of some of its frames.

Opening indexes the recording once (file names; a bag's message times, read from the message
headers without decoding a frame; a video's frame count and rate from its container); frames are
decoded only when read. A bag reads the messages between the first and last frame asked for; a
video decodes forward from where it stands and seeks only to a frame more than AHEAD frames away
or behind it, so reading windows of consecutive frames decodes each frame once.
Image files are decoded by ``sequence.read_image``, the one decoder of files.
"""
from __future__ import annotations

import os
import struct
from pathlib import Path

import cv2
import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.image import ImageError, message_to_cvimage
from rosbags.typesys import Stores, get_typestore

from greenloop.datasets import sequence

VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov")
BAG_SUFFIXES = (".bag",)                    # ROS 1; a ROS 2 bag is a folder holding metadata.yaml
ROS2_FILES = (".db3", ".mcap")              # a ROS 2 bag's storage file names its folder
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
AHEAD = 64   # frames: a read further ahead than this seeks (video) or starts a new pass (bag)


class FrameSource:
    """The frames of one recording (module doc), or a view of some of them.

    path: the recording (Path). kind: "folder", "bag" or "video". topic: the bag's image topic
    (None for a folder or a video). sequence: the folder's ``sequence.Sequence`` (None for a bag or a
    video). names: list[str], one label a frame. stamps: (N,) float64 seconds or None.
    ``len``, ``read(indices)``, ``src[key]`` (a slice or an index array: a view) and
    :attr:`frame_rate` as documented on each."""

    def __init__(self, path, kind: str, names: list, stamps, decoder, topic=None, seq=None, index=None):
        self.path, self.kind, self.topic, self.sequence = Path(path), kind, topic, seq
        self._given = os.fspath(path)                    # as given: "data/x/" prints as typed
        self._all_names, self._all_stamps, self._decoder = names, stamps, decoder
        self._index = np.arange(len(names), dtype=np.int64) if index is None else np.asarray(index, np.int64)

    def __len__(self) -> int:
        return len(self._index)

    def __repr__(self) -> str:
        return f"FrameSource({os.fspath(self.path)!r}, {self.kind}, {len(self)} frames" + (
            f", topic {self.topic})" if self.topic else ")")

    def __str__(self) -> str:
        """The recording as named in printouts: its path as given, and the topic of a bag."""
        return self._given + (f" (topic {self.topic})" if self.topic else "")

    def __getitem__(self, key) -> FrameSource:
        """A view of some frames: ``src[::step]``, ``src[a:b]`` or an (M,) index array."""
        sub = self._index[key] if isinstance(key, slice) else self._index[np.asarray(key, np.int64)]
        return FrameSource(self._given, self.kind, self._all_names, self._all_stamps, self._decoder,
                           self.topic, self.sequence, np.atleast_1d(sub))

    @property
    def names(self) -> list[str]:
        return [self._all_names[k] for k in self._index]

    @property
    def stamps(self) -> np.ndarray | None:
        return None if self._all_stamps is None else self._all_stamps[self._index]

    @property
    def frame_rate(self) -> float | None:
        """Frames per second of the recording (the median spacing of its stamps), None where unknown."""
        t = self._all_stamps
        if t is None or len(t) < 2:
            return None
        dt = float(np.median(np.diff(t)))
        return 1.0 / dt if dt > 0 else None

    def read(self, indices=None) -> list[np.ndarray]:
        """Decode frames ``indices`` (of this source or view; default: all of them), in the order
        given: a list of (H, W, 3) uint8 BGR arrays. IndexError for an index outside 0..len-1."""
        idx = np.arange(len(self)) if indices is None else np.asarray(indices, np.int64).reshape(-1)
        if idx.size and (idx.min() < -len(self) or idx.max() >= len(self)):
            raise IndexError(f"frames {idx.min()}..{idx.max()} asked of {self!s}, which has {len(self)} frames")
        absolute = self._index[idx]
        wanted = np.unique(absolute)
        decoded = dict(zip(wanted.tolist(), self._decoder.read(wanted.tolist())))
        return [decoded[k] for k in absolute.tolist()]


def kind_of(path) -> str:
    """"folder", "bag" or "video": what :func:`open_frames` reads ``path`` as (ValueError for none)."""
    path = Path(path)
    if path.is_dir():
        return "bag" if (path / "metadata.yaml").is_file() else "folder"
    suffix = path.suffix.lower()
    if suffix in BAG_SUFFIXES or (suffix in ROS2_FILES and (path.parent / "metadata.yaml").is_file()):
        return "bag"
    if suffix in VIDEO_SUFFIXES:
        return "video"
    raise ValueError(f"{path}: not a recording greenloop reads; give a folder of images, a ROS 1 .bag, a ROS 2 bag "
                     f"folder (with metadata.yaml) or a video ({' '.join(VIDEO_SUFFIXES)})")


def open_frames(path, topic: str | None = None) -> FrameSource:
    """The frames of a recording (module doc), indexed, none decoded yet.

    path: an image folder, a ``sequence.Sequence``, a ROS 1 .bag, a ROS 2 bag folder, a video file,
        or a FrameSource (returned as it is; reopened for another topic). topic: the bag's image topic (needed when it has
        several); ValueError when given for a folder or a video.
    Raises FileNotFoundError for a missing path, ValueError (listing the bag's image topics with
    their message counts) for a bag without the topic or with several and none chosen.
    """
    if isinstance(path, FrameSource):
        if topic in (None, path.topic):
            return path
        path = path.path                                 # another topic of the same bag
    if not Path(path).exists():
        raise FileNotFoundError(f"recording {path} does not exist: give a folder of images, a ROS bag or a video file")
    kind = kind_of(path)
    if topic is not None and kind != "bag":
        raise ValueError(f"--topic {topic} given for {path}, a {kind}: a topic names a bag's camera; drop it")
    return {"folder": _folder, "bag": lambda p: _bag(p, topic), "video": _video}[kind](path)


# ------------------------------------------------------------- image folders
class _FileDecoder:
    """Decodes the image files of a folder, in the folder's frame order."""

    def __init__(self, paths: list):
        self.paths = paths

    def read(self, indices: list) -> list[np.ndarray]:
        return [sequence.read_image(self.paths[k]) for k in indices]


def _folder(folder) -> FrameSource:
    """An image folder's FrameSource: file names; stamps from sequence.yaml's frame_rate, else None."""
    seq = sequence.open(folder)
    paths = seq.frame_paths
    rate = seq.description["frame_rate"]
    stamps = None if rate is None else np.arange(len(paths), dtype=np.float64) / float(rate)
    return FrameSource(seq, "folder", [p.name for p in paths], stamps, _FileDecoder(paths), seq=seq)


# ------------------------------------------------------------- ROS bags
def bag_path(path) -> Path:
    """The path AnyReader opens: a ROS 1 .bag file, or a ROS 2 bag's folder (a .db3/.mcap file names it)."""
    path = Path(path)
    return path.parent if path.suffix.lower() in ROS2_FILES else path


def pick_topic(path, reader, types, topic, what: str) -> str:
    """The topic of an open AnyReader to read: ``topic`` when it is one of the bag's topics of a type in
    ``types``, the only such topic when none is given. Else ValueError listing them (type, message
    count) and the fix. what: what they hold, for the message ("image", "odometry")."""
    found = {name: (info.msgtype, int(info.msgcount)) for name, info in sorted(reader.topics.items())
             if info.msgtype in types}
    if topic is None and len(found) == 1:
        return next(iter(found))
    if topic is not None and topic in found:
        return topic
    if not found:
        raise ValueError(f"{path} has no {what} topic ({' or '.join(types)}); it records "
                         f"{', '.join(sorted(reader.topics)) or 'nothing'}: record one")
    listing = "; ".join(f"{t} ({ty.split('/')[-1]}, {n} messages)" for t, (ty, n) in found.items())
    why = f"has no {what} topic {topic}" if topic is not None else f"has {len(found)} {what} topics"
    raise ValueError(f"{path} {why}: its {what} topics are {listing}; pass --topic TOPIC")


def open_bag(path) -> AnyReader:
    """An AnyReader on a bag (:func:`bag_path`), ROS 2 Humble's message types for a bag that
    embeds none; ValueError naming the bag where rosbags cannot read it. Use it in a ``with``."""
    try:
        return AnyReader([bag_path(path)], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    except AnyReaderError as e:
        raise ValueError(f"{path}: not a ROS bag rosbags reads ({e})") from e


def header_stamps(rows: list, cdr: bool) -> np.ndarray:
    """(N,) float64 seconds of bag messages [(first 12 raw bytes, log time ns)] whose type starts
    with a std_msgs/Header (Image, CompressedImage, Odometry): the header's stamp, read without
    deserialising (bytes 4..12: after ROS 1's uint32 seq, or CDR's encapsulation word, whose byte 1
    says the byte order; cdr: the bag is ROS 2); the log times where any header stamp is zero (a
    driver that left it unset)."""
    stamps = []
    for raw, _ in rows:
        order = "<" if not cdr or raw[1] & 1 else ">"
        sec, nsec = struct.unpack_from(order + "iI", raw, 4)
        stamps.append(sec + nsec * 1e-9)
    t = np.asarray(stamps, np.float64)
    if not len(t) or np.any(t == 0):
        t = np.asarray([ns for _, ns in rows], np.float64) * 1e-9
    return t


class _BagDecoder:
    """Decodes one image topic's messages of a bag, the messages found by their log times."""

    def __init__(self, path: Path, topic: str, log_ns: np.ndarray):
        self.path, self.topic, self.log_ns = path, topic, log_ns

    def read(self, indices: list) -> list[np.ndarray]:
        out, wanted = {}, set(indices)
        with open_bag(self.path) as reader:
            conns = [c for c in reader.connections if c.topic == self.topic]
            for a, b in _runs(indices):
                k = int(np.searchsorted(self.log_ns, self.log_ns[a], "left"))
                for conn, _, raw in reader.messages(conns, start=int(self.log_ns[a]), stop=int(self.log_ns[b]) + 1):
                    if k in wanted and k not in out:
                        out[k] = _to_bgr(reader.deserialize(raw, conn.msgtype), self.path, k)
                    k += 1
        return [out[k] for k in indices]


def _runs(indices: list) -> list[tuple[int, int]]:
    """Sorted frame numbers -> [(first, last)] runs, split where the next is more than AHEAD away."""
    runs = []
    for k in indices:
        if runs and k - runs[-1][1] <= AHEAD:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return [(a, b) for a, b in runs]


def _to_bgr(msg, path, k: int) -> np.ndarray:
    """A deserialised Image / CompressedImage -> (H, W, 3) uint8 BGR (ValueError naming the message)."""
    try:
        img = message_to_cvimage(msg, "bgr8")
    except (ImageError, ValueError, cv2.error) as e:
        raise ValueError(f"{path}: image message {k} cannot be decoded as 8-bit BGR ({e}); "
                         f"record the camera's colour or mono8 topic") from e
    if img is None or img.dtype != np.uint8:
        raise ValueError(f"{path}: image message {k} is not 8-bit ({getattr(msg, 'encoding', 'compressed')})")
    return np.ascontiguousarray(img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))


def _bag(path, topic) -> FrameSource:
    """A bag's FrameSource: one image topic's messages in log-time order, named by header stamp."""
    path = bag_path(path)
    with open_bag(path) as reader:
        topic = pick_topic(path, reader, IMAGE_TYPES, topic, "image")
        conns = [c for c in reader.connections if c.topic == topic]
        rows = [(bytes(raw[:12]), ns) for _, ns, raw in reader.messages(conns)]
        stamps = header_stamps(rows, reader.is2)
    log_ns = np.asarray([ns for _, ns in rows], np.int64)
    return FrameSource(path, "bag", [f"{t:.6f}" for t in stamps], stamps, _BagDecoder(path, topic, log_ns), topic)


# ------------------------------------------------------------- videos
class _VideoDecoder:
    """Decodes a video's frames, forward from where the capture stands (a seek only when far)."""

    def __init__(self, path: Path, n: int):
        self.path, self.n, self._cap, self._pos = path, n, None, 0

    def read(self, indices: list) -> list[np.ndarray]:
        return [self._frame(k) for k in indices]

    def _frame(self, k: int) -> np.ndarray:
        if self._cap is None or k < self._pos or k - self._pos > AHEAD:
            if self._cap is None:
                self._cap = cv2.VideoCapture(str(self.path))
            if k != self._pos or k == 0:
                self._cap.set(cv2.CAP_PROP_POS_FRAMES, k)
            self._pos = k
        while self._pos < k:
            self._grab(k)
        ok, img = self._cap.read()
        self._pos += 1
        if not ok or img is None:
            raise ValueError(f"{self.path}: frame {k} cannot be decoded (the container says {self.n} frames); "
                             f"the file may be truncated: re-encode it (ffmpeg -i IN -c:v mjpeg OUT.avi)")
        return img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)

    def _grab(self, k: int) -> None:
        if not self._cap.grab():
            raise ValueError(f"{self.path}: the video ends at frame {self._pos}, before frame {k} "
                             f"(the container says {self.n} frames): re-encode it")
        self._pos += 1


def _video(path) -> FrameSource:
    """A video's FrameSource: the container's frame count (counted by reading where it gives none) and
    rate; stamps k / rate seconds (None where the rate is unknown), names the stamps or frame numbers."""
    path = Path(path)
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise ValueError(f"{path}: OpenCV cannot open this video (codec or container not supported); "
                         f"re-encode it (ffmpeg -i IN -c:v mjpeg OUT.avi) or extract its frames to a folder")
    n, fps = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), float(cap.get(cv2.CAP_PROP_FPS))
    if n <= 0:
        n = 0
        while cap.grab():
            n += 1
    cap.release()
    if n == 0:
        raise ValueError(f"{path}: the video holds no frames")
    stamps = np.arange(n, dtype=np.float64) / fps if fps > 0 else None
    names = [f"{t:.6f}" for t in stamps] if stamps is not None else [str(k) for k in range(n)]
    return FrameSource(path, "video", names, stamps, _VideoDecoder(path, n))
