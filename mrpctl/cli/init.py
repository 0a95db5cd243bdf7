"""``mrpctl example`` and ``mrpctl init``: the paper's example, and a starter scenario file to edit."""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path
from typing import Any

from mrpctl import paper
from mrpctl.cli.common import EXIT_CODES, Formatter, add_json, atomic_output, print_json, refuse_existing
from mrpctl.scenario import STARTER_SCENARIO, Scenario, parse_scenario, resolve_scenario, shipped_scenarios

__all__ = ["add_example", "add_init"]


def _example(args: argparse.Namespace) -> int:
    if args.json:
        print_json(
            {
                "inertia": paper.SPACECRAFT.inertia,
                "K": paper.GAIN,
                "sigma0": paper.INITIAL_SIGMA,
                "omega0": paper.INITIAL_OMEGA,
                "tau": paper.TAU,
                "rate": paper.MEASUREMENT_RATE,
                "boundary_layer_eps": paper.BOUNDARY_LAYER_EPS,
            }
        )
    else:
        print(paper.summary())
    return 0


def add_example(commands: Any) -> None:
    parser = commands.add_parser(
        "example", help="print the paper's example (plant, gains, state, delay)", formatter_class=Formatter
    )
    add_json(parser)
    parser.set_defaults(handler=_example)


def _init(args: argparse.Namespace) -> int:
    path = Path(args.path)
    refuse_existing(path, args.overwrite, "path")
    text = STARTER_SCENARIO if args.source is None else resolve_scenario(args.source).read_text(encoding="utf-8")
    _parse_text(text, path)  # what is written must load
    with atomic_output(path) as stream:
        stream.write(text)
    if args.json:
        print_json({"path": path, "source": args.source or "starter"})
    else:
        print(f"scenario written to {path} (run: mrpctl verify {path}; mrpctl simulate {path})")
    return 0


def _parse_text(text: str, path: Path) -> Scenario:
    """Parse scenario text as [load_scenario][mrpctl.scenario.load_scenario] would read it from ``path``."""

    return parse_scenario(tomllib.loads(text), name=path.stem)


def add_init(commands: Any) -> None:
    parser = commands.add_parser(
        "init",
        help="write a commented starter scenario (or a copy of a shipped one)",
        formatter_class=Formatter,
        epilog=EXIT_CODES,
    )
    parser.add_argument("path", nargs="?", type=Path, default=Path("scenario.toml"), help="file to write")
    parser.add_argument(
        "--from",
        dest="source",
        metavar="NAME",
        help=f"copy a shipped scenario instead of the starter: {', '.join(shipped_scenarios())}",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing file")
    add_json(parser)
    parser.set_defaults(handler=_init)
