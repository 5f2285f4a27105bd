"""Where a real dataset builder finds its source images: a local folder, or a shallow clone.

Every builder (``nordland``, ``gardenspoint``) accepts either the folder that holds its image
subfolders or a clone of the public repository that contains it; without a local copy it clones
the repository into a temporary folder. Both failures (folder missing, clone impossible) raise
one error that ends with the builder's fix.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from greenloop.datasets import sequence
from greenloop.util.files import publish_folder


def source_folder(src, subdir: str, needs: tuple[str, ...], what: str, fix: str) -> Path:
    """The folder holding every subfolder in ``needs``: ``src`` itself or ``src / subdir`` (a
    clone of the source repository). Raises FileNotFoundError naming ``what`` and ending with
    ``fix`` when neither holds them all."""
    src = Path(src)
    for cand in (src, src / subdir):
        if all((cand / n).is_dir() for n in needs):
            return cand
    raise FileNotFoundError(f"{what} source {src} not found or incomplete (it needs "
                            f"{', '.join(n + '/' for n in needs)} with the images): {fix}")


def aligned_traversals(src: Path, names: tuple[str, ...], fix: str) -> dict[str, list[Path]]:
    """The frames of aligned traversals (frame k of each is one place): {name: paths of src/name
    in numeric order}. Raises ValueError ending with ``fix`` for a subfolder without images, and
    ValueError naming the files only in one when two traversals' file names differ."""
    found = {}
    for t in names:
        try:
            found[t] = sequence.list_frames(src / t)
        except ValueError:
            raise ValueError(f"{src / t} holds no .png/.jpg images: {fix}") from None
    first = [p.name for p in found[names[0]]]
    for t in names[1:]:
        other = [p.name for p in found[t]]
        if other != first:
            raise ValueError(f"{src / t} does not match {src / names[0]} ({len(other)} vs {len(first)} frames; "
                             f"only in {names[0]}/: {sorted(set(first) - set(other))[:3]}, only in {t}/: "
                             f"{sorted(set(other) - set(first))[:3]}): frame k of every traversal must show "
                             f"the same place, so all need the same file names")
    return found


def check_output(out, tolerance: int, overwrite: bool) -> Path:
    """A builder's arguments checked before any work: ``tolerance`` an integer >= 0 frames (else
    ValueError), ``out`` not a file and, unless ``overwrite``, not a non-empty folder (else
    FileExistsError). Returns ``out`` as a Path."""
    if isinstance(tolerance, bool) or not isinstance(tolerance, int) or tolerance < 0:
        raise ValueError(f"tolerance must be an integer >= 0 frames, got {tolerance!r}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder: choose another output path")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise FileExistsError(f"{out} already exists and is not empty: delete it, choose another "
                              f"folder, or pass overwrite=True (CLI: --overwrite)")
    return out


def write_folder(out: Path, write) -> Path:
    """``write(tmp)`` fills a temporary folder beside ``out``, which then replaces ``out``
    (``util.files.publish_folder``), so a complete folder means a complete build; the temporary
    folder is removed if anything fails. Returns ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        write(tmp)
        publish_folder(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _git(args: list[str], timeout: float) -> subprocess.CompletedProcess:
    """Run git without prompts, aborting a transfer that stalls below 1 kB/s for 20 s."""
    env = dict(os.environ, GIT_TERMINAL_PROMPT="0", GIT_HTTP_LOW_SPEED_LIMIT="1000",
               GIT_HTTP_LOW_SPEED_TIME="20")
    return subprocess.run(["git", *args], env=env, capture_output=True, text=True,
                          timeout=timeout, check=True)


def shallow_clone(dest, url: str, fix: str, what: str, timeout: float = 20.0,
                  clone_timeout: float = 1800.0) -> Path:
    """``git clone --depth 1 url dest``; returns ``dest``.

    The remote is probed first (``git ls-remote``, ``timeout`` seconds), so an offline machine
    fails at once. Raises RuntimeError naming ``what`` and ending with ``fix`` when git is
    missing or the clone fails or times out.
    """
    if shutil.which("git") is None:
        raise RuntimeError(f"git is not installed, so the {what} source cannot be cloned: {fix}")
    try:
        _git(["ls-remote", url, "HEAD"], timeout)
        _git(["clone", "--depth", "1", "--quiet", url, str(dest)], clone_timeout)
    except subprocess.TimeoutExpired as e:
        raise RuntimeError(f"could not reach {url} (no answer in {e.timeout:.0f} s): {fix}") from None
    except subprocess.CalledProcessError as e:
        why = (e.stderr or "").strip().splitlines()
        raise RuntimeError(f"could not clone {url} ({why[-1] if why else f'git exit {e.returncode}'}): "
                           f"{fix}") from None
    return Path(dest)


def run_describe(out, describe) -> int:
    """A builder's ``--describe``: ``describe(out)`` rewrites the sequence.yaml of the built folder
    ``out``; prints what it wrote. Returns 0, or 1 with ``error: ...`` when ``out`` is no build of it."""
    try:
        path = describe(out)
    except (ValueError, FileNotFoundError, KeyError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(f"wrote {path}")
    return 0


def run_builder(a, build, clone, subdir: str, summary) -> int:
    """A builder's CLI after parsing: ``build(src)`` from ``a.src``, or from ``clone(tmp)`` (the
    source folder of a shallow clone of ``a.url`` into a temporary folder) as
    ``build(src, source_name="URL (subdir)")``; then prints ``summary(out)`` and the seconds taken.
    Returns the exit status: 0, or 1 with ``error: ...`` on stderr when the source is missing,
    the clone fails or the output exists."""
    t0 = time.perf_counter()
    try:
        if a.src:
            out = build(a.src)
        else:
            with tempfile.TemporaryDirectory(prefix=f"{Path(a.out).name}-src-") as tmp:
                print(f"cloning {a.url} (no --src given) ...", file=sys.stderr, flush=True)
                out = build(clone(Path(tmp)), source_name=f"{a.url} ({subdir})")
    except (RuntimeError, ValueError, FileNotFoundError, FileExistsError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(f"{summary(out)} in {time.perf_counter() - t0:.1f} s")
    return 0
