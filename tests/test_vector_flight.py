"""Speed work on the flight loop (issue 10's bench goal, issue 12's lane engine): same numbers, less time."""

from __future__ import annotations

import ctypes
import itertools
import math

import noise_reference as reference
import numpy as np
import pytest

from mrpctl import _compile, flight
from mrpctl.engines import isa
from mrpctl.engines import lanes as _vectorize
from mrpctl.engines.libm import inline_min_max
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import DelayModel, SensorModel


def _whole_stream(seed: int, stream: int, n: int) -> np.ndarray:
    """The documented layout, written out: component c of sample k is normal number 3k + c of the stream."""
    return reference.stream_normals(reference.stream_key(seed, stream), 0, 3 * n).reshape(n, 3)


# ============================================================================ noise in place
def test_noise_rows_are_the_documented_streams_bit_for_bit_in_any_slicing():
    sensor = SensorModel(attitude_noise=0.01, rate_noise=2e-4, seed=5)
    n = 2 * 4096 + 77
    attitude = 0.01 * _whole_stream(5, flight.STREAM_ATTITUDE, n)
    rate = 2e-4 * _whole_stream(5, flight.STREAM_RATE, n)
    buffer = np.full((4096 + 10, 6), np.nan)  # reused slice after slice, larger than a slice
    cuts = [0, 1, 300, 4095, 4096 + 2, 2 * 4096, n]
    for a, b in itertools.pairwise(cuts):
        rows = sensor.noise_rows(a, b, out=buffer)
        assert rows.shape == (b - a, 6) and np.shares_memory(rows, buffer)
        assert np.array_equal(rows[:, 0:3], attitude[a:b]) and np.array_equal(rows[:, 3:6], rate[a:b])
        theta, eta = sensor.noise(a, b)
        assert np.array_equal(theta, attitude[a:b]) and np.array_equal(eta, rate[a:b])


def test_noise_rows_of_a_zero_sigma_are_zero_and_a_bad_buffer_is_refused():
    rows = SensorModel(rate_noise=1e-3, seed=2).noise_rows(10, 20, out=np.full((10, 6), np.nan))
    assert not np.any(rows[:, 0:3]) and np.all(rows[:, 3:6] != 0)
    with pytest.raises(DimensionError, match="out"):
        SensorModel(rate_noise=1e-3).noise_rows(0, 20, out=np.empty((10, 6)))
    with pytest.raises(SpecificationError, match="C-contiguous"):
        SensorModel(rate_noise=1e-3).noise_rows(0, 5, out=np.empty((6, 10)).T)


def test_jitter_is_the_multiply_shift_of_the_stream_values_in_any_slicing():
    model = DelayModel.jitter(0.01, 0.05, seed=4)
    key = flight.stream_key(4, flight.STREAM_JITTER)
    whole = [10 + ((reference.value(key, k << 12) >> 32) * 41 >> 32) for k in range(2000)]  # Python ints
    assert model.samples(1000.0, 0, 123).tolist() == whole[:123]
    assert model.samples(1000.0, 100, 2000).tolist() == whole[100:2000]


# ============================================================================ fmax/fmin inlined
def test_inlined_fmax_fmin_return_what_the_libm_returns_on_ties_nans_and_infinities(tmp_path):
    flags, source = inline_min_max()
    if not flags:
        pytest.skip("this libm's fmax/fmin match no known tie rule: the calls stay")
    if _compile.find_compiler() is None:
        pytest.skip("no C compiler")
    code = (
        "#include <math.h>\n"
        + source
        + (
            "double probe_fmax(double x, double y) { return fmax(x, y); }\n"
            "double probe_fmin(double x, double y) { return fmin(x, y); }\n"
        )
    )
    built = _compile.compile_source(
        code, "probe_min_max", flags=(*_compile.SIMULATION_FLAGS, *flags), directory=tmp_path
    )
    library = ctypes.CDLL(str(built))
    libm = ctypes.CDLL(None)
    values = [0.0, -0.0, 1.0, -1.0, 1e-300, math.inf, -math.inf, math.nan, 2.5]
    for name in ("fmax", "fmin"):
        inline, reference = getattr(library, "probe_" + name), getattr(libm, name)
        for function in (inline, reference):
            function.restype = ctypes.c_double
            function.argtypes = [ctypes.c_double, ctypes.c_double]
        for x, y in itertools.product(values, repeat=2):
            got, want = inline(x, y), reference(x, y)
            if math.isnan(want):
                assert math.isnan(got)
            else:
                assert np.float64(got).view(np.int64) == np.float64(want).view(np.int64), (name, x, y)


# ============================================================================ no C compiler
def test_the_virtual_machine_runs_noise_and_bias_bit_for_bit_and_refuses_jitter_clearly(monkeypatch):
    """Without a compiler the flight sample's sensor ports get the NumPy mirror of the C noise: the same run."""
    import warnings

    from mrpctl import paper, simulate
    from mrpctl.engines import scalar as _engine
    from mrpctl.errors import CodegenError
    from mrpctl.flight import ActuatorModel, Hysteretic
    from mrpctl.simulation import _batch

    noisy = SensorModel(attitude_noise=0.01, rate_noise=1e-4, gyro_bias=[1e-4, -2e-4, 5e-5], seed=3)
    cases = [
        dict(tau=0.05, rule=Hysteretic(0.0), sensor=noisy, actuator=ActuatorModel([20.0, 25.0, 30.0], norm_max=35.0)),
        dict(tau=0.05, rule=Hysteretic(0.1), sensor=SensorModel(gyro_bias=[1e-4, 0.0, 0.0])),
        dict(tau=0.0, rule=Hysteretic(0.05), sensor=SensorModel(rate_noise=1e-3, seed=8)),
        dict(tau=0.05, rule=Hysteretic(0.1), sensor=SensorModel()),
    ]
    compiled = [
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, t_final=2.0, rate=200.0, **case) for case in cases
    ]
    assert len(compiled[0].switch_indices) >= 3  # the noise makes the delta = 0 rule switch
    monkeypatch.setattr(_compile, "find_compiler", lambda: None)
    monkeypatch.setattr(_batch, "find_compiler", lambda: None)
    _engine.clear_engines()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", _compile.CompilerWarning)
            machine = [
                simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, t_final=2.0, rate=200.0, **case)
                for case in cases
            ]
            with pytest.raises(CodegenError, match=r"delay: .*compiled engine"):
                simulate(
                    paper.SPACECRAFT,
                    paper.GAIN,
                    paper.INITIAL_STATE,
                    tau=0.05,
                    rule=Hysteretic(0.1),
                    t_final=0.3,
                    delay=DelayModel.jitter(0.02, 0.05),
                )
    finally:
        _engine.clear_engines()
    assert machine[0].saturated_fraction is None and compiled[0].saturated_fraction > 0  # it ran the VM
    for got, want in zip(machine, compiled, strict=True):
        for name in ("sigma", "omega", "u"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), name
        assert got.switch_indices.tolist() == want.switch_indices.tolist()


# ============================================================================ -march=native, keyed by the CPU
def test_native_flags_are_this_cpu_s_fingerprint_and_key_the_cache_per_cpu(tmp_path):
    if _compile.find_compiler() is None:
        pytest.skip("no C compiler")
    flags = isa.native_isa_flags()
    if not flags:
        pytest.skip("this compiler does not resolve -march=native")
    assert "-march=native" not in flags and any(flag.startswith("-march=") for flag in flags)
    cpu = isa._cpu_flags()  # /proc/cpuinfo, independent of the compiler
    for feature in ("avx2", "avx512f", "sse4_2", "fma"):
        if cpu:  # the compiler enables exactly what the CPU reports
            flag = "-m" + feature.replace("_", ".")
            assert (flag in flags) == (feature in cpu), feature
    # a library built for another CPU (another fingerprint) is another file of the cache
    code = "int probe_cpu(void) { return 7; }\n"
    other = tuple("-march=x86-64-v2" if flag.startswith("-march=") else flag for flag in flags)
    here = _compile.compile_source(code, "probe_cpu", flags=(*_compile.DEFAULT_FLAGS, *flags), directory=tmp_path)
    there = _compile.compile_source(code, "probe_cpu", flags=(*_compile.DEFAULT_FLAGS, *other), directory=tmp_path)
    assert here != there and here.exists() and there.exists()
    assert _vectorize.host_isa_flags() == flags or "MRPCTL_LANES_ISA" in __import__("os").environ
