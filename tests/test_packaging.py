"""Packaging as the ecosystem expects: ``pip install .`` gives a ``greenloop`` console script that
runs ``detect`` from the installed copy; pyproject, LICENSE and CITATION.cff agree."""
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from greenloop.datasets import sequence

ROOT = Path(__file__).resolve().parents[1]


def _pins() -> dict[str, str]:
    """{name: version} of environment.txt's pins."""
    lines = (ROOT / "environment.txt").read_text().splitlines()
    return dict(ln.split("==") for ln in lines if "==" in ln and not ln.startswith("#"))


def test_pyproject_declares_the_pinned_dependencies_the_script_and_the_license():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["scripts"] == {"greenloop": "greenloop.cli:main"} and meta["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    pins = _pins()
    declared = meta["dependencies"] + [d for group in meta["optional-dependencies"].values() for d in group]
    for req in declared:
        name, spec, version = re.match(r"([\w.-]+)\s*(~=|>=)\s*([\d.]+)", req).groups()
        if name in pins:              # a range that admits the pinned version, from the same major release
            pin = pins[name]
            assert tuple(map(int, pin.split("."))) >= tuple(map(int, version.split("."))), req
            assert spec == ">=" or pin.split(".")[0] == version.split(".")[0], req
    names = {re.match(r"[\w.-]+", d).group(0).lower() for d in declared}
    assert set(pins) - {"pip"} <= names and "evo" not in names      # every pin declared; no GPL dependency
    cff = (ROOT / "CITATION.cff").read_text()
    assert f'version: "{meta["version"]}"' in cff and "greenloop contributors" in cff and "license: MIT" in cff


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The package installed by pip from a copy of the source into a throwaway prefix, offline (no
    index, no build isolation: the virtualenv's setuptools builds it). Returns (prefix, environment)."""
    tmp = tmp_path_factory.mktemp("install")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "LICENSE", "README.md", "CITATION.cff"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "greenloop", src / "greenloop", ignore=shutil.ignore_patterns("__pycache__"))
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                        "--no-index", "--prefix", str(tmp / "prefix"), str(src)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    site = next((tmp / "prefix").glob("lib/python*/site-packages"))
    env = dict(os.environ, PYTHONPATH=str(site), TF_CPP_MIN_LOG_LEVEL="3")
    return tmp / "prefix", env


def test_pip_install_gives_a_greenloop_script_that_runs_detect_from_the_installed_copy(installed, tiny_sequence,
                                                                                         tmp_path):
    prefix, env = installed
    script = prefix / "bin" / "greenloop"
    where = subprocess.run([sys.executable, "-c", "import greenloop, greenloop.util.cache as c; "
                            "print(greenloop.__file__); print(c._STAMP_V1[0].is_file())"],
                           capture_output=True, text=True, env=env, cwd=tmp_path)
    assert where.stdout.split() == [str(next(prefix.glob("lib/python*/site-packages")) / "greenloop" / "__init__.py"),
                                    "True"], where.stderr          # the installed copy, with its data file
    r = subprocess.run([str(script), "--help"], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert r.returncode == 0 and "detect" in r.stdout
    folder = tmp_path / "field"
    (folder / "rgb").mkdir(parents=True)
    paths = sequence.list_frames(tiny_sequence)
    for k, src in enumerate(list(range(80)) + list(range(40))):         # frames 80..119 revisit 0..39
        shutil.copy(paths[src], folder / "rgb" / f"{k}.png")
    (folder / "sequence.yaml").write_text("exclude: 20\n")
    r = subprocess.run([str(script), "detect", str(folder)], capture_output=True, text=True, env=env, cwd=tmp_path,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    found = [tuple(map(int, ln.split("\t")[:2])) for ln in r.stdout.splitlines() if ln[:1].isdigit()]
    assert found and all(f >= 80 and m == f - 80 for f, m in found) and "# summary: 120 frames" in r.stdout
