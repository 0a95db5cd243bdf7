"""LMI criteria: literature delays, soundness against the exact margin, certificate checks, failures."""

from __future__ import annotations

import copy
import itertools
import math

import numpy as np
import pytest

import mrpctl.design.lmi as lmi_module
from mrpctl import paper
from mrpctl.design import (
    JENSEN,
    WIRTINGER,
    CertificateStatus,
    Positivity,
    SearchStatus,
    certify,
    delay_margin,
    linearized_loop,
    lmi_blocks,
    max_certified_delay,
)
from mrpctl.design._common import SolveOutcome
from mrpctl.errors import DimensionError, SpecificationError

BENCH_A = np.array([[-2.0, 0.0], [0.0, -0.9]])
BENCH_AD = np.array([[-1.0, 0.0], [-1.0, -1.0]])
GU_A = np.array([[0.0, 1.0], [-2.0, 0.1]])
GU_AD = np.array([[0.0, 0.0], [1.0, 0.0]])


# Seuret & Gouaisbaut (2013) Table 1 and (2015) Table 1: maximal delays for the classic benchmark,
# with P > 0 as in those papers.
@pytest.mark.parametrize(("order", "literature"), [(JENSEN, 4.472), (WIRTINGER, 6.059), (2, 6.166), (3, 6.172)])
def test_classic_benchmark_reproduces_literature(order: int, literature: float) -> None:
    result = max_certified_delay(BENCH_A, BENCH_AD, order=order, positivity=Positivity.STRICT)
    assert result.status is SearchStatus.CERTIFIED
    assert result.lower == 0.0
    assert result.upper == pytest.approx(literature, abs=1.5e-3)
    assert result.certificate is not None and result.certificate.certified


def test_relaxed_positivity_is_between_strict_and_exact() -> None:
    exact = delay_margin(BENCH_A, BENCH_AD).margin
    for order in (2, 3):
        strict = max_certified_delay(BENCH_A, BENCH_AD, order=order, positivity=Positivity.STRICT).upper
        relaxed = max_certified_delay(BENCH_A, BENCH_AD, order=order).upper
        assert strict * (1 - 2e-4) <= relaxed <= exact


def test_hierarchy_is_monotone_on_benchmark() -> None:
    uppers = [max_certified_delay(BENCH_A, BENCH_AD, order=n, rtol=1e-5).upper for n in range(4)]
    assert all(b >= a * (1 - 1e-5) for a, b in itertools.pairwise(uppers))


def test_scalar_pure_delay_jensen_is_sqrt_two() -> None:
    jensen = max_certified_delay(0.0, -1.0, order=JENSEN)
    assert jensen.upper == pytest.approx(math.sqrt(2.0), abs=1e-3)
    best = max_certified_delay(0.0, -1.0, order=2)
    assert math.pi / 2 * (1 - 1e-3) <= best.upper <= math.pi / 2


def test_paper_system_best_criterion_within_1e3_of_exact_and_tau_half_certified() -> None:
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    assert loop.split
    exact = loop.delay_margin().margin
    best = loop.max_certified_delay(order=3)
    assert best.status is SearchStatus.CERTIFIED
    assert exact * (1 - 1e-3) <= best.upper <= exact
    assert best.certificate is not None and best.certificate.certified
    for order in range(4):
        cert = loop.certify(paper.TAU, order=order)
        assert cert.certified, str(cert)
        assert cert.P.shape == (6 * (order + 1), 6 * (order + 1))


def test_per_axis_split_gives_the_full_answer() -> None:
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    split = loop.max_certified_delay(order=JENSEN, rtol=1e-4)
    full = max_certified_delay(loop.A, loop.A_d, order=JENSEN, rtol=1e-4)
    assert full.upper == pytest.approx(split.upper, rel=2e-4)
    # The assembled certificate is checked on the full 6x6 blocks by an independent recomputation.
    cert = loop.certify(1.0, order=WIRTINGER)
    blocks = lmi_blocks(loop.A, loop.A_d, 1.0, cert.P, cert.S, cert.R, order=WIRTINGER)
    assert all(np.linalg.eigvalsh(b)[0] > 0 for b in blocks.values())


def test_certified_interval_for_system_unstable_without_delay() -> None:
    exact = delay_margin(GU_A, GU_AD).stable_intervals[0]
    result = max_certified_delay(GU_A, GU_AD, order=2)
    assert result.status is SearchStatus.CERTIFIED
    assert exact[0] <= result.lower < result.upper <= exact[1]
    assert result.lower == pytest.approx(exact[0], rel=1e-3)  # Seuret & Gouaisbaut 2015: [0.1002, 1.7178]
    assert result.upper == pytest.approx(exact[1], rel=1e-2)
    assert "[" in str(result)
    jensen = max_certified_delay(GU_A, GU_AD, order=JENSEN)
    assert jensen.status is SearchStatus.NOT_CERTIFIED
    assert "too conservative" in jensen.reason


def test_system_unstable_for_every_delay_is_not_certified_with_reason() -> None:
    result = max_certified_delay(np.eye(2), np.zeros((2, 2)), order=1)
    assert result.status is SearchStatus.NOT_CERTIFIED
    assert result.solves == 0
    assert "unstable for every delay" in result.reason
    assert math.isnan(result.tau)


def test_delay_independent_system_hits_search_limit() -> None:
    result = max_certified_delay(-2.0 * np.eye(2), 0.5 * np.eye(2), order=0, tau_max=50.0)
    assert result.status is SearchStatus.SEARCH_LIMIT
    assert result.upper == 50.0


def _random_stable_pairs(rng: np.random.Generator, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    pairs = []
    while len(pairs) < count:
        n = int(rng.integers(1, 4))
        a = rng.normal(size=(n, n)) - rng.uniform(0.0, 2.0) * np.eye(n)
        a_d = rng.normal(size=(n, n))
        if np.max(np.linalg.eigvals(a + a_d).real) < -0.05:
            pairs.append((a, a_d))
    return pairs


def test_soundness_on_random_stable_systems(rng: np.random.Generator) -> None:
    certified = 0
    for i, (a, a_d) in enumerate(_random_stable_pairs(rng, 50)):
        exact = delay_margin(a, a_d)
        result = max_certified_delay(a, a_d, order=i % 3, rtol=1e-3, tau_max=20.0)
        if result.certified:
            certified += 1
            assert result.upper <= exact.margin * (1 + 1e-9), (a, a_d, result, exact)
        # A certificate just above the exact margin would be a soundness failure.
        if math.isfinite(exact.margin):
            assert not certify(a, a_d, exact.margin * 1.001, order=i % 3).certified
    assert certified >= 40


def test_parametric_and_rebuilt_problems_agree() -> None:
    assert lmi_module._compiled(2, 3, Positivity.RELAXED).problem.is_dpp()
    one = certify(BENCH_A, BENCH_AD, 5.0, order=1)
    two = certify(BENCH_A, BENCH_AD, 5.0, order=1, parametric=False)
    assert one.certified and two.certified
    assert one.solver_margin == pytest.approx(two.solver_margin, rel=1e-5, abs=1e-9)


def test_certificate_fields_and_str() -> None:
    cert = certify(BENCH_A, BENCH_AD, 4.0, order=JENSEN)
    assert cert.status is CertificateStatus.CERTIFIED
    assert cert.solver == "CLARABEL" and cert.solver_status == "optimal"
    assert {m.name for m in cert.margins} == {"S", "R", "positivity", "derivative"}
    assert cert.min_margin > 0
    with pytest.raises(ValueError, match="read-only"):
        cert.P[0, 0] = 1.0
    text = str(cert)
    assert "Jensen" in text and "certified" in text and "tau = 4" in text
    # Above the Jensen limit: a clean NOT_CERTIFIED with a reason.
    above = certify(BENCH_A, BENCH_AD, 4.6, order=JENSEN)
    assert above.status is CertificateStatus.NOT_CERTIFIED
    assert "margin" in above.reason


class PanicException(BaseException):
    pass


def test_rust_panic_becomes_solver_failed(monkeypatch: pytest.MonkeyPatch) -> None:
    problem = lmi_module._compiled(2, 1, Positivity.RELAXED).problem

    def panic(*args: object, **kwargs: object) -> None:
        raise PanicException("called `Result::unwrap()` on an `Err` value")

    monkeypatch.setattr(problem, "solve", panic)
    cert = certify(BENCH_A, BENCH_AD, 1.0, order=1)
    assert cert.status is CertificateStatus.SOLVER_FAILED
    assert "PanicException" in cert.reason
    assert cert.P is None

    def interrupt(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(problem, "solve", interrupt)
    with pytest.raises(KeyboardInterrupt):
        certify(BENCH_A, BENCH_AD, 1.0, order=1)


def test_optimal_inaccurate_is_never_a_certificate(monkeypatch: pytest.MonkeyPatch) -> None:
    certify(BENCH_A, BENCH_AD, 1.0, order=1)  # leaves feasible values in the variables
    monkeypatch.setattr(lmi_module, "solve", lambda problem: SolveOutcome("optimal_inaccurate", 0.0))
    cert = certify(BENCH_A, BENCH_AD, 1.0, order=1)
    assert cert.status is CertificateStatus.SOLVER_FAILED
    assert "optimal_inaccurate" in cert.reason


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (
            {"A": np.zeros((2, 3)), "A_d": np.zeros((2, 3)), "tau": 1.0},
            DimensionError,
            "A: expected a square",
        ),
        ({"A": np.eye(2), "A_d": np.eye(3), "tau": 1.0}, DimensionError, "A_d"),
        ({"A": BENCH_A, "A_d": BENCH_AD, "tau": -1.0}, SpecificationError, "tau must be > 0"),
        ({"A": BENCH_A, "A_d": BENCH_AD, "tau": math.nan}, SpecificationError, "tau must be finite"),
        ({"A": BENCH_A, "A_d": BENCH_AD, "tau": 1.0, "order": -1}, SpecificationError, "order"),
        ({"A": BENCH_A, "A_d": BENCH_AD, "tau": 1.0, "order": 1.5}, SpecificationError, "order"),
        (
            {"A": BENCH_A, "A_d": BENCH_AD, "tau": 1.0, "positivity": "strict"},
            SpecificationError,
            "positivity",
        ),
    ],
)
def test_bad_input(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        certify(**kwargs)


def test_bad_search_options() -> None:
    with pytest.raises(SpecificationError, match="rtol"):
        max_certified_delay(BENCH_A, BENCH_AD, rtol=0.0)
    with pytest.raises(SpecificationError, match="tau_max"):
        max_certified_delay(BENCH_A, BENCH_AD, tau_max=-1.0)


# ---- issue 9: threads, large delays, structure ------------------------------------------------


def _thread_jobs() -> list[tuple[str, tuple, dict]]:
    from mrpctl import paper as p

    loop = linearized_loop(p.SPACECRAFT, p.GAIN)
    jobs: list[tuple[str, tuple, dict]] = []
    for order, tau in ((0, 3.0), (1, 5.0), (2, 6.0), (3, 6.1)):
        jobs.append(("certify", (BENCH_A, BENCH_AD, tau), {"order": order}))
    for order in (0, 1, 2):
        jobs.append(("max", (BENCH_A / 7.0, BENCH_AD / 7.0), {"order": order, "rtol": 1e-2}))
    jobs.append(("max", (GU_A, GU_AD), {"order": 2, "rtol": 1e-2}))
    jobs.append(("certify", (loop.A, loop.A_d, 1.2), {"order": 1}))
    jobs.append(("certify", (-2.0 * np.eye(2), 0.5 * np.eye(2), 40.0), {"order": 2}))
    jobs.append(("pd", (p.SPACECRAFT, 0.5), {"order": 1}))
    jobs.append(("pd", (p.SPACECRAFT, 2.0), {"zeta": 1.3, "order": 2}))
    return jobs


def _run_job(job: tuple[str, tuple, dict]) -> tuple:
    from mrpctl.design import synthesize_pd

    kind, args, kwargs = job
    if kind == "certify":
        c = certify(*args, **kwargs)
        return (c.status, c.solver_margin)
    if kind == "max":
        r = max_certified_delay(*args, **kwargs)
        return (r.status, r.lower, r.upper, r.solves)
    s = synthesize_pd(*args, **kwargs)
    return (s.status, s.omega_n, s.decay_rate)


def test_thread_pool_answers_equal_serial_answers() -> None:
    # Main shared one compiled cvxpy problem between threads: different, wrong answers.
    from concurrent.futures import ThreadPoolExecutor

    jobs = _thread_jobs()
    serial = [_run_job(j) for j in jobs]
    with ThreadPoolExecutor(max_workers=4) as pool:
        threaded = list(pool.map(_run_job, jobs))
    assert threaded == serial
    assert sum(1 for r in serial if r[0] in (CertificateStatus.CERTIFIED, SearchStatus.CERTIFIED)) >= 8


@pytest.mark.parametrize("tau", [300.0, 1000.0])
def test_delay_independent_system_certified_at_large_delays(tau: float) -> None:
    # Main: Clarabel optimal_inaccurate for tau >~ 300 s; the unit-delay problem is well scaled.
    for order in range(4):
        cert = certify(-2.0 * np.eye(2), 0.5 * np.eye(2), tau, order=order)
        assert cert.certified, str(cert)
        # The certificate mapped back to the original time scale is a certificate there too.
        blocks = lmi_blocks(-2.0 * np.eye(2), 0.5 * np.eye(2), tau, cert.P, cert.S, cert.R, order=order)
        assert all(np.linalg.eigvalsh(b)[0] > 0 for b in blocks.values())


def test_slow_benchmark_certified_delays_are_monotone_in_order_and_scale_exactly() -> None:
    # The benchmark slowed down 100 times: exact margin 617.25 s, certified delays 100 x literature.
    c = 0.01
    uppers = []
    for order, literature in zip(range(4), (4.472, 6.059, 6.166, 6.172), strict=True):
        result = max_certified_delay(c * BENCH_A, c * BENCH_AD, order=order, positivity=Positivity.STRICT, rtol=1e-5)
        assert result.status is SearchStatus.CERTIFIED
        assert result.upper * c == pytest.approx(literature, abs=1.5e-3)
        uppers.append(result.upper)
    assert all(b >= a for a, b in itertools.pairwise(uppers))
    delay_independent = [
        max_certified_delay(-2.0 * np.eye(2), 0.5 * np.eye(2), order=n, tau_max=1000.0).upper for n in range(4)
    ]
    assert delay_independent == [1000.0] * 4


def test_complex_input_is_refused() -> None:
    with pytest.raises(SpecificationError, match="A must be real"):
        certify(BENCH_A + 1j, BENCH_AD, 1.0)
    with pytest.raises(SpecificationError, match="A_d must be real"):
        max_certified_delay(BENCH_A, BENCH_AD * (1 + 0j) + 1j)
    with pytest.raises(SpecificationError, match="real"):
        delay_margin(BENCH_A, BENCH_AD + 1j)


def test_results_compare_by_identity_without_raising() -> None:
    # Main: frozen dataclasses with eq=True over NumPy fields, so comparing two equal results raised
    # "truth value of an array is ambiguous". Now == is identity and never raises.
    from mrpctl.design import analyze_gains, pd_gains, synthesize_lmi, synthesize_pd

    def build() -> list[object]:
        return [
            certify(BENCH_A, BENCH_AD, 1.0, order=0),
            max_certified_delay(BENCH_A, BENCH_AD, order=0, rtol=1e-2),
            delay_margin(BENCH_A, BENCH_AD),
            linearized_loop(paper.SPACECRAFT, paper.GAIN),
            pd_gains(paper.SPACECRAFT, omega_n=0.5),
            analyze_gains(paper.SPACECRAFT, paper.GAIN),
            synthesize_pd(paper.SPACECRAFT, 0.5, order=0),
            synthesize_lmi(paper.SPACECRAFT, 0.5, decay_rate=0.1, order=0),
        ]

    for one, two in zip(build(), build(), strict=True):
        assert one == one
        assert one != two
        assert one != copy.copy(one)


def test_no_private_cross_imports_and_dead_code_gone() -> None:
    import ast
    import pathlib

    import mrpctl.design as design

    for path in pathlib.Path(design.__file__).parent.glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("mrpctl.design."):
                private = [a.name for a in node.names if a.name.startswith("_")]
                assert not private, (path.name, node.module, private)
    assert not hasattr(lmi_module, "_bessel_weights")
