"""greenloop.util: the one integer check (checks) and the one atomic file write / folder publish (files)."""
import os
from pathlib import Path

import numpy as np
import pytest

from conftest import execute_notebook
from greenloop.util import checks, files


def test_positive_int_accepts_and_refuses_with_the_argument_named():
    assert checks.positive_int("k", 3) == 3 and type(checks.positive_int("k", np.int64(3))) is int
    assert checks.positive_int("exclude", 0, 0, unit="frames") == 0
    with pytest.raises(ValueError, match=r"^exclude must be an integer >= 0 \(frames\), got -1$"):
        checks.positive_int("exclude", -1, 0, unit="frames")
    with pytest.raises(ValueError, match=r"n_bits must be an integer in \[1, 32\], got 33"):
        checks.positive_int("n_bits", 33, 1, 32)
    for bad in (True, 2.0, "3", None, 0):
        with pytest.raises(ValueError, match="k must be an integer >= 1"):
            checks.positive_int("k", bad)
    assert checks.positive_int("seq_len", 4.0, whole_floats=True) == 4
    with pytest.raises(ValueError, match="seq_len must be an integer >= 1, got 4.5"):
        checks.positive_int("seq_len", 4.5, whole_floats=True)


def test_write_atomic_writes_text_bytes_and_callables_and_leaves_nothing_on_failure(tmp_path):
    p = tmp_path / "sub" / "a.txt"
    assert files.write_atomic(p, "héllo") == p and p.read_text(encoding="utf-8") == "héllo"
    files.write_atomic(p, b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"
    files.write_atomic(p, lambda t: np.save(t, np.arange(3)) or os.replace(str(t) + ".npy", t))
    assert np.load(p).tolist() == [0, 1, 2]

    def fail(t):
        t.write_text("half")
        raise OSError("disk full")
    with pytest.raises(OSError, match="disk full"):
        files.write_atomic(p, fail)
    assert np.load(p).tolist() == [0, 1, 2]                       # the old file untouched
    assert sorted(x.name for x in p.parent.iterdir()) == ["a.txt"]   # no temporary left behind
    with pytest.raises(TypeError):
        files.write_atomic(p, 3)


def test_publish_folder_replaces_a_folder_whole(tmp_path):
    dest = tmp_path / "out"
    for content in ("old", "new"):
        tmp = tmp_path / f".tmp-{content}"
        tmp.mkdir()
        (tmp / "f").write_text(content)
        assert files.publish_folder(tmp, dest) == dest
        assert (dest / "f").read_text() == content and not tmp.exists()
    assert sorted(x.name for x in tmp_path.iterdir()) == ["out"]       # the old one deleted


def test_log_lines_go_to_the_terminal_not_the_notebook(tmp_path):
    """In a kernel (papermill), TensorFlow's log lines land on the kernel's own stderr once greenloop
    is imported, so the executed notebook has no output from them."""
    import nbformat
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell("import greenloop\nimport tensorflow as tf\n"
                                          "tf.get_logger().warning('a log line a reader must not scroll past')")]
    src, out = tmp_path / "a.ipynb", tmp_path / "b.ipynb"
    nbformat.write(nb, src)
    execute_notebook(src, out, cwd=str(Path(__file__).resolve().parents[1]))
    outputs = nbformat.read(out, as_version=4).cells[0].outputs
    assert not any("must not scroll past" in str(o) for o in outputs), outputs
