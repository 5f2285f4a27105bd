"""``python -m greenloop.datasets.synthetic OUT [--frames N] [--size WxH] ...``: see ``main``."""
import sys

from greenloop.datasets.synthetic import main

if __name__ == "__main__":
    sys.exit(main())
