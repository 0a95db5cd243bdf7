"""``python -m mrpctl.cli``: the ``mrpctl`` command line, as ``python -m mrpctl``."""

from __future__ import annotations

import sys

from mrpctl.cli import main

if __name__ == "__main__":
    sys.exit(main())
