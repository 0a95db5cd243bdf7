"""An independent NumPy reference loop of the predictor controller (no mrpctl code is used here).

The rigid body is written again from scratch: J ω̇ = −ω × J ω + u, σ̇ = ¼ [(1 − σᵀσ) I + 2[σ×] + 2σσᵀ] ω,
state x = [σ; ω/4]; attitudes are compared and composed as direction cosine matrices [BN]
(C = I + (8[σ×]² − 4(1 − σ²)[σ×]) / (1 + σ²)², Schaub & Junkins). Sampling as in mrpctl: at t_k = k h
the controller gets y_k = x(t_{k−d}) (for k < d the initial state, the "constant" history, referred to
t = 0), and the torque u_k is held over [t_k, t_{k+1}); the plant is integrated by RK4 with
``plant_substeps`` substeps, the controller's model (inertia J_m) by RK4 with one step per sample.

Predictor forms (see design/predictor.md):

* ``"none"``: x̂_k = y_k (the plain delayed PD law).
* ``"reintegrate"``: x̂_k = the model integrated over min(k, d) samples from y_k with u_{k−d..k−1}.
* ``"model-copy"``: a model copy z_{k+1} = RK4_m(z_k, u_k), z_0 = x0, runs in parallel; the error of the
  copy at the measurement time is composed on the rotation group and carried over τ:
  C_E = C_z(k−d)ᵀ C_y (inertial-frame attitude error, invariant under equal body rates),
  δω = ω_y − ω_z(k−d) (body frame), Ĉ_k = C(τ δω) C_z(k) C_E, ω̂_k = ω_z(k) + δω.
* ``"smith"``: the same without the τ δω rotation (the textbook Smith correction x̂ = z_k + (y − z_{k−d})).
* ``"linear"``: the copy is the linear zero-order-hold model of [σ; w] (w = ω/4), never shortened:
  z_σ ← z_σ + h z_w + (h²/8) J_m⁻¹ u_k, z_w ← z_w + (h/4) J_m⁻¹ u_k, z_0 = x0 (short set). Its forced
  response over the last τ is S_σ = z_σ(k) − z_σ(k−d) − τ z_w(k−d), S_w = z_w(k) − z_w(k−d) (for k < d,
  z_{k−d} is z_0). The FSA increment v = τ w_y + S_σ is applied on the rotation group as the MRP
  p = v (15 − x²)/(15 − 6x²), x² = min(v·v, 1.5625) (the [3/2] Padé form of tan|v| along v, ≈ the MRP
  of the rotation by the vector 4v; the guard keeps it off the pole at v·v = 2.5):
  Ĉ_k = C(p) C(σ_y), ω̂_k = 4 (w_y + S_w).

Flight-loop options (for the compiled engine's predictor sample): ``u_max`` clips each torque axis (the
torque actually applied drives both the plant and the model copy), ``disturbance`` is a torque added on
the plant only (never on the model copy: the controller does not know it), constant (3,) or one row w_k
per sample (n, 3), held over [t_k, t_{k+1}) like u_k, and ``noise`` = (θ (n, 3), η (n, 3), b (3,)) makes the measurement
[B̃N] = exp(−[θ_k×]) [BN] (short set), ω̃ = ω + b + η_k; the delayed measurement is then y_k = m̃_{k−d}.

Switching on the predicted attitude: σ̂_k is taken in the set nearest σ̂_{k−1} (continuity); with
``alpha`` given, σ̂_k is replaced by its shadow when |σ̂_k| >= α (α >= 1: hysteresis) and the sample
is recorded as a switch. The plant's own MRPs are kept in the short set (a change of coordinates only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FORMS = ("none", "reintegrate", "model-copy", "smith", "linear")


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rhs(inertia: np.ndarray, inverse: np.ndarray, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    sigma = x[:3]
    omega = 4.0 * x[3:]
    s2 = sigma @ sigma
    sigma_dot = 0.25 * ((1.0 - s2) * omega + 2.0 * np.cross(sigma, omega) + 2.0 * sigma * (sigma @ omega))
    omega_dot = inverse @ (-np.cross(omega, inertia @ omega) + u)
    return np.concatenate((sigma_dot, omega_dot / 4.0))


def rk4(inertia: np.ndarray, inverse: np.ndarray, x: np.ndarray, u: np.ndarray, h: float, steps: int) -> np.ndarray:
    dt = h / steps
    for _ in range(steps):
        k1 = rhs(inertia, inverse, x, u)
        k2 = rhs(inertia, inverse, x + 0.5 * dt * k1, u)
        k3 = rhs(inertia, inverse, x + 0.5 * dt * k2, u)
        k4 = rhs(inertia, inverse, x + dt * k3, u)
        x = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def shadow(sigma: np.ndarray) -> np.ndarray:
    return -sigma / (sigma @ sigma)


def to_short(x: np.ndarray) -> np.ndarray:
    if x[:3] @ x[:3] > 1.0:
        return np.concatenate((shadow(x[:3]), x[3:]))
    return x


def dcm(sigma: np.ndarray) -> np.ndarray:
    s2 = sigma @ sigma
    s = skew(sigma)
    return np.eye(3) + (8.0 * s @ s - 4.0 * (1.0 - s2) * s) / (1.0 + s2) ** 2


def mrp_from_dcm(c: np.ndarray) -> np.ndarray:
    """Short-set MRP of a DCM, through the quaternion (Shepperd's method)."""
    trace = np.trace(c)
    b2 = np.array(
        [(1 + trace) / 4, (1 + 2 * c[0, 0] - trace) / 4, (1 + 2 * c[1, 1] - trace) / 4, (1 + 2 * c[2, 2] - trace) / 4]
    )
    i = int(np.argmax(b2))
    b = np.empty(4)
    b[i] = math.sqrt(b2[i])
    if i == 0:
        b[1] = (c[1, 2] - c[2, 1]) / (4 * b[0])
        b[2] = (c[2, 0] - c[0, 2]) / (4 * b[0])
        b[3] = (c[0, 1] - c[1, 0]) / (4 * b[0])
    elif i == 1:
        b[0] = (c[1, 2] - c[2, 1]) / (4 * b[1])
        b[2] = (c[0, 1] + c[1, 0]) / (4 * b[1])
        b[3] = (c[2, 0] + c[0, 2]) / (4 * b[1])
    elif i == 2:
        b[0] = (c[2, 0] - c[0, 2]) / (4 * b[2])
        b[1] = (c[0, 1] + c[1, 0]) / (4 * b[2])
        b[3] = (c[1, 2] + c[2, 1]) / (4 * b[2])
    else:
        b[0] = (c[0, 1] - c[1, 0]) / (4 * b[3])
        b[1] = (c[2, 0] + c[0, 2]) / (4 * b[3])
        b[2] = (c[1, 2] + c[2, 1]) / (4 * b[3])
    if b[0] < 0:
        b = -b
    return b[1:] / (1.0 + b[0])


def rotation_dcm(theta: np.ndarray) -> np.ndarray:
    """[BN] of a body-frame rotation by the rotation vector θ (rad): C = exp(−[θ×])."""
    angle = float(np.linalg.norm(theta))
    if angle < 1e-300:
        return np.eye(3)
    k = skew(theta / angle)
    return np.eye(3) - math.sin(angle) * k + (1.0 - math.cos(angle)) * k @ k


def angle_between(c1: np.ndarray, c2: np.ndarray) -> float:
    """Principal angle (rad) of C1 C2ᵀ, as 4 atan |σ| of its short MRP (accurate near 0, unlike acos)."""
    return 4.0 * math.atan(float(np.linalg.norm(mrp_from_dcm(c1 @ c2.T))))


@dataclass
class Run:
    t: np.ndarray
    x: np.ndarray  # (n, 6) plant state at t_k (short set)
    sigma_hat: np.ndarray  # (n, 3) the controller's σ̂ (after its switching rule)
    x_hat: np.ndarray  # (n, 6) the prediction [σ̂; ω̂/4] the torque is computed from
    u: np.ndarray  # (n, 3)
    switches: list[int]
    attitude_error: np.ndarray  # (n,) angle (rad) between predicted and true attitude
    rate_error: np.ndarray  # (n,) |ω̂ − ω| (rad/s)
    settling_time: float | None


def run(
    j_plant: np.ndarray,
    j_model: np.ndarray,
    gain: np.ndarray,
    x0: np.ndarray,
    *,
    tau: float,
    rate: float,
    t_final: float,
    form: str = "model-copy",
    alpha: float | None = 1.0,
    plant_substeps: int = 1,
    u_max: float | None = None,
    disturbance: np.ndarray | None = None,
    noise: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> Run:
    assert form in FORMS
    inertia = np.diag(j_plant) if np.ndim(j_plant) == 1 else np.asarray(j_plant, float)
    inverse = np.linalg.inv(inertia)
    model = np.diag(j_model) if np.ndim(j_model) == 1 else np.asarray(j_model, float)
    model_inverse = np.linalg.inv(model)
    h = 1.0 / rate
    d = round(tau * rate)
    n = math.floor(t_final * rate + 1e-9) + 1
    x = to_short(np.asarray(x0, float).copy())
    xs = np.empty((n, 6))
    ms = np.empty((n, 6))  # the measurements (the true state without noise)
    us = np.zeros((n, 3))
    zs = np.empty((n, 6))
    sigma_hats = np.empty((n, 3))
    x_hats = np.empty((n, 6))
    att_err = np.empty(n)
    rate_err = np.empty(n)
    switches: list[int] = []
    z = x.copy()
    previous = x[:3].copy()
    for k in range(n):
        xs[k] = x
        zs[k] = z
        if noise is None:
            ms[k] = x
        else:
            theta, eta, bias = noise
            sigma_meas = mrp_from_dcm(rotation_dcm(theta[k]) @ dcm(x[:3]))
            ms[k] = np.concatenate((sigma_meas, (4.0 * x[3:] + bias + eta[k]) / 4.0))
        y = ms[k - d] if k >= d else xs[0]
        if form == "none":
            c_hat, omega_hat = dcm(y[:3]), 4.0 * y[3:]
        elif form == "reintegrate":
            p = y
            for j in range(max(k - d, 0), k):
                p = to_short(rk4(model, model_inverse, p, us[j], h, 1))
            c_hat, omega_hat = dcm(p[:3]), 4.0 * p[3:]
        elif form == "linear":
            z_old = zs[k - d] if k >= d else zs[0]
            forced_sigma = z[:3] - z_old[:3] - tau * z_old[3:]
            forced_w = z[3:] - z_old[3:]
            v = tau * y[3:] + forced_sigma
            x2 = min(float(v @ v), 1.5625)
            p = v * (15.0 - x2) / (15.0 - 6.0 * x2)
            c_hat = dcm(p) @ dcm(y[:3])
            omega_hat = 4.0 * (y[3:] + forced_w)
        else:
            z_old = zs[k - d] if k >= d else zs[0]
            c_error = dcm(z_old[:3]).T @ dcm(y[:3])
            d_omega = 4.0 * (y[3:] - z_old[3:])
            c_hat = dcm(z[:3]) @ c_error
            if form == "model-copy":
                c_hat = rotation_dcm(tau * d_omega) @ c_hat
            omega_hat = 4.0 * z[3:] + d_omega
        sigma_hat = mrp_from_dcm(c_hat)
        if sigma_hat @ sigma_hat > 1e-8 and np.linalg.norm(shadow(sigma_hat) - previous) < np.linalg.norm(
            sigma_hat - previous
        ):
            sigma_hat = shadow(sigma_hat)
        if alpha is not None and sigma_hat @ sigma_hat >= alpha**2:
            sigma_hat = shadow(sigma_hat)
            switches.append(k)
        previous = sigma_hat
        sigma_hats[k] = sigma_hat
        att_err[k] = angle_between(c_hat, dcm(x[:3]))
        rate_err[k] = float(np.linalg.norm(omega_hat - 4.0 * x[3:]))
        x_hats[k] = np.concatenate((sigma_hat, omega_hat / 4.0))
        u = gain @ x_hats[k]
        if u_max is not None:
            u = np.clip(u, -u_max, u_max)
        us[k] = u
        if disturbance is None:
            w = np.zeros(3)
        else:
            w = disturbance[k] if np.ndim(disturbance) == 2 else np.asarray(disturbance, float)
        x = to_short(rk4(inertia, inverse, x, u + w, h, plant_substeps))
        if form == "linear":
            acceleration = model_inverse @ u
            z = np.concatenate((z[:3] + h * z[3:] + (h * h / 8.0) * acceleration, z[3:] + (h / 4.0) * acceleration))
        else:
            z = to_short(rk4(model, model_inverse, z, u, h, 1))
        if not np.all(np.isfinite(x)) or np.max(np.abs(x)) > 1e6:
            n = k + 1
            break
    xs, us, sigma_hats = xs[:n], us[:n], sigma_hats[:n]
    return Run(
        t=np.arange(n) / rate,
        x=xs,
        sigma_hat=sigma_hats,
        x_hat=x_hats[:n],
        u=us,
        switches=switches,
        attitude_error=att_err[:n],
        rate_error=rate_err[:n],
        settling_time=settling_time(xs, rate),
    )


def settling_time(xs: np.ndarray, rate: float) -> float | None:
    """First t_k from which |σ| < 1e-2 and |ω| < 1e-3 rad/s to the end (mrpctl's definition)."""
    bad = (np.linalg.norm(xs[:, :3], axis=1) >= 1e-2) | (4.0 * np.linalg.norm(xs[:, 3:], axis=1) >= 1e-3)
    if bad[-1]:
        return None
    last = np.flatnonzero(bad)
    return 0.0 if last.size == 0 else (last[-1] + 1) / rate


def linear_run(
    a: np.ndarray, b: np.ndarray, b_model: np.ndarray, gain: np.ndarray, x0: np.ndarray, *, d: int, h: float, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """ẋ = A x + B u, y_k = x_{k−d}, sampled FSA predictor with B_m by explicit sums (exact ZOH by expm).

    Returns the plant states (n, size) and the predictions (n, size). For k < d, y = x0 at t = 0.
    """
    import scipy.linalg

    size = a.shape[0]

    def zoh(bb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = np.zeros((size + bb.shape[1],) * 2)
        m[:size, :size] = a
        m[:size, size:] = bb
        e = scipy.linalg.expm(m * h)
        return e[:size, :size], e[:size, size:]

    phi, gamma = zoh(b)
    _, gamma_m = zoh(b_model)
    xs = np.empty((n, size))
    preds = np.empty((n, size))
    us = np.empty((n, gain.shape[0]))
    x = np.asarray(x0, float)
    powers = [np.eye(size)]
    for _ in range(d):
        powers.append(phi @ powers[-1])
    columns = [p @ gamma_m for p in powers]
    for k in range(n):
        xs[k] = x
        start = max(k - d, 0)
        pred = powers[k - start] @ xs[start]
        for j in range(start, k):
            pred = pred + columns[k - 1 - j] @ us[j]
        preds[k] = pred
        us[k] = gain @ pred
        x = phi @ x + gamma @ us[k]
    return xs, preds


def measure(rate: float = 1000.0, t_final: float = 20.0) -> None:  # pragma: no cover - run by hand
    """The paper case at τ = 0.5 s: settling of the predictor loop with fast gains at 0, 5, 10 % error."""
    import time

    from mrpctl import paper
    from mrpctl.design import pd_gains
    from mrpctl.predictor import inertia_mismatch_margin

    inertia = np.diag(paper.SPACECRAFT.inertia)
    x0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])
    # The best certified PD without prediction, on mrpctl's compiled engine at 1 kHz, and the inertia
    # error it tolerates (exact delay margin of the perturbed delayed loop > tau).
    from mrpctl import simulate_batch
    from mrpctl.design import linearized_loop, synthesize_pd
    from mrpctl.predictor import margin_side, perturbed_spacecraft
    from mrpctl.switching import NoSwitching, OnCurrent

    baseline = synthesize_pd(paper.SPACECRAFT, 0.5)
    assert baseline.gains is not None
    k_pd = baseline.gains.K
    print(baseline, flush=True)
    for rule in (NoSwitching(), OnCurrent()):
        for e in (0.0, 0.05, 0.1):
            batch = simulate_batch(
                perturbed_spacecraft(paper.SPACECRAFT, e), k_pd, x0, tau=0.5, rule=rule, t_final=60.0, trajectories=True
            )
            assert batch.runs is not None
            print(
                f"  PD {rule.label} e {e:+.2f}: settling {batch.runs[0].settling_time} switches "
                f"{batch.runs[0].switch_count}",
                flush=True,
            )

    def delayed_stable(e: float) -> bool:
        return linearized_loop(perturbed_spacecraft(paper.SPACECRAFT, e), k_pd).delay_margin().margin > 0.5

    print(
        "  PD inertia margin",
        margin_side(delayed_stable, -1.0, 0.999, 1e-3),
        margin_side(delayed_stable, 1.0, 10.0, 1e-3),
    )
    for omega_n in (12.85, 31.925, 3.0):
        gain = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=omega_n).K
        margin = inertia_mismatch_margin(paper.SPACECRAFT, gain, 0.5, rate=rate)
        print(f"omega_n {omega_n}: {margin}", flush=True)
        for e in (0.0, 0.05, 0.1, -0.05, -0.1):
            for form in ("model-copy", "smith"):
                start = time.time()
                r = run(inertia * (1 + e), inertia, gain, x0, tau=0.5, rate=rate, t_final=t_final, form=form)
                print(
                    f"  e {e:+.2f} {form:10s} settling {r.settling_time} switches {len(r.switches)} "
                    f"max|u| {np.max(np.abs(r.u)):.4g} final|sigma| {np.linalg.norm(r.x[-1, :3]):.3g} "
                    f"max pred err (t>tau) {np.max(r.attitude_error[int(0.5 * rate) :]):.3g} rad "
                    f"({time.time() - start:.1f} s)",
                    flush=True,
                )


if __name__ == "__main__":  # pragma: no cover
    import sys

    measure(float(sys.argv[1]) if len(sys.argv) > 1 else 1000.0, float(sys.argv[2]) if len(sys.argv) > 2 else 20.0)
