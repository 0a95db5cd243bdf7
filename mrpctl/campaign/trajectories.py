"""Trajectories of chosen campaign runs, kept with the campaign: the worst N and any runs asked for.

A campaign stores each run's inputs and metrics, not its trajectory (a million runs of 60 s at 1 kHz
would be terabytes). The runs a reviewer wants to look at, the worst ones first, are re-simulated
from (seed, run) ([`replay`][mrpctl.campaign.report.replay]); a run is written only when its replay
reproduces every stored input and metric bit for bit, so the trajectory is the one the campaign ran.

``OUT/trajectories/run-<index>.nc`` is [`mrpctl.data.save`][mrpctl.data.save]'s NetCDF (read it back
with [`mrpctl.data.load`][mrpctl.data.load]), each file written atomically, and
``OUT/trajectories/SHA256SUMS`` (the ``sha256sum`` format, rewritten atomically after each file) lists
every file with its SHA-256, so ``sha256sum -c SHA256SUMS`` in that folder checks them.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from mrpctl._files import file_sha256
from mrpctl._validation import integer
from mrpctl.campaign.report import CampaignReport, replay
from mrpctl.campaign.store import open_campaign
from mrpctl.data import save
from mrpctl.errors import SpecificationError

__all__ = ["FOLDER", "StoredTrajectories", "store_trajectories", "trajectory_runs"]

#: The folder, under the campaign's results folder, that holds the trajectories.
FOLDER = "trajectories"
_SUMS = "SHA256SUMS"


@dataclass(frozen=True)
class StoredTrajectories:
    """The trajectories written: one file per run, with its SHA-256.

    Attributes
    ----------
    folder : pathlib.Path
        ``OUT/trajectories``.
    runs : tuple of int
        The runs written, in the order asked (worst first, then the chosen runs).
    files : tuple of pathlib.Path
        Their files.
    sha256 : tuple of str
        Their SHA-256 (hex), as listed in ``SHA256SUMS``.
    """

    folder: Path
    runs: tuple[int, ...]
    files: tuple[Path, ...]
    sha256: tuple[str, ...]

    def __str__(self) -> str:
        if not self.runs:
            return f"no trajectories written to {self.folder}"
        runs = ", ".join(str(run) for run in self.runs)
        return f"{len(self.runs)} trajectories (runs {runs}) written to {self.folder}, checksums in {_SUMS}"


def trajectory_runs(summary: CampaignReport, worst: int, runs: Iterable[int] = ()) -> tuple[int, ...]:
    """The worst ``worst`` runs of ``summary`` (its severity order), then ``runs``, each once."""
    worst = integer("trajectories", worst, minimum=0)
    if worst > len(summary.worst):
        raise SpecificationError(
            f"trajectories: {worst} worst runs asked, but the report lists {len(summary.worst)} "
            f"(report with worst >= {worst})"
        )
    chosen = [case.run for case in summary.worst[:worst]]
    for run in runs:
        run = integer("run", run, minimum=0, maximum=summary.count - 1)
        if run not in chosen:
            chosen.append(run)
    return tuple(chosen)


def _write_sums(folder: Path, sums: dict[str, str]) -> None:
    text = "".join(f"{digest}  {name}\n" for name, digest in sorted(sums.items()))
    handle, temporary = tempfile.mkstemp(dir=folder, prefix=f".{_SUMS}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, folder / _SUMS)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)


def _read_sums(folder: Path) -> dict[str, str]:
    path = folder / _SUMS
    if not path.exists():
        return {}
    sums = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        digest, _, name = line.partition("  ")
        if name:
            sums[name] = digest
    return sums


def store_trajectories(out: str | Path, runs: Iterable[int]) -> StoredTrajectories:
    """Replay ``runs`` of the campaign in ``out`` and write their trajectories to ``out/trajectories``.

    Raises
    ------
    SpecificationError
        If a run is not stored yet, or its replay does not reproduce what the campaign stored (its
        trajectory would not be the campaign's; the replay's mismatches are named).
    """
    out = Path(out)
    dataset = open_campaign(out, intact_only=True)
    seed = int(str(dataset.attrs["seed"]))
    folder = out / FOLDER
    folder.mkdir(exist_ok=True)
    sums = _read_sums(folder)
    written, files, digests = [], [], []
    for run in runs:
        result = replay(out, run, trajectory=True)
        if not result.matches or result.trajectory is None:
            raise SpecificationError(
                f"run {run}: its replay differs from the stored run in {', '.join(result.mismatches) or 'its damage'}"
                f"; no trajectory written (mrpctl campaign replay {out} --run {run} shows the numbers)"
            )
        path = save(result.trajectory, folder / f"run-{run}.nc", seed=seed)
        sums[path.name] = file_sha256(path)
        _write_sums(folder, sums)
        written.append(run)
        files.append(path)
        digests.append(sums[path.name])
    return StoredTrajectories(folder=folder, runs=tuple(written), files=tuple(files), sha256=tuple(digests))
