"""``sequence.yaml``: the keys a sequence folder may state about itself, and their checks.

:func:`read` returns the file checked, {key: value or None} for every key of KEYS (None where the
file or the key is absent); ``greenloop.datasets.sequence`` documents each key and reads it once
per folder (``sequence.open``). Every problem is a ValueError naming the file, the key and the fix.

``protocol`` says how the detector's targets judge the sequence (greenloop.study.targets,
greenloop.experiments.leaderboard.target_protocols)::

    protocol:
      targets: gardenspoint          # one of PROTOCOL_TARGETS; absent: generic
      target_streams:                # the streams the targets are defined on; absent: none (the
        - traversals: [day_right, night_right]   #   leaderboard itself). Each is every frame of its
          tolerance: 2               #   traversals in this order, the first the database, frame k of
        - name: every frame, +- 2 frames         #   each the same place +- tolerance frames
          traversals: {summer: [0, 3576], winter: [3576, 7152]}   # names or frame ranges [start, stop)

A stream's ``name`` defaults to its traversals' names joined by " -> ", its ``tolerance`` to
TARGET_TOLERANCE frames. Names must be traversals of the sequence (``traversals:`` above, or its
folders); ranges frames of it. Imports nothing of greenloop but ``util``.
"""
from __future__ import annotations

from pathlib import Path

import yaml

from greenloop.util.checks import positive_int

NAME = "sequence.yaml"
KEYS = ("exclude", "frame_step", "frame_rate", "traversals", "ground_truth", "tolerance",
        "threshold_m", "ground_truth_format", "protocol")
PROTOCOL_TARGETS = ("generic", "nordland", "gardenspoint")   # study.targets' target sets
PROTOCOL_KEYS = ("targets", "target_streams")
STREAM_KEYS = ("name", "traversals", "tolerance")
TARGET_TOLERANCE = 2       # frames: a target stream's ground truth, frame k of each traversal +- 2
PROTOCOL_FIX = ("write it as `protocol: {targets: generic | nordland | gardenspoint, target_streams: "
                "[{traversals: [first, second], tolerance: 2}, ...]}` (greenloop.datasets.description)")


def read(folder) -> dict:
    """``sequence.yaml`` of ``folder``, checked (module doc): {key: value or None} for every key of
    KEYS. exclude: int >= 0 frames; frame_step: int >= 1; frame_rate: float > 0 frames/s;
    traversals: a list of names or {name: [start, stop]}; ground_truth, ground_truth_format:
    strings; tolerance: int >= 0 frames; threshold_m: float > 0 metres; protocol: {"targets": one
    of PROTOCOL_TARGETS, "target_streams": [{"name": str or None, "traversals": list or dict,
    "tolerance": int or None}]}. Raises ValueError naming the file and the key."""
    path = Path(folder) / NAME
    out = dict.fromkeys(KEYS)
    if not path.is_file():
        return out
    try:
        d = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as e:
        raise ValueError(f"{path} is not valid YAML ({str(e).splitlines()[0]}): fix it") from None
    if not isinstance(d, dict):
        raise ValueError(f"{path} must be a mapping `key: value` (keys {', '.join(KEYS)})")
    unknown = sorted(set(d) - set(KEYS))
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; the keys are {', '.join(KEYS)}")
    _check_values(path, d)
    if d.get("protocol") is not None:
        d["protocol"] = check_protocol(path, d["protocol"])
    out.update(d)
    return out


def _check_values(path: Path, d: dict) -> None:
    """Check (and make ints of) every key but protocol in place."""
    for key, minimum in (("exclude", 0), ("frame_step", 1), ("tolerance", 0)):
        if d.get(key) is not None:
            d[key] = positive_int(f"{path}: {key}", d[key], minimum, unit="frames")
    for key in ("frame_rate", "threshold_m"):
        v = d.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0):
            raise ValueError(f"{path}: {key} must be a number > 0, got {v!r}")
    for key in ("ground_truth", "ground_truth_format"):
        if d.get(key) is not None and not isinstance(d[key], str):
            raise ValueError(f"{path}: {key} must be a string (e.g. `ground_truth: aligned` or a file "
                             f"name of the folder), got {d[key]!r}")
    if not _traversal_spec(d.get("traversals"), allow_none=True):
        raise ValueError(f"{path}: traversals must be a list of names of traversals/ folders "
                         f"([day, night]) or, for an rgb/ stream, {{name: [start, stop]}}; got {d['traversals']!r}")


def _traversal_spec(t, allow_none: bool = False, minimum: int = 0) -> bool:
    """Whether ``t`` is a list of names or {name: [start, stop]} (at least ``minimum`` of them)."""
    if t is None:
        return allow_none
    names = isinstance(t, list) and all(isinstance(x, str) for x in t)
    ranges = isinstance(t, dict) and all(isinstance(v, list) and len(v) == 2 for v in t.values())
    return (names or ranges) and len(t) >= minimum


def check_protocol(path, p) -> dict:
    """sequence.yaml's ``protocol`` value checked (module doc): {"targets", "target_streams"} with
    every default filled but the streams' names and tolerances (None: the reader's default).
    Raises ValueError naming the key and the fix."""
    where = f"{path}: protocol"
    if not isinstance(p, dict):
        raise ValueError(f"{where} must be a mapping, got {p!r}: {PROTOCOL_FIX}")
    unknown = sorted(set(p) - set(PROTOCOL_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; the keys are {', '.join(PROTOCOL_KEYS)}: {PROTOCOL_FIX}")
    targets = p.get("targets", "generic")
    if targets not in PROTOCOL_TARGETS:
        raise ValueError(f"{where}: targets must be one of {', '.join(PROTOCOL_TARGETS)}, got {targets!r}: "
                         f"name the target set that judges this sequence, or leave the key out for generic")
    streams = p.get("target_streams") or []
    if not isinstance(streams, list):
        raise ValueError(f"{where}: target_streams must be a list of streams, got {streams!r}: {PROTOCOL_FIX}")
    return {"targets": targets,
            "target_streams": [_check_stream(f"{where}: target_streams[{k}]", s) for k, s in enumerate(streams)]}


def _check_stream(where: str, s) -> dict:
    """One target stream of sequence.yaml's protocol, checked: {"name", "traversals", "tolerance"}."""
    if not isinstance(s, dict):
        raise ValueError(f"{where} must be a mapping with traversals (and name, tolerance), got {s!r}: {PROTOCOL_FIX}")
    unknown = sorted(set(s) - set(STREAM_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; the keys are {', '.join(STREAM_KEYS)}: {PROTOCOL_FIX}")
    t = s.get("traversals")
    if not _traversal_spec(t, minimum=2) or (isinstance(t, dict) and not all(
            isinstance(a, int) and isinstance(b, int) and not isinstance(a, bool) and not isinstance(b, bool)
            for a, b in t.values())):
        raise ValueError(f"{where}: traversals must name at least two traversals of the sequence ([day, night]) "
                         f"or give at least two frame ranges ({{summer: [0, 100], winter: [100, 200]}}); got {t!r}")
    name = s.get("name")
    if name is not None and (not isinstance(name, str) or not name.strip()):
        raise ValueError(f"{where}: name must be a non-empty string (the stream's label), got {name!r}")
    tol = s.get("tolerance")
    tol = None if tol is None else positive_int(f"{where}: tolerance", tol, 0, unit="frames")
    return {"name": name, "traversals": t, "tolerance": tol}
