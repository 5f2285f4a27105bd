"""Progress bars for long work: shown in the terminal that runs ``make``, never in a notebook.

Inside a Jupyter kernel ``sys.stderr`` is the notebook's output area, while ``sys.__stderr__``
is the kernel process's own stderr: the terminal of the papermill/``make`` run that started it
(the kernel is started with ``IPKernelApp.capture_fd_output = False``, set for the project's
venv by the Makefile, so that low-level output is not copied into the notebook either).
Outside a kernel both are the same terminal.
"""
from __future__ import annotations

import sys

from tqdm import tqdm


def bar(iterable=None, **kw) -> tqdm:
    """A tqdm bar (same arguments as ``tqdm.tqdm``) written to the process's own stderr."""
    kw.setdefault("file", sys.__stderr__ or sys.stderr)
    kw.setdefault("mininterval", 1.0)
    return tqdm(iterable, **kw)
