"""Keep TensorFlow from probing CUDA on a machine that has no NVIDIA GPU.

On such a machine the pinned TensorFlow (2.21) calls ``cuInit`` when it first lists its devices (the
first op, ``tf.config.list_physical_devices``) and logs ``E0000 ... cuda_platform.cc:52] failed call
to cuInit: ... CUDA error`` to the process's stderr: in every ``make`` notebook run a line that reads
as a failure. ``TF_CPP_MIN_LOG_LEVEL=2`` (the Makefile's) lets it through, ``CUDA_VISIBLE_DEVICES=""``
does not stop the call, and ``TF_CPP_MIN_LOG_LEVEL=3`` would hide every other C++ error too;
``TF_ENABLED_DEVICE_TYPES=CPU`` makes TensorFlow create only its CPU device factory, so it never
calls ``cuInit`` (same CPU devices, XLA and TFLite conversion as before).

:func:`quiet_cuda_probe` sets it, run by ``import greenloop`` (before any TensorFlow import), only
where no NVIDIA device is present (:func:`nvidia_present`): a GPU machine keeps every device. A
process started from a GPU-less one (a sweep's jobs submitted from a login node inherit its
environment) drops the setting again when it finds a GPU, since :data:`MARK` says greenloop set it.
A user's own ``TF_ENABLED_DEVICE_TYPES`` is left alone.
"""
from __future__ import annotations

import glob
import os
import shutil

VARIABLE = "TF_ENABLED_DEVICE_TYPES"
MARK = "GREENLOOP_CPU_ONLY"       # set beside VARIABLE when greenloop set it (not the user)


def nvidia_present() -> bool:
    """True when this machine shows an NVIDIA GPU: a /dev/nvidia<N> device node, the driver's
    /proc/driver/nvidia, or ``nvidia-smi`` on PATH (any one of them: a GPU is never hidden)."""
    return bool(glob.glob("/dev/nvidia[0-9]*") or os.path.isdir("/proc/driver/nvidia")
                or shutil.which("nvidia-smi"))


def quiet_cuda_probe(environ=None, gpu: bool | None = None) -> bool:
    """Restrict TensorFlow to its CPU devices when there is no NVIDIA GPU (``gpu``: None detects
    it), in ``environ`` (default ``os.environ``, which TensorFlow reads when it is imported later in
    this process and which the kernels and workers it starts inherit). Returns True when TensorFlow
    is restricted by greenloop afterwards."""
    environ = os.environ if environ is None else environ
    gpu = nvidia_present() if gpu is None else gpu
    if environ.get(MARK):
        if not gpu:
            return True
        environ.pop(MARK, None)          # inherited from a GPU-less parent: use this machine's GPU
        if environ.get(VARIABLE) == "CPU":
            environ.pop(VARIABLE)
        return False
    if gpu or VARIABLE in environ:
        return False
    environ[VARIABLE] = "CPU"
    environ[MARK] = "1"
    return True
