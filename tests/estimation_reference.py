"""An independent NumPy MEKF and MRP-EKF, written from the equations of design/estimation.md.

It shares no code with ``mrpctl.estimation``: quaternions as 4 × 4 product matrices, Φ of the MEKF as
the matrix exponential of F h from its definition (Φ₁₁ = exp(−[ω×]h) as the rotation's direction cosine
matrix, Φ₁₂ = −∫₀ʰ exp(−[ω×]s) ds by 8-point Gauss-Legendre quadrature), the residual's rotation vector by
arctan2, the MRP propagation through quaternions, and the delayed measurement handled as an on-time
filter whose posterior is replayed, in a plain loop over the whole run, to every sample's time.
Also a truth simulator for the consistency tests.
"""

from __future__ import annotations

import numpy as np


def cross(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def qmul(a, b):
    """β of C(a) C(b), as the 4 × 4 matrix of a acting on b."""
    a0, a1, a2, a3 = a
    left = np.array([[a0, -a1, -a2, -a3], [a1, a0, a3, -a2], [a2, -a3, a0, a1], [a3, a2, -a1, a0]])
    return left @ b


def qrot(theta):
    angle = np.linalg.norm(theta)
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate(([np.cos(angle / 2)], np.sin(angle / 2) * theta / angle))


def q_of_mrp(s):
    n = s @ s
    return np.concatenate(([(1 - n) / (1 + n)], 2 * s / (1 + n)))


def mrp_of_q(q):
    return q[1:] / (1 + q[0])


def rotvec_of_q(q):
    if q[0] < 0:
        q = -q
    v = np.linalg.norm(q[1:])
    if v == 0.0:
        return np.zeros(3)
    return 2 * np.arctan2(v, q[0]) * q[1:] / v


_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(8)


def dcm_of_q(q):
    """[BN] of β (scalar first): (β₀² − βᵀβ) I + 2 β βᵀ − 2 β₀ [β×]."""
    v = q[1:]
    return (q[0] ** 2 - v @ v) * np.eye(3) + 2 * np.outer(v, v) - 2 * q[0] * cross(v)


def mekf_transition(w, h):
    """Φ = exp(F h), F = [[−[ω×], −I], [0, 0]]: Φ₁₁ = exp(−[ω×]h), Φ₁₂ = −∫₀ʰ exp(−[ω×]s) ds."""
    phi = np.eye(6)
    phi[:3, :3] = dcm_of_q(qrot(w * h))
    s = h * (_NODES + 1) / 2
    phi[:3, 3:] = -(h / 2) * sum(weight * dcm_of_q(qrot(w * si)) for weight, si in zip(_WEIGHTS, s, strict=True))
    return phi


def qconj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def process_noise(sv, su, h):
    e = np.eye(3)
    return np.block(
        [[(sv**2 * h + su**2 * h**3 / 3) * e, -(su**2) * h**2 / 2 * e], [-(su**2) * h**2 / 2 * e, su**2 * h * e]]
    )


class Mekf:
    """State (q, b, P)."""

    def __init__(self, h, sv, su, r):
        self.h, self.q_noise, self.r = h, process_noise(sv, su, h), np.asarray(r)

    def propagate(self, x, g):
        q, b, p = x
        w = g - b
        qn = qmul(qrot(w * self.h), q)
        qn = qn / np.linalg.norm(qn)
        phi = mekf_transition(w, self.h)
        pn = phi @ p @ phi.T + self.q_noise
        return qn, b, 0.5 * (pn + pn.T)

    def update(self, x, sigma_m):
        q, b, p = x
        y = rotvec_of_q(qmul(q_of_mrp(sigma_m), qconj(q)))
        hm = np.hstack((np.eye(3), np.zeros((3, 3))))
        k = p @ hm.T @ np.linalg.inv(hm @ p @ hm.T + self.r)
        a = np.eye(6) - k @ hm
        pn = a @ p @ a.T + k @ self.r @ k.T
        dx = k @ y
        qn = qmul(qrot(dx[:3]), q)
        return (qn / np.linalg.norm(qn), b + dx[3:], 0.5 * (pn + pn.T)), y

    @staticmethod
    def sigma(x):
        q = x[0] if x[0][0] >= 0 else -x[0]
        return mrp_of_q(q)


def shadow_map(s, p):
    n = s @ s
    m = np.eye(6)
    m[:3, :3] = 2 * np.outer(s, s) / n**2 - np.eye(3) / n
    pn = m @ p @ m.T
    return -s / n, 0.5 * (pn + pn.T)


class MrpEkf:
    """State (σ, b, P) with the shadow set at |σ| > 1."""

    def __init__(self, h, sv, su, r):
        self.h, self.q_noise, self.r = h, process_noise(sv, su, h), np.asarray(r)

    @staticmethod
    def bmat(s):
        return (1 - s @ s) * np.eye(3) + 2 * cross(s) + 2 * np.outer(s, s)

    def propagate(self, x, g):
        s, b, p = x
        w = g - b
        qn = qmul(qrot(w * self.h), q_of_mrp(s))
        sn = mrp_of_q(qn)  # the set that continues σ (long when q₀ < 0)
        # ∂(¼ B(σ) ω)/∂σ written out from B(σ)ω = (1 − σᵀσ)ω + 2 σ×ω + 2 σ(σᵀω)
        jac = (-2 * np.outer(w, s) - 2 * cross(w) + 2 * (s @ w) * np.eye(3) + 2 * np.outer(s, w)) / 4
        f = np.zeros((6, 6))
        f[:3, :3] = jac
        f[:3, 3:] = -self.bmat(s) / 4
        phi = np.eye(6) + f * self.h + f @ f * self.h**2 / 2
        t = np.eye(6)
        t[:3, :3] = self.bmat(s) / 4
        pn = phi @ p @ phi.T + t @ self.q_noise @ t.T
        pn = 0.5 * (pn + pn.T)
        if sn @ sn > 1:
            sn, pn = shadow_map(sn, pn)
        return sn, b, pn

    def update(self, x, sigma_m):
        s, b, p = x
        alt = -sigma_m / (sigma_m @ sigma_m)
        z = alt if np.linalg.norm(alt - s) < np.linalg.norm(sigma_m - s) else sigma_m
        y = z - s
        bm = self.bmat(s)
        rs = bm @ self.r @ bm.T / 16
        hm = np.hstack((np.eye(3), np.zeros((3, 3))))
        k = p @ hm.T @ np.linalg.inv(hm @ p @ hm.T + rs)
        a = np.eye(6) - k @ hm
        pn = a @ p @ a.T + k @ rs @ k.T
        pn = 0.5 * (pn + pn.T)
        dx = k @ y
        sn = s + dx[:3]
        if sn @ sn > 1:
            sn, pn = shadow_map(sn, pn)
        return (sn, b + dx[3:], pn), y

    @staticmethod
    def sigma(x):
        return x[0]


def run_delayed(filt, x0, pre, gyro, measurement, available, latency):
    """The estimate now at each sample k with a rate-integrating gyro (reading r_k: the mean rate over
    [t_{k−1}, t_k]) and the measurement of t_{k−ℓ} arriving at k (``available[k]``).

    x0 is the posterior at t_{−ℓ−1}, ``pre`` the readings r_{−ℓ} … r_{−1}. The on-time filter runs from
    t_{−ℓ−1}; the estimate now is its posterior at t_{k−ℓ} propagated over r_{k−ℓ+1} … r_k with no update.
    Returns (sigma, bias, covariance, innovation) with one row per sample.
    """
    n = len(gyro)
    readings = list(pre) + list(gyro)  # readings[i] is r_{i − latency}
    x = x0
    sig, bia, cov, inn = [], [], [], []
    for k in range(n):
        x = filt.propagate(x, readings[k])  # to t_{k − latency}
        y = np.zeros(3)
        if available[k]:
            x, y = filt.update(x, measurement[k])
        now = x
        for i in range(k + 1, k + latency + 1):
            now = filt.propagate(now, readings[i])
        sig.append(filt.sigma(now))
        bia.append(now[1])
        cov.append(now[2])
        inn.append(y)
    return np.array(sig), np.array(bia), np.array(cov), np.array(inn)


def truth(n, h, omega_of_t, sigma0, bias_path, gyro_noise, scale=None):
    """True attitude (quaternions q_0 … q_n) under the rate ω_i = omega_of_t(i h) held over [t_i, t_{i+1}], and
    the gyro's readings of those periods, ω_i + (β_i + β_{i+1})/2 + noise (reading i delivered at t_{i+1})."""
    scale = np.zeros(3) if scale is None else np.asarray(scale)
    q = [q_of_mrp(np.asarray(sigma0, dtype=float))]
    rates, readings = [], []
    for k in range(n):
        w = omega_of_t(k * h)
        rates.append(w)
        readings.append((1 + scale) * w + 0.5 * (bias_path[k] + bias_path[k + 1]) + gyro_noise[k])
        qn = qmul(qrot(w * h), q[-1])
        q.append(qn / np.linalg.norm(qn))
    return np.array(q), np.array(rates), np.array(readings)


def compose_mrp(sigma, theta):
    """σ of the attitude σ followed by the small rotation θ (the star tracker's error)."""
    return mrp_of_q(_positive(qmul(qrot(theta), q_of_mrp(sigma))))


def _positive(q):
    return q if q[0] >= 0 else -q
