"""The true error's statistics form (`settling_error_expr`) against exact rational arithmetic and a quaternion
formula written here, the regulation special case bit for bit, and the driver's record function
(`true_error_function`) against the sample's own ``tracking_error`` output."""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import numpy as np

from mrpctl.flight.tracking import settling_error_expr, tracking_error_expr
from mrpctl.loop.functions import true_error_function


def _function() -> ca.Function:
    sigma_b, omega, sigma_r, omega_r = (ca.SX.sym(name, 3) for name in ("sigma_b", "omega", "sigma_r", "omega_r"))
    squared, rate = settling_error_expr(sigma_b, omega, sigma_r, omega_r)
    return ca.Function("settling", [sigma_b, omega, sigma_r, omega_r], [squared, rate])


def _exact_short_squared(sigma_b: np.ndarray, sigma_r: np.ndarray) -> float:
    """|σ_B/R|² of the short set from the MRP composition n/D in exact rational arithmetic."""
    b = [Fraction(float(v)) for v in sigma_b]
    r = [Fraction(float(v)) for v in sigma_r]
    sb, sr = sum(v * v for v in b), sum(v * v for v in r)
    cross = [b[1] * r[2] - b[2] * r[1], b[2] * r[0] - b[0] * r[2], b[0] * r[1] - b[1] * r[0]]
    n = [(1 - sr) * b[i] - (1 - sb) * r[i] + 2 * cross[i] for i in range(3)]
    d = 1 + sr * sb + 2 * sum(b[i] * r[i] for i in range(3))
    size = sum(v * v for v in n)
    return float(min(size / (d * d), d * d / size)) if size > 0 else 0.0


def _quaternion(sigma: np.ndarray) -> np.ndarray:
    s = float(sigma @ sigma)
    return np.concatenate(([(1 - s) / (1 + s)], 2 * sigma / (1 + s)))


def _dcm(sigma: np.ndarray) -> np.ndarray:
    """[BN] of an MRP from its quaternion (Schaub & Junkins Eq. 3.64)."""
    q0, q1, q2, q3 = _quaternion(sigma)
    return np.array(
        [
            [q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 + q0 * q3), 2 * (q1 * q3 - q0 * q2)],
            [2 * (q1 * q2 - q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 + q0 * q1)],
            [2 * (q1 * q3 + q0 * q2), 2 * (q2 * q3 - q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3],
        ]
    )


def _mrps(rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (σ_B, σ_R) in the short set: independent ones, and σ_R within 1e-12..1e-3 of σ_B."""
    body = rng.normal(size=(count, 3))
    body *= (rng.uniform(0.0, 1.0, count) / np.linalg.norm(body, axis=1))[:, None]
    reference = rng.normal(size=(count, 3))
    reference *= (rng.uniform(0.0, 1.0, count) / np.linalg.norm(reference, axis=1))[:, None]
    near = body + rng.normal(size=(count, 3)) * 10.0 ** rng.uniform(-12.0, -3.0, count)[:, None]
    near /= np.maximum(1.0, np.linalg.norm(near, axis=1))[:, None]
    return np.vstack((body, body)), np.vstack((reference, near))


def test_squared_error_is_the_short_composition_to_a_few_ulps() -> None:
    f = _function()
    body, reference = _mrps(np.random.default_rng(7), 400)
    worst = 0.0
    for sigma_b, sigma_r in zip(body, reference, strict=True):
        squared = float(f(sigma_b, np.zeros(3), sigma_r, np.zeros(3))[0])
        exact = _exact_short_squared(sigma_b, sigma_r)
        worst = max(worst, abs(squared - exact) / exact)
        # the short set's half angle from the error quaternion: |σ|² = (1 − |β₀|)/(1 + |β₀|), β₀ = β_B·β_R
        cosine = abs(float(_quaternion(sigma_b) @ _quaternion(sigma_r)))
        assert np.isclose(squared, (1 - cosine) / (1 + cosine), rtol=1e-6, atol=1e-15)
    assert worst < 8 * np.finfo(float).eps


def test_rate_error_is_the_body_rate_minus_the_rotated_reference_rate() -> None:
    f = _function()
    rng = np.random.default_rng(11)
    body, reference = _mrps(rng, 50)
    for sigma_b, sigma_r in zip(body, reference, strict=True):
        omega, omega_r = rng.normal(size=3), rng.normal(size=3)
        rate = np.asarray(f(sigma_b, omega / 4.0, sigma_r, omega_r)[1]).ravel()
        np.testing.assert_allclose(rate, omega - _dcm(sigma_b) @ omega_r, rtol=1e-13, atol=1e-14)


def test_origin_reference_gives_the_regulation_statistics_bit_for_bit() -> None:
    f = _function()
    rng = np.random.default_rng(3)
    body, _ = _mrps(rng, 100)
    for sigma_b in body:
        omega = rng.normal(size=3)
        squared, rate = f(sigma_b, omega / 4.0, np.zeros(3), np.zeros(3))
        assert float(squared) == float((sigma_b[0] ** 2 + sigma_b[1] ** 2) + sigma_b[2] ** 2)
        assert np.array_equal(np.asarray(rate).ravel(), 4.0 * (omega / 4.0))


def test_record_function_is_the_sample_true_error_bit_for_bit() -> None:
    x = ca.SX.sym("x", 6)
    row = ca.SX.sym("row", 9)
    sample_form = ca.Function("e", [x, row], [tracking_error_expr(x[0:3], x[3:6], row[0:3], row[3:6])[0]])
    record = true_error_function()
    rng = np.random.default_rng(5)
    body, reference = _mrps(rng, 100)
    for sigma_b, sigma_r in zip(body, reference, strict=True):
        state = np.concatenate((sigma_b, rng.normal(size=3)))
        ref = np.concatenate((sigma_r, rng.normal(size=6)))
        assert np.array_equal(np.asarray(record(state, ref)), np.asarray(sample_form(state, ref)))
        exact = _exact_short_squared(sigma_b, sigma_r)
        value = np.asarray(record(state, ref)).ravel()
        assert np.isclose(value @ value, exact, rtol=2e-4)  # |n/D|²: cancellation near σ_B = σ_R


def _nadir_rows(n: int, rate: float, orbit_rate: float) -> np.ndarray:
    angle = orbit_rate * np.arange(n) / rate
    rows = np.zeros((n, 9))
    rows[:, 2] = np.tan(angle / 4.0)
    rows[:, 5] = orbit_rate
    return rows


def test_lagged_statistics_equal_the_in_sample_statistics_of_the_lanes() -> None:
    """With an ideal sensor at the measurement time the scalar engine folds sample k − d's statistics at sample k
    and the last d samples' at the end; the lanes fold each sample's own: the same max |σ_B/R| and settling time,
    also when the settling time falls in the last d samples and when the run is shorter than the delay."""
    import mrpctl
    from mrpctl import paper
    from mrpctl.flight import Hysteretic

    rate, tau = 1000.0, 0.5  # d = 500
    rows = _nadir_rows(60_001, rate, 0.0011)
    for t_final in (0.3, 51.6, 53.0):
        kw = dict(tau=tau, rule=Hysteretic(0.0), t_final=t_final, rate=rate, reference=rows, feedforward=True)
        alone = mrpctl.simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, keep_every=None, **kw)
        batch = mrpctl.simulate_batch(paper.SPACECRAFT, paper.GAIN, np.array([paper.INITIAL_STATE] * 2), **kw)
        assert batch.max_sigma[0] == alone.max_sigma
        assert np.nan_to_num(batch.settling_time[0], nan=-1.0) == (alone.settling_time or -1.0)
        if t_final > 51.0:  # settled in the last τ of the 51.6 s run (the folded tail), before it in the 53 s run
            assert alone.settling_time is not None
            assert (t_final - tau < alone.settling_time) == (t_final < 52.0)
