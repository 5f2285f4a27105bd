"""Manifests say where a result comes from (commit, environment hash, CPU, date), and
results/PROVENANCE.md lists it per results folder and notebook (greenloop.study.provenance)."""
import hashlib
import json
import platform
import shutil
import subprocess
from pathlib import Path

import pytest

from greenloop import report
from greenloop.cli import main as cli_main
from greenloop.study import provenance

ROOT = Path(__file__).resolve().parents[1]
GIT = shutil.which("git")


def git(repo, *args) -> str:
    return subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", *args],
                          capture_output=True, text=True, check=True).stdout.strip()


def test_manifest_records_commit_environment_hash_cpu_and_date(tmp_path):
    report.manifest(tmp_path, {"epochs": 3})
    m = json.loads((tmp_path / "manifest.json").read_text())
    pins = (ROOT / "environment.txt").read_bytes()
    assert m["environment_hash"] == hashlib.sha256(f"python {platform.python_version()}\n".encode() + pins).hexdigest()
    assert m["cpu_model"] == report.cpu_name() and m["cpu_model"] and m["cpu"].startswith(m["cpu_model"])
    assert m["date"][:2] == "20" and "machine" not in m          # the host name said nothing; the CPU does
    assert m["parameters"] == {"epochs": 3} and "numpy" in m["versions"] and "wall_seconds" in m
    if GIT and (ROOT / ".git").exists():
        assert m["git_commit"] == git(ROOT, "rev-parse", "HEAD") and isinstance(m["git_dirty"], bool)


def test_a_manifest_outside_a_git_checkout_says_null(tmp_path, monkeypatch):
    shutil.copy(ROOT / "environment.txt", tmp_path / "environment.txt")
    monkeypatch.setattr(report, "ROOT", tmp_path)                 # greenloop copied out of any checkout
    report.manifest(tmp_path / "out", {})
    m = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert m["git_commit"] is None and m["git_dirty"] is None and m["environment_hash"] == report.environment_hash()
    assert report.environment_hash(tmp_path / "absent.txt") is None

    def no_git(*a, **k):
        raise FileNotFoundError("git")
    monkeypatch.setattr(report.subprocess, "run", no_git)
    assert report.git_state(ROOT) == {"git_commit": None, "git_dirty": None}


@pytest.mark.skipif(GIT is None, reason="no git")
def test_dirty_means_a_tracked_file_outside_results_changed(tmp_path):
    git(tmp_path, "init", "-q")
    (tmp_path / "code.py").write_text("x = 1\n")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "t.csv").write_text("a\n1\n")
    git(tmp_path, "add", ".")
    git(tmp_path, "commit", "-qm", "c")
    head = git(tmp_path, "rev-parse", "HEAD")
    (tmp_path / "results" / "t.csv").write_text("a\n2\n")          # a run rewrites its results
    (tmp_path / "notes.txt").write_text("untracked\n")
    assert report.git_state(tmp_path) == {"git_commit": head, "git_dirty": False}
    (tmp_path / "README.md").write_text("prose\n")                  # prose and tests change no result
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("x\n")
    git(tmp_path, "add", "README.md", "docs")
    git(tmp_path, "commit", "-qm", "prose")
    head = git(tmp_path, "rev-parse", "HEAD")
    (tmp_path / "README.md").write_text("edited\n")
    (tmp_path / "docs" / "a.md").write_text("edited\n")
    assert report.git_state(tmp_path) == {"git_commit": head, "git_dirty": False}
    (tmp_path / "code.py").write_text("x = 2\n")
    assert report.git_state(tmp_path) == {"git_commit": head, "git_dirty": True}
    (tmp_path / "sub").mkdir()                                     # a folder inside a checkout is not its top
    assert report.git_state(tmp_path / "sub") == {"git_commit": None, "git_dirty": None}


def test_provenance_md_lists_each_notebook_and_dashes_what_an_old_manifest_lacks(tmp_path, capsys):
    res = tmp_path / "results"
    report.manifest(res / "01_new", {}, dataset="data/synthetic-greenhouse")
    (res / "01_new.ipynb").write_text(json.dumps({"cells": [], "metadata": {"papermill": {"duration": 12.34}}}))
    report.write_json(res / "00_old" / "manifest.json", {"date": "2026-12-05T01:53:16+00:00",
                                                         "cpu": "AMD EPYC (2 cores)", "wall_seconds": 18.4})
    report.write_json(res / "02_bare" / "manifest.json", {"parameters": {}})
    (res / "models").mkdir()                                       # no manifest: not a row
    new = json.loads((res / "01_new" / "manifest.json").read_text())
    assert cli_main(["provenance", str(res), "--out", str(tmp_path / "PROVENANCE.md")]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "PROVENANCE.md")
    text = (tmp_path / "PROVENANCE.md").read_text()
    assert "synthetic-greenhouse" in text and "models" not in text
    rows = {line.split(" | ")[0].strip("| "): line.strip("| \n").split(" | ") for line in text.splitlines()
            if line.startswith("| 0")}
    commit = "not a git checkout" if new["git_commit"] is None else new["git_commit"][:12]
    assert commit in rows["01_new"][1] and new["environment_hash"][:12] in rows["01_new"][2]
    assert rows["01_new"][3:] == [new["cpu_model"], new["date"], "12.3 s"]
    assert rows["00_old"] == ["00_old", "—", "—", "AMD EPYC (2 cores)", "2026-12-05T01:53:16+00:00", "18.4 s †"]
    assert rows["02_bare"] == ["02_bare", "—", "—", "—", "—", "—"]
    assert list(rows) == ["00_old", "01_new", "02_bare"]


def test_the_benchmarks_provenance_reads_scale_json_and_an_older_run_s_scale_md_line(tmp_path):
    bench = tmp_path / "bench"
    bench.mkdir()
    (bench / "scale.md").write_text("# x\n\nMachine: AMD EPYC (2 cores), searches on 1 thread; written 2026-12-04 19:33 UTC by x\n")
    (old,) = provenance.bench_rows(bench)                       # before scale.json: the md's line, dashes
    assert old == {"notebook": "scale.md (`make bench-scale`)", "commit": "—", "environment": "—",
                   "CPU": "AMD EPYC (2 cores)", "date": "2026-12-04 19:33 UTC", "duration": "—"}
    report.write_json(bench / "scale.json", {"git_commit": "0123456789abcdef", "environment_hash": "fedcba9876543210",
                                             "cpu_model": "AMD EPYC", "date": "2026-12-07T20:17:00+00:00",
                                             "wall_seconds": 1623.4})
    (new,) = provenance.bench_rows(bench)
    assert new == {"notebook": "scale.json (`make bench-scale`)", "commit": "`0123456789ab`", "environment": "`fedcba987654`",
                   "CPU": "AMD EPYC", "date": "2026-12-07T20:17:00+00:00", "duration": "1623.4 s †"}
    report.write_json(bench / "stream100k.json", {"git_commit": "abcdef0123456789", "cpu_model": "AMD EPYC",
                                                  "date": "2026-12-07T23:00:00+00:00", "wall_seconds": 301.26})
    rows = provenance.bench_rows(bench)                         # the long CLI stream's run beside it
    assert [r["notebook"] for r in rows] == ["scale.json (`make bench-scale`)", "stream100k.json (`make bench-stream`)"]
    assert rows[1]["commit"] == "`abcdef012345`" and rows[1]["duration"] == "301.3 s †"
