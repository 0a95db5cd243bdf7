"""``mrpctl verify`` of a tracking scenario ([reference]): the verdict of the linearised tracking loop.

The independent reference: the linearised Hill-frame equations of a rigid body in a circular orbit written
here by hand (Wie, Space Vehicle Dynamics and Control, the roll-pitch-yaw equations mapped to the Hill axes x
radial, y along-track, z orbit normal), the sampled, zero-order-hold, delay-augmented closed loop lifted in
NumPy (expm of the augmented matrix, a companion of x_k ... x_{k-d}), and the exact delay margin as the root
(ω, τ) of det(iωI − A − A_d e^{−iωτ}) found with scipy's fsolve from the per-axis analytic crossings of
inertial pointing. Each item the verdict does not cover makes it NOT VERIFIED (exit 1)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from cli_assertions import one_line_error

from mrpctl.cli import main
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml

ROOT = Path(__file__).resolve().parents[1]
NADIR = ROOT / "examples" / "scenarios" / "nadir.toml"
K_SIGMA, K_OMEGA = -70.11, -163.08


def _hill_loop(inertia: np.ndarray, n: float, *, gravity: bool, feedforward: bool) -> tuple[np.ndarray, ...]:
    """(A, B, L): ẋ = A x + B u, u = L x(t − τ), x = [σ_B/R; ω_B/R/4], for J = diag(J_x, J_y, J_z) in the Hill axes.

    In small angles θ = 4σ (θ̇ = ω_B/R to first order):
        J_x θ̈_x = n²(J_y − J_z) θ_x + n(J_x + J_y − J_z) θ̇_y + u_x
        J_y θ̈_y = [n²(J_x − J_z) + 3n²(J_x − J_z)] θ_y − n(J_x + J_y − J_z) θ̇_x + u_y
        J_z θ̈_z = 3n²(J_x − J_y) θ_z + u_z
    (the 3n² terms the gravity gradient, the others gyroscopic). The feedforward supplies, on the delayed
    measurement, minus the gyroscopic stiffness and coupling.
    """
    jx, jy, jz = inertia
    gyro = np.diag([n**2 * (jy - jz), n**2 * (jx - jz), 0.0])
    grav = np.diag([0.0, 3 * n**2 * (jx - jz), 3 * n**2 * (jx - jy)]) if gravity else np.zeros((3, 3))
    coupling = np.zeros((3, 3))
    coupling[0, 1], coupling[1, 0] = n * (jx + jy - jz), -n * (jx + jy - jz)
    j_inv = np.diag(1.0 / np.asarray(inertia))
    # θ = 4 x₁, θ̇ = 4 x₂, ẋ₂ = θ̈ / 4
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [j_inv @ (gyro + grav), j_inv @ coupling]])
    b = np.vstack((np.zeros((3, 3)), 0.25 * j_inv))
    gain = np.hstack((K_SIGMA * np.eye(3), K_OMEGA * np.eye(3)))
    if feedforward:
        gain = gain - np.hstack((4.0 * gyro, 4.0 * coupling))
    return a, b, gain


def _lifted_radius(a: np.ndarray, b: np.ndarray, gain: np.ndarray, h: float, d: int) -> float:
    """Spectral radius of z_{k+1} = M z_k, z_k = [x_k; x_{k−1}; ...; x_{k−d}], x_{k+1} = Φ x_k + Γ L x_{k−d}."""
    nx, nu = b.shape
    augmented = scipy.linalg.expm(np.block([[a, b], [np.zeros((nu, nx + nu))]]) * h)
    phi, gamma = augmented[:nx, :nx], augmented[:nx, nx:]
    size = nx * (d + 1)
    m = np.zeros((size, size))
    m[:nx, :nx] = phi
    m[:nx, d * nx :] += gamma @ gain
    for i in range(d):
        m[(i + 1) * nx : (i + 2) * nx, i * nx : (i + 1) * nx] = np.eye(nx)
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def _exact_margin(a: np.ndarray, a_d: np.ndarray, inertia: np.ndarray) -> float:
    """The smallest τ > 0 with a root iω of det(sI − A − A_d e^{−sτ}); started from each axis of inertial pointing,
    s² = (k_ω s + k_σ) e^{−sτ} / (4J): ω⁴ = a² + b² ω², τ = arg(−ω² / (a + i b ω))⁻ / ω."""
    margins = []
    for j in inertia:
        ka, kb = K_SIGMA / (4 * j), K_OMEGA / (4 * j)
        w0 = math.sqrt((kb**2 + math.sqrt(kb**4 + 4 * ka**2)) / 2)
        tau0 = (-np.angle(-(w0**2) / complex(ka, kb * w0))) % (2 * math.pi) / w0

        def residual(p: np.ndarray, scale: float = w0**6) -> list[float]:
            w, tau = p
            value = np.linalg.det(1j * w * np.eye(6) - a - a_d * np.exp(-1j * w * tau)) / scale
            return [value.real, value.imag]

        solution, _, ok, message = scipy.optimize.fsolve(residual, [w0, tau0], xtol=1e-12, full_output=True)
        assert ok == 1 and max(map(abs, residual(solution))) < 1e-12, message
        margins.append(float(solution[1]))
    return min(margins)


def _verify_json(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict[str, Any]]:
    code = main(["verify", *argv, "--json"])
    return code, json.loads(capsys.readouterr().out)


@pytest.mark.parametrize(
    ("tau", "d", "code", "status"), [(0.0, 0, 0, "VERIFIED"), (0.5, 10, 0, "VERIFIED"), (1.6, 32, 1, "UNSTABLE")]
)
def test_nadir_verdict_equals_the_lifted_loop_built_by_hand(
    capsys: pytest.CaptureFixture[str], tau: float, d: int, code: int, status: str
) -> None:
    scenario = load_scenario(NADIR)
    inertia = np.diag(scenario.spacecraft.inertia)
    n = scenario.reference.orbit_rate
    exit_code, report = _verify_json(capsys, str(NADIR), "--tau", str(tau), "--orders", "0", "1")
    assert exit_code == code and report["exit_code"] == code and report["verified"] is (code == 0)
    assert [check["loop"] for check in report["checks"]] == [
        "nadir pointing with the gravity gradient",
        "nadir pointing",
    ]
    for check, gravity in zip(report["checks"], (True, False), strict=True):
        a, b, gain = _hill_loop(inertia, n, gravity=gravity, feedforward=True)
        radius = _lifted_radius(a, b, gain, 1.0 / scenario.rate, d)
        assert check["delay_samples"] == d and (check["criteria"] == []) is (tau == 0.0)
        assert check["spectral_radius"] == pytest.approx(radius, rel=1e-9, abs=0.0)
        assert check["sampled_stable"] is (radius < 1.0)
        margin = _exact_margin(a, b @ gain, inertia)
        assert check["exact_delay_margin"] == pytest.approx(margin, rel=1e-9)
        assert check["stable_at_tau"] is (tau < margin)
        assert check["status"] == status and check["verified"] is (code == 0)
    assert report["not_covered"] == []


def test_verify_json_keys(capsys: pytest.CaptureFixture[str]) -> None:
    _, report = _verify_json(capsys, str(NADIR), "--orders", "0")
    assert set(report) == {
        "tau",
        "rate",
        "reference",
        "error_time",
        "feedforward",
        "checks",
        "not_covered",
        "local",
        "verified",
        "exit_code",
    }
    assert set(report["checks"][0]) == {
        "loop",
        "linearisation",
        "exact_delay_margin",
        "stable_at_tau",
        "criteria",
        "certified",
        "delay_samples",
        "spectral_radius",
        "sampled",
        "sampled_stable",
        "status",
        "verified",
    }
    assert report["checks"][0]["criteria"] == [
        {"criterion": "Jensen (N=0)", "order": 0, "status": "CERTIFIED", "certified": True}
    ]
    assert (report["tau"], report["rate"], report["error_time"], report["feedforward"]) == (
        0.5,
        20.0,
        "measurement",
        True,
    )


def _scenario(tmp_path: Path, reference: dict[str, Any], **tables: Any) -> Path:
    data: dict[str, Any] = {
        "name": "tracking",
        "tau": 0.5,
        "rate": 20.0,
        "t_final": 20.0,
        "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
        "gains": {"k_sigma": K_SIGMA, "k_omega": K_OMEGA},
        "initial": {"sigma": [0.0, 0.0, 0.0], "omega": [0.0, 0.0, 0.0]},
        "rule": {"type": "hysteretic", "delta": 0.0},
        "reference": reference,
        **tables,
    }
    path = tmp_path / "tracking.toml"
    path.write_text(scenario_toml(parse_scenario(data, base=tmp_path)), encoding="utf-8")
    return path


SLEW = {"type": "slew", "axis": [1.0, 0.0, 0.0], "angle_deg": 270.0, "rate_limit": 0.1, "acceleration_limit": 0.02}


@pytest.mark.parametrize(
    ("reference", "tables", "words", "checked"),
    [
        (SLEW, {}, ["the slew's time-varying profile"], 1),
        ({"type": "nadir", "altitude": 5e5, "error_time": "current"}, {}, ["error_time = current"], 2),
        ({**SLEW, "error_time": "current"}, {}, ["the slew's time-varying profile", "error_time = current"], 1),
        (
            {"type": "nadir", "altitude": 5e5},
            {"predictor": {}, "rule": {"type": "on-predicted", "alpha": 1.0}},
            ["error_time = current", "the predictor"],  # the predictor's default error time is now
            2,
        ),
        (
            {"type": "nadir", "altitude": 5e5},
            {"actuator": {"u_max": 20.0}, "uncertainty": {"inertia_tolerance": 0.05}},
            ["loop-as-flown models (actuator, uncertainty)"],
            2,
        ),
        (
            {"type": "nadir", "altitude": 5e5},
            {"spacecraft": {"inertia": [[140.0, 5.0, 0.0], [5.0, 100.0, 0.0], [0.0, 0.0, 80.0]]}},
            ["N m of the reference's torque unsupplied"],
            2,
        ),
    ],
)
def test_what_is_not_covered_is_named_and_never_passes(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    reference: dict[str, Any],
    tables: dict[str, Any],
    words: list[str],
    checked: int,
) -> None:
    path = _scenario(tmp_path, reference, **tables)
    code, report = _verify_json(capsys, str(path), "--orders", "1")
    assert code == 1 and report["verified"] is False
    assert len(report["checks"]) == checked and all(check["verified"] for check in report["checks"])
    assert len(report["not_covered"]) == len(words)
    for word, item in zip(words, report["not_covered"], strict=True):
        assert word in item, item
    assert main(["verify", str(path), "--orders", "1"]) == 1
    out = capsys.readouterr().out
    assert out.count("not covered: ") == len(words) and "tracking verdict: NOT VERIFIED (exit 1)" in out


def test_a_file_reference_is_not_checked_at_all(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = np.zeros((401, 9))
    np.save(tmp_path / "rows.npy", rows)
    path = _scenario(tmp_path, {"type": "file", "file": "rows.npy"})
    code, report = _verify_json(capsys, str(path))
    assert code == 1 and report["checks"] == [] and "FileReference is time-varying" in report["not_covered"][0]
    assert main(["verify", str(path)]) == 1
    assert "tracking verdict: NOT VERIFIED (exit 1): nothing could be checked" in capsys.readouterr().out


def test_inertial_pointing_is_verified_and_the_current_time_costs_nothing_on_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """ω_R = 0: both error times give the same loop, the regulation plant per axis (the margin of
    `_exact_margin`'s inertial start, to 1e-9)."""
    inertia = np.array([140.0, 100.0, 80.0])
    for extra in ({}, {"error_time": "current"}):
        path = _scenario(tmp_path, {"type": "inertial", "sigma": [0.1, 0.0, 0.0], **extra})
        code, report = _verify_json(capsys, str(path), "--orders", "1")
        assert code == 0 and report["not_covered"] == [] and report["checks"][0]["loop"] == "inertial pointing"
        a, b, gain = _hill_loop(inertia, 0.0, gravity=False, feedforward=False)
        assert report["checks"][0]["exact_delay_margin"] == pytest.approx(_exact_margin(a, b @ gain, inertia), rel=1e-9)
        assert report["checks"][0]["spectral_radius"] == pytest.approx(
            _lifted_radius(a, b, gain, 0.05, 10), rel=1e-9, abs=0.0
        )


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--jitter", "0.4"], ["--jitter does not apply to a tracking scenario"]),
        (["--sampled", "100"], ["--sampled does not apply"]),
        (["--inertia-tolerance", "0.05"], ["--inertia-tolerance does not apply"]),
        (["--no-flown"], ["--no-flown does not apply"]),
        (["--tau", "0.51"], ["--tau 0.51", "whole number"]),
        (["--inertia", "1", "2", "3"], ["--inertia does not apply with a scenario file"]),
    ],
)
def test_bad_options_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], needles: list[str]
) -> None:
    assert main(["verify", str(NADIR), *argv]) == 2
    one_line_error(capsys, *needles)


def test_a_sampled_loop_too_large_to_lift_is_not_checked_and_not_verified(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """1 kHz and tau = 1.2 s: the roll-yaw block's companion is 4 (1200 + 1) = 4804 rows, above the limit."""
    path = tmp_path / "fast.toml"
    text = (
        NADIR.read_text(encoding="utf-8").replace("rate = 20.0 ", "rate = 1000.0 ").replace("tau = 0.5 ", "tau = 1.2 ")
    )
    path.write_text(text, encoding="utf-8")
    code, report = _verify_json(capsys, str(path), "--orders", "1")
    assert code == 1 and [check["status"] for check in report["checks"]] == ["NOT CHECKED", "NOT CHECKED"]
    assert all(check["stable_at_tau"] and check["certified"] for check in report["checks"])
    assert all(
        check["spectral_radius"] is None and "d = 1200: not checked" in check["sampled"] for check in report["checks"]
    )
    assert len(report["not_covered"]) == 2 and "would exceed 4000 rows" in report["not_covered"][0]


def test_the_verdict_says_it_is_local_with_the_initial_error(capsys: pytest.CaptureFixture[str]) -> None:
    """The linearised checks say nothing of the loop far from the reference: the output says so, with the
    scenario's initial pointing error (here from scipy: the reference starts at the origin, the body at sigma0)."""
    from scipy.spatial.transform import Rotation

    from mrpctl.scenario import load_scenario

    code, report = _verify_json(capsys, str(NADIR), "--orders", "0")
    sigma0 = load_scenario(NADIR).sigma0
    angle = np.degrees(Rotation.from_mrp(np.array(sigma0)).magnitude())
    assert code == 0 and "no region of attraction is certified" in report["local"]
    assert f"starts {angle:.3g} deg from its reference" in report["local"]
    main(["verify", str(NADIR), "--orders", "0"])
    assert "not checked (the verdict is local)" in capsys.readouterr().out
