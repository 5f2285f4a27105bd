"""The notebook parameters a sequence folder implies, and the check make runs before each notebook.

``make`` runs every notebook as ``papermill -f <one YAML file>``, written here (:func:`main`,
``--params-out``): RESULTS/sequence_params.yaml, then params/datasets/<name>.yaml, then PARAMS,
later ones winning (a user's PARAMS overrides the dataset's budget, which overrides what the folder
says of itself), only the names the notebook's parameters cell declares (papermill warns about
others; a PARAMS name no notebook declares gets one line). ``sequence_params.yaml`` is written here
(:func:`sequence_parameters`) from the folder: ``exclude`` by the one exclusion rule
(greenloop.exclusion, which ``python -m greenloop detect`` reads too), and from its
``sequence.yaml`` (greenloop.datasets.sequence.read_description) ``frame_step`` and the traversal
boundaries; one line says how each was chosen, printed once per run.

Before each notebook, :func:`main` reads the parameters that notebook will get and, for the
notebooks that score loops (LOOP_NOTEBOOKS), whether the ground truth keeps any loop pair at that
exclude, at its frame_step or a finer one (:func:`loop_step`; a finer one is then passed and
printed, :func:`finer_step`). Where not even every frame keeps one, the notebook is not run: an
executed notebook that says why is written in its place and ``<results>/<stem>/skipped.md``
records the reason, so ``make`` carries on with the next one.

CLI (the Makefile's): ``python -m greenloop notebook-params NOTEBOOK DATASET RESULTS --out TMP.ipynb
[--params-out TMP.yaml --args-out TMP.args] -- [papermill -f/-p arguments]``.
"""
from __future__ import annotations

import ast
import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

from greenloop import exclusion, groundtruth, report
from greenloop.datasets import sequence
from greenloop.methods.dictionary import cnn, spots
from greenloop.util.files import write_atomic

DEFAULT_EXCLUDE = exclusion.DEFAULT_EXCLUDE   # every notebook's default exclusion window, frames
LOOP_NOTEBOOKS = ("07", "08", "09", "10", "11", "12", "13")   # they score loops: none, nothing to score
GROUND_TRUTH_NOTEBOOKS = ("05",) + LOOP_NOTEBOOKS   # they read a ground truth: without one, skipped
PARAMS_NAME = "sequence_params.yaml"


def loop_distances(folder) -> tuple[int, int] | None:
    """(closest, farthest) frame distance |i - j| of the loops of a loop-pair ground truth, before
    any exclusion window; None for poses (every neighbour is close), no ground truth or no loop.
    folder: a sequence folder or ``sequence.Sequence`` (opened once)."""
    seq = sequence.open(folder)
    if seq.ground_truth is None or seq.ground_truth.kind != "pairs":
        return None
    n = seq.n_frames
    p = seq.loop_pairs()
    if not len(p):
        return None
    i, lo, hi = p[:, 0], np.maximum(p[:, 1] - p[:, 2], 0), np.minimum(p[:, 1] + p[:, 2], n - 1)
    inside = (lo <= i) & (i <= hi)
    near = np.where(inside, np.where(hi > lo, 1, np.iinfo(np.int64).max),
                    np.minimum(np.abs(i - lo), np.abs(i - hi)))
    far = np.where(inside & (hi == lo), -1, np.maximum(np.abs(i - lo), np.abs(i - hi)))
    if far.max() < 1:
        return None
    return int(near.min()), int(far.max())


def sequence_parameters(folder) -> tuple[dict, list[str]]:
    """Papermill parameters a folder implies and one note per choice made for it.

    Returns ({name: value}: ``exclude`` by greenloop.exclusion's rule, ``frame_step`` from
    sequence.yaml, ``first_traversal_end`` (notebook 12) where the folder has several traversals),
    [sentences saying why]). folder: a sequence folder or ``sequence.Sequence`` (opened once).
    """
    seq = sequence.open(folder)
    rule = exclusion.exclusion(seq)
    params, notes = {"exclude": rule.frames}, [f"{seq.path}: {rule.rule}"]
    if seq.frame_step is not None:
        params["frame_step"] = seq.frame_step
        notes.append(f"frame_step {seq.frame_step} from {seq.path / sequence.DESCRIPTION_NAME}")
    ts = seq.traversals
    if len(ts) > 1:
        params["first_traversal_end"] = ts[1].start
        notes.append(f"first_traversal_end {ts[1].start}: the start of traversal {ts[1].name!r}")
    return params, notes


def write_parameters(folder, out) -> tuple[dict, list[str]]:
    """Write :func:`sequence_parameters` of ``folder`` as a papermill YAML file ``out`` (the notes
    as comments); returns what it wrote."""
    params, notes = sequence_parameters(folder)
    text = (f"# Parameters {folder} implies (greenloop.study.params); make passes this file first, so\n"
            f"# params/datasets/<name>.yaml and PARAMS override it.\n"
            + "".join(f"# {n}\n" for n in notes) + (yaml.safe_dump(params, sort_keys=True) if params else ""))
    write_atomic(out, text)
    return params, notes


def _value(text: str):
    """A ``-p NAME VALUE`` value as papermill reads it (bool, None, int, float, else the string)."""
    special = {"True": True, "False": False, "None": None}
    if text in special:
        return special[text]
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def notebook_defaults(notebook) -> dict:
    """{name: default} of a notebook's cell tagged ``parameters`` (each top-level assignment; a
    value that is not a literal, e.g. ``list(range(40, 125, 5))``, is evaluated when it can be
    and kept as its source text otherwise)."""
    cells = json.loads(Path(notebook).read_text())["cells"]
    cell = next((c for c in cells if "parameters" in c.get("metadata", {}).get("tags", [])), None)
    if cell is None:
        raise ValueError(f"{notebook} has no cell tagged 'parameters': papermill cannot run it")
    src = "".join(cell["source"])
    out = {}
    for node in ast.parse(src).body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            text = ast.get_source_segment(src, node.value)
            try:
                out[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                try:
                    out[node.targets[0].id] = eval(text, {"__builtins__": {"list": list, "range": range}})
                except Exception:
                    out[node.targets[0].id] = text
    return out


def effective_parameters(notebook, files=(), args=()) -> dict:
    """The parameters a papermill run of ``notebook`` gets: the defaults of its parameters cell,
    then each YAML file of ``files``, then papermill's arguments ``args`` (``-f FILE``, ``-y YAML``,
    ``-p NAME VALUE``, ``-r NAME VALUE``, in papermill's order of precedence); only the names its
    parameters cell declares (papermill injects the others too, but the notebook ignores them)."""
    out = notebook_defaults(notebook)
    declared = set(out)
    args, f_files, y, p, r = list(args), list(files), [], [], []
    k = 0
    while k < len(args):
        a = args[k]
        if a in ("-f", "--parameters_file") and k + 1 < len(args):
            f_files.append(args[k + 1]); k += 2
        elif a in ("-y", "--parameters_yaml") and k + 1 < len(args):
            y.append(args[k + 1]); k += 2
        elif a in ("-p", "--parameters", "-r", "--parameters_raw") and k + 2 < len(args):
            (r if a.startswith("-r") or a == "--parameters_raw" else p).append((args[k + 1], args[k + 2])); k += 3
        else:
            k += 1
    for f in f_files:
        out.update(yaml.safe_load(Path(f).read_text()) or {})
    for text in y:
        out.update(yaml.safe_load(text) or {})
    out.update({n: _value(v) for n, v in p})
    out.update(dict(r))
    return {k: v for k, v in out.items() if k in declared}


def loop_step(folder, params: dict) -> int | None:
    """The largest frame step <= ``params``' frame_step (1 when absent) whose described frames keep at
    least one ground-truth loop pair beyond ``params``' exclude: the step itself where it does, a finer
    one where only that does (a coarse budget step must not hide a short recording's loops), None
    where not even every frame does."""
    exclude, step = int(params.get("exclude", DEFAULT_EXCLUDE)), int(params.get("frame_step", 1) or 1)
    seq = sequence.open(folder)
    for s in range(step, 0, -1):
        if groundtruth.for_sequence(seq, np.arange(0, seq.n_frames, s), params.get("loop_threshold", 0.5), exclude).any():
            return s
    return None


def finer_step(notebook, folder, params: dict) -> tuple[int | None, str | None]:
    """(step, the printed line) where a loop notebook's frame_step keeps no ground-truth loop but a
    finer step does (:func:`loop_step`): e.g. quick's every 8th frame on a 200-frame recording driven
    twice; else (None, None). Notebook 13 chooses its own step (``experiments.leaderboard.choose_step``)."""
    stem = Path(notebook).stem
    if stem[:2] not in LOOP_NOTEBOOKS or stem[:2] == "13" or "frame_step" not in params:
        return None, None
    requested = int(params["frame_step"] or 1)
    step = loop_step(folder, params) if sequence.open(folder).ground_truth is not None else None
    if step is None or step == requested:
        return None, None
    return step, (f"{stem}: frame_step {step}, not the requested {requested}: at every {requested}th frame no "
                  f"described frame keeps a ground-truth loop beyond exclude={params.get('exclude')}; {step} is the "
                  f"largest step that keeps one")


def skip_reason(notebook, folder, params: dict) -> str | None:
    """Why ``notebook`` cannot run on ``folder`` with ``params`` (one sentence), or None: a
    LOOP_NOTEBOOKS notebook needs at least one ground-truth loop pair at its exclude, at its
    frame_step or a finer one (:func:`loop_step`); a GROUND_TRUTH_NOTEBOOKS one (05 counts its
    closure events against the ground truth) needs a ground truth; notebook 12 needs 2 spots in its
    first traversal (:func:`first_traversal_reason`)."""
    stem = Path(notebook).stem
    if stem[:2] not in GROUND_TRUTH_NOTEBOOKS:
        return None
    seq = sequence.open(folder)
    if seq.ground_truth is None:
        return (f"{stem} scores loop closures, and {folder} has no ground truth (add ground_truth.csv, "
                f"CameraTrajectory.txt or `ground_truth: aligned` in sequence.yaml, or run "
                f"`python -m greenloop import-gt FILE`)")
    if stem[:2] not in LOOP_NOTEBOOKS or loop_step(seq, params) is not None:
        return first_traversal_reason(stem, seq, params) if stem[:2] == "12" else None
    exclude = int(params.get("exclude", DEFAULT_EXCLUDE))
    dist = loop_distances(seq)
    closest = (f"its closest loop is {dist[0]} frames apart and its farthest {dist[1]}"
               if dist else "it has no loop at all")
    yaml_file = Path(folder) / sequence.DESCRIPTION_NAME
    if dist is None:
        fix = "this sequence does not revisit a place, so there is nothing to score"
    elif exclude < dist[1]:          # loops outside the window exist: the tolerance misses their partners
        fix = "widen the ground truth's tolerance"
    else:
        fix = f"write `exclude: {dist[0] // 2}` in {yaml_file} or run make with PARAMS='-p exclude {dist[0] // 2}'"
    return (f"{stem} scores loop closures, and the ground truth of {folder} has no loop pair more than "
            f"exclude={exclude} frames apart, even among all frames ({closest}): skipped; to run it, {fix}")


def first_traversal_reason(stem: str, folder, params: dict) -> str | None:
    """Why notebook 12 cannot learn places on ``folder``'s first traversal (``spots.first_traversal``:
    fewer than 2 spots of ``frames_per_spot`` frames before the first revisit at ``params``' exclude
    and loop_threshold, or before first_traversal_end; or its blocked split with ``gap`` leaves no
    training frame, ``cnn.split_indices``), or None."""
    seq = sequence.open(folder)
    gt = groundtruth.for_sequence(seq, threshold=params.get("loop_threshold", 0.5),
                                  exclude=int(params.get("exclude", DEFAULT_EXCLUDE)))
    try:
        _, y = spots.first_traversal(gt, params.get("frames_per_spot", 60), params.get("first_traversal_end"))
        cnn.split_indices(y, 0, split="blocked", gap=params.get("gap", 5))
    except ValueError as e:
        return f"{stem} trains a classifier of the places of the first traversal, and on {folder} {e}: skipped"
    return None


def write_skipped(notebook, out, folder, results_dir, reason: str, params: dict) -> Path:
    """Record a skipped notebook: the executed notebook ``out`` (one cell saying why) and
    ``<results_dir>/<stem>/skipped.md`` with its manifest. Returns ``out``."""
    import nbformat
    stem = Path(notebook).stem
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_markdown_cell(f"# {stem}: skipped\n\n{reason}")]
    nb.metadata["kernelspec"] = {"name": "greenloop", "display_name": "Python (greenloop)", "language": "python"}
    write_atomic(out, nbformat.writes(nb))
    folder_out = Path(results_dir) / stem
    write_atomic(folder_out / "skipped.md", f"### {stem}: skipped\n\n{reason}\n")
    report.manifest(folder_out, params, dataset=folder, skipped=reason)
    return Path(out)


PARAMETER_OPTIONS = {"-f": "-f", "--parameters_file": "-f", "-y": "-y", "--parameters_yaml": "-y",
                     "-p": "-p", "--parameters": "-p", "-r": "-r", "--parameters_raw": "-r"}


def split_arguments(args) -> tuple[dict[str, str], list[str]]:
    """Papermill arguments -> ({parameter name: where it comes from (a file, ``-y``, ``-p``, ``-r``)},
    [the other arguments, e.g. ``--start-timeout 120``, in their order]), read as
    :func:`effective_parameters` reads them."""
    args, names, other, k = list(args), {}, [], 0
    while k < len(args):
        kind = PARAMETER_OPTIONS.get(args[k])
        if kind in ("-f", "-y") and k + 1 < len(args):
            text = Path(args[k + 1]).read_text() if kind == "-f" else args[k + 1]
            names.update(dict.fromkeys(yaml.safe_load(text) or {}, args[k + 1] if kind == "-f" else kind))
            k += 2
        elif kind in ("-p", "-r") and k + 2 < len(args):
            names[args[k + 1]] = kind
            k += 3
        else:
            other.append(args[k])
            k += 1
    return names, other


def declared_names(notebook) -> set[str]:
    """The names ``notebook``'s parameters cell declares (:func:`notebook_defaults`)."""
    return set(notebook_defaults(notebook))


def declared_only(notebook, params: dict) -> dict:
    """``params`` without the names ``notebook``'s parameters cell does not declare (papermill would
    inject them anyway, warning "Passed unknown parameter")."""
    declared = declared_names(notebook)
    return {k: v for k, v in params.items() if k in declared}


def passed_parameters(notebook, files=(), args=()) -> dict:
    """What make passes ``notebook``: :func:`effective_parameters` of ``files`` and ``args`` (the
    same precedence), only the names they give that the notebook declares; never its own defaults,
    so that papermill injects what was chosen and nothing else."""
    names, _ = split_arguments([a for f in files for a in ("-f", str(f))] + list(args))
    return {k: v for k, v in effective_parameters(notebook, files, args).items() if k in names}


def undeclared(names, notebook) -> list[str]:
    """One line per name of ``names`` ({name: where from}) that no numbered notebook beside
    ``notebook`` (NN_*.ipynb in its folder) declares: most likely a typo, which papermill would
    inject unread."""
    import difflib
    folder = Path(notebook).parent
    known = set().union(*(declared_names(nb) for nb in sorted(folder.glob("[0-9][0-9]_*.ipynb"))),
                        declared_names(notebook))
    lines = []
    for name, source in names.items():
        if name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            lines.append(f"warning: parameter {name!r} ({source}) is declared by no notebook in "
                         f"{folder}{hint}: ignored")
    return lines


class NotebookRun(NamedTuple):
    """What make runs one notebook with (:func:`prepare_run`). notes: sequence_params.yaml's notes
    (empty when the file was already written by this run of make); undeclared: one line per name
    after -- that no notebook declares; reason: why the notebook cannot run on the folder (None: it
    can); params: the effective parameters; papermill: the run's papermill parameters (only the names
    the notebook declares; None when skipped); step_why: why a finer frame_step was chosen ("" when
    not); other: the other papermill options."""
    notes: list
    undeclared: list
    reason: str | None
    params: dict
    papermill: dict | None
    step_why: str
    other: list


def prepare_run(notebook, dataset, results, rest=()) -> NotebookRun:
    """Write RESULTS/sequence_params.yaml and decide a notebook's run: its parameters in papermill's
    precedence (sequence_params.yaml, then ``-p dataset DATASET -p results_dir RESULTS``, then
    ``rest``: the papermill -f/-p arguments of the run, params/datasets/*.yaml and PARAMS), or the
    reason it cannot run (:func:`skip_reason`)."""
    seq_file = Path(results) / PARAMS_NAME
    before = seq_file.read_text() if seq_file.is_file() else None
    _, notes = write_parameters(dataset, seq_file)
    params = effective_parameters(notebook, [seq_file], list(rest))
    reason = skip_reason(notebook, dataset, params)
    names, other = split_arguments(list(rest))
    run, why = None, ""
    if not reason:
        run = passed_parameters(notebook, [seq_file], ["-p", "dataset", str(dataset), "-p", "results_dir", str(results)]
                                + list(rest))
        step, why = finer_step(notebook, dataset, params)
        if why:
            run["frame_step"] = step
    return NotebookRun(notes if seq_file.read_text() != before else [], undeclared(names, notebook), reason, params,
                       run, why or "", other)


def write_run(r: NotebookRun, notebook, out, dataset, results, params_out=None, args_out=None) -> None:
    """A skipped notebook's executed stand-in at ``out`` (:func:`write_skipped`), else the run's one
    papermill YAML file (``params_out``) and its other options, NUL-separated (``args_out``)."""
    if r.reason:
        write_skipped(notebook, out, dataset, results, r.reason, r.params)
        return
    if params_out:
        write_atomic(params_out, f"# papermill parameters of {Path(notebook).name} (greenloop.study.params): "
                                 f"{PARAMS_NAME}, then the dataset's and PARAMS, only the names it declares\n"
                                 + yaml.safe_dump(r.papermill, sort_keys=False, allow_unicode=True))
    if args_out:
        write_atomic(args_out, "".join(f"{x}\0" for x in r.other))
