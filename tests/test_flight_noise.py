"""The counter-based random streams: mrpctl/engines/noise.c, the package's one generator (mrpctl.flight.streams
calls it), against the independent NumPy reimplementation of tests/noise_reference.py.

The C generator and the NumPy reference must give the same bits for every value (compared on >= 10^6
normals over several seeds and slicings); the normals must be standard normal (Kolmogorov-Smirnov
and chi-square against scipy.stats.norm, the tail beyond 3.5 sigma) and the streams uncorrelated.
"""

from __future__ import annotations

import ctypes
import itertools
import math
from importlib import resources

import noise_reference as reference
import numpy as np
import pytest
from scipy import stats

from mrpctl import _compile, flight
from mrpctl.errors import SpecificationError
from mrpctl.flight import STREAM_ATTITUDE, STREAM_JITTER, STREAM_RATE, DelayModel, SensorModel, stream_key

MILLION = 1_000_000


@pytest.fixture(scope="module")
def c_fill(tmp_path_factory):
    """mrpctl_stream_fill of _noise.c, compiled alone with the simulator's flags (no FMA contraction)."""
    if _compile.find_compiler() is None:
        pytest.skip("no C compiler")
    folder = tmp_path_factory.mktemp("noise")
    source = folder / "noise.c"
    source.write_text(resources.files("mrpctl.engines").joinpath("noise.c").read_text(encoding="utf-8"))
    assert "-ffp-contract=off" in _compile.SIMULATION_FLAGS
    _compile.build_library(source, folder / "noise.so", flags=_compile.SIMULATION_FLAGS)
    library = ctypes.CDLL(str(folder / "noise.so"))
    fill = library.mrpctl_stream_fill
    fill.restype = None
    fill.argtypes = [ctypes.c_ulonglong, ctypes.c_longlong, ctypes.c_longlong, ctypes.c_double, ctypes.c_int]
    fill.argtypes += [ctypes.c_longlong, ctypes.c_longlong, ctypes.c_void_p, ctypes.c_longlong]

    def normals(key: int, n0: int, count: int, scale: float = 1.0) -> np.ndarray:
        out = np.full(count, np.nan)
        fill(key, n0, count, scale, 0, 0, 0, out.ctypes.data, 3)
        return out

    def integers(key: int, k0: int, count: int, low: int, high: int) -> np.ndarray:
        out = np.full(count, np.nan)
        fill(key, k0, count, 0.0, 1, low, high, out.ctypes.data, 3)
        return out.astype(np.int64)

    return normals, integers


def _bits(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)


# ============================================================================ one source of bits
def test_the_tables_in_the_c_source_are_the_documented_recursion_bit_for_bit():
    x, f = reference._ziggurat_tables()
    table_x, table_f = reference._c_tables()
    assert np.array_equal(_bits(np.array(x)), _bits(table_x)) and np.array_equal(_bits(np.array(f)), _bits(table_f))
    assert table_x[1] == 3.6541528853610088 and table_x[256] == 0.0 and table_f[256] == 1.0
    assert np.all(np.diff(table_x) < 0) and np.all(np.diff(table_f) > 0)
    # every layer has the same area v (layer 0: its rectangle of width X[0] = v / f(r))
    areas = table_x[1:256] * (table_f[2:257] - table_f[1:256])
    assert np.allclose(areas, table_x[0] * table_f[1], rtol=1e-12)


def test_the_prescaled_table_is_x_times_two_to_the_minus_53_exactly():
    """mrpctl_zig_xs[i] = X[i] 2^-53 (the driver's one product (h >> 11) X[i] 2^-53 gives the documented bits)."""
    from importlib import resources

    text = resources.files("mrpctl").joinpath("engines", "noise.c").read_text(encoding="utf-8")
    body = text.split("mrpctl_zig_xs[256] = {", 1)[1].split("}", 1)[0]
    scaled = np.array([float.fromhex(item) for item in body.replace("\n", " ").split(",") if item.strip()])
    table_x, _ = reference._c_tables()
    assert scaled.shape == (256,)
    assert np.array_equal(_bits(scaled), _bits(np.ldexp(table_x[:256], -53)))
    # the product is the same real number as the documented ((h >> 11) 2^-53) X[i]: the same rounding
    m = np.array([1, 3, 2**52 + 12345, 2**53 - 1], dtype=np.float64)
    for i in (0, 1, 128, 255):
        assert np.array_equal(_bits(m * scaled[i]), _bits(m * 2.0**-53 * table_x[i]))


def test_mix64_is_splitmix64():
    """The first outputs of SplitMix64 seeded with 0 (the reference sequence of Vigna's splitmix64.c)."""
    assert [reference.value(0, i) for i in range(3)] == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F]
    assert reference.values(0, np.arange(3, dtype=np.uint64)).tolist() == [reference.value(0, i) for i in range(3)]


@pytest.mark.parametrize("seed", [0, 1, 20261201, 2**64 - 1])
def test_c_and_numpy_give_the_same_million_normals_bit_for_bit(c_fill, seed):
    normals, _ = c_fill
    key = stream_key(seed, STREAM_ATTITUDE)
    start = 12345 if seed else 0
    assert key == reference.stream_key(seed, STREAM_ATTITUDE)
    expected = reference.stream_normals(key, start, start + MILLION // 4)
    assert np.array_equal(_bits(flight.stream_normals(key, start, start + MILLION // 4)), _bits(expected))
    assert np.array_equal(_bits(normals(key, start, MILLION // 4)), _bits(expected))
    # any slicing of the C calls gives the same values
    cuts = [start, start + 1, start + 999, start + 70_001, start + MILLION // 4]
    parts = np.concatenate([normals(key, a, b - a) for a, b in itertools.pairwise(cuts)])
    assert np.array_equal(_bits(parts), _bits(expected))


def test_c_and_numpy_agree_in_the_tail_and_with_a_scale(c_fill):
    """Every rejected value (wedge or tail) of 10^6 draws goes through the scalar math.exp/math.log path."""
    normals, _ = c_fill
    key = stream_key(3, STREAM_RATE)
    values = reference.stream_normals(key, 0, MILLION)
    assert np.sum(np.abs(values) > 3.6541528853610088) > 100  # tail samples were drawn and compared
    assert np.array_equal(_bits(normals(key, 0, MILLION)), _bits(values))
    assert np.array_equal(_bits(normals(key, 0, 1000, 0.01)), _bits(0.01 * values[:1000]))
    assert not np.any(normals(key, 0, 10, 0.0))


def test_sensor_noise_rows_are_the_streams_in_any_slicing(c_fill):
    normals, _ = c_fill
    sensor = SensorModel(attitude_noise=0.01, rate_noise=2e-4, seed=5)
    n = 10_007
    attitude = normals(stream_key(5, STREAM_ATTITUDE), 0, 3 * n, 0.01).reshape(n, 3)
    rate = normals(stream_key(5, STREAM_RATE), 0, 3 * n, 2e-4).reshape(n, 3)
    buffer = np.full((5000, 6), np.nan)
    for a, b in itertools.pairwise([0, 1, 300, 4095, 4097, 8192, n]):
        rows = sensor.noise_rows(a, b, out=buffer)
        assert np.shares_memory(rows, buffer)
        assert np.array_equal(rows[:, 0:3], attitude[a:b]) and np.array_equal(rows[:, 3:6], rate[a:b])


def test_the_noise_rows_of_the_engines_are_the_reference_s():
    from mrpctl.engines.scalar import noise_rows

    if _compile.find_compiler() is None:
        pytest.skip("no C compiler")
    for sensor in (SensorModel(attitude_noise=0.01, rate_noise=2e-4, seed=5), SensorModel(rate_noise=1e-3, seed=1)):
        for a, b in ((0, 5000), (4999, 70_000)):
            expected = np.hstack(
                [
                    reference.stream_normal_rows(sensor.seed, stream, a, b, scale=sigma)
                    if sigma > 0
                    else np.zeros((b - a, 3))
                    for stream, sigma in ((STREAM_ATTITUDE, sensor.attitude_noise), (STREAM_RATE, sensor.rate_noise))
                ]
            )
            assert np.array_equal(_bits(noise_rows(sensor, a, b)), _bits(expected))


def test_jitter_integers_c_and_numpy_agree_and_are_uniform(c_fill):
    _, integers = c_fill
    model = DelayModel.jitter(0.01, 0.05, seed=4)
    key = stream_key(4, STREAM_JITTER)
    n = 200_000
    values = model.samples(1000.0, 0, n)
    assert np.array_equal(integers(key, 0, n, 10, 50), values)
    assert np.array_equal(reference.stream_integers(4, STREAM_JITTER, 0, n, 10, 50), values)
    assert np.array_equal(np.concatenate((model.samples(1000.0, 0, 777), model.samples(1000.0, 777, n))), values)
    counts = np.bincount(values - 10, minlength=41)
    assert values.min() == 10 and values.max() == 50 and counts.size == 41
    chi2 = stats.chisquare(counts)
    assert chi2.pvalue > 1e-6
    assert np.array_equal(DelayModel.jitter(0.02, 0.02, seed=3).samples(1000.0, 0, 100), np.full(100, 20))


# ============================================================================ distribution
def test_a_million_normals_are_standard_normal():
    values = flight.stream_normals(stream_key(11, STREAM_ATTITUDE), 0, MILLION)
    assert stats.kstest(values, stats.norm.cdf).pvalue > 1e-6
    edges = stats.norm.ppf(np.linspace(0.0, 1.0, 201))  # 200 equiprobable bins
    counts = np.histogram(values, bins=edges)[0]
    assert stats.chisquare(counts).pvalue > 1e-6
    # the tail beyond 3.5 sigma (the ziggurat's base layer and its exponential tail sampler)
    p = 2.0 * stats.norm.sf(3.5)
    tail = int(np.sum(np.abs(values) > 3.5))
    assert abs(tail - MILLION * p) < 5.0 * math.sqrt(MILLION * p)
    beyond = int(np.sum(np.abs(values) > 4.5))
    q = 2.0 * stats.norm.sf(4.5)
    assert abs(beyond - MILLION * q) < 5.0 * math.sqrt(MILLION * q) + 1
    # signs and the moments
    assert abs(np.mean(values > 0) - 0.5) < 5.0 * 0.5 / math.sqrt(MILLION)
    assert abs(np.mean(values**4) - 3.0) < 0.05


def test_streams_components_and_samples_are_uncorrelated():
    n = 300_000
    bound = 5.0 / math.sqrt(n)
    attitude = SensorModel(attitude_noise=1.0, rate_noise=1.0, seed=9).noise_rows(0, n)
    other_seed = SensorModel(attitude_noise=1.0, seed=10).noise_rows(0, n)
    columns = [attitude[:, i] for i in range(6)] + [other_seed[:, 0]]
    for a, b in itertools.combinations(range(len(columns)), 2):
        assert abs(np.corrcoef(columns[a], columns[b])[0, 1]) < bound, (a, b)
    for i in range(6):  # adjacent samples of one component, and |x| (the layer bits) of adjacent samples
        assert abs(np.corrcoef(attitude[1:, i], attitude[:-1, i])[0, 1]) < bound
        assert abs(np.corrcoef(np.abs(attitude[1:, i]), np.abs(attitude[:-1, i]))[0, 1]) < bound


def test_seeds_outside_64_bits_are_refused():
    with pytest.raises(SpecificationError, match="seed"):
        SensorModel(attitude_noise=0.01, seed=2**64)
    with pytest.raises(SpecificationError, match="seed"):
        DelayModel.jitter(0.01, 0.02, seed=-1)


# ============================================================================ jitter scheduled in the C driver
@pytest.mark.parametrize("slice_samples", [7, 64, 2**16])
def test_the_driver_s_jitter_schedule_is_newest_arrived_in_any_slicing(slice_samples, monkeypatch):
    """d_min = 1 period (the engine's smallest), slices shorter and longer than d_max: j* as newest_arrived says."""
    from mrpctl import paper, simulate
    from mrpctl.engines import scalar as _engine
    from mrpctl.flight import Hysteretic, newest_arrived

    if _compile.find_compiler() is None:
        pytest.skip("no C compiler")
    rate, n, depth = 100.0, 601, 12
    model = DelayModel.jitter(0.01, 0.12, seed=6)
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", slice_samples)
    run = simulate(
        paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.12, rate=rate, rule=Hysteretic(0.1), t_final=6.0,
        delay=model, keep_every=1,
    )  # fmt: skip
    used, delay_used = newest_arrived(model.samples(rate, 0, n), history=depth)
    assert run.delay_used is not None and run.delay_used.tolist() == delay_used.tolist()
    seen = set(delay_used[depth:].tolist())
    assert seen <= set(range(1, depth + 1)) and {1, 2, 3, 4} <= seen  # the delay used varies, d_min included
    assert np.all(np.diff(used) >= 0)  # an overtaken measurement is never used
