"""Progress bars for long work: shown in the terminal that runs ``make``, never in a notebook.

Inside a Jupyter kernel ``sys.stderr`` is the notebook's output area, while ``sys.__stderr__``
is the kernel process's own stderr: the terminal of the papermill/``make`` run that started it
(the kernel is started with ``IPKernelApp.capture_fd_output = False``, set for the project's
venv by the Makefile, so that low-level output is not copied into the notebook either).
Outside a kernel both are the same terminal. Log lines (TensorFlow's "Assets written", its
retracing warnings) go there too: :func:`log_to_terminal`, run when greenloop is imported.
"""
from __future__ import annotations

import logging
import sys

from tqdm import tqdm


def bar(iterable=None, **kw) -> tqdm:
    """A tqdm bar (same arguments as ``tqdm.tqdm``) written to the process's own stderr."""
    kw.setdefault("file", sys.__stderr__ or sys.stderr)
    kw.setdefault("mininterval", 1.0)
    return tqdm(iterable, **kw)


def log_to_terminal() -> None:
    """Send Python logging to the process's own stderr (the terminal, as the bars), once.

    A handler on the root logger, added before TensorFlow is imported, also keeps TensorFlow from
    adding its own handler, which writes to ``sys.stdout`` / ``sys.stderr``: in a kernel those are
    the notebook's output area. Levels are left as the libraries set them.
    """
    root = logging.getLogger()
    if any(getattr(h, "greenloop_terminal", False) for h in root.handlers):
        return
    h = logging.StreamHandler(sys.__stderr__ or sys.stderr)
    h.setFormatter(logging.Formatter("%(levelname)s:%(name)s:%(message)s"))
    h.greenloop_terminal = True
    root.addHandler(h)
