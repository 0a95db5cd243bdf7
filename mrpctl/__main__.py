"""``python -m mrpctl``: the ``mrpctl`` command line."""

from __future__ import annotations

import sys

from mrpctl.cli import main

if __name__ == "__main__":
    sys.exit(main())
