"""``python -m grasp_apso.experiment``: the command line of :mod:`grasp_apso.experiment.cli`."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
