"""Atomic file and folder writes: readers see the old file or the whole new one, never a part.

Standard library only, no greenloop import: the results writer, the dataset builders, the model
cache and the TFLite export all write through these two functions.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path


def write_atomic(path, content) -> Path:
    """Write a file so that readers see the old file or the whole new one, never a part.

    path: the file to write (its folder is created). content: str (written as UTF-8), bytes, or a
    callable ``content(tmp_path)`` that writes the file itself (e.g. ``np.savez``, a streamed
    download). The data goes to a temporary file in the same folder, renamed over ``path``
    (``os.replace``) once complete; on any error the temporary file is removed and ``path`` is
    left as it was. Returns ``Path(path)``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".tmp-{path.name}-")
    os.close(fd)
    try:
        if callable(content):
            content(Path(tmp))
        elif isinstance(content, (bytes, bytearray, memoryview)):
            Path(tmp).write_bytes(content)
        elif isinstance(content, str):
            Path(tmp).write_text(content, encoding="utf-8")
        else:
            raise TypeError(f"content must be str, bytes or a callable(tmp_path), got {type(content)}")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def publish_folder(tmp, dest) -> Path:
    """Move a completely written folder ``tmp`` to ``dest``, replacing any folder there.

    tmp must be on the same file system as dest (make it a sibling). An existing dest is renamed
    aside first, then tmp renamed to dest, then the old one deleted, so dest is always either the
    old folder or the whole new one (a gap of one rename at most). Returns ``Path(dest)``.
    """
    tmp, dest = Path(tmp), Path(dest)
    if dest.exists():
        old = Path(tempfile.mkdtemp(dir=dest.parent, prefix=f".old-{dest.name}-"))
        old.rmdir()
        dest.rename(old)
        try:
            tmp.rename(dest)
        except BaseException:
            old.rename(dest)
            raise
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(dest)
    return dest
