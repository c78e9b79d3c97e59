"""``python -m lodprt``: the ``lodprt`` command line (:mod:`lodprt.cli`)."""

import sys

from lodprt.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
