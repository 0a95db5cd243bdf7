"""An independent, plain-NumPy reference loop of the flight loop (no CasADi, nothing from mrpctl's models).

Written again from the equations of ``design/flight.md``, vectorised over N runs:

* plant: J ω̇ = −ω × J ω + u + w, σ̇ = ¼ ((1 − σ²) ω + 2 σ × ω + 2 σ (σ·ω)), RK4 with a
  fixed number of substeps per period h, torque held (ZOH);
* plant bookkeeping (optional): σ_k replaced by −σ_k/|σ_k|² when |σ_k|² >= 1 (no physical effect);
* sensor: quaternion product β̃ = β(θ_k) ⊗ β(σ_k) (Hamilton, scalar first, [B̃N] = [B̃B][BN]),
  made canonical (β̃₀ >= 0); ω̃ = ω + b + η;
* delay: measurement j arrives at j + d_j, the history (x0, noise-free) at j + D; the controller
  uses the newest arrived one (a loop over arrival buckets, written separately from
  ``mrpctl.flight.newest_arrived``);
* controller: sign continuity of the used quaternion (q̂ = ±β̃ with q̂·q̂_prev >= 0), then the
  Mayhew-Sanfelice-Teel rule h ← −h when h q̂₀ < −δ, σ_c = h q̂_v/(1 + h q̂₀),
  u = K [σ_c; ω̃/4];
* actuator: direction-preserving scaling (or per-axis clip, then norm scaling), then + w.

Only the noise samples (``SensorModel.noise``) and the per-sample delays are taken from
mrpctl, as inputs: they are data, not logic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

SETTLING_SIGMA = 1e-2
SETTLING_OMEGA = 1e-3
DIVERGENCE_BOUND = 1e6
_CHUNK = 4096


@dataclass
class ReferenceRun:
    """Outputs of :func:`reference_loop` (N runs, n samples). Trajectory fields are None unless asked for."""

    n: int
    rate: float
    used: np.ndarray  # (n,) measurement index used at sample k
    delay_used: np.ndarray  # (n,) samples
    logic_switch_count: np.ndarray  # (N,)
    logic_first: np.ndarray  # (N,) sample or -1
    min_dwell: np.ndarray  # (N,) samples between logic switches (inf with < 2 switches)
    plant_switch_count: np.ndarray  # (N,)
    saturated_fraction: np.ndarray  # (N,)
    peak_command: np.ndarray  # (N, 3) max_k |u_cmd,i|
    peak_command_norm: np.ndarray  # (N,) max_k |u_cmd|
    max_omega: np.ndarray  # (N,) max_k |ω_k| (rad/s)
    max_sigma_c: np.ndarray  # (N,)
    settling_time: np.ndarray  # (N,) s, nan if not settled
    diverged: np.ndarray  # (N,) bool
    sigma: np.ndarray | None = None  # (N, n, 3) plant σ_k after bookkeeping
    omega: np.ndarray | None = None  # (N, n, 3)
    sigma_c: np.ndarray | None = None  # (N, n, 3)
    h: np.ndarray | None = None  # (N, n) logic variable after the rule
    logic_switched: np.ndarray | None = None  # (N, n) bool
    plant_switched: np.ndarray | None = None  # (N, n) bool
    u_command: np.ndarray | None = None  # (N, n, 3)
    u_applied: np.ndarray | None = None  # (N, n, 3)
    saturated: np.ndarray | None = None  # (N, n) bool

    @property
    def converged(self) -> np.ndarray:
        return np.isfinite(self.settling_time)

    def logic_switch_samples(self, run: int = 0) -> np.ndarray:
        assert self.logic_switched is not None
        return np.flatnonzero(self.logic_switched[run])

    def plant_switch_samples(self, run: int = 0) -> np.ndarray:
        assert self.plant_switched is not None
        return np.flatnonzero(self.plant_switched[run])


def used_measurements(delays: np.ndarray, history: int) -> np.ndarray:
    """j*(k): newest arrived measurement at each sample (history j < 0 arrives at j + history)."""
    n = len(delays)
    arriving: list[list[int]] = [[] for _ in range(n)]
    for j in range(-history, 0):
        arriving[j + history].append(j)
    for j in range(n):
        a = j + int(delays[j])
        if a < n:
            arriving[a].append(j)
    used = np.empty(n, dtype=np.int64)
    best = -history - 1
    for k in range(n):
        for j in arriving[k]:
            best = max(best, j)
        if best < -history:
            raise ValueError(f"no measurement has arrived at sample {k}")
        used[k] = best
    return used


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack(
        (
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ),
        axis=1,
    )


def _derivative(sigma: np.ndarray, omega: np.ndarray, inertia: np.ndarray, inverse: np.ndarray, torque: np.ndarray):
    s2 = np.sum(sigma * sigma, axis=1, keepdims=True)
    sigma_dot = 0.25 * (
        (1.0 - s2) * omega + 2.0 * _cross(sigma, omega) + 2.0 * sigma * np.sum(sigma * omega, axis=1, keepdims=True)
    )
    momentum = omega @ inertia.T
    omega_dot = (torque - _cross(omega, momentum)) @ inverse.T
    return sigma_dot, omega_dot


def _rk4(sigma, omega, torque, dt, substeps, inertia, inverse):
    for _ in range(substeps):
        a1, b1 = _derivative(sigma, omega, inertia, inverse, torque)
        a2, b2 = _derivative(sigma + 0.5 * dt * a1, omega + 0.5 * dt * b1, inertia, inverse, torque)
        a3, b3 = _derivative(sigma + 0.5 * dt * a2, omega + 0.5 * dt * b2, inertia, inverse, torque)
        a4, b4 = _derivative(sigma + dt * a3, omega + dt * b3, inertia, inverse, torque)
        sigma = sigma + (dt / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        omega = omega + (dt / 6.0) * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    return sigma, omega


def _quaternion(sigma: np.ndarray) -> np.ndarray:
    s2 = np.sum(sigma * sigma, axis=1, keepdims=True)
    return np.hstack(((1.0 - s2) / (1.0 + s2), 2.0 * sigma / (1.0 + s2)))


def _noise_quaternion(theta: np.ndarray) -> np.ndarray:
    angle = np.linalg.norm(theta, axis=1, keepdims=True)
    safe = np.where(angle > 0.0, angle, 1.0)
    return np.hstack((np.cos(angle / 2.0), np.where(angle > 0.0, np.sin(angle / 2.0) / safe, 0.5) * theta))


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊗ b for [FN] = [FB(a)][BN(b)] (Schaub & Junkins Eq. 3.101, matrix of a times b)."""
    a0, a1, a2, a3 = a.T
    b0, b1, b2, b3 = b.T
    return np.stack(
        (
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a1 * b0 + a0 * b1 + a3 * b2 - a2 * b3,
            a2 * b0 - a3 * b1 + a0 * b2 + a1 * b3,
            a3 * b0 + a2 * b1 - a1 * b2 + a0 * b3,
        ),
        axis=1,
    )


def reference_loop(
    inertia: Any,
    K: Any,
    x0: Any,
    *,
    rate: float,
    t_final: float,
    delta: Any = 0.0,
    delays: Any = 0,
    history: int | None = None,
    sensors: Any = None,
    u_max: Any = None,
    norm_max: float = math.inf,
    clip: bool = False,
    disturbance: Any = None,
    keep_short: bool = True,
    substeps: int = 1,
    trajectories: bool = True,
) -> ReferenceRun:
    """Run N flight loops side by side (see the module docstring). x0: (N, 6) or (6,) as [σ; ω/4]."""
    inertia = np.asarray(inertia, dtype=float)
    if inertia.shape == (3,):
        inertia = np.diag(inertia)
    inverse = np.linalg.inv(inertia)
    x0 = np.atleast_2d(np.asarray(x0, dtype=float))
    runs = x0.shape[0]
    gains = np.broadcast_to(np.asarray(K, dtype=float), (runs, 3, 6))
    n = math.floor(t_final * rate + 1e-9) + 1
    h_period = 1.0 / rate
    dt = h_period / substeps
    delta = np.broadcast_to(np.asarray(delta, dtype=float), (runs,))
    delay_array = np.broadcast_to(np.asarray(delays, dtype=np.int64), (n,))
    depth = int(delay_array.max()) if history is None else int(history)
    used = used_measurements(delay_array, depth)
    if sensors is None:
        sensors = []
    elif not isinstance(sensors, (list, tuple)):
        sensors = [sensors] * runs
    bias = np.array([s.gyro_bias for s in sensors]) if sensors else np.zeros((runs, 3))
    limits = None if u_max is None else np.broadcast_to(np.asarray(u_max, dtype=float), (3,))
    w_all = None if disturbance is None else np.asarray(disturbance, dtype=float)

    sigma = x0[:, 0:3].copy()
    omega = 4.0 * x0[:, 3:6]
    slots = depth + 1
    ring_q = np.zeros((slots, runs, 4))
    ring_w = np.zeros((slots, runs, 3))
    history_q = _quaternion(x0[:, 0:3])
    history_q = np.where(history_q[:, :1] < 0.0, -history_q, history_q)
    history_w = 4.0 * x0[:, 3:6]
    h = np.ones(runs)
    q_prev = None
    alive = np.ones(runs, dtype=bool)

    logic_count = np.zeros(runs, dtype=np.int64)
    logic_first = np.full(runs, -1, dtype=np.int64)
    logic_last = np.full(runs, -1, dtype=np.int64)
    min_dwell = np.full(runs, np.inf)
    plant_count = np.zeros(runs, dtype=np.int64)
    saturated_count = np.zeros(runs, dtype=np.int64)
    counted = np.zeros(runs, dtype=np.int64)
    peak = np.zeros((runs, 3))
    peak_norm = np.zeros(runs)
    max_omega = np.zeros(runs)
    max_sigma_c = np.zeros(runs)
    unsettled = np.full(runs, -1, dtype=np.int64)
    diverged_at = np.full(runs, -1, dtype=np.int64)
    record: dict[str, np.ndarray] = {}
    if trajectories:
        record = {
            "sigma": np.zeros((runs, n, 3)),
            "omega": np.zeros((runs, n, 3)),
            "sigma_c": np.zeros((runs, n, 3)),
            "h": np.zeros((runs, n)),
            "logic_switched": np.zeros((runs, n), dtype=bool),
            "plant_switched": np.zeros((runs, n), dtype=bool),
            "u_command": np.zeros((runs, n, 3)),
            "u_applied": np.zeros((runs, n, 3)),
            "saturated": np.zeros((runs, n), dtype=bool),
        }
    theta_chunk = eta_chunk = None
    for k in range(n):
        if k % _CHUNK == 0 and sensors:
            stop = min(n, k + _CHUNK)
            pairs = [s.noise(k, stop) for s in sensors]
            theta_chunk = np.stack([p[0] for p in pairs])
            eta_chunk = np.stack([p[1] for p in pairs])
        # 1. plant bookkeeping: short set (no physical effect)
        if keep_short:
            s2 = np.sum(sigma * sigma, axis=1, keepdims=True)
            switch_plant = (s2[:, 0] >= 1.0) & alive
            sigma = np.where(switch_plant[:, None], -sigma / np.where(s2 > 0, s2, 1.0), sigma)
        else:
            switch_plant = np.zeros(runs, dtype=bool)
        # 2. measurement k
        q_true = _quaternion(sigma)
        if sensors:
            assert theta_chunk is not None and eta_chunk is not None
            q_meas = _product(_noise_quaternion(theta_chunk[:, k % _CHUNK]), q_true)
            w_meas = omega + bias + eta_chunk[:, k % _CHUNK]
        else:
            q_meas = q_true
            w_meas = omega
        q_meas = np.where(q_meas[:, :1] < 0.0, -q_meas, q_meas)
        ring_q[k % slots] = q_meas
        ring_w[k % slots] = w_meas
        # 3. controller on the newest arrived measurement
        j = used[k]
        if j < 0:
            q_used, w_used = history_q, history_w
        else:
            q_used, w_used = ring_q[j % slots], ring_w[j % slots]
        if q_prev is None:
            q_prev = q_used
        q_hat = np.where(np.sum(q_used * q_prev, axis=1, keepdims=True) < 0.0, -q_used, q_used)
        q_prev = q_hat
        switch_logic = (h * q_hat[:, 0] < -delta) & alive
        h = np.where(switch_logic, -h, h)
        sigma_c = h[:, None] * q_hat[:, 1:4] / (1.0 + h[:, None] * q_hat[:, 0:1])
        x_c = np.hstack((sigma_c, w_used / 4.0))
        u_command = np.einsum("rij,rj->ri", gains, x_c)
        # 4. actuator
        if limits is None:
            u_applied = u_command
            saturated = np.zeros(runs, dtype=bool)
        elif clip:
            clipped = np.clip(u_command, -limits, limits)
            ratio = np.linalg.norm(clipped, axis=1) / norm_max
            u_applied = np.where((ratio > 1.0)[:, None], clipped / np.where(ratio > 1, ratio, 1.0)[:, None], clipped)
            saturated = np.any(np.abs(u_command) > limits, axis=1) | (ratio > 1.0)
        else:
            ratio = np.maximum(np.max(np.abs(u_command) / limits, axis=1), np.linalg.norm(u_command, axis=1) / norm_max)
            saturated = ratio > 1.0
            scaled = np.where(saturated[:, None], u_command / np.where(saturated, ratio, 1.0)[:, None], u_command)
            u_applied = np.clip(scaled, -limits, limits)
        torque = u_applied
        if w_all is not None:
            torque = u_applied + (w_all if w_all.ndim == 1 else w_all[k])
        # metrics at sample k (runs still alive)
        live = alive.copy()
        logic_count += switch_logic
        gap = np.where(logic_last >= 0, k - logic_last, np.inf)
        min_dwell = np.where(switch_logic & (logic_last >= 0), np.minimum(min_dwell, gap), min_dwell)
        logic_first = np.where(switch_logic & (logic_first < 0), k, logic_first)
        logic_last = np.where(switch_logic, k, logic_last)
        plant_count += switch_plant
        saturated_count += saturated & live
        counted += live
        peak = np.where(live[:, None], np.maximum(peak, np.abs(u_command)), peak)
        peak_norm = np.where(live, np.maximum(peak_norm, np.linalg.norm(u_command, axis=1)), peak_norm)
        omega_norm = np.linalg.norm(omega, axis=1)
        max_omega = np.where(live, np.maximum(max_omega, omega_norm), max_omega)
        max_sigma_c = np.where(live, np.maximum(max_sigma_c, np.linalg.norm(sigma_c, axis=1)), max_sigma_c)
        not_settled = (np.sum(sigma * sigma, axis=1) >= SETTLING_SIGMA**2) | (omega_norm**2 >= SETTLING_OMEGA**2)
        unsettled = np.where(live & not_settled, k, unsettled)
        if trajectories:
            record["sigma"][:, k] = sigma
            record["omega"][:, k] = omega
            record["sigma_c"][:, k] = sigma_c
            record["h"][:, k] = h
            record["logic_switched"][:, k] = switch_logic
            record["plant_switched"][:, k] = switch_plant
            record["u_command"][:, k] = u_command
            record["u_applied"][:, k] = u_applied
            record["saturated"][:, k] = saturated
        # 5. integrate one period
        sigma_next, omega_next = _rk4(sigma, omega, torque, dt, substeps, inertia, inverse)
        ok = (np.sum(sigma_next**2, axis=1) <= DIVERGENCE_BOUND**2) & (
            np.sum(omega_next**2, axis=1) <= DIVERGENCE_BOUND**2
        )
        newly = alive & ~ok
        diverged_at = np.where(newly, k, diverged_at)
        alive = alive & ok
        sigma = np.where(alive[:, None], sigma_next, sigma)
        omega = np.where(alive[:, None], omega_next, omega)

    diverged = diverged_at >= 0
    settle = unsettled + 1
    settling = np.where(~diverged & (settle < n), settle / rate, np.nan)
    return ReferenceRun(
        n=n,
        rate=rate,
        used=used,
        delay_used=np.arange(n) - used,
        logic_switch_count=logic_count,
        logic_first=logic_first,
        min_dwell=min_dwell,
        plant_switch_count=plant_count,
        saturated_fraction=saturated_count / np.maximum(counted, 1),
        peak_command=peak,
        peak_command_norm=peak_norm,
        max_omega=max_omega,
        max_sigma_c=max_sigma_c,
        settling_time=settling,
        diverged=diverged,
        **record,
    )


# ============================================================================ the study of design/flight.md
def _tumbles(count: int, omega_max: float, seed: int, *, fixed_rate: bool = False) -> np.ndarray:
    """Initial [σ; ω/4]: attitude uniform on SO(3) (short set), ω of uniform direction and |ω| uniform in
    [0, ω_max] (or |ω| = ω_max with ``fixed_rate``)."""
    rng = np.random.default_rng(seed)
    q = rng.standard_normal((count, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(q[:, :1] < 0.0, -q, q)
    sigma = q[:, 1:] / (1.0 + q[:, :1])
    direction = rng.standard_normal((count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    magnitude = rng.uniform(0.0, omega_max, (count, 1))
    omega = direction * (omega_max if fixed_rate else magnitude)
    return np.hstack((sigma, omega / 4.0))


def study(
    part: str, out: str, rate: float = 1000.0, fixed_rate: bool = False
) -> None:  # pragma: no cover - a measurement script
    """The measurements of design/flight.md: part "noise" (noise x delta table) or "tumble" (200 tumbles)."""
    import json
    import time

    from mrpctl import DelayAware, NoSwitching, OnCurrent, paper, simulate_batch
    from mrpctl.design import pd_gains, synthesize_pd
    from mrpctl.flight import Hysteretic, SensorModel

    results: dict[str, Any] = {"rate": rate, "fixed_rate": fixed_rate}
    if part in ("noise", "seeds"):
        alphas = (1.0, 1.05, 1.2, 1.5)
        noises = (0.0, 0.001, 0.01) if part == "noise" else (0.001, 0.01)
        seeds = (1,) if part == "noise" else (1, 2, 3, 4, 5)
        started = time.time()
        deltas = [Hysteretic.from_alpha(a).delta for a in alphas]
        cases = [(s, a, d, seed) for s in noises for a, d in zip(alphas, deltas, strict=True) for seed in seeds]
        ref = reference_loop(
            paper.SPACECRAFT.inertia,
            paper.GAIN,
            np.tile(paper.INITIAL_STATE, (len(cases), 1)),
            rate=rate,
            t_final=60.0,
            delta=[c[2] for c in cases],
            delays=round(0.5 * rate),
            sensors=[SensorModel(attitude_noise=c[0], seed=c[3]) for c in cases],
            trajectories=False,
        )
        results["noise_delta"] = [
            dict(
                noise=c[0],
                alpha=c[1],
                delta=c[2],
                seed=c[3],
                switches=int(ref.logic_switch_count[i]),
                first=int(ref.logic_first[i]),
                min_dwell=float(ref.min_dwell[i]),
                settling=float(ref.settling_time[i]),
                max_sigma_c=float(ref.max_sigma_c[i]),
            )
            for i, c in enumerate(cases)
        ]
        results["seconds"] = time.time() - started
        print(json.dumps(results, indent=1), flush=True)
        with open(out, "w") as handle:
            json.dump(results, handle, indent=1)
        return
    count = 200
    x0 = _tumbles(count, 5.0, 2026, fixed_rate=fixed_rate)
    study_deltas = (0.0, Hysteretic.from_alpha(1.2).delta)
    for tau in (0.5, 1.0):
        started = time.time()
        synthesis = synthesize_pd(paper.SPACECRAFT, tau, zeta=1.0)
        assert synthesis.gains is not None
        omega_n = float(synthesis.gains.omega_n[0])
        K = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=0.7 * omega_n).K
        entry: dict[str, Any] = dict(tau=tau, omega_n=omega_n, count=count)
        for batch_rate in sorted({rate, 1000.0}):
            for name, rule in (
                ("DelayAware", DelayAware()),
                ("NoSwitching", NoSwitching()),
                ("OnCurrent", OnCurrent()),
            ):
                batch = simulate_batch(paper.SPACECRAFT, K, x0, tau=tau, rule=rule, t_final=60.0, rate=batch_rate)
                entry[f"{name}@{batch_rate:g}Hz"] = dict(
                    failed=int((~batch.converged).sum()),
                    diverged=int(batch.diverged.sum()),
                    failed_runs=np.flatnonzero(~batch.converged).tolist(),
                )
        print(json.dumps(entry, indent=1), flush=True)
        ref = reference_loop(
            paper.SPACECRAFT.inertia,
            K,
            np.vstack([x0] * len(study_deltas)),
            rate=rate,
            t_final=60.0,
            delta=np.repeat(study_deltas, count),
            delays=round(tau * rate),
            trajectories=False,
        )
        for i, delta in enumerate(study_deltas):
            part_runs = slice(i * count, (i + 1) * count)
            entry[f"Hysteretic(delta={delta:.4f})@{rate:g}Hz"] = dict(
                failed=int((~ref.converged[part_runs]).sum()),
                diverged=int(ref.diverged[part_runs].sum()),
                failed_runs=np.flatnonzero(~ref.converged[part_runs]).tolist(),
                max_switches=int(ref.logic_switch_count[part_runs].max()),
                median_settling=float(np.nanmedian(ref.settling_time[part_runs])),
                max_settling=float(np.nanmax(ref.settling_time[part_runs])),
            )
        entry["seconds"] = time.time() - started
        results[f"tau={tau}"] = entry
        print(json.dumps(entry, indent=1), flush=True)
        with open(out, "w") as handle:
            json.dump(results, handle, indent=1)


if __name__ == "__main__":  # pragma: no cover
    import sys

    study(sys.argv[1], sys.argv[2], float(sys.argv[3]), fixed_rate=len(sys.argv) > 4 and sys.argv[4] == "fixed")
