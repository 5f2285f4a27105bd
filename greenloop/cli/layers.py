"""``python -m greenloop layers``: check the package against its layer contract
(``greenloop.architecture``), or print the listing docs/ARCHITECTURE.md holds."""
from __future__ import annotations

from pathlib import Path

from greenloop import architecture


def add_parser(sub) -> None:
    """The ``layers`` subcommand's arguments."""
    s = sub.add_parser("layers", help="check the package's import layers (exit 1 and the violations)")
    s.add_argument("--markdown", action="store_true", help="print the layer listing of docs/ARCHITECTURE.md")
    s.set_defaults(func=run)


def run(args) -> int:
    """Print the listing, or the violations (status 1) or one line saying the layers hold."""
    if args.markdown:
        print(architecture.markdown(), end="")
        return 0
    problems = architecture.check(Path(architecture.__file__).resolve().parent)
    print("\n".join(problems) if problems else
          f"greenloop holds its {len(architecture.LAYERS)} layers: no import up a layer, no cycle, none inside a function")
    return 1 if problems else 0
