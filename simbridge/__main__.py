"""``python -m simbridge``: the ``simbridge`` command."""

from __future__ import annotations

import sys

from simbridge.cli import main


if __name__ == "__main__":
    sys.exit(main())
