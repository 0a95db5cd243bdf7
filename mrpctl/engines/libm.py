"""fmin/fmax as this host's libm computes them: probed once, then inlined into the scalar code and
written as lane forms, so that every engine gives the libm's bits (ties of +0/-0 and NaNs included)."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import math

import casadi as ca

__all__ = ["inline_min_max", "libm_ties", "min_max_forms"]


@functools.lru_cache(maxsize=1)
def libm_ties() -> dict[str, str]:
    """How this host's libm fmax/fmin break a (+0, -0) tie: {"fmax": "first" or "second", ...}.

    C99 leaves fmax(+0, -0) to the library: glibc's generic code returns the first argument
    on ties, its old x86-64 assembly (maxsd) the second. Both return the non-NaN argument
    when one is NaN and the first when both are. Probed from the libm that the scalar code
    links; a function matching neither rule is left out.
    """
    name = ctypes.util.find_library("m")
    libm = ctypes.CDLL(name) if name else ctypes.CDLL(None)
    ties: dict[str, str] = {}
    for c_name in ("fmax", "fmin"):
        function = getattr(libm, c_name)
        function.restype = ctypes.c_double
        function.argtypes = [ctypes.c_double, ctypes.c_double]
        first_on_tie = math.copysign(1.0, function(0.0, -0.0)) > 0 and math.copysign(1.0, function(-0.0, 0.0)) < 0
        second_on_tie = math.copysign(1.0, function(0.0, -0.0)) < 0 and math.copysign(1.0, function(-0.0, 0.0)) > 0
        nan_ok = function(math.nan, 1.0) == 1.0 and function(1.0, math.nan) == 1.0
        if nan_ok and (first_on_tie or second_on_tie):
            ties[c_name] = "first" if first_on_tie else "second"
    return ties


@functools.lru_cache(maxsize=1)
def min_max_forms() -> dict[int, str]:
    """Lane forms of fmin/fmax that reproduce this host's libm on ties (+0, -0) and NaNs
    (`libm_ties`); a libm matching neither rule refuses fmin/fmax."""
    forms: dict[int, str] = {}
    for op, c_name, compare in ((ca.OP_FMAX, "fmax", ">"), (ca.OP_FMIN, "fmin", "<")):
        tie = libm_ties().get(c_name)
        if tie is not None:
            test = compare + "=" if tie == "first" else compare
            forms[op] = f"L_SELECT(L_MASK(({{0}}{test}{{1}})|({{1}}!={{1}})), {{0}}, {{1}})"
    return forms


@functools.lru_cache(maxsize=1)
def inline_min_max() -> tuple[tuple[str, ...], str]:
    """Compiler flags and C source that replace the libm calls fmax/fmin by inline code, same results.

    gcc calls fmax/fmin through the PLT under IEEE flags (no ``-ffinite-math-only``); CasADi's
    ``casadi_fmax``/``casadi_fmin`` call them (the flight sample: 22 calls per sample). The flags
    ``-Dfmax(x,y)=mrpctl_fmax_(x,y)`` (and fmin) rename them, <math.h>'s declarations included,
    and the source (to append to the translation unit) defines ``mrpctl_fmax_``/``mrpctl_fmin_``
    to return what this host's libm returns (`libm_ties`: the non-NaN argument, the
    library's tie rule), which gcc then inlines. Both are part of the compile cache key (flags
    and code). ``((), "")`` when the libm matches neither tie rule (the calls stay).
    """
    flags: list[str] = []
    source = "/* fmax/fmin as this host's libm computes them, inlined (mrpctl.engines.libm.inline_min_max) */\n"
    for c_name, compare in (("fmax", ">"), ("fmin", "<")):
        tie = libm_ties().get(c_name)
        if tie is None:
            return (), ""
        test = compare + "=" if tie == "first" else compare
        flags.append(f"-D{c_name}(x,y)=mrpctl_{c_name}_(x,y)")
        source += (
            f'__attribute__((visibility("hidden"))) double mrpctl_{c_name}_(double x, double y) {{\n'
            f"  return (x {test} y || y != y) ? x : y;\n}}\n"
        )
    return tuple(flags), source
