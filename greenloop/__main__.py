"""``python -m greenloop COMMAND ...``: the command line (``greenloop.cli``; ``--help`` lists the commands)."""
import sys

from greenloop.cli import main

if __name__ == "__main__":
    sys.exit(main())
