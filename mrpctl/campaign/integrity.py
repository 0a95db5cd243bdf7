"""A campaign store's integrity: per-chunk SHA-256 records, their check, and the one-writer lock.

**Checksums.** Every file of a campaign chunk (one Zarr chunk file per per-run array) is hashed
(SHA-256 and size) right after the chunk is written, and the record is written atomically
(temporary file, then rename) to ``campaign.zarr/chunk_complete/sha256/<chunk>.json`` *before*
the chunk's completion flag is set. The files written when the store is created (every
``zarr.json``, the ``run`` coordinate, the per-sample files' arrays) are recorded in
``chunk_complete/sha256/store.json`` inside the temporary store, before it is renamed into place,
so a store that exists has its record (the ``zarr.json`` files only as "must exist and parse": their
attributes may be edited on purpose; the data files by SHA-256). A chunk file Zarr did not write (its values all equal
the array's fill value) is recorded as absent. The records live inside the ``chunk_complete`` array's
folder, where Zarr never looks (no warning for readers of the group) and where they travel with
the store.

A SHA-256 manifest rather than Zarr's CRC32C codec: the codec checks the bytes of a chunk that is
there, but a *deleted* chunk file reads as the fill value (NaN, −1) without any error, and Zarr does
not write chunks equal to the fill value at all; the manifest catches deletion, truncation and any
changed byte, names the file, and leaves the chunk files (and so the campaign hash) as they were.

A store written before the records existed (no ``sha256`` folder) is read as before, with the note
that it cannot be verified; such a store is resumed without records (no partial verification).

**One writer.** [writer_lock][mrpctl.campaign.integrity.writer_lock] takes ``fcntl.flock`` on
``out/campaign.lock`` before the first byte of the store is written and holds it until the run ends (normally,
by an exception or by Ctrl-C); the kernel releases it when the process dies, so a lock file left by a process
that is gone (a stale lock) is simply taken over. The file holds the holder's host, pid, start time and
command, which the refusal quotes. On a network file system the lock is as good as its ``flock`` (Linux NFS v4
maps it to a byte-range lock).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import logging
import os
import socket
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl.errors import MrpctlError

__all__ = [
    "LOCK_NAME",
    "ChunkDamage",
    "StoreCheck",
    "StoreDamagedError",
    "StoreLockedError",
    "check_store",
    "writer_lock",
]

logger = logging.getLogger(__name__)

LOCK_NAME = "campaign.lock"
#: The folder of the checksum records, relative to the store.
RECORDS = Path("chunk_complete") / "sha256"
_STATIC = "store.json"


class StoreLockedError(MrpctlError, RuntimeError):
    """Another process is writing this campaign store."""


class StoreDamagedError(MrpctlError, RuntimeError):
    """A campaign store's files do not match their checksum records."""


# -- the lock -----------------------------------------------------------------------------------------------------

_held: dict[str, list[Any]] = {}  # resolved lock path -> [fd, depth]
_held_guard = threading.Lock()


def _describe(holder: dict[str, Any]) -> str:
    parts = [f"host {holder.get('host', '?')}", f"pid {holder.get('pid', '?')}"]
    if holder.get("started"):
        parts.append(f"since {holder['started']}")
    if holder.get("command"):
        parts.append(f"command {holder['command']!r}")
    return ", ".join(parts)


def _read_holder(fd: int) -> dict[str, Any]:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 65536).decode("utf-8", "replace")
        holder = json.loads(text) if text.strip() else {}
        return holder if isinstance(holder, dict) else {}
    except (OSError, ValueError):
        return {}


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextlib.contextmanager
def writer_lock(out: str | Path) -> Iterator[None]:
    """Hold the one-writer lock of the results folder ``out`` (created if needed) for the ``with`` block.

    Re-entrant within one process (a run that opens its store holds it once). Released on every exit
    of the block, and by the kernel if the process dies.

    Raises
    ------
    StoreLockedError
        If another process holds it; the message names the holder (host, pid, start time, command).
    """
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    key = str(path.resolve())
    with _held_guard:
        if key in _held:
            _held[key][1] += 1
            entry = _held[key]
        else:
            entry = None
    if entry is None:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            os.close(fd)
            note = ""
            pid = holder.get("pid")
            if holder.get("host") == socket.gethostname() and isinstance(pid, int) and not _pid_alive(pid):
                note = " (that pid is gone; a process it started still holds the lock)"
            raise StoreLockedError(
                f"out: {folder} is being written by another process ({_describe(holder)}){note}; wait until it "
                f"ends (the lock {path} is released when it exits) or choose another --out"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        previous = _read_holder(fd)
        if previous.get("pid") is not None and previous.get("pid") != os.getpid():
            logger.info("campaign lock %s: took over the stale lock of %s", path, _describe(previous))
        record = {
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "command": " ".join(sys.argv),
        }
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, (json.dumps(record, sort_keys=True) + "\n").encode("utf-8"))
        with _held_guard:
            entry = _held[key] = [fd, 1]
    try:
        yield
    finally:
        with _held_guard:
            entry[1] -= 1
            last = entry[1] == 0
            if last:
                del _held[key]
        if last:
            os.close(entry[0])  # releases the flock; the file stays (unlinking it would race a new holder)


# -- checksums ----------------------------------------------------------------------------------------------------


def _digest(path: Path) -> list[Any] | None:
    """[sha256, size] of a file, None when it does not exist."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    return [hashlib.sha256(data).hexdigest(), len(data)]


def _write_json_atomically(path: Path, value: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + f".tmp{os.getpid()}")
    with open(temporary, "w", encoding="utf-8") as handle:
        handle.write(json.dumps(value, sort_keys=True, allow_nan=False))
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(temporary, path)


def chunk_files(store: Path, arrays: dict[str, int], index: int) -> dict[str, Path]:
    """The chunk file of campaign chunk ``index`` of each per-run array (name -> ndim), Zarr v3 or v2 keys."""
    v3 = (store / "zarr.json").exists()
    found = {}
    for name, ndim in arrays.items():
        coords = [str(index)] + ["0"] * (ndim - 1)
        found[name] = store / name / ("c/" + "/".join(coords) if v3 else ".".join(coords))
    return found


def record_path(store: Path, index: int) -> Path:
    return store / RECORDS / f"{index:06d}.json"


def record_chunk(store: Path, arrays: dict[str, int], index: int) -> None:
    """Hash chunk ``index``'s files and write the record atomically (before its flag is set)."""
    files = chunk_files(store, arrays, index)
    _write_json_atomically(record_path(store, index), {str(p.relative_to(store)): _digest(p) for p in files.values()})


def forget_chunk(store: Path, arrays: dict[str, int], index: int) -> None:
    """Remove chunk ``index``'s record and files (before it is written again)."""
    record_path(store, index).unlink(missing_ok=True)
    for path in chunk_files(store, arrays, index).values():
        path.unlink(missing_ok=True)


def record_static(store: Path, skip: set[str]) -> None:
    """Hash the files a new store is created with (metadata, coordinates), except the per-run arrays' chunks."""
    entries = {}
    for path in sorted(store.rglob("*")):
        relative = path.relative_to(store)
        metadata = path.name in ("zarr.json", ".zarray", ".zattrs", ".zgroup")
        if not path.is_file() or (relative.parts[0] in skip and not metadata):
            continue
        if relative.parts[:2] == RECORDS.parts:
            continue
        # metadata may be edited on purpose (attributes): it must exist and parse; data files are hashed
        entries[str(relative)] = "metadata" if metadata else _digest(path)
    _write_json_atomically(store / RECORDS / _STATIC, entries)


@dataclass(frozen=True)
class ChunkDamage:
    """One damaged campaign chunk: its index, runs [start, stop), the array and file, and what is wrong."""

    index: int
    start: int
    stop: int
    array: str
    file: str
    problem: str

    def __str__(self) -> str:
        return f"chunk {self.index} (runs {self.start}-{self.stop - 1}), array {self.array}: {self.file} {self.problem}"


@dataclass(frozen=True)
class StoreCheck:
    """What [check_store][mrpctl.campaign.integrity.check_store] found.

    Attributes
    ----------
    verified : bool
        False for a store written without checksum records (nothing could be checked).
    intact : tuple of bool
        Per campaign chunk: complete and every file matches its record (for an unverified store: the flag).
    damaged : tuple of ChunkDamage
        The first problem of each damaged chunk (a complete flag without a record, a record without a
        flag file, a missing, truncated or changed file).
    static : tuple of str
        Problems of the files written at creation (metadata, coordinates): not repairable by a resume.
    """

    path: Path
    verified: bool
    intact: tuple[bool, ...]
    damaged: tuple[ChunkDamage, ...] = field(default=())
    static: tuple[str, ...] = field(default=())

    def runs_text(self) -> str:
        return ", ".join(f"{d.start}-{d.stop - 1}" for d in self.damaged)

    def error(self, *, repair: str) -> StoreDamagedError:
        """The refusal: store, each damaged chunk (array, file, runs, problem) and the repairing command."""
        if self.static:
            return StoreDamagedError(
                f"out: the campaign store {self.path} is damaged: {'; '.join(self.static[:3])}"
                + (f" (and {len(self.static) - 3} more)" if len(self.static) > 3 else "")
                + "; these files are written once when the store is created, so a resume cannot repair them: run "
                "the campaign again into a new --out"
            )
        shown = "; ".join(str(d) for d in self.damaged[:5])
        more = f" (and {len(self.damaged) - 5} more chunk(s))" if len(self.damaged) > 5 else ""
        return StoreDamagedError(
            f"out: the campaign store {self.path} has {len(self.damaged)} damaged chunk(s): {shown}{more}; "
            f"repair with: {repair} (re-runs the damaged chunks), or report over the intact runs with --intact-only"
        )


def _flag_files(store: Path, chunks: int) -> list[Path]:
    return [chunk_files(store, {"chunk_complete": 1}, i)["chunk_complete"] for i in range(chunks)]


def _flags(store: Path, chunks: int) -> tuple[list[bool], list[str | None]]:
    """Each chunk's completion flag, and a problem text where its file cannot be decoded."""
    # deferred: zarr (with xarray about 0.5 s to import), only when a store is read
    import zarr

    array = zarr.open_array(str(store / "chunk_complete"), mode="r")
    try:
        return [bool(v) for v in np.asarray(array[:], dtype=bool)], [None] * chunks
    except Exception:
        flags: list[bool] = []
        problems: list[str | None] = []
        for i in range(chunks):
            try:
                flags.append(bool(array[i]))
                problems.append(None)
            except Exception as exc:
                flags.append(False)
                problems.append(f"cannot be decoded ({type(exc).__name__})")
        return flags, problems


def check_store(store: Path, arrays: dict[str, int], runs_per_chunk: int, count: int) -> StoreCheck:
    """Check every complete chunk of the store at ``store`` against its records (see the module's notes)."""
    chunks = -(-count // runs_per_chunk)
    flags, flag_problems = _flags(store, chunks)
    records = store / RECORDS
    if not records.is_dir():
        return StoreCheck(store, False, tuple(flags))
    static = []
    try:
        expected = json.loads((records / _STATIC).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        expected = {}
        static.append(f"its record {records / _STATIC} cannot be read ({type(exc).__name__})")
    for name, digest in expected.items():
        if digest == "metadata":
            try:
                json.loads((store / name).read_text(encoding="utf-8"))
            except FileNotFoundError:
                static.append(f"{store / name} is missing")
            except (OSError, ValueError) as exc:
                static.append(f"{store / name} is not valid JSON ({type(exc).__name__})")
            continue
        found = _digest(store / name)
        if found != digest:
            static.append(f"{store / name} {_problem(found, digest)}")
    intact = []
    damaged = []
    flag_files = _flag_files(store, chunks)
    for i in range(chunks):
        start, stop = i * runs_per_chunk, min((i + 1) * runs_per_chunk, count)
        record = record_path(store, i)
        problem: ChunkDamage | None = None
        if flag_problems[i] is not None:
            problem = ChunkDamage(i, start, stop, "chunk_complete", str(flag_files[i]), flag_problems[i] or "")
        elif record.exists():
            try:
                entries = json.loads(record.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                entries = None
                problem = ChunkDamage(i, start, stop, "-", str(record), f"(checksum record) unreadable: {exc}")
            if entries is not None:
                for name, digest in entries.items():
                    found = _digest(store / name)
                    if found != digest:
                        problem = ChunkDamage(
                            i, start, stop, Path(name).parts[0], str(store / name), _problem(found, digest)
                        )
                        break
                if problem is None and not flags[i]:
                    if not flag_files[i].exists():
                        problem = ChunkDamage(
                            i, start, stop, "chunk_complete", str(flag_files[i]), "is missing (its chunk was recorded)"
                        )
                    else:  # interrupted between the record and the flag: not complete, simulated again
                        intact.append(False)
                        continue
        elif flags[i]:
            problem = ChunkDamage(i, start, stop, "-", str(record), "(checksum record) is missing for a complete chunk")
        if problem is not None:
            damaged.append(problem)
            intact.append(False)
        else:
            intact.append(bool(flags[i]))
    return StoreCheck(store, True, tuple(intact), tuple(damaged), tuple(static))


def _problem(found: list[Any] | None, expected: list[Any] | None) -> str:
    if found is None:
        return "is missing"
    if expected is None:
        return "exists but was not written (the chunk equals the fill value)"
    if found[1] != expected[1]:
        return f"is {found[1]} bytes, {expected[1]} were written (truncated or overwritten)"
    return f"has SHA-256 {found[0][:16]}…, {expected[0][:16]}… was written (changed bytes)"
