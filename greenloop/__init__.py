"""greenloop: CNN-based visual loop-closure detection for agricultural robots, as a study, and the
detector a robot runs (``python -m greenloop detect FOLDER``).

From the bottom layer up (``architecture.LAYERS`` says which may import which; docs/ARCHITECTURE.md
draws the layout and what flows through it): ``util`` (building blocks: checks, atomic writes, the
cache, progress, threads, the one clock, kernels) and ``architecture`` (the layer contract);
``datasets`` (the sequence-folder contract, ground-truth formats and the builders); ``report``
(results on disk); ``groundtruth``, ``exclusion`` and ``evaluate`` (the one definition of a loop, the
one exclusion rule, scoring); ``backbones``, ``similarity`` and ``features`` (CNN ports and weights,
whitening, whole-image descriptors); ``methods`` (one folder per method: the paper's CNN + dictionary,
SeqSLAM, greenloop-seq, the Siamese CNN, the single-frame matcher, LSH retrieval; their ``interface``
and the ``registry``, the only door into them); ``speed`` (measuring only: timing and benchmarks);
``study`` (assembled tables, coverage, notebook parameters, sweeps, targets, provenance);
``experiments`` (one module per notebook's study); ``detect`` (a user's recording streamed through a
registered detector); ``cli`` and ``__main__`` (the command line).
"""
from greenloop.util.devices import quiet_cuda_probe, quiet_tensorflow_import
from greenloop.util.progress import log_to_terminal

quiet_cuda_probe()     # no CUDA probe (and its cuInit error line) where there is no NVIDIA GPU
quiet_tensorflow_import()   # nor TensorFlow's C++ start-up notices on stderr, whenever it is imported
log_to_terminal()      # log lines in the terminal that runs make, never in a rendered notebook
