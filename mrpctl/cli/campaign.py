"""``mrpctl campaign run | report | replay``: Monte Carlo campaigns from a TOML spec into a Zarr store.

`add_parser` adds ``campaign`` and its three actions to the subparsers of the ``mrpctl`` parser.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm  # type: ignore[import-untyped]

from mrpctl.campaign.spec import load_campaign

__all__ = ["MISMATCH", "add_parser"]

#: Exit code when a replayed run differs from the stored one, or a campaign did not finish.
MISMATCH = 1


def _run(args: argparse.Namespace) -> int:
    # deferred: xarray and zarr (through the campaign store), only for campaign run
    from mrpctl.campaign.run import SchedulerLostError, run_campaign
    from mrpctl.campaign.store import CampaignStore

    spec = load_campaign(args.spec)
    store = CampaignStore(args.out, spec, args.chunk)  # creates or checks the store before the bar starts
    complete = store.complete()
    done = sum(store.bounds(i)[1] - store.bounds(i)[0] for i in range(store.chunks) if complete[i])
    stream = sys.stderr
    bar = tqdm(
        total=spec.count,
        initial=done,
        unit="run",
        desc=f"campaign {spec.base.name}",
        file=stream,
        disable=not stream.isatty(),
        smoothing=0.1,
    )

    def progress(index: int, start: int, stop: int) -> None:
        bar.update(stop - start)

    def failures(state: Any) -> None:  # the runs/s and the time left are tqdm's own
        bar.set_postfix(diverged=state.diverged, not_settled=state.not_settled, refresh=False)

    try:
        result = run_campaign(
            spec,
            args.out,
            chunk=args.chunk,
            scheduler=args.scheduler,
            workers=args.workers,
            on_chunk=progress,
            on_progress=failures,
        )
    except KeyboardInterrupt:
        bar.close()
        print(
            f"mrpctl: interrupted; the complete chunks are kept in {args.out}. "
            f"Resume with: mrpctl campaign run {args.spec} --out {args.out}",
            file=sys.stderr,
        )
        return 130
    except SchedulerLostError as lost:
        bar.close()
        resume = f"mrpctl campaign run {args.spec} --out {args.out} --scheduler {args.scheduler}"
        raise SchedulerLostError(lost.out, lost.scheduler, lost.stored, lost.todo, lost.cause, resume) from None
    bar.close()
    print(result)
    if args.report:
        # deferred: xarray and zarr (through the campaign store), only for --report
        from mrpctl.campaign.report import write_report

        summary, paths = write_report(args.out)
        print(summary)
        print(f"report written to {paths[0].parent}")
    return 0 if result.complete else MISMATCH


def _report(args: argparse.Namespace) -> int:
    # deferred: xarray and zarr (through the campaign store), only for campaign report
    from mrpctl.campaign.report import strict_json, write_report
    from mrpctl.campaign.trajectories import store_trajectories, trajectory_runs

    worst = max(args.worst, args.trajectories)
    summary, paths = write_report(args.out, worst=worst, intact_only=args.intact_only)
    runs = trajectory_runs(summary, args.trajectories, args.trajectory_run or ())
    stored = store_trajectories(args.out, runs) if runs else None
    if args.json:
        document = strict_json(summary.summary())
        document["files"] = [str(path) for path in paths]
        if stored is not None:
            document["trajectories"] = [
                {"run": run, "file": str(path), "sha256": digest}
                for run, path, digest in zip(stored.runs, stored.files, stored.sha256, strict=True)
            ]
        print(json.dumps(document, indent=2, allow_nan=False))
        return 0
    print(summary)
    print(f"report.md, summary.json and {len(paths) - 2} figures written to {paths[0].parent}")
    if stored is not None:
        print(stored)
    return 0


def _replay(args: argparse.Namespace) -> int:
    # deferred: xarray and zarr (through the campaign store), only for campaign replay
    from mrpctl.campaign.report import replay, save_replay_plot

    result = replay(args.out, args.run, trajectory=args.plot is not None)
    print(result)
    if args.plot is not None:
        print(f"figure written to {save_replay_plot(result, args.plot)}")
    return 0 if result.matches and result.damage is None else MISMATCH


def _folder(text: str) -> Path:
    """A results folder of this machine (a URL is refused: only this process writes the store)."""
    if "://" in text:
        raise argparse.ArgumentTypeError(
            f"{text} is a URL; the store is a folder of this machine (the workers send their chunks back)"
        )
    return Path(text)


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``campaign`` with its ``run``, ``report`` and ``replay`` sub-commands to ``subparsers``."""
    campaign = subparsers.add_parser("campaign", help="Monte Carlo campaigns: run (resumable), report, replay")
    commands = campaign.add_subparsers(dest="campaign_command", required=True, metavar="ACTION")

    run = commands.add_parser("run", help="run or resume a campaign into a Zarr store")
    run.add_argument("spec", type=Path, help="campaign TOML (see examples/campaigns)")
    run.add_argument("--out", type=_folder, required=True, help="results folder (resumed when it exists)")
    run.add_argument("--chunk", type=int, help="runs per chunk for a new store (default 1000)")
    run.add_argument(
        "--scheduler",
        help="'local' for a Dask LocalCluster, or a Dask scheduler address tcp://host:port (default: this process)",
    )
    run.add_argument("--workers", type=int, help="processes of the 'local' Dask cluster (default: the CPUs)")
    run.add_argument("--report", action="store_true", help="write the report when the campaign is complete")
    run.set_defaults(handler=_run)

    report = commands.add_parser("report", help="table and figures of a campaign's complete runs")
    report.add_argument("out", type=Path, help="results folder")
    report.add_argument("--worst", type=int, default=10, help="worst cases to list (default 10)")
    report.add_argument(
        "--json", action="store_true", help="print the summary as JSON (strict: NaN is null) instead of the table"
    )
    report.add_argument(
        "--trajectories",
        type=int,
        default=0,
        metavar="N",
        help="replay the N worst runs and keep their trajectories in OUT/trajectories (checksummed)",
    )
    report.add_argument(
        "--trajectory-run",
        type=int,
        action="append",
        metavar="RUN",
        help="also keep the trajectory of this run (repeatable)",
    )
    report.add_argument(
        "--intact-only", action="store_true", help="report over the intact runs of a damaged store and list the rest"
    )
    report.set_defaults(handler=_report)

    replay = commands.add_parser("replay", help="re-run one run alone and check it against the stored metrics")
    replay.add_argument("out", type=Path, help="results folder")
    replay.add_argument("--run", type=int, required=True, help="run index")
    replay.add_argument("--plot", type=Path, help="write sigma, omega, u against t to this PNG")
    replay.set_defaults(handler=_replay)
    return campaign
