"""greenloop.speed.timing: the one timing definition (decoded frame -> decision), interleaved."""
import time

import cv2
import numpy as np
import pytest

from greenloop.methods.dictionary.dictionary import LoopDetector
from greenloop.methods.greenloop_seq import seqstream
from greenloop.speed import timing
from greenloop.util import clock as clockmod


class _Clock:
    """A stand-in for timing's wall clock that only the methods below move: outcomes that depend on
    no machine's speed."""
    def __init__(self):
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now


def _sleeper(name, log, ms=2.0, start_ms=150.0, clock=None):
    """A method whose start takes start_ms and each step ms on `clock` (on the real clock without one)."""
    def spend(s):
        if clock is None:
            time.sleep(s)
        else:
            clock.now += s

    def start(pre):
        log.append(("start", name))
        spend(start_ms / 1e3)                          # building the database is NOT timed
        return {"stored": len(pre), "steps": 0}

    def step(state, frame):
        state["steps"] += 1
        spend(ms / 1e3)
        return None
    return timing.Method(name, start, step)


def test_times_only_the_steps_interleaved(monkeypatch):
    log, clock = [], _Clock()
    monkeypatch.setattr(clockmod, "time", clock)            # the one clock, greenloop.util.clock
    methods = [_sleeper("a", log, clock=clock), _sleeper("b", log, ms=4.0, clock=clock)]
    frames = [np.zeros((4, 4, 3), np.uint8)] * 10
    rows = timing.time_methods(methods, frames, {"a": np.zeros((7, 2)), "b": np.zeros((3, 2))}, repeats=3)
    a, b = rows
    assert a["method"] == "a" and a["stored_at_start"] == 7 and b["stored_at_start"] == 3
    # 2 ms and 4 ms per frame exactly; timing the 150 ms start as well would give 10 / 0.17 s = 59 frames/s
    assert a["fps_median"] == pytest.approx(500) and b["fps_median"] == pytest.approx(250)
    assert a["fps_min"] <= a["fps_median"] <= a["fps_max"] and a["frames_timed"] == 10 and a["repeats"] == 3
    assert a["ms_per_frame_median"] == pytest.approx(1e3 / a["fps_median"])
    assert a["cpu"] and "cores" in a["cpu"]
    # one warm-up start each, then repeats rotated: a b | b a | a b
    assert [n for _, n in log] == ["a", "b", "a", "b", "b", "a", "a", "b"]


def test_at_least_three_repeats_and_a_preload_for_each():
    m = [_sleeper("a", [], ms=0, start_ms=0)]
    with pytest.raises(ValueError, match="repeats"):
        timing.time_methods(m, [np.zeros((2, 2, 3), np.uint8)], {"a": []}, repeats=2)
    with pytest.raises(ValueError, match="no preload"):
        timing.time_methods(m, [np.zeros((2, 2, 3), np.uint8)], {}, repeats=3)
    with pytest.raises(ValueError, match="empty"):
        timing.time_methods(m, [], {"a": []})


def test_detector_method_preloads_the_database_then_matches_each_frame():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(30, 8)).astype(np.float32)
    frames = [X[25 + k] for k in range(5)]                 # "frames" that describe to themselves
    det = seqstream.Detector(None, seq_len=3, exclude=5, contrast_window=0)
    m = timing.detector_method("seq", det, describe=lambda f: f)
    state = m.start(X[:25])
    assert state.frame_index == 25
    for f in frames:
        m.step(state, f)
    assert state.frame_index == 30
    S = seqstream.score_matrix(X, 5, 3, contrast_window=0)
    assert np.allclose(state.last_scores, S[:24, 29], atol=1e-5)   # query 29 saw the 24 older frames


def test_dictionary_method_counts_the_preloaded_labels():
    class Stub:
        def __init__(self):
            self.dictionary = LoopDetector(4, 3)
            self.reset()

        def reset(self):
            self.dictionary.reset(); self.frame_index = 0; self.labels = []

        def update(self, frame):
            c = self.dictionary.add(int(frame)); self.frame_index += 1
            return c == 3 or None
    m = timing.dictionary_method("dict", Stub())
    s = m.start([1, 1, 2])
    assert s.frame_index == 3 and s.dictionary.counts.tolist() == [0, 2, 1, 0]
    assert m.step(s, 1) is True                            # the third frame of spot 1 reaches tau = 3


def test_decode_ms(tmp_path):
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"{i}.png"), np.full((20, 30, 3), i, np.uint8))
    d = timing.decode_ms(sorted(tmp_path.glob("*.png")))
    assert 0 < d["decode_ms_min"] <= d["decode_ms_median"] <= d["decode_ms_max"]
    (tmp_path / "bad.png").write_text("not an image")
    with pytest.raises(ValueError, match="cannot read image"):
        timing.decode_ms([tmp_path / "bad.png"])


def test_timed_is_the_one_clock_of_the_speed_package():
    """timed returns the call's result and its wall time; bench and scale read no clock of their own."""
    import time
    from pathlib import Path

    out, secs = timing.timed(lambda s: time.sleep(s) or "done", 0.02)
    assert out == "done" and secs >= 0.02                  # the sleep's wall time (more on a loaded machine)
    speed = Path(timing.__file__).parent
    for module in ("bench.py", "scale.py"):
        assert "perf_counter" not in (speed / module).read_text(), module
