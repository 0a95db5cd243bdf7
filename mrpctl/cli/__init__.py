"""The ``mrpctl`` command: a thin layer over the public API that maps errors to exit codes.

One module per subcommand family adds its parsers and handlers: `init` (``example``, ``init``),
`design`, `verify`, `analyze`, `simulate` (``simulate``, ``sweep``), `reproduce`, `export` and `campaign`;
`common` holds the shared options, the output helpers and the mapping of errors to exit codes,
`overrides` the scenario the options give, `limits` the memory and time refused before a run.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from typing import Any

from mrpctl.cli import analyze, campaign, design, export, init, reproduce, simulate, verify
from mrpctl.cli.common import (
    EXIT_BROKEN_PIPE,
    EXIT_CODES,
    EXIT_DIVERGED,
    EXIT_INTERRUPTED,
    NOT_VERIFIED,
    USER_ERROR,
    VERIFY_EXIT_CODES,
    Formatter,
    Parser,
    run_command,
)
from mrpctl.provenance import mrpctl_version

__all__ = [
    "EXIT_BROKEN_PIPE",
    "EXIT_CODES",
    "EXIT_DIVERGED",
    "EXIT_INTERRUPTED",
    "NOT_VERIFIED",
    "USER_ERROR",
    "VERIFY_EXIT_CODES",
    "build_parser",
    "main",
]


#: The subcommands in the order of ``mrpctl --help``; each adds its parser to the subparsers object.
SUBCOMMANDS: tuple[Callable[[Any], Any], ...] = (
    init.add_example,
    init.add_init,
    design.add_parser,
    verify.add_parser,
    analyze.add_parser,
    simulate.add_simulate,
    simulate.add_sweep,
    reproduce.add_parser,
    export.add_parser,
    campaign.add_parser,
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``mrpctl`` command."""
    parser = Parser(
        prog="mrpctl",
        description="Delayed-feedback attitude control with MRP shadow-set switching.",
        formatter_class=Formatter,
        epilog=EXIT_CODES,
    )
    parser.add_argument("--version", action="version", version=f"mrpctl {mrpctl_version()}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in SUBCOMMANDS:
        add(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (see `EXIT_CODES`)."""
    args = build_parser().parse_args(argv)
    return run_command(args.handler, args)
