"""The command line, in one place: ``python -m greenloop COMMAND ...``.

One module per command, each with ``add_parser(subparsers)`` (its arguments) and ``run(args)``
(calls the library, prints, returns the exit status); the work lives in the library (evo's style).
A command that passes arguments on (``notebook-params``: papermill's) sets ``takes_rest`` and
reads what follows ``--`` as ``args.rest``.
``COMMANDS`` lists them in ``--help`` order; a new command is a module and one line there.
"""
from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")

from greenloop.cli import bench, data, detect, import_gt, layers, notebook_params, results, slam, sweep  # noqa: E402

COMMANDS = (detect, slam, import_gt, data, sweep, notebook_params, results, bench, layers)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser: one subparser per module of ``COMMANDS``."""
    ap = argparse.ArgumentParser(prog="python -m greenloop",
                                 description="greenloop: CNN visual loop-closure detection for agricultural robots.")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return ap


def main(argv=None) -> int:
    """Parse ``argv`` and run the command; errors print one line ``error: ...`` and return 2."""
    ap = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    cut = argv.index("--") if "--" in argv else len(argv)      # after --: arguments the command passes on
    args = ap.parse_args(argv[:cut])
    args.rest = argv[cut + 1:]
    if args.rest and not getattr(args, "takes_rest", False):
        ap.error(f"unrecognized arguments after --: {' '.join(args.rest)}")
    if not getattr(args, "func", None):
        ap.print_help()
        return 0
    try:
        return args.func(args)
    except (FileNotFoundError, FileExistsError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
