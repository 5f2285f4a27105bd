"""greenloop: CNN-based visual loop-closure detection for agricultural robots, as a study.

The pipeline's stages stand at the top of the package (``groundtruth``, ``exclusion``, ``spots``,
``cnn``, ``shift``, ``dictionary``, ``features``, ``similarity``, ``lsh``, ``retrieval``, ``siamese``,
``seqmatch``, ``seqslam``, ``evaluate``), beside ``report`` (results on disk); the study's other parts
are folders: ``datasets`` (the sequence-folder contract and its builders), ``backbones`` (CNN ports
and their weights), ``speed`` (the streaming detectors, timing and benchmarks), ``detectors`` (one
interface, one registry), ``study`` (assembled tables, coverage, sweeps), ``experiments`` (one module
per notebook's study) and ``util`` (building blocks). ``architecture.LAYERS`` says which may import
which; docs/ARCHITECTURE.md draws the layout and what flows through it.
"""
from greenloop.util.devices import quiet_cuda_probe, quiet_tensorflow_import
from greenloop.util.progress import log_to_terminal

quiet_cuda_probe()     # no CUDA probe (and its cuInit error line) where there is no NVIDIA GPU
quiet_tensorflow_import()   # nor TensorFlow's C++ start-up notices on stderr, whenever it is imported
log_to_terminal()      # log lines in the terminal that runs make, never in a rendered notebook
