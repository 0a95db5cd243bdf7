"""The ``mrpctl`` command: a thin layer over the public API that maps errors to exit codes."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from mrpctl import paper
from mrpctl.errors import MrpctlError

__all__ = ["main"]


def _example(_: argparse.Namespace) -> int:
    print(paper.summary())
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``mrpctl`` command."""
    parser = argparse.ArgumentParser(prog="mrpctl", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    example = commands.add_parser("example", help="print the paper's example (plant, gains, state, delay)")
    example.set_defaults(handler=_example)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 success, 2 user error)."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args))
    except MrpctlError as exc:
        print(f"mrpctl: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
