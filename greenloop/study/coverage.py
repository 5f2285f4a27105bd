"""What of the five papers this study reproduces: one row per table and figure, read from results.

``ITEMS`` lists every table and figure of the papers in ``../shared/papers/`` with the notebook
output that reproduces it (a file under ``<results>/<notebook stem>/``) and what differs from the
paper. :func:`coverage` turns it into a table whose status comes from the results folders, not from
this list: an item whose output file exists in none of them, or only as a table whose every row
says "skipped" (an RGB-D experiment on a set without depth), is reported as "not run", whatever is
declared here, so the table cannot claim more than the committed outputs hold.

Statuses: "protocol ran" (the experiment's protocol runs end to end and is scored; the data differ
from the paper's, see ``data``; whether the paper's claim holds is ``greenloop.study.verdict``'s
question, not this table's), "protocol partly ran" (some of it runs; ``note`` says what is missing),
"not reproduced" (``note`` says why), "not an experiment" (diagrams, photographs, dataset
descriptions: nothing to measure).
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from greenloop.study import provenance

MAIN, QI, ZCA, ZHANG, XU = ("main paper (CNN + dictionary)", "Qi 2024", "ResNet/Inception/ZCA",
                            "Zhang 2017", "Xu 2022")
NO_IMAGES = "no {} images on the build machines (not downloadable offline)"

# (paper, item, what it shows, output "<stem>/<file>" or None, declared status, note)
ITEMS: list[tuple[str, str, str, str | None, str, str]] = [
    (MAIN, "Fig. 1, Fig. 2", "system overview, block diagram", None, "not an experiment", ""),
    (MAIN, "Table 1", "accuracy vs frames per spot L = 50/60/70", "01_spot_grouping/table1.csv",
     "protocol ran", "random 80/20 split as the paper; the blocked-split control beside it"),
    (MAIN, "Fig. 3, Fig. 4", "training/validation accuracy and loss over 200 epochs",
     "02_training_over_seeds/learning_curves.png", "protocol ran", "several seeds, not one"),
    (MAIN, "Fig. 5", "confusion matrix on the test set", "03_confusion_matrix/confusion_matrix.png",
     "protocol ran", ""),
    (MAIN, "Table 2", "per-class precision, recall, F1 on the test set", "03_confusion_matrix/table2.csv",
     "protocol ran", ""),
    (MAIN, "Table 3", "accuracy, original vs 1-pixel shifted frames", "04_shift_robustness/table3.csv",
     "protocol ran", ""),
    (MAIN, "Table 4", "per-class metrics on the shifted frames", "04_shift_robustness/table4.csv",
     "protocol ran", ""),
    (MAIN, "Sec. dictionary", "frequency-count dictionary, τ = L + Δ",
     "05_dictionary_threshold/tau_sweep.csv", "protocol ran", "closures also scored against ground "
     "truth, which the paper does not do"),
    (MAIN, "speed claim", "920 frames/s", "06_speed/stream.csv", "protocol ran", "on the 2-core build "
     "machine, beside plain Keras"),
    (MAIN, "Table 5", "comparison with other studies (quoted numbers)", None, "not an experiment",
     "literature table; the measured counterpart is the leaderboard (13_leaderboard)"),
    (QI, "Fig. 1, 2, 3", "network and RHLSH diagrams", None, "not an experiment", ""),
    (QI, "Table 1, Fig. 4", "datasets and example images", "00_dataset/frames.png", "protocol partly ran",
     NO_IMAGES.format("TUM or GreenHouse") + "; the sequences studied here are described instead"),
    (QI, "Fig. 5", "PR curves, RGB features", "07_feature_baselines/pr_curves.png", "protocol ran", ""),
    (QI, "Table 2", "AP and time per image: GhostNet, VGG19, EfficientNet-B0, ShuffleNet v2, SIFT",
     "07_feature_baselines/table2.csv", "protocol partly ran", "only MobileNet v1/v2 and EfficientNet-Lite0 carry "
     "ImageNet weights here; the paper's four networks run random-init"),
    (QI, "Fig. 6", "PR curves, RGB-D features", "09_rgbd_features/pr_rgb_vs_rgbd.png", "protocol ran",
     "needs a depth/ folder (synthetic sequence only)"),
    (QI, "Tables 3, 4", "RGB-D AP and time per image", "09_rgbd_features/rgbd.csv", "protocol partly ran",
     "depth needed; the paper's networks random-init (EfficientNet-Lite0 pretrained)"),
    (QI, "Table 5", "LSH parameters (16-bit codes, radius 4)", "11_lsh_matching/table6.csv",
     "protocol ran", "the parameters of 11's manifest"),
    (QI, "Fig. 7", "PR curves of LSH matching", "11_lsh_matching/figure7_pr_curves.png", "protocol ran", ""),
    (QI, "Table 6", "brute force vs SWP vs QDP: AP and matching time",
     "11_lsh_matching/table6.csv", "protocol ran", "plus scaling to 100k stored frames"),
    (QI, "Fig. 8, Fig. 9", "the robot; SLAM camera tracks in orchards", None, "not reproduced",
     "needs the robot's orchard sequences and a full SLAM system"),
    (ZCA, "Fig. 1, Table I", "pipeline diagram, ResNet architecture", None, "not an experiment", ""),
    (ZCA, "Fig. 2", "an example similarity matrix", "07_feature_baselines/similarity_matrices.png",
     "protocol ran", ""),
    (ZCA, "Table II", "datasets (City Centre, New College)", None, "not reproduced",
     NO_IMAGES.format("City Centre or New College")),
    (ZCA, "Fig. 3", "similarity matrices of ResNet50/101/152, Inception", "07_feature_baselines/"
     "similarity_matrices.png", "protocol partly ran", "cosine matrices of every network; InceptionV3 for "
     "Inception-v4 (not in Keras); random-init"),
    (ZCA, "Table III", "MPCA of ResNet50/101/152, Inception-v4 with ZCA + median filter",
     "08_descriptor_postprocessing/postprocessing.csv", "protocol partly ran", "MPCA with a threshold tuned on "
     "another part; random-init networks, other data"),
    (ZHANG, "Fig. 1, Fig. 2", "system overview, OverFeat architecture", None, "not an experiment", ""),
    (ZHANG, "Fig. 3", "an example similarity matrix", "07_feature_baselines/similarity_matrices.png",
     "protocol ran", ""),
    (ZHANG, "Table I", "datasets (New College, City Centre)", None, "not reproduced",
     NO_IMAGES.format("New College or City Centre")),
    (ZHANG, "Fig. 4", "similarity matrix S = 1 - D / max D of whitened features",
     "08_descriptor_postprocessing/similarity_raw_vs_whitened.png", "protocol ran",
     "VGG19 fc1 stands in for OverFeat"),
    (ZHANG, "Fig. 5", "PR curves, CNN features vs FAB-MAP",
     "08_descriptor_postprocessing/pr_raw_vs_whitened.png", "protocol partly ran", "raw vs L2 + PCA-whitened; "
     "no FAB-MAP implementation (SIFT-BoVW is the hand-crafted baseline in 07)"),
    (XU, "Fig. 1, 2, 3", "example scenes, SIFT matches, an RGB-D image", "00_dataset/frames.png",
     "not an experiment", ""),
    (XU, "Fig. 4, Table 1", "Siamese network and its layers", "10_siamese_rgbd/supervisions.csv",
     "protocol partly ran", "AlexNet-like trunk scaled down to fit 2 CPU cores (greenloop.methods.siamese.siamese)"),
    (XU, "Fig. 5, Fig. 6", "early and mid-level fusion pipelines", "10_siamese_rgbd/fusions.csv",
     "protocol ran", "needs depth"),
    (XU, "Fig. 8", "PR curves of the three supervisions", "10_siamese_rgbd/figure8_supervisions.png",
     "protocol ran", "on this study's sequences, not New College"),
    (XU, "Fig. 9", "PR curves of the three fusions", "10_siamese_rgbd/figure9_fusions.png",
     "protocol ran", "needs depth (no NYU images)"),
    (XU, "Table 2", "AP of mid-level fusion per layer", "10_siamese_rgbd/table2_mid_level_layers.csv",
     "protocol ran", "needs depth"),
    (XU, "Table 3", "extraction time per image", "10_siamese_rgbd/table3_extraction_time.csv",
     "protocol ran", "CPU only"),
]


def ran(path: Path) -> bool:
    """Whether a notebook output holds a result: it exists and, for a csv, not every row has a
    cell that is "skipped" or starts with "skipped:" (what a notebook writes for rows it could not run)."""
    if not path.is_file():
        return False
    if path.suffix != ".csv":
        return True
    cells = pd.read_csv(path, dtype=str, keep_default_na=False)
    skipped = cells.apply(lambda col: col.str.match(r"^skipped(:|$)")).any(axis=1)
    return not (len(cells) and skipped.all())


def coverage(results_dirs) -> pd.DataFrame:
    """Every table and figure of the five papers with its status in these results folders.

    results_dirs: results folders (``results``, ``results/nordland``, ...). Returns a DataFrame
    with columns paper, item, content, notebook, status, datasets (those whose folder holds the
    item's output with a result in it, :func:`ran`), note. The status is the declared one when some folder holds the output and
    "not run" when none does; items without an output keep their declared status.
    """
    folders = [Path(d) for d in results_dirs]
    names = [provenance.dataset_name(f) or f.name for f in folders]
    rows = []
    for paper, item, content, output, status, note in ITEMS:
        found = [n for f, n in zip(folders, names) if output and ran(f / output)]
        if output and not found and status != "not an experiment":
            status, note = "not run", f"no {output} in the results of {', '.join(names)}"
        rows.append({"paper": paper, "item": item, "content": content,
                     "notebook": output.split("/")[0] if output else "",
                     "status": status, "datasets": ", ".join(found), "note": note})
    return pd.DataFrame(rows)


def markdown(results_dirs) -> str:
    """:func:`coverage` as a GitHub markdown table (the README's and results/coverage.md's)."""
    return coverage(results_dirs).to_markdown(index=False) + "\n"
