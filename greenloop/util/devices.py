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

TensorFlow also writes start-up notices from C++ straight to file descriptor 2, whatever
``TF_CPP_MIN_LOG_LEVEL`` says: absl's "All log messages before absl::InitializeLog()", oneDNN's
"custom operations are on", "Could not find cuda drivers", and the converter's own ``cuInit``
call (the TFLite conversion of the CNN configuration). :func:`without_backend_notices` runs a
block with descriptor 2 going to a file and writes back every line that is not one of
:data:`NOTICES`; :func:`quiet_tensorflow_import` (run by ``import greenloop``) runs TensorFlow's
first import inside it. Everything else on descriptor 2 (errors, warnings, progress bars) still
reaches the terminal, after the block.
"""
from __future__ import annotations

import contextlib
import glob
import importlib.machinery
import os
import re
import shutil
import sys
import tempfile

NOTICES = re.compile(r"absl::InitializeLog\(\)|oneDNN custom operations are on|cudart_stub\.cc.*Could not find cuda"
                     r"|failed call to cuInit|Created TensorFlow Lite XNNPACK delegate for CPU")

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


@contextlib.contextmanager
def without_backend_notices(notices=NOTICES):
    """Run the block with file descriptor 2 (C++ and Python stderr alike) going to a temporary
    file; afterwards write every line of it that ``notices`` does not match back to descriptor 2,
    in order. Exceptions propagate unchanged."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as caught:
        os.dup2(caught.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            lines = caught.read().decode(errors="replace").splitlines(keepends=True)
            kept = "".join(line for line in lines if not notices.search(line))
            if kept:
                os.write(2, kept.encode())


class _QuietFirstImport:
    """A meta-path finder for one module name: it finds the module as the path finder does and
    runs its loader inside :func:`without_backend_notices`, once (then it leaves sys.meta_path)."""

    def __init__(self, name: str):
        self.name = name

    def find_spec(self, name, path=None, target=None):
        if name != self.name:
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is not None and hasattr(spec.loader, "exec_module"):
            run = spec.loader.exec_module

            def exec_module(module):
                with without_backend_notices():
                    run(module)
            spec.loader.exec_module = exec_module
        return spec


def quiet_tensorflow_import() -> bool:
    """Make TensorFlow's first import in this process drop its start-up :data:`NOTICES` (a
    finder at the head of sys.meta_path, gone after that import). Returns False when TensorFlow
    is already imported or the finder is already in place."""
    if "tensorflow" in sys.modules or any(isinstance(f, _QuietFirstImport) for f in sys.meta_path):
        return False
    sys.meta_path.insert(0, _QuietFirstImport("tensorflow"))
    return True
