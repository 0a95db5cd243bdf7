"""The vectorised lane engine (mrpctl.engines.lanes) against CasADi and the scalar engine.

Independent references: CasADi's own generated C of the same Function compiled with the
simulator's flags (bit for bit), CasADi's virtual machine (to an ulp), and the scalar engine
of mrpctl.simulation run after run (bit for bit, every statistic), directly and through
simulate_batch (whose metrics-only path is the lane engine).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math
from typing import Any

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mrpctl import _compile, paper
from mrpctl.engines import lanes as _vectorize
from mrpctl.engines import scalar as _engine
from mrpctl.engines.stats import STATS_SIZE, initial_stats
from mrpctl.errors import CodegenError, DimensionError, SpecificationError
from mrpctl.loop import InertiaInput, core_function
from mrpctl.model import state
from mrpctl.simulation import _batch, _simulate, simulate_batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, SwitchingRule

RATE = 1000.0
PERIOD = 1.0 / RATE


def bits(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=float).view(np.int64)


# ------------------------------------------------------------------ the emitter alone
def lanes_eval(function: ca.Function, inputs: list[np.ndarray], *, fuse: bool) -> list[np.ndarray]:
    """Evaluate the emitted lane code: inputs (W, nnz_i) per port -> outputs (W, nnz_o)."""
    width = inputs[0].shape[0]
    program = _vectorize.emit_lanes(function, width, name=f"t_{function.name()}", fuse=fuse, standalone=True)
    library = _vectorize._build_library(program.code, f"test_{function.name()}_w{width}", _vectorize.LANE_FLAGS)
    evaluate = getattr(ctypes.CDLL(str(library)), program.name + "_eval")
    soa_in = [np.ascontiguousarray(value.T) for value in inputs]
    soa_out = [np.zeros((function.nnz_out(i), width)) for i in range(function.n_out())]
    arg = (ctypes.c_void_p * len(soa_in))(*[_compile.address(a) for a in soa_in])
    res = (ctypes.c_void_p * len(soa_out))(*[_compile.address(a) for a in soa_out])
    assert evaluate(arg, res) == 0
    return [value.T for value in soa_out]


def casadi_c_eval(function: ca.Function, inputs: list[np.ndarray]) -> list[np.ndarray]:
    """CasADi's generated scalar C (simulator flags), lane by lane, called through ctypes."""
    compiled = _compile.compile_function(function, flags=_compile.SIMULATION_FLAGS)
    assert compiled.compiled and compiled.library is not None
    evaluate = getattr(ctypes.CDLL(str(compiled.library)), function.name())
    evaluate.restype = ctypes.c_int
    iw = np.zeros(max(function.sz_iw(), 1), dtype=np.int64)
    w = np.zeros(max(function.sz_w(), 1))
    width = inputs[0].shape[0]
    outputs = [np.zeros((width, function.nnz_out(i))) for i in range(function.n_out())]
    for lane in range(width):
        row_in = [np.ascontiguousarray(value[lane]) for value in inputs]
        row_out = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
        arg = (ctypes.c_void_p * max(function.sz_arg(), 1))(*[_compile.address(a) for a in row_in])
        res = (ctypes.c_void_p * max(function.sz_res(), 1))(*[_compile.address(a) for a in row_out])
        assert evaluate(arg, res, ctypes.c_void_p(_compile.address(iw)), ctypes.c_void_p(_compile.address(w)), 0) == 0
        for i, value in enumerate(row_out):
            outputs[i][lane] = value
    return outputs


def vm_eval(function: ca.Function, inputs: list[np.ndarray]) -> list[np.ndarray]:
    width = inputs[0].shape[0]
    mapped = function.map(width)
    shapes_in = [function.size_in(i) for i in range(function.n_in())]
    out = mapped(
        *[
            np.hstack([row.reshape(shape, order="F") for row in value])
            for value, shape in zip(inputs, shapes_in, strict=True)
        ]
    )
    out = out if isinstance(out, (list, tuple)) else [out]
    rows = []
    for i, value in enumerate(out):
        columns = function.size_out(i)[1]
        array = np.asarray(value)
        rows.append(
            np.array([array[:, lane * columns : (lane + 1) * columns].ravel(order="F") for lane in range(width)])
        )
    return rows


def special_values(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Random values with signed zeros, ties, infinities and NaNs mixed in."""
    values = rng.normal(scale=3.0, size=shape)
    pool = np.array([0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan, 2.5, 1e-300, -1e300])
    mask = rng.uniform(size=shape) < 0.3
    values[mask] = rng.choice(pool, size=int(mask.sum()))
    return values


def arithmetic_function() -> ca.Function:
    x = ca.SX.sym("x", 3)
    y = ca.SX.sym("y", 2)
    e = [
        x[0] + x[1], x[0] - y[0], x[1] * y[1], x[0] / x[2], -x[2], ca.sqrt(x[1]), x[0] ** 2, 2 * y[0], 1 / x[1],
        ca.fabs(x[2]), ca.sign(x[0]), ca.copysign(x[0], y[1]),
        x[0] < x[1], x[0] <= y[0], x[1] == y[1], x[2] != y[0],
        ca.logic_not(x[0]), ca.logic_and(x[0], y[0]), ca.logic_or(x[1], y[1]),
        ca.if_else(x[0] > y[0], x[1] * y[1], x[2] / y[0]),
    ]  # fmt: skip
    return ca.Function("arith", [x, y], [ca.vertcat(*e), x[0] * y[0] + 3.0], ["x", "y"], ["r", "s"])


def libm_function() -> ca.Function:
    x = ca.SX.sym("x", 2)
    e = [
        ca.exp(x[0]), ca.log(x[1]), ca.fabs(x[0]) ** x[1], ca.sin(x[0]) * ca.cos(x[1]), ca.tan(x[0]),
        ca.atan2(x[0], x[1]),
        ca.tanh(x[1]), ca.floor(x[0]) + ca.ceil(x[1]), ca.fmod(x[0], x[1]), ca.erf(x[0]), ca.hypot(x[0], x[1]),
        ca.log1p(ca.fabs(x[1])), ca.expm1(x[0] / 8), ca.asin(x[0] / 10) + ca.acos(x[1] / 10) + ca.atan(x[0]),
        ca.sinh(x[0] / 4) + ca.cosh(x[1] / 4), x[0] * ca.exp(-x[1] * x[1]) + 1,
    ]  # fmt: skip
    return ca.Function("libm", [x], [ca.vertcat(*e)], ["x"], ["r"])


def engine_sample_function(rule) -> ca.Function:
    d = 7
    core = core_function(paper.SPACECRAFT, rule, d, PERIOD, 1, inertia=InertiaInput.FULL)
    return _engine.engine_sample(core, d, "sample_t")


def tilted(rng: np.random.Generator, count: int) -> list[Spacecraft]:
    """The paper's spacecraft with dispersed principal inertias (+-10 %) in random body axes:
    full inertia matrices (products of inertia), physically valid."""
    principal = np.diag(paper.SPACECRAFT.inertia)
    crafts = []
    for rotation in Rotation.random(count, random_state=rng):
        axes = rotation.as_matrix()
        j = axes @ np.diag(principal * rng.uniform(0.9, 1.1, 3)) @ axes.T
        crafts.append(Spacecraft((j + j.T) / 2))
    # run 0: the paper's J with a 1e-6 kg m^2 product of inertia (a full matrix; the paper's chatter)
    crafts[0] = Spacecraft(paper.SPACECRAFT.inertia + 1e-6 * (np.ones((3, 3)) - np.eye(3)))
    return crafts


@pytest.mark.parametrize("fuse", [True, False])
def test_emitter_bit_identical_to_casadi_c_on_special_values(rng: np.random.Generator, fuse: bool) -> None:
    function = arithmetic_function()
    width = 37
    inputs = [special_values(rng, (width, 3)), special_values(rng, (width, 2))]
    got = lanes_eval(function, inputs, fuse=fuse)
    expected = casadi_c_eval(function, inputs)
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_array_equal(bits(g), bits(e))
    assert np.isnan(expected[0]).any() and np.isinf(expected[0]).any()  # the special values were exercised


def selection_function() -> ca.Function:
    """if_else (CasADi's SX: (c?a:0) + (!c?b:0), which adds +0.0 to the chosen value) between values that may be
    -0.0 or a signaling NaN (inputs, products, negations, quotients, |x| of an input) and values that never are
    (sums with a constant, squares, |x| of a result, square roots of those, their sums and differences)."""
    x = ca.SX.sym("x", 3)
    c = x[0] > x[1]
    e = [
        ca.if_else(c, x[1], x[2]), ca.if_else(c, x[0] * x[1], -x[2]), ca.if_else(c, x[0] / x[1], x[2] + 0.0),
        ca.if_else(c, ca.fabs(x[2]), x[1]), ca.if_else(c, x[2] + 1.0, x[0] ** 2),  # the clean ones from here
        ca.if_else(c, ca.fabs(x[0] - x[1]), x[1] ** 2 - x[2]), ca.if_else(c, ca.sqrt(x[0] ** 2 + 1), 2 * (x[1] + 1.0)),
        ca.if_else(x[2] < 0, ca.if_else(c, x[0] ** 2, 1.0), x[1] * x[1] + x[2] ** 2),
    ]  # fmt: skip
    return ca.Function("selections", [x], [ca.vertcat(*e)], ["x"], ["r"])


def test_emitter_selections_keep_signed_zeros_bit_identical_to_casadi_c(rng: np.random.Generator) -> None:
    """A selection adds the +0.0 of CasADi's zero arm unless both values are provably neither -0.0 nor a
    signaling NaN (then x + 0.0 is x): bit for bit CasADi's C on inputs full of -0.0, +0.0 and NaNs."""
    function = selection_function()
    width = 64
    values = special_values(rng, (width, 3))
    values[rng.uniform(size=values.shape) < 0.3] = -0.0
    # signaling NaNs, each in a row without another NaN: where two NaNs meet in a sum or a product, which payload
    # survives is the compiler's choice of operand order (in CasADi's C as in the lanes)
    signaling = np.array([0x7FF0000000000001, 0xFFF0000000000123], dtype=np.uint64).view(float)
    for column, start in ((0, 0), (1, 3), (2, 5)):
        values[start::7] = np.where(np.isnan(values[start::7]), -0.0, values[start::7])
        values[start::7, column] = signaling[column % 2]
    got = lanes_eval(function, [values], fuse=True)
    expected = casadi_c_eval(function, [values])
    np.testing.assert_array_equal(bits(got[0]), bits(expected[0]))
    plain = np.where(values[:, 0] > values[:, 1], values[:, 1], values[:, 2])  # the choice without the + 0.
    assert (bits(plain) != bits(expected[0][:, 0])).any()  # a -0.0 or a signaling NaN was chosen: the + 0. showed
    code = _vectorize.emit_lanes(function, 4).code
    selections = [line for line in code.splitlines() if "L_SELECT(L_MASK(" in line]
    assert sum(line.endswith("+0.);") for line in selections) == 4  # the four selections that may meet -0.0/sNaN
    assert len(selections) == 9  # and five without the + 0. (the nested one is two)


def minmax_function() -> ca.Function:
    x = ca.SX.sym("x", 2)
    e = [ca.fmin(x[0], x[1]), ca.fmax(x[0], x[1]), ca.fmax(x[1], x[0]), ca.fmin(ca.sqrt(x[0]), 2 * x[1])]
    return ca.Function("minmax", [x], [ca.vertcat(*e)], ["x"], ["r"])


def test_emitter_fmin_fmax_bit_identical_to_casadi_c_and_to_the_libm_on_ties(rng: np.random.Generator) -> None:
    function = minmax_function()
    values = special_values(rng, (41, 2))
    values[:4] = [[np.nan, 1.0], [1.0, np.nan], [np.nan, np.nan], [np.inf, -np.inf]]
    zero = (values == 0.0).all(axis=1) & (np.signbit(values[:, 0]) != np.signbit(values[:, 1]))
    values[zero, 1] = 0.5  # no (+0, -0) ties here: see below
    got = lanes_eval(function, [values], fuse=True)[0]
    np.testing.assert_array_equal(bits(got), bits(casadi_c_eval(function, [values])[0]))
    # C99 leaves fmin/fmax(+0, -0) to the library, and gcc may swap the arguments of these
    # commutative builtins in CasADi's C, so on a tie the lanes follow the libm called with
    # CasADi's argument order (through ctypes: no compiler in between).
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    ties = np.array([[0.0, -0.0], [-0.0, 0.0]])
    got = lanes_eval(function, [ties], fuse=True)[0]
    for name, column, (a, b) in (("fmin", 0, (0, 1)), ("fmax", 1, (0, 1)), ("fmax", 2, (1, 0))):
        reference = getattr(libm, name)
        reference.restype = ctypes.c_double
        reference.argtypes = [ctypes.c_double, ctypes.c_double]
        for row in range(2):
            expected = reference(ties[row, a], ties[row, b])
            assert math.copysign(1.0, got[row, column]) == math.copysign(1.0, expected)


def test_emitter_libm_calls_bit_identical_to_casadi_c_and_an_ulp_from_the_vm(rng: np.random.Generator) -> None:
    function = libm_function()
    inputs = [np.column_stack((rng.uniform(-3, 3, 19), rng.uniform(0.2, 4, 19)))]
    got = lanes_eval(function, inputs, fuse=True)[0]
    np.testing.assert_array_equal(bits(got), bits(casadi_c_eval(function, inputs)[0]))
    vm = vm_eval(function, inputs)[0]
    assert np.all(np.isfinite(vm))
    np.testing.assert_array_less(np.abs(got - vm), 2.0 * np.spacing(np.maximum(np.abs(got), np.abs(vm))) + 1e-300)


@pytest.mark.parametrize("rule", [OnDelayed(), DelayAware(1.1)], ids=["OnDelayed", "DelayAware"])
def test_emitter_on_the_engine_sample(rng: np.random.Generator, rule) -> None:
    function = engine_sample_function(rule)
    width = 16
    x = state(Rotation.random(width, random_state=rng).as_mrp() * rng.uniform(0.5, 1.9, (width, 1)),
              rng.uniform(-5, 5, (width, 3)))  # fmt: skip
    stats = np.tile(initial_stats(100), (width, 1))
    stats[:, 0] = rng.integers(0, 120, width)  # some lanes past the horizon: masked
    stats[::5, 13] = 3.0  # some already diverged: masked
    inputs = [
        x,
        rng.integers(0, 9, (width, 1)).astype(float),
        stats,
        state(rng.normal(scale=0.8, size=(width, 3)), rng.uniform(-5, 5, (width, 3))),
        np.tile(paper.GAIN.T.ravel(), (width, 1)) * rng.uniform(0.5, 1.5, (width, 1)),
        np.full((width, 1), rule.parameters()[0]),
    ]
    crafts = tilted(rng, width)
    inputs += [np.array([c.inertia.T.ravel() for c in crafts]), np.array([c.inertia_inverse.T.ravel() for c in crafts])]
    got = lanes_eval(function, inputs, fuse=True)
    compiled = casadi_c_eval(function, inputs)
    vm = vm_eval(function, inputs)
    for g, e, v in zip(got, compiled, vm, strict=True):
        np.testing.assert_array_equal(bits(g), bits(e))
        np.testing.assert_array_less(np.abs(g - v), 2.0 * np.spacing(np.maximum(np.abs(g), np.abs(v))) + 1e-300)
    assert 0 < got[5].sum() < width  # some lanes switched, some did not


def test_emitter_refuses_unsupported_operations_and_mx() -> None:
    x = ca.SX.sym("x", 2)
    printing = ca.Function("printing", [x], [x[0].printme(x[1]) + 1])
    with pytest.raises(CodegenError, match=r"cannot vectorise instruction .*OP_PRINTME.*supported: .*OP_ADD"):
        _vectorize.emit_lanes(printing, 4)
    z = ca.MX.sym("z", 2)
    with pytest.raises(CodegenError, match="pure SX Function"):
        _vectorize.emit_lanes(ca.Function("mx", [z], [z * 2]), 4)
    with pytest.raises(SpecificationError, match="drop"):
        _vectorize.emit_lanes(arithmetic_function(), 4, drop=["nope"])
    with pytest.raises(SpecificationError, match="width"):
        _vectorize.emit_lanes(arithmetic_function(), 0)


# ------------------------------------------------------------------ lanes against the scalar engine
def dispersed_batch(rng: np.random.Generator, rule_class, count: int = 13):
    """Attitudes uniform on SO(3), rates to 5 rad/s, gains 0.5-1.5x the paper's, one run the
    paper's chattering case, one diverging run (|omega| = 4e5 rad/s), dispersed rule parameters."""
    x0 = state(Rotation.random(count, random_state=rng).as_mrp(), rng.uniform(-5, 5, (count, 3)))
    x0[0] = paper.INITIAL_STATE
    x0[1, 3:] = 1e5  # omega = 4e5 rad/s: the divergence guard fires
    gains = paper.GAIN[None] * rng.uniform(0.5, 1.5, (count, 1, 1))
    gains[0] = paper.GAIN
    rules: list[SwitchingRule]
    if rule_class is BoundaryLayer:
        rules = [BoundaryLayer(float(eps)) for eps in rng.uniform(0.001, 0.2, count)]
    elif rule_class is DelayAware:
        rules = [DelayAware(float(alpha)) for alpha in rng.uniform(1.0, 1.3, count)]
    else:
        rules = [rule_class()] * count
    return x0, gains, rules


def scalar_stats(x0, gains, rules, d: int, n: int, crafts=None) -> np.ndarray:
    """The scalar engine, run after run (Engine.run: one C call per slice, stops at divergence)."""
    crafts = crafts or [paper.SPACECRAFT] * len(x0)
    rows = []
    for i in range(len(x0)):
        scalar = _engine.engine(crafts[i], rules[i], d, PERIOD, 1)
        rows.append(
            scalar.run(
                x0[i],
                rules[i].initial_memory(delay_samples=d),
                _simulate.measurement_history("constant", x0[i], d)[0],
                gains[i],
                np.array(rules[i].parameters()),
                n,
                spacecraft=crafts[i],
                keep_every=None,
                workspace=scalar.workspace(n, switches=False),
            ).stats
        )
    return np.array(rows)


def lane_stats(x0, gains, rules, d: int, n: int, *, width: int, threads: int | None = None, crafts=None):
    crafts = crafts or [paper.SPACECRAFT] * len(x0)
    lanes = _vectorize.lane_engine(crafts[0], rules[0], d, PERIOD, 1, width=width)
    return _vectorize.simulate_lanes(
        lanes,
        x0,
        np.array([rule.initial_memory(delay_samples=d) for rule in rules]),
        np.stack([_simulate.measurement_history("constant", x, d)[0].T for x in x0]),
        gains,
        np.array([rule.parameters() for rule in rules]),
        n,
        spacecraft=crafts,
        threads=threads,
    )


RULES = [NoSwitching, OnCurrent, OnDelayed, BoundaryLayer, DelayAware]


@pytest.mark.slow
@pytest.mark.parametrize("d", [0, 150])
@pytest.mark.parametrize("rule_class", RULES, ids=[rule.__name__ for rule in RULES])
def test_every_lane_bit_identical_to_the_scalar_engine(rng: np.random.Generator, rule_class, d: int) -> None:
    n = 1501  # 1.5 s at 1 kHz: the paper's case crosses |sigma| = 1 at 0.44 s
    x0, gains, rules = dispersed_batch(rng, rule_class)
    crafts = tilted(rng, len(x0))  # per-lane J, J^-1 (full matrices)
    expected = scalar_stats(x0, gains, rules, d, n, crafts)
    got = lane_stats(x0, gains, rules, d, n, width=4, crafts=crafts)  # 13 runs: 3 full batches and one padded
    np.testing.assert_array_equal(bits(got), bits(expected))
    # the batch holds what it should: a diverged run, settled and unsettled ones, switching ones
    assert expected[1, 13] >= 0 and (expected[:, 13] < 0).sum() >= 10
    if rule_class is not NoSwitching:
        assert (expected[:, 2] >= 1).sum() >= 3
    if rule_class is OnDelayed and d > 0:
        assert expected[0, 2] > 50  # the paper's chatter


def test_lanes_default_width_threads_and_padding(rng: np.random.Generator) -> None:
    d, n = 150, 1501
    x0, gains, rules = dispersed_batch(rng, OnDelayed, count=11)
    expected = scalar_stats(x0, gains, rules, d, n)
    assert expected[0, 2] > 50 and expected[1, 13] >= 0  # chattering and diverging runs present
    pooled = lane_stats(x0, gains, rules, d, n, width=_vectorize.DEFAULT_WIDTH, threads=2)
    serial = lane_stats(x0, gains, rules, d, n, width=_vectorize.DEFAULT_WIDTH, threads=1)
    np.testing.assert_array_equal(bits(pooled), bits(expected))
    np.testing.assert_array_equal(bits(serial), bits(expected))
    lanes = _vectorize.lane_engine(paper.SPACECRAFT, rules[0], d, PERIOD, 1, width=_vectorize.DEFAULT_WIDTH)
    constant_history = _vectorize.simulate_lanes(
        lanes,
        x0,
        np.array([r.initial_memory(delay_samples=d) for r in rules]),
        np.repeat(x0[:, :, None], d, axis=2),
        gains,
        np.array([r.parameters() for r in rules]),
        n,
        spacecraft=paper.SPACECRAFT,
    )  # (N, 6, d): the "constant" history written out as d columns (lane_stats gives one column)
    np.testing.assert_array_equal(bits(constant_history), bits(expected))
    alone = lane_stats(x0[5:6], gains[5:6], rules[5:6], d, n, width=_vectorize.DEFAULT_WIDTH)
    np.testing.assert_array_equal(bits(alone), bits(expected[5:6]))  # padding lanes do not leak in


def test_lane_engine_reads_its_ports_and_checks_inputs(monkeypatch: pytest.MonkeyPatch) -> None:
    lanes = _vectorize.lane_engine(paper.SPACECRAFT, OnDelayed(), 150, PERIOD, 1, width=_vectorize.DEFAULT_WIDTH)
    assert set(lanes.carried) == {"x", "memory", "stats"}
    assert set(lanes.constants) == {"K", "parameters", "J", "J_inv"}
    assert lanes.constants["J"].stop - lanes.constants["J"].start == 3  # the paper's J is diagonal
    assert lanes.program.dropped == ("u", "switched")
    assert lanes.history_columns == 150
    good = {"x": np.zeros((2, 6)), "memory": np.zeros((2, 1)), "stats": np.zeros((2, STATS_SIZE))}
    constants = {"K": np.zeros((2, 18)), "parameters": np.zeros((2, 1)), "J": np.ones((2, 3)), "J_inv": np.ones((2, 3))}
    history = np.zeros((2, 150, 6))
    with pytest.raises(SpecificationError, match="missing \\['K'\\]"):
        lanes.run(good, {"parameters": np.zeros((2, 1)), "J": np.ones((2, 3)), "J_inv": np.ones((2, 3))}, history, 10)
    with pytest.raises(DimensionError, match="history: expected shape \\(N, 150, 6\\) or \\(N, 1, 6\\)"):
        lanes.run(good, constants, np.zeros((2, 149, 6)), 10)
    with pytest.raises(DimensionError, match="x: expected shape \\(2, 6\\)"):
        lanes.run({**good, "x": np.zeros((3, 6))}, constants, history, 10)
    with pytest.raises(SpecificationError, match="threads"):
        lanes.run(good, constants, history, 10, threads=0)
    assert math.isfinite(lanes.run(good, constants, history, 3)["stats"][0, 0])
    monkeypatch.setattr(_vectorize, "_available_memory", lambda: 2**30)
    with pytest.raises(
        SpecificationError, match=r"about 5\.6 GiB .* about 1\.0 GiB are available; run fewer runs per call"
    ):
        huge = 10**7  # 8 * (2 * 25 + 25) bytes per run (state 6, memory 1, stats 18): refused before any allocation
        lanes.run(
            {key: np.broadcast_to(value[:1], (huge, value.shape[1])) for key, value in good.items()},
            {key: np.broadcast_to(value[:1], (huge, value.shape[1])) for key, value in constants.items()},
            np.broadcast_to(history[:1, :1], (huge, 1, 6)),
            10,
        )


# ------------------------------------------------------------------ simulate_batch on the lanes
def scalar_batch(monkeypatch: pytest.MonkeyPatch, *args, **kwargs):
    """simulate_batch on the scalar engine (one C call per run and slice): the reference."""
    with monkeypatch.context() as patch:
        patch.setattr(_batch, "_LANES", False)
        return simulate_batch(*args, **kwargs)


def assert_batches_identical(got, expected) -> None:
    for name in ("switch_count", "first_switch_time", "last_switch_time", "sign_flips", "settling_time",
                 "converged", "diverged", "max_sigma", "peak_torque"):  # fmt: skip
        a, b = np.asarray(getattr(got, name)), np.asarray(getattr(expected, name))
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a.view(np.uint8), b.view(np.uint8), err_msg=name)


def test_simulate_batch_lanes_bit_identical_to_the_scalar_path(
    rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every rule in one batch (a lane group each), per-run spacecraft (full inertias, and the
    diagonal paper one), per-run K and rule parameters, two delays, diverging and chattering
    runs, 27 runs (not a multiple of W = 8); thread pool and series."""
    count = 27
    x0, gains, _ = dispersed_batch(rng, OnDelayed, count)
    x0[2] = paper.INITIAL_STATE * [1, 1, 1, -1, 1, 1]
    x0[4] = state([2e-4, -1e-4, 5e-5], [0.0, 0.0, 0.0])  # settled from the start: converged
    rules: list[SwitchingRule] = []
    for i in range(count):
        kind = RULES[i % len(RULES)]
        if kind is BoundaryLayer:
            rules.append(BoundaryLayer(float(rng.uniform(0.001, 0.2))))
        elif kind is DelayAware:
            rules.append(DelayAware(float(rng.uniform(1.0, 1.3))))
        else:
            rules.append(kind())
    rules[0] = OnDelayed()  # the paper's chattering case: run 0
    crafts = tilted(rng, count)
    crafts[3::4] = [paper.SPACECRAFT] * len(crafts[3::4])  # the diagonal layout too
    tau = np.where(np.arange(count) % 3 == 2, 0.0, 0.15)
    tau[0] = tau[1] = 0.15
    common: dict[str, Any] = dict(tau=tau, rule=rules, t_final=1.5, rate=RATE)
    expected = scalar_batch(monkeypatch, crafts, gains, x0, **common, threads=1)
    assert expected.switch_count[0] > 50 and expected.diverged[1]  # chattering and diverging runs present
    assert expected.converged.any() and (~expected.converged & ~expected.diverged).any()
    pooled = simulate_batch(crafts, gains, x0, **common, threads=2)
    serial = simulate_batch(crafts, gains, x0, **common, threads=1)
    assert_batches_identical(pooled, expected)
    assert_batches_identical(serial, expected)
    keys = {(c.is_diagonal, type(r), t) for c, r, t in zip(crafts, rules, tau, strict=True)}
    assert len(keys) >= 15  # many lane groups, most not a multiple of W


def test_simulate_batch_lanes_histories_and_fallback(rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch) -> None:
    """zero-input and array histories through the lanes equal the scalar path; a rule without a
    lane form (remainder) is run by the scalar engine, with the same result."""
    count = 11
    x0, gains, rules = dispersed_batch(rng, DelayAware, count)
    d = 30
    history = state(rng.normal(scale=0.3, size=(d, 3)), rng.uniform(-1, 1, (d, 3)))
    for kind in ("zero-input", history):
        common: dict[str, Any] = dict(tau=d / RATE, rule=rules, t_final=0.8, rate=RATE, history=kind)
        assert_batches_identical(
            simulate_batch(paper.SPACECRAFT, gains, x0, **common),
            scalar_batch(monkeypatch, paper.SPACECRAFT, gains, x0, **common),
        )

    class Remainder(OnCurrent):  # |sigma|^2 + (remainder(sigma_1, 1e9) - sigma_1) >= 1: OnCurrent's values
        def _condition(self, sigma, sigma_meas, memory, parameters, d):
            return ca.sumsqr(sigma) + (ca.remainder(sigma[0], 1e9) - sigma[0]) >= 1

    with pytest.raises(CodegenError, match="OP_REMAINDER"):
        _vectorize.lane_engine(paper.SPACECRAFT, Remainder(), d, PERIOD, 1)
    common = dict(tau=d / RATE, rule=Remainder(), t_final=0.3, rate=RATE)
    fallback = simulate_batch(paper.SPACECRAFT, gains[:3], x0[:3], **common)
    assert_batches_identical(fallback, scalar_batch(monkeypatch, paper.SPACECRAFT, gains[:3], x0[:3], **common))


def test_simulate_batch_lanes_stop_between_slices(rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch) -> None:
    """A lane batch runs its horizon in slices and sees the stop flag between them: a batch's
    stop hook is called once per slice, and True abandons the batch; through simulate_batch, a
    KeyboardInterrupt raised by progress stops the batch long before its end and propagates."""
    x0, gains, rules = dispersed_batch(rng, OnDelayed, 3)
    lanes = _vectorize.lane_engine(paper.SPACECRAFT, rules[0], 150, PERIOD, 1)
    packed = _vectorize.closed_loop_batches(
        lanes, x0, np.zeros(3), x0[:, :, None], gains, np.ones((3, 1)), 1000,
        spacecraft=paper.SPACECRAFT, slice_samples=300,
    )  # fmt: skip
    calls: list[int] = []

    def hook(answer: bool):
        def stop(done: int) -> bool:
            calls.append(done)
            return answer

        return stop

    assert packed.run(0, hook(False))
    assert calls == [300 * 3, 600 * 3, 900 * 3, 1000 * 3]  # run-samples after each slice
    calls.clear()
    assert not packed.run(0, hook(True))
    assert calls == [300 * 3]

    monkeypatch.setattr(_batch, "slice_samples", lambda substeps: 1000)
    seen: list[int] = []

    def progress(done: int, total: int) -> None:
        seen.append(done)
        if done > 0:
            raise KeyboardInterrupt

    # 3e7 samples of 3 runs: 10 % of them is 0.3 s of work even on a host whose lanes do 3e7 run-samples a second
    # (AVX-512, measured), far more than the 50 ms before the first progress poll; stopped after the first slices
    t_final = 30000.0
    with pytest.raises(KeyboardInterrupt):
        simulate_batch(paper.SPACECRAFT, gains, x0, tau=0.15, rule=rules, t_final=t_final, rate=RATE, progress=progress)
    assert 0 < seen[-1] < 3 * (t_final * RATE) / 10
