"""Export folders published atomically: written into a private staging folder beside the target, then swapped
in by two renames (or, where a folder cannot be swapped, replaced file by file with the manifest last); folders
left by a killed export are cleaned up or put back first."""

from __future__ import annotations

import contextlib
import logging
import os
import re
import secrets
import shutil
import stat
from pathlib import Path
from typing import Any

from mrpctl._compile import abandoned
from mrpctl.errors import CodegenError, SpecificationError

__all__ = [
    "check_folder",
    "clean_leftovers",
    "folder_path",
    "in_place_only",
    "publish",
    "publish_in_place",
    "staging_folder",
    "write_file",
]

logger = logging.getLogger(__name__)


def folder_path(out_dir: Any) -> Path:
    try:
        return Path(out_dir)
    except TypeError as exc:
        raise SpecificationError(f"out_dir must be a path, got {out_dir!r}") from exc


def check_folder(folder: Path, overwrite: bool) -> None:
    """Refuse ``folder`` if it is a file, or a non-empty folder without ``overwrite``."""
    if folder.exists() and not folder.is_dir():
        raise SpecificationError(f"out_dir {str(folder)!r} exists and is not a folder")
    if folder.is_dir():
        try:
            present = sorted(entry.name for entry in folder.iterdir())
        except OSError as exc:
            raise CodegenError(f"cannot read the export folder out_dir {str(folder)!r}: {exc}") from exc
        if not os.access(folder, os.W_OK | os.X_OK):
            raise CodegenError(f"the export folder out_dir {str(folder)!r} is not writable")
        if present and not overwrite:
            shown = ", ".join(present[:5]) + (", ..." if len(present) > 5 else "")
            raise SpecificationError(
                f"out_dir {str(folder)!r} is not empty ({len(present)} entries: {shown}); "
                "choose an empty or new folder, or pass overwrite=True to replace a previous export"
            )


def in_place_only(target: Path) -> bool:
    """True when ``target`` cannot be swapped: the working directory (or above it), a mount point,
    or its parent is not writable. Files are then replaced one by one inside it."""
    if not target.is_dir():
        return False
    cwd = Path(os.path.realpath(os.getcwd()))
    if cwd == target or target in cwd.parents or os.path.ismount(target):
        return True
    return not os.access(target.parent, os.W_OK | os.X_OK)


def staging_folder(target: Path, in_place: bool) -> Path:
    """A new private folder beside ``target`` (inside it when in place); leftovers are cleaned first."""
    tag = f"{os.getpid()}-{secrets.token_hex(4)}"
    if in_place:
        home, staging = target, target / f"{_IN_PLACE_PREFIX}{tag}"
    else:
        home, staging = target.parent, target.parent / f".{target.name}{_NEW_INFIX}{tag}"
    try:
        home.mkdir(parents=True, exist_ok=True)
        staging.mkdir()
    except OSError as exc:
        raise CodegenError(f"cannot create the export folder out_dir {str(target)!r}: {exc}") from exc
    return staging


_NEW_INFIX = ".export-"
_OLD_INFIX = ".replaced-"
_IN_PLACE_PREFIX = ".mrpctl-export-"


def clean_leftovers(target: Path) -> None:
    """Remove staging folders of killed exports; put back a folder a killed export had moved aside."""
    patterns = [(target.parent, re.compile(rf"\.{re.escape(target.name)}(\.export-|\.replaced-)(\d+)-[0-9a-f]+"))]
    if target.is_dir():
        patterns.append((target, re.compile(r"\.mrpctl-export-()(\d+)-[0-9a-f]+")))
    for home, pattern in patterns:
        try:
            entries = list(home.iterdir())
        except OSError:
            continue
        for entry in entries:
            match = pattern.fullmatch(entry.name)
            if match is None or not abandoned(entry, int(match.group(2))):
                continue
            if match.group(1) == _OLD_INFIX and not os.path.lexists(target):
                try:
                    os.rename(entry, target)  # killed between the two renames of the swap: restore
                except OSError as exc:
                    logger.warning("could not restore %s from %s: %s", target, entry, exc)
                else:
                    logger.warning("restored %s from %s, left by an interrupted export", target, entry)
            else:
                shutil.rmtree(entry, ignore_errors=True)
                logger.info("removed %s, left by an interrupted export", entry)


def _carry_over(old: Path, staging: Path, ours: frozenset[str]) -> None:
    """Hard-link (or copy) the entries of ``old`` that export did not write into ``staging``."""
    for entry in old.iterdir():
        if entry.name in ours or entry.name.startswith(_IN_PLACE_PREFIX):
            continue
        destination = staging / entry.name
        if entry.is_dir() and not entry.is_symlink():
            shutil.copytree(entry, destination, symlinks=True, copy_function=_link_or_copy)
        elif entry.is_symlink():
            os.symlink(os.readlink(entry), destination)
        else:
            _link_or_copy(str(entry), str(destination))


def _link_or_copy(source: str, destination: str) -> None:
    try:
        os.link(source, destination)
    except OSError:
        shutil.copy2(source, destination)


def publish(staging: Path, target: Path, ours: frozenset[str]) -> None:
    """Swap ``staging`` in as ``target``: old folder renamed aside, new one renamed in, old one removed."""
    if not os.path.lexists(target):
        _swap_rename(staging, target, target)
        return
    try:
        _carry_over(target, staging, ours)
        os.chmod(staging, stat.S_IMODE(target.stat().st_mode))
    except OSError as exc:
        raise CodegenError(f"cannot carry the other files of out_dir {str(target)!r} over: {exc}") from exc
    aside = target.parent / f".{target.name}{_OLD_INFIX}{os.getpid()}-{secrets.token_hex(4)}"
    _swap_rename(target, aside, target)
    try:
        _swap_rename(staging, target, target)
    except BaseException:
        os.rename(aside, target)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def _swap_rename(source: Path, destination: Path, target: Path) -> None:
    try:
        os.rename(source, destination)
    except OSError as exc:
        raise CodegenError(f"cannot put the export in place at out_dir {str(target)!r}: {exc}") from exc


def publish_in_place(staging: Path, target: Path, names: list[str], ours: frozenset[str], manifest: str) -> None:
    """Replace the export's files in ``target`` one by one (each atomically), the manifest last.

    The old manifest goes first, so that a folder interrupted half-way has none."""
    try:
        with contextlib.suppress(FileNotFoundError):
            (target / manifest).unlink()
        for name in names:
            if name != manifest:
                os.replace(staging / name, target / name)
        for name in ours - set(names):
            with contextlib.suppress(FileNotFoundError):
                (target / name).unlink()
        os.replace(staging / manifest, target / manifest)
    except OSError as exc:
        raise CodegenError(f"cannot write the export into out_dir {str(target)!r}: {exc}") from exc


def write_file(path: Path, action: Any) -> None:
    """Run ``action`` (which writes ``path``), turning failures into a CodegenError naming the file."""
    try:
        action()
    except (OSError, RuntimeError) as exc:
        raise CodegenError(f"cannot write {path}: {exc}") from exc
