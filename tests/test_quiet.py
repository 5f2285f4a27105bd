"""A quiet terminal (nothing a user would read as a failure): make passes each notebook only the parameters it declares,
papermill parses every notebook's parameters cell, and TensorFlow does not probe CUDA where there
is no NVIDIA GPU. One test runs a one-cell kernel: the one make runs is quiet too."""
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
import yaml

from greenloop.study import params, sweep
from greenloop.util import devices
from greenloop.cli import main as cli_main
from conftest import HANG_S, KERNEL_START_S, write_frames

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))


def _parameters_cell(notebook):
    nb = nbformat.read(notebook, as_version=4)
    return next(c for c in nb.cells if "parameters" in c.metadata.get("tags", []))


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_papermill_parses_every_line_of_each_parameters_cell(notebook, caplog):
    """papermill's PythonTranslator.inspect skips (warning "Unable to parse line N") a line with two
    '=', e.g. one in its comment, and then calls that declared name an unknown parameter."""
    from papermill.translators import PythonTranslator
    with caplog.at_level(logging.WARNING, logger="papermill"):
        found = {p.name for p in PythonTranslator.inspect(_parameters_cell(notebook))}
    assert not caplog.records, [r.getMessage() for r in caplog.records]
    assert found == set(params.notebook_defaults(notebook))


def test_the_params_cli_writes_one_file_of_declared_names_in_makes_precedence(tmp_path, capsys):
    from papermill.iorw import read_yaml_file
    seq = write_frames(tmp_path / "seq", 5)
    (seq / "sequence.yaml").write_text("exclude: 3\nframe_step: 2\n")       # frame_step: 00 does not declare it
    (tmp_path / "budget.yaml").write_text("exclude: 4\nframes_per_spot: 30\nepochs: 9\n")
    res, nb = tmp_path / "res", ROOT / "notebooks" / "00_dataset.ipynb"
    out, yml, args = res / ".tmp-00.ipynb", res / ".tmp-00.yaml", res / ".tmp-00.args"
    assert cli_main(["notebook-params", str(nb), str(seq), str(res), "--out", str(out), "--params-out", str(yml),
                        "--args-out", str(args), "--", "-f", str(tmp_path / "budget.yaml"),
                        "-p", "exclude", "5", "-p", "max_angle", "12.5", "-y", "loop_threshold: 0.25",
                        "-r", "reference_trajectory", "12", "-p", "epoch", "3", "--start-timeout", "90"]) == 0
    err = capsys.readouterr().err
    assert not out.exists()
    got = read_yaml_file(str(yml))                         # as papermill -f reads it
    assert got == {"dataset": str(seq), "results_dir": str(res), "frames_per_spot": 30, "loop_threshold": 0.25,
                   "exclude": 5, "max_angle": 12.5, "reference_trajectory": "12"}
    assert type(got["exclude"]) is int and type(got["max_angle"]) is float    # -p read as papermill reads it
    assert args.read_bytes() == b"--start-timeout\x0090\x00"                  # other papermill options, for xargs -0
    # epochs (another notebook's) is dropped quietly; epoch, declared by none, gets one line
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "'epoch' (-p)" in lines[0] and "did you mean 'epochs'" in lines[0], err
    # sequence.yaml < dataset budget < PARAMS: without -p exclude the budget wins, without both sequence.yaml
    cli_main(["notebook-params", str(nb), str(seq), str(res), "--out", str(out), "--params-out", str(yml), "--",
                 "-f", str(tmp_path / "budget.yaml")])
    assert read_yaml_file(str(yml))["exclude"] == 4
    cli_main(["notebook-params", str(nb), str(seq), str(res), "--out", str(out), "--params-out", str(yml)])
    assert read_yaml_file(str(yml)) == {"dataset": str(seq), "results_dir": str(res), "exclude": 3}
    assert not capsys.readouterr().err


def test_papermill_gets_no_unknown_parameter_from_make_for_any_notebook(tiny_near_loop_sequence, tmp_path, caplog):
    """Every notebook, prepared by papermill (parameters injected, not run) with what make passes
    on a two-traversal folder (first_traversal_end: notebook 12's only), a dataset budget and
    params/tiny.yaml + params/quick.yaml as PARAMS: no papermill warning at all."""
    import papermill
    rest = ["-f", str(ROOT / "params" / "datasets" / "gardenspoint.yaml"), "-f", str(ROOT / "params" / "quick.yaml"),
            "-f", str(ROOT / "params" / "tiny.yaml")]
    for nb in NOTEBOOKS:
        tmp, yml = tmp_path / f".tmp-{nb.stem}.ipynb", tmp_path / f".tmp-{nb.stem}.yaml"
        assert cli_main(["notebook-params", str(nb), str(tiny_near_loop_sequence), str(tmp_path), "--out", str(tmp),
                            "--params-out", str(yml), "--"] + rest) == 0
        assert yml.is_file() and not tmp.exists(), nb.stem
        given = yaml.safe_load(yml.read_text())
        declared = set(params.notebook_defaults(nb))
        assert set(given) <= declared and given.get("exclude", 20) == 20 and ("exclude" in given) == ("exclude" in declared)
        assert ("first_traversal_end" in given) == nb.stem.startswith("12")
        with caplog.at_level(logging.WARNING, logger="papermill"):
            papermill.execute_notebook(str(nb), str(tmp_path / nb.name), parameters=given, prepare_only=True,
                                       kernel_name="greenloop", progress_bar=False)
        assert not caplog.records, (nb.stem, [r.getMessage() for r in caplog.records])
        cells = json.loads((tmp_path / nb.name).read_text())["cells"]
        assert any("injected-parameters" in c["metadata"].get("tags", []) for c in cells)


def test_a_sweep_injects_only_the_names_its_notebook_declares(tiny_sequence, tmp_path):
    nb = ROOT / "notebooks" / "01_spot_grouping.ipynb"
    base = {"epochs": 2, "first_traversal_end": 100, "input_size": 64}     # 12's and 07's, not 01's
    p, = sweep.plan({"frames_per_spot_list": [[40]]}, tmp_path, base, tiny_sequence, nb)
    assert p["parameters"] == {"epochs": 2, "dataset": str(tiny_sequence.resolve()),
                               "frames_per_spot_list": [40], "results_dir": str(p["folder"])}
    assert sweep.plan({"x": [1]}, tmp_path, base, tiny_sequence)[0]["parameters"]["input_size"] == 64   # no notebook: as given


def test_tensorflow_is_kept_on_its_cpu_only_where_no_nvidia_gpu_is():
    env = {}
    assert devices.quiet_cuda_probe(env, gpu=False) and env == {devices.VARIABLE: "CPU", devices.MARK: "1"}
    assert devices.quiet_cuda_probe(env, gpu=False) and env[devices.VARIABLE] == "CPU"   # idempotent
    assert not devices.quiet_cuda_probe(env, gpu=True) and env == {}    # inherited by a GPU machine: dropped
    env = {}
    assert not devices.quiet_cuda_probe(env, gpu=True) and env == {}    # a GPU machine: nothing hidden
    env = {devices.VARIABLE: "CPU,GPU"}
    assert not devices.quiet_cuda_probe(env, gpu=False) and env == {devices.VARIABLE: "CPU,GPU"}   # the user's


@pytest.mark.skipif(devices.nvidia_present(), reason="this machine has an NVIDIA GPU: TensorFlow may use it")
def test_tensorflow_through_greenloop_prints_no_cuda_error_on_a_cpu_machine():
    """The pinned TensorFlow logs "failed call to cuInit: ... CUDA error" at its first op on a machine
    without a GPU, even with TF_CPP_MIN_LOG_LEVEL=2 (the Makefile's); imported after greenloop it
    does not, and it still computes (on its CPU); and it prints no absl/oneDNN/CUDA notice on stderr
    (one interpreter checks both: each TensorFlow start-up costs seconds)."""
    env = {k: v for k, v in os.environ.items() if k not in (devices.VARIABLE, devices.MARK)}
    env.update(PYTHONPATH=str(ROOT), TF_CPP_MIN_LOG_LEVEL="2", OMP_NUM_THREADS="1", TF_NUM_INTRAOP_THREADS="1")
    code = ("import {first}tensorflow as tf; print(float(tf.constant(1.0) + 1), "
            "[d.device_type for d in tf.config.list_physical_devices()])")
    runs = {k: subprocess.run([sys.executable, "-c", code.format(first=first)], env=env, capture_output=True,
                              text=True, timeout=HANG_S) for k, first in (("plain", ""), ("greenloop", "greenloop, "))}
    assert runs["greenloop"].returncode == 0 and runs["greenloop"].stdout.split() == ["2.0", "['CPU']"], runs["greenloop"]
    assert "cuInit" not in runs["greenloop"].stderr and "CUDA error" not in runs["greenloop"].stderr, runs["greenloop"].stderr
    assert not devices.NOTICES.search(runs["greenloop"].stderr), runs["greenloop"].stderr
    assert "cuInit" in runs["plain"].stderr        # what it hides (else the setting is no longer needed)


def test_the_kernel_make_runs_prints_nothing_of_its_own(tmp_path):
    """papermill's kernel (the venv's config that `make venv` writes) does not print its TCP
    transport warning once per notebook; the notebook's own output still reaches the notebook."""
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("print('hello from the cell')")])
    nbformat.write(nb, tmp_path / "in.ipynb")
    r = subprocess.run([sys.executable, "-m", "papermill", str(tmp_path / "in.ipynb"), str(tmp_path / "out.ipynb"),
                        "-k", "greenloop", "--no-progress-bar", "--start-timeout", str(KERNEL_START_S)],
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    assert "WARNING" not in r.stderr and "encryption" not in r.stderr, r.stderr
    assert "hello from the cell" in (tmp_path / "out.ipynb").read_text()


def test_backend_notices_are_dropped_and_every_other_line_kept():
    """without_backend_notices: TensorFlow's start-up notices written to descriptor 2 (as its C++
    code writes them) are dropped; other lines, C-level or Python, come back in order."""
    code = ("import os, sys\n"
            "from greenloop.util import devices\n"
            "with devices.without_backend_notices():\n"
            "    os.write(2, b'WARNING: All log messages before absl::InitializeLog() is called are written to STDERR\\n')\n"
            "    os.write(2, b'E0000 cuda_platform.cc:52] failed call to cuInit: INTERNAL: CUDA error\\n')\n"
            "    os.write(2, b'a real error from C\\n')\n"
            "    print('a python warning', file=sys.stderr)\n"
            "print('after', file=sys.stderr)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_S,
                       env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert r.returncode == 0, r.stderr
    assert r.stderr.splitlines() == ["a real error from C", "a python warning", "after"]
