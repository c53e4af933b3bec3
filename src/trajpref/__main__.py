"""``python -m trajpref``: the ``trajpref`` command (``trajpref.cli.main``)."""

import sys

from trajpref.cli import main

if __name__ == "__main__":
    sys.exit(main())
