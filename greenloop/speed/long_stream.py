"""A long recording streamed end to end through the CLI: ``make bench-stream`` ->
results/bench/stream100k.json and scale.md's section on it (:func:`write_section`).

The recording: frames 0..n-1 of the augmented Nordland recording (``augment.write_recording``:
colour 64x32 PNGs, written once into a work folder outside the repository). The command:
``python -m greenloop detect REC --index hnsw --state STATE --save-every S``, no knob: the named
default as a user runs it on a long recording. Measured: the wall seconds (``timing.timed``), the
child's user and system CPU seconds and its peak resident memory (``resource.getrusage``), the
frames/s and bytes per stored frame that detect prints, the state file's size, the closures printed
and how many match the query's place (+-2 route frames, ``scale.route_ground_truth``'s rule). The
resume check: the same command stopped halfway (``--stop-after``) then run again must print the same
closures (frame, match, score to 4 decimals) as the uninterrupted run.
"""
from __future__ import annotations

import json
import re
import resource
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from greenloop import report
from greenloop.datasets import augment, nordland
from greenloop.speed import scale
from greenloop.speed.timing import timed

class Child(NamedTuple):
    """One finished detect process: its stdout lines, wall and CPU seconds, peak memory (kB)."""
    lines: list
    wall_s: float
    user_s: float
    system_s: float
    peak_rss_kB: int


def recording(src, work: Path, frames: int, seed: int = 0) -> Path:
    """work/rec holding frames 0..frames-1 of the augmented recording (written unless work/rec's
    recording.json says it already holds them). Returns the folder."""
    rec, mark = work / "rec", work / "rec" / "recording.json"
    want = {"frames": frames, "seed": seed, "src": str(Path(src).resolve())}
    if mark.is_file() and json.loads(mark.read_text()) == want:
        return rec
    augment.write_recording(src, rec, frames, seed)
    mark.write_text(json.dumps(want))
    return rec


def detect_command(rec: Path, state: Path, save_every: int, stop_after: int | None = None) -> list[str]:
    """The CLI command streamed: detect with the named default in candidate mode (hnsw), saving state."""
    cmd = [sys.executable, "-m", "greenloop", "detect", str(rec), "--index", "hnsw", "--state", str(state),
           "--save-every", str(save_every)]
    return cmd + ([] if stop_after is None else ["--stop-after", str(stop_after)])


def run_child(cmd: list[str]) -> Child:
    """Run ``cmd`` (its progress bar on this terminal's stderr), capture stdout. Peak memory: the
    largest of this process's children so far (measure the run of interest first)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done, wall = timed(lambda: subprocess.run(cmd, stdout=subprocess.PIPE))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        raise RuntimeError(f"{' '.join(cmd)} exited with {done.returncode}")
    return Child(done.stdout.decode().splitlines(), wall, after.ru_utime - before.ru_utime,
                 after.ru_stime - before.ru_stime, after.ru_maxrss)


def closures(lines) -> list[tuple[int, int, str]]:
    """(frame, match, score as printed) of each closure line detect printed (after its header
    ``frame<TAB>match<TAB>score...``; lines starting with # are comments)."""
    out, cols = [], None
    for line in lines:
        f = line.split("\t")
        if f[0] == "frame":
            cols = {c: i for i, c in enumerate(f)}
        elif cols is not None and not line.startswith("#") and len(f) == len(cols):
            out.append((int(f[cols["frame"]]), int(f[cols["match"]]), f[cols["score"]]))
    return out


def summary(lines) -> dict:
    """frames/s and bytes per stored frame from detect's ``# summary:`` line."""
    line = next(l for l in lines if l.startswith("# summary:"))
    fps = re.search(r"([\d.]+) frames/s", line)
    b = re.search(r"(\d+) bytes per stored frame", line)
    return {"frames_per_s_reported": float(fps.group(1)), "bytes_per_stored_frame": int(b.group(1)) if b else None}


def route_frames(src) -> int:
    """Frames of the route the recording passes over: the source's summer plus winter frames."""
    summer, winter, _ = nordland.check_source(nordland.source_folder(src))
    return len(summer) + len(winter)


def correct(events, m: int, tolerance: int = 2) -> int:
    """How many (frame, match, ...) events match the query's place within ``tolerance`` frames of
    a route of m frames (``scale.route_places``)."""
    if not events:
        return 0
    e = np.array([(f, k) for f, k, *_ in events])
    places = scale.route_places(int(e.max()) + 1, m)
    return int((np.abs(places[e[:, 0]] - places[e[:, 1]]) <= tolerance).sum())


def stream(rec: Path, work: Path, save_every: int, m: int) -> tuple[dict, list]:
    """The uninterrupted run of detect over ``rec`` (its state in work/), a recording over a route of
    m frames: (the measured fields of stream100k.json, its closures as :func:`closures` gives them)."""
    state = work / "state.pkl"
    state.unlink(missing_ok=True)
    c = run_child(detect_command(rec, state, save_every))
    events = closures(c.lines)
    return {"wall_seconds": round(c.wall_s, 1), "cpu_percent": round(100 * (c.user_s + c.system_s) / c.wall_s),
            "user_s": round(c.user_s, 2), "system_s": round(c.system_s, 2), "peak_rss_kB": c.peak_rss_kB,
            **summary(c.lines), "closures": len(events), "closures_correct": correct(events, m),
            "state_file_bytes": state.stat().st_size}, events


def resume_check(rec: Path, work: Path, save_every: int, frames: int, events) -> str:
    """Stop the same command halfway, run it again, and say whether its closures equal ``events``
    (the uninterrupted run's)."""
    state = work / "state_resume.pkl"
    state.unlink(missing_ok=True)
    first = run_child(detect_command(rec, state, save_every, stop_after=frames // 2))
    second = run_child(detect_command(rec, state, save_every))
    resumed = closures(first.lines) + closures(second.lines)
    same = resumed == events
    return (f"the same command with --stop-after {frames // 2:,} ({first.wall_s:.0f} s, then stopped and saved), "
            f"then rerun (resumed at frame {frames // 2:,}, {second.wall_s:.0f} s): its {len(resumed):,} printed "
            f"closures (frame, match, score to 4 decimals) are {'identical to' if same else 'NOT identical to'} "
            f"the uninterrupted run's")


def run(src, out, frames: int = 100_000, work="/tmp/greenloop-stream", seed: int = 0, save_every: int = 25_000,
        note: str = "") -> dict:
    """Write the recording (once), stream it, check the resume; write out/stream100k.json (the
    measured fields, the command, ``report.provenance()``, versions, ``note``) and scale.md's section
    (:func:`write_section`). Returns the JSON's dict."""
    out, work = Path(out), Path(work)
    work.mkdir(parents=True, exist_ok=True)
    rec, m = recording(src, work, frames, seed), route_frames(src)
    r, events = stream(rec, work, save_every, m)
    cmd = detect_command(Path("REC"), Path("STATE"), save_every)
    r = {"frames": frames, "command": " ".join(["python"] + cmd[1:]),
         "recording": f"frames 0..{frames - 1} of the augmented Nordland recording (seed {seed}, colour 64x32 PNGs "
                      f"written by greenloop.datasets.augment into {work}, not in the repo): "
                      f"{frames / m:.1f} passes over the {m}-frame route", **r,
         "resume_check": resume_check(rec, work, save_every, frames, events),
         **report.provenance(), "versions": report.versions(), "note": note}
    report.write_json(out / "stream100k.json", r)
    write_section(out)
    return r


def section(r: dict) -> list[str]:
    """scale.md's lines on the measured run ``r`` (stream100k.json)."""
    made = (f" Run {r['date'][:10]} on {r['cpu']}, commit {r['git_commit'][:12]}." if "git_commit" in r else "")
    return [scale.STREAM_HEADING, "", f"{r['recording']}. Command: `{r['command']}` (`make bench-stream`).{made}", "",
            f"Wall time {r['wall_seconds']:.0f} s for {r['frames']:,} frames (target <= 900 s on 2 cores: "
            f"{'met' if r['wall_seconds'] <= 900 else 'not met'}), {r['frames_per_s_reported']:.0f} frames/s with PNG "
            f"decoding as detect reports it; CPU {r['cpu_percent']} % of one core (user {r['user_s']:.0f} s, system "
            f"{r['system_s']:.0f} s); peak RSS {r['peak_rss_kB'] / 1e6:.2f} GB; {r['bytes_per_stored_frame']} B per "
            f"stored frame; state file {r['state_file_bytes'] / 1e9:.2f} GB; {r['closures']:,} closures, "
            f"{r['closures_correct']:,} at the query's place (+-2 route frames: "
            f"{100 * r['closures_correct'] / max(r['closures'], 1):.2f} %).", "",
            *([f"Resume: {r['resume_check']}.", ""] if "resume_check" in r else []),
            *([f"Notes: {r['note']}", ""] if r.get("note") else [])]


def write_section(out) -> None:
    """Replace scale.md's section on the long CLI stream (from ``scale.STREAM_HEADING``, or the end) with the
    one read from out/stream100k.json; nothing when either file is missing."""
    md, js = Path(out) / "scale.md", Path(out) / "stream100k.json"
    if not (md.is_file() and js.is_file()):
        return
    lines = md.read_text().split("\n")
    kept = lines[:len(lines) - len(scale.stream_section(md))]
    report.write_atomic(md, "\n".join(kept + section(json.loads(js.read_text()))))
