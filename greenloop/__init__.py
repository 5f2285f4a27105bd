"""greenloop: CNN-based visual loop-closure detection for agricultural robots, as a study.

The pipeline's stages stand at the top of the package (``groundtruth``, ``spots``, ``cnn``,
``shift``, ``dictionary``, ``features``, ``similarity``, ``lsh``, ``siamese``, ``seqmatch``,
``evaluate``); the study's other parts are folders: ``datasets`` (the sequence-folder contract and
its builders), ``backbones`` (CNN ports and their weights), ``speed`` (the streaming detector and
its benchmark), ``study`` (results, coverage, sweeps) and ``util`` (building blocks).
docs/ARCHITECTURE.md draws the layout and what flows through it.
"""
from greenloop.util.devices import quiet_cuda_probe
from greenloop.util.progress import log_to_terminal

quiet_cuda_probe()     # no CUDA probe (and its cuInit error line) where there is no NVIDIA GPU
log_to_terminal()      # log lines in the terminal that runs make, never in a rendered notebook
