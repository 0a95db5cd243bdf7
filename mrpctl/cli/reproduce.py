"""``mrpctl reproduce``: every scenario of the paper, its figures and the claims table."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from mrpctl.cli.common import EXIT_CODES, Formatter, add_json, print_json
from mrpctl.reproduction import reproduce

__all__ = ["add_parser"]


def _reproduce(args: argparse.Namespace) -> int:
    out = Path(args.out)
    result = reproduce(out, t_final=args.t_final, overwrite=args.overwrite)  # refuses before the runs
    if args.json:
        print_json(
            {
                "claims": [
                    {"source": c.source, "claim": c.claim, "measurement": c.measurement, "verdict": c.verdict.value}
                    for c in result.claims
                ],
                "agreeing": result.agreeing,
                "differing": result.differing,
                "files": list(result.files),
            }
        )
    else:
        print(result)
        print(f"figures, claims.md and summary.json written to {out}")
    return 0


def add_parser(commands: Any) -> None:
    parser = commands.add_parser(
        "reproduce",
        help="run every scenario of the paper; figures and claims table",
        formatter_class=Formatter,
        epilog=EXIT_CODES,
    )
    parser.add_argument("--out", type=Path, default=Path("results"), help="output folder")
    parser.add_argument("--t-final", type=float, default=60.0, help="horizon of every run (s)")
    parser.add_argument(
        "--overwrite", action="store_true", help="replace claims.md, summary.json and the figures in --out"
    )
    add_json(parser)
    parser.set_defaults(handler=_reproduce)
