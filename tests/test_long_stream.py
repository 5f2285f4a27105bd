"""The long CLI stream's benchmark (greenloop.speed.long_stream): what it reads from detect's
output, how it counts the closures at the query's place, and the scale.md section it rewrites."""
import json

from greenloop.speed import long_stream, scale
from test_seqspeed import _drive  # noqa: E402  (the pan whose end revisits its start)

DETECT_OUT = """greenloop-seq: knobs of the named default
# resumed at frame 40 (--state s.pkl)
frame\tmatch\tscore\tfile\tmatch_file
7162\t10\t3.2500\t7162.png\t10.png
3581\t5\t2.9000\t3581.png\t5.png
7352\t205\t3.1000\t7352.png\t205.png
# summary: 7400 frames, 3 closures, 812.5 frames/s (decoding included, 9.11 s for frames 40..7399); 2312 bytes per stored frame
"""


def test_closures_and_summary_are_read_from_detect_output():
    lines = DETECT_OUT.splitlines()
    assert long_stream.closures(lines) == [(7162, 10, "3.2500"), (3581, 5, "2.9000"), (7352, 205, "3.1000")]
    assert long_stream.summary(lines) == {"frames_per_s_reported": 812.5, "bytes_per_stored_frame": 2312}
    assert long_stream.closures(["no header", "1\t2\t3.0\ta\tb"]) == []       # lines before the header: not events


def test_correct_counts_matches_at_the_querys_place():
    # 7162 is pass 2's frame 10 (place 10): right; 3581 is winter's place 5, matched to summer's 5: right;
    # 7352 is place 200 matched to 205: 5 route frames off, outside +-2: wrong
    events = long_stream.closures(DETECT_OUT.splitlines())
    assert long_stream.correct(events, 7152) == 2
    assert long_stream.correct([(7354, 204, "3")], 7152) == 1        # place 202 vs 204: within 2
    assert long_stream.correct([], 7152) == 0


def test_write_section_replaces_the_stream_section_only(tmp_path):
    md = tmp_path / "scale.md"
    md.write_text(f"# Scaling\n\nkept table\n\n{scale.STREAM_HEADING}\n\nold\n")
    r = {"frames": 1000, "recording": "frames 0..999", "command": "python -m greenloop detect REC", "wall_seconds": 12.3,
         "frames_per_s_reported": 90.0, "cpu_percent": 97, "user_s": 10, "system_s": 2, "peak_rss_kB": 500_000,
         "bytes_per_stored_frame": 2312, "state_file_bytes": 3_000_000, "closures": 7, "closures_correct": 6,
         "resume_check": "identical", "note": "alone on the cores"}
    long_stream.write_section(tmp_path)                         # no JSON yet: scale.md untouched
    assert "old" in md.read_text()
    (tmp_path / "stream100k.json").write_text(json.dumps(r))
    for _ in range(2):                                          # rewriting twice leaves one section
        long_stream.write_section(tmp_path)
    text = md.read_text()
    assert text.startswith("# Scaling\n\nkept table\n\n") and "old" not in text
    assert text.count(scale.STREAM_HEADING) == 1 and "Wall time 12 s for 1,000 frames" in text
    kept = scale.stream_section(md)                              # what bench-scale keeps when it rewrites scale.md
    assert kept[0] == scale.STREAM_HEADING and "\n".join(kept) == text.split("kept table\n\n")[1]
    assert scale.stream_section(tmp_path / "absent.md") == []
    assert "7 closures, 6 at the query's place (+-2 route frames: 85.71 %)" in text and "Resume: identical." in text


def test_stream_and_resume_measure_a_detect_run(tmp_path):
    """The benchmark's own runs of detect, on a 500-frame drive whose last 150 frames revisit its
    start (test_seqspeed's pan): the closures it counts, the child's memory, the state file, and a
    run stopped halfway and resumed that prints the same closures."""
    rec = _drive(tmp_path / "back", list(range(350)) + list(range(150)))
    r, events = long_stream.stream(rec, tmp_path, save_every=100, m=7152)
    assert r["closures"] == len(events) >= 50 and all(f >= 350 for f, _, _ in events)
    assert r["state_file_bytes"] > 0 and r["peak_rss_kB"] > 50_000 and r["bytes_per_stored_frame"] >= 2048
    assert r["wall_seconds"] > 0 and r["frames_per_s_reported"] > 0
    said = long_stream.resume_check(rec, tmp_path, 100, 500, events)
    assert f"its {len(events):,} printed closures" in said and "are identical to" in said


def test_the_route_is_the_sources_summer_and_winter_frames(tmp_path):
    import cv2
    import numpy as np
    for season in ("summer", "winter"):
        (tmp_path / season).mkdir()
        for k in range(3):
            cv2.imwrite(str(tmp_path / season / f"images-{k:05d}.png"), np.zeros((32, 64, 3), np.uint8))
    assert long_stream.route_frames(tmp_path) == 6
