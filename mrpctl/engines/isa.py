"""The host's vector instruction set: the CPU's flags and the `-m` options the lane engine compiles with."""

from __future__ import annotations

import functools
import os
import shlex
import subprocess

from mrpctl import _compile

__all__ = ["host_isa_flags", "native_isa_flags"]


def _cpu_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as handle:
            for line in handle:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


@functools.lru_cache(maxsize=1)
def host_isa_flags() -> tuple[str, ...]:
    """Vector-ISA flags for this host: ``-march=native`` as the compiler resolves it.

    `native_isa_flags` (explicit flags, so that the cache key, which hashes the flags,
    tells libraries for different CPUs apart); measured 1.2x the explicit ``-mavx2`` on the
    AVX2 development host (``bench/lanes_rate.py``, bit for bit the same results). Where the
    compiler does not resolve it: ``-mavx2`` where the CPU has AVX2, else none (SSE2).
    ``$MRPCTL_LANES_ISA`` overrides (space-separated flags, empty for SSE2). The FMA the CPU may
    have is never used: ``-ffp-contract=off`` keeps the IEEE sequence of the scalar code.
    """
    configured = os.environ.get("MRPCTL_LANES_ISA")
    if configured is not None:
        return tuple(configured.split())
    native = native_isa_flags()
    if native:
        return native
    return ("-mavx2",) if "avx2" in _cpu_flags() else ()


@functools.lru_cache(maxsize=4)
def native_isa_flags(compiler: str | None = None) -> tuple[str, ...]:
    """``-march=native`` resolved by the compiler into explicit flags: this CPU's fingerprint.

    ``gcc -### -march=native`` prints the options its compiler proper gets: the CPU model
    (``-march=znver3``), every ISA extension on or off (``-mavx2 -mno-avx512f ...``) and the cache
    ``--param``s. Compiling with those rather than with the string ``-march=native`` puts them
    in the compile cache key (which hashes the flags), so a cache shared by several machines
    (a Dask cluster's home directory) never serves one CPU a library built for another: each
    worker compiles for its own machine, and machines whose compiler resolves ``native`` the
    same share one library. Empty when the compiler does not say (then the caller falls back
    to explicit flags).
    """
    compiler = compiler or _compile.find_compiler()
    if compiler is None:
        return ()
    try:
        done = subprocess.run(
            [compiler, "-###", "-march=native", "-x", "c", "-c", os.devnull, "-o", os.devnull],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return ()
    for line in done.stderr.splitlines():
        if "cc1" not in line or "-march=" not in line:
            continue
        words = shlex.split(line)
        flags: list[str] = []
        for i, word in enumerate(words):
            cpu = word.startswith(("-march=", "-mtune=")) and not word.endswith("=native")
            if cpu or (word.startswith("-m") and word[2:3].isalpha() and "=" not in word):  # -mavx2, -mno-avx512f
                flags.append(word)
            elif word == "--param" and i + 1 < len(words) and "cache" in words[i + 1]:
                flags += [word, words[i + 1]]
        return tuple(flags) if any(flag.startswith("-march=") for flag in flags) else ()
    return ()
