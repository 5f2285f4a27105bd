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
from pathlib import Path


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
