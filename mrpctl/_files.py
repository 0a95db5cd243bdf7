"""Reading the files users hand to mrpctl (TOML scenario and campaign files, per-sample CSV / NPY files).

Every refusal is one [SpecificationError][mrpctl.errors.SpecificationError] naming the file (and, for a link, the file
it points to), the place (row and column counted from 1, as a spreadsheet shows them) and the rule broken.
No message quotes the file's content: a file name given by mistake (a link to another file, a binary
file with a ``.csv`` name) is named, never echoed. Memory is estimated from the file's size or from a
``.npy`` header before anything is read.
"""

from __future__ import annotations

import hashlib
import math
import os
import stat
import tomllib
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl.errors import SpecificationError

#: Largest TOML file read (bytes): a scenario or campaign file is a few kB; per-sample numbers go in a
#: .csv or .npy file named by the TOML file.
MAX_TOML_BYTES = 16 * 2**20
#: Bytes a CSV file may need in memory per byte of text, at most: the decoded text and its lines (about 2)
#: and the numbers (at most one per 2 bytes of text, 8 bytes each, and the parser's copy).
_CSV_BYTES_PER_BYTE = 10
#: Largest .npy header read (bytes; NumPy's own default limit).
_NPY_HEADER_LIMIT = 10000


def file_sha256(path: str | os.PathLike[str]) -> str:
    """The SHA-256 of a file's bytes (hex), read in 1 MiB blocks: the one checksum of the engine cache, export
    manifests and stored trajectories."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def memory_limit() -> float:
    """Half of the memory available now (bytes): the most one file may take once read (4 GiB if unknown)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return 0.5 * int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return 0.5 * os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, OSError, ValueError):  # pragma: no cover - not POSIX
        return 4.0 * 2**30


def size_text(nbytes: float) -> str:
    """``nbytes`` in B, KB, MB, GB or TB (binary units), 3 significant digits."""
    for unit, scale in (("TB", 2**40), ("GB", 2**30), ("MB", 2**20), ("KB", 2**10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes:.0f} B"


def shown(path: Path) -> str:
    """``path`` as messages name it: with the file a link points to."""
    if path.is_symlink():
        return f"{path} (a link to {os.path.realpath(path)})"
    return str(path)


def regular_file(path: Path, key: str, *, missing: str | None = None) -> os.stat_result:
    """Check that ``path`` is an existing regular file (links followed) and return its status.

    ``missing``: the message for a file that does not exist (default ``"{key}: no file {path}"``).
    A folder, a dangling link, a device, pipe or socket, or a file that cannot be examined is refused
    naming ``key``.
    """
    if path.is_symlink() and not path.exists():
        raise SpecificationError(f"{key}: {path} is a link to {os.path.realpath(path)}, which does not exist")
    try:
        status = path.stat()
    except FileNotFoundError:
        raise SpecificationError(missing or f"{key}: no file {path}") from None
    except OSError as exc:
        raise SpecificationError(f"{key}: cannot examine {shown(path)}: {exc.strerror or type(exc).__name__}") from exc
    if stat.S_ISDIR(status.st_mode):
        raise SpecificationError(f"{key}: {shown(path)} is a folder, not a file")
    if not stat.S_ISREG(status.st_mode):
        raise SpecificationError(f"{key}: {shown(path)} is not a regular file (a device, pipe or socket)")
    return status


def _read_bytes(path: Path, key: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise SpecificationError(f"{key}: cannot read {shown(path)}: {exc.strerror or type(exc).__name__}") from exc


def _position(raw: bytes, offset: int) -> tuple[int, int]:
    """(line, column) of byte ``offset`` of ``raw``, both from 1 (the column counts bytes)."""
    line_start = raw.rfind(b"\n", 0, offset) + 1
    return raw.count(b"\n", 0, offset) + 1, offset - line_start + 1


def decode_text(raw: bytes, key: str, path: Path, *, what: str = "text") -> str:
    """``raw`` decoded as UTF-8, a leading byte-order mark dropped (a spreadsheet's "CSV UTF-8" export).

    A byte that is not UTF-8 is refused with its line and column (its value in hex, never the text
    around it); UTF-16 (a BOM FF FE or FE FF) is named as such.
    """
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise SpecificationError(
            f"{key}: {shown(path)} is UTF-16 {what}; save it as UTF-8 (a spreadsheet's 'CSV UTF-8' format)"
        )
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line, column = _position(raw, exc.start)
        raise SpecificationError(
            f"{key}: {shown(path)} is not UTF-8 {what}: line {line}, column {column} holds the byte "
            f"{raw[exc.start : exc.start + 1]!r}; save the file as UTF-8"
        ) from exc


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """The parsed TOML file ``path`` (UTF-8, a BOM allowed) of a ``what`` ("scenario file", "campaign file").

    Refused, naming the file: missing, a folder, not a regular file, above
    [MAX_TOML_BYTES][mrpctl._files.MAX_TOML_BYTES], not UTF-8 (line and column), not valid TOML (TOML's
    own line and column).
    """
    status = regular_file(path, what, missing=f"{what} not found: {path}")
    if status.st_size > MAX_TOML_BYTES:
        raise SpecificationError(
            f"{what}: {shown(path)} is {size_text(status.st_size)}, more than the {size_text(MAX_TOML_BYTES)} a "
            "TOML file may have (it names its per-sample numbers as .csv or .npy files instead of holding them)"
        )
    text = decode_text(_read_bytes(path, what), what, path, what="text (TOML files must be UTF-8)")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecificationError(f"{what}: {shown(path)} is not valid TOML: {exc}") from exc


# ------------------------------------------------------------------------------------ per-sample files
def _first_bad_cell(lines: list[str]) -> tuple[int, int | None, str] | None:
    """(line, column or None, what is wrong) of the first cell of ``lines`` that is not a number, or of the
    first row whose width differs from the first row's; None when every cell is a number."""
    width = first = 0
    for number, line in enumerate(lines, 1):
        content = line.split("#", 1)[0]
        if not content.strip():
            continue
        cells = content.split(",")
        for column, cell in enumerate(cells, 1):
            if not cell.strip():
                return number, column, "is empty"
            try:
                float(cell)
            except ValueError:
                return number, column, "is not a number"
        if not width:
            width, first = len(cells), number
        elif len(cells) != width:
            return number, None, f"has {len(cells)} values but row {first} has {width}"
    return None


def _data_lines(lines: list[str]) -> list[int]:
    """The line numbers (from 1) of the lines of ``lines`` that hold numbers (not blank, not a comment)."""
    return [number for number, line in enumerate(lines, 1) if line.split("#", 1)[0].strip()]


def _csv_numbers(path: Path, key: str, size: int) -> tuple[np.ndarray, list[str]]:
    estimate = _CSV_BYTES_PER_BYTE * size
    limit = memory_limit()
    if estimate > limit:
        raise SpecificationError(
            f"{key}: {shown(path)} is {size_text(size)} of text, up to {size_text(estimate)} once read, more than the "
            f"{size_text(limit)} allowed (half of the memory available); save the numbers as .npy (8 bytes a number) "
            "or shorten the run (one row per measurement sample)"
        )
    text = decode_text(_read_bytes(path, key), key, path)
    lines = text.splitlines()
    where = f"{key}: {shown(path)}"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": refused below
            array = np.loadtxt(lines, delimiter=",", comments="#", ndmin=2, dtype=float)
    except ValueError as exc:
        bad = _first_bad_cell(lines)
        if bad is None:
            raise SpecificationError(f"{where} is not a comma-separated table of numbers") from exc
        line, column, problem = bad
        cell = f"row {line}" if column is None else f"row {line}, column {column}"
        raise SpecificationError(
            f"{where}: {cell} {problem} (rows and columns from 1, as a spreadsheet shows them; the file must hold "
            "comma-separated numbers, a header line starting with #)"
        ) from exc
    if array.size == 0:
        raise SpecificationError(f"{where} holds no numbers (comma-separated, one row per measurement sample)")
    return array, lines


def _npy_numbers(path: Path, key: str, size: int) -> np.ndarray:
    where = f"{key}: {shown(path)}"
    try:
        with path.open("rb") as handle:
            version = np.lib.format.read_magic(handle)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(handle, _NPY_HEADER_LIMIT)
            else:  # 2.0 and 3.0 (3.0 differs only in the header's text encoding)
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(handle, _NPY_HEADER_LIMIT)
            offset = handle.tell()
    except (ValueError, OSError, SyntaxError, TypeError) as exc:
        raise SpecificationError(f"{where} is not a NumPy .npy file (its header cannot be read)") from exc
    if dtype.hasobject or dtype.fields is not None or dtype.kind not in "iuf":
        raise SpecificationError(
            f"{where} holds {dtype} values; a per-sample file holds real numbers (an integer or float array)"
        )
    if len(shape) not in (1, 2):
        raise SpecificationError(
            f"{where} holds an array of shape {shape}; a per-sample file holds a table (one row per sample)"
        )
    count = math.prod(shape)
    # the file's array, its float64 copy (none for float64) and the finiteness mask
    estimate = count * (dtype.itemsize + (0 if dtype == np.float64 else 8) + 1)
    limit = memory_limit()
    if estimate > limit:
        raise SpecificationError(
            f"{where}: its header declares an array of shape {shape} ({dtype}), about {size_text(estimate)} once "
            f"read, more than the {size_text(limit)} allowed (half of the memory available); a per-sample file "
            "holds one row per measurement sample (n = floor(t_final * rate) + 1): shorten the run or lower the rate"
        )
    expected = offset + count * dtype.itemsize
    if size != expected:
        state = "truncated" if size < expected else "longer than its header says"
        raise SpecificationError(
            f"{where} is {state}: its header declares shape {shape} ({dtype}), {expected} bytes in all, but the "
            f"file has {size} bytes"
        )
    try:
        with path.open("rb") as handle:
            handle.seek(offset)
            array = np.fromfile(handle, dtype=dtype, count=count)
    except (OSError, ValueError) as exc:
        raise SpecificationError(f"{where}: cannot read its numbers") from exc
    if array.size != count:
        raise SpecificationError(f"{where} is truncated: {array.size} of the {count} numbers its header declares")
    return np.asarray(array.reshape(shape, order="F" if fortran else "C"), dtype=float)


def read_numbers(path: Path, key: str) -> np.ndarray:
    """The numbers of a per-sample file (``.npy``, or ``.csv`` / ``.txt`` comma-separated with ``#`` comments
    and an optional UTF-8 byte-order mark) as a finite float64 array of 1 or 2 dimensions.

    ``path`` is checked to be a regular file ([regular_file][mrpctl._files.regular_file]); memory is
    estimated before reading (from a ``.npy`` header, whose size must match the file's, or from the CSV's
    size). The first value that is not a finite number is refused with its row and column (from 1; a CSV's
    row is its line).
    """
    status = regular_file(path, key)
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".csv", ".txt"):
        raise SpecificationError(f"{key}: {path} must be a .npy or a .csv (.txt) file, got the suffix {suffix!r}")
    lines: list[str] | None = None
    if suffix == ".npy":
        array = _npy_numbers(path, key, status.st_size)
    else:
        array, lines = _csv_numbers(path, key, status.st_size)
    finite = np.isfinite(array)
    if not np.all(finite):
        index = np.unravel_index(int(np.flatnonzero(~finite)[0]), array.shape)
        row = int(index[0])
        column = int(index[1]) + 1 if array.ndim == 2 else 1
        value = float(array[index])
        text = "NaN" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        line = _data_lines(lines)[row] if lines is not None else row + 1
        raise SpecificationError(
            f"{key} value at row {line}, column {column} of {shown(path)} is {text} (rows and columns from 1, as a "
            "spreadsheet shows them); every value must be finite (no NaN or inf)"
        )
    return array


def toml_value(value: Any) -> str:
    """A bool, a string, a float or a (nested) list or array of them as TOML, floats to full precision (repr)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(float(value))
