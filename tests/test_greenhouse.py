import shutil

import pytest

from greenloop.datasets import greenhouse, sequence
from conftest import write_frames


def _fake_source(tmp_path, n=4):
    src = tmp_path / "src"
    write_frames(src, n, size=(8, 6))
    (src / "depth").mkdir()
    for p in (src / "rgb").iterdir():
        shutil.copy(p, src / "depth" / p.name)
    for name in greenhouse.TEXT_FILES:
        (src / name).write_text("0 0 0 0 0 0 0 1\n")
    return src


def test_download_from_local_url_is_resumable(tmp_path):
    src = _fake_source(tmp_path)
    dest = tmp_path / "dest"
    greenhouse.download(dest, base_url=src.as_uri(), n_frames=4, progress=False)
    assert len(sequence.list_frames(dest)) == 4 and (dest / "CameraTrajectory.txt").is_file()
    (dest / "rgb" / "2.png").unlink()
    before = (dest / "rgb" / "0.png").stat().st_mtime_ns
    greenhouse.download(dest, base_url=src.as_uri(), n_frames=4, progress=False)
    assert (dest / "rgb" / "2.png").is_file()
    assert (dest / "rgb" / "0.png").stat().st_mtime_ns == before  # kept, not fetched again


def test_download_checks_frame_count(tmp_path):
    src = _fake_source(tmp_path, n=3)
    with pytest.raises(RuntimeError, match="files failed"):
        greenhouse.download(tmp_path / "d", base_url=src.as_uri(), n_frames=4, progress=False)


def test_offline_fails_at_once_with_manual_instructions(tmp_path):
    with pytest.raises(RuntimeError, match=r"git clone --depth 1 .*SLAM-for-agricultural-equipment"):
        greenhouse.download(tmp_path / "d", base_url="http://127.0.0.1:9/dataset", n_frames=2,
                            timeout=2, progress=False)
