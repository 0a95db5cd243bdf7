"""The host a bench ran on, printed beside its ratios: the CPU model, its vector extensions and the ISA flags the
lane engine compiles with."""

from __future__ import annotations

from mrpctl.engines import isa as host_isa


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


def vector_isa() -> str:
    """The CPU's vector extensions (from its flags) and the ISA flags the lane engine compiles with."""
    flags = host_isa._cpu_flags()
    has = [name for name in ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512vl", "avx512dq") if name in flags]
    compiled = host_isa.host_isa_flags()
    chosen = [flag for flag in compiled if flag.startswith("-march=")]
    chosen += [flag for flag in compiled if flag.startswith("-mavx") or flag.startswith("-mprefer-vector-width")]
    return f"CPU flags {' '.join(has) or 'none'}; lanes compiled with {' '.join(chosen) or '(SSE2)'}"
