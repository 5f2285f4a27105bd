"""Small helpers every pipeline stage shares: integer-argument checks and atomic writes.

Standard library and NumPy only, and no greenloop import, so any module (the downloader, the
streaming detector, the results writer, the model cache) can use them without import cycles.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np


def positive_int(name: str, value, minimum: int = 1, maximum: int | None = None, unit: str = "",
                 whole_floats: bool = False) -> int:
    """``value`` as an int within [minimum, maximum], or ValueError naming ``name``.

    name: the argument's name as the caller knows it (e.g. "exclude", "--step").
    unit: an optional note appended in parentheses, e.g. "frames" -> "... >= 0 (frames), got 3.5".
    whole_floats: also accept floats that hold a whole number (3.0); by default only int and
        NumPy integer types pass. bool never passes (True is not a count).
    Returns int(value).
    """
    ok = not isinstance(value, bool) and (
        isinstance(value, (int, np.integer))
        or (whole_floats and isinstance(value, (float, np.floating)) and float(value).is_integer()))
    if ok:
        ok = value >= minimum and (maximum is None or value <= maximum)
    if not ok:
        rng = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        note = f" ({unit})" if unit else ""
        raise ValueError(f"{name} must be an integer {rng}{note}, got {value!r}")
    return int(value)


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
