"""An independent NumPy MEKF and MRP-EKF, written from the equations of design/estimation.md.

It shares no code with ``mrpctl.estimation``: quaternions as 4 × 4 product matrices, Φ of the MEKF as the
matrix exponential of F h (scipy), the residual's rotation vector by arctan2, the MRP propagation through
quaternions, and the delayed measurement handled by keeping the whole history of states and re-running
from the measurement's time. Also a truth simulator for the consistency tests.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm


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
        f = np.zeros((6, 6))
        f[:3, :3] = -cross(w)
        f[:3, 3:] = -np.eye(3)
        phi = expm(f * self.h)
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


def run_delayed(filt, x0, pre, gyro, measurement, taken, latency):
    """The estimate now at each sample k, from the whole history: the measurement of sample j (taken[j])
    arrives at j + latency; the estimate now is the on-time filter's state at k − latency (all its
    measurements) propagated over ω̃_{k−latency} … ω̃_{k−1} with no update.

    ``pre`` holds the latency gyro samples before t = 0; x0 is the state at t_{−latency}.
    Returns (sigma, bias, covariance, innovation) with one row per sample.
    """
    n = len(gyro)
    samples = list(pre) + list(gyro)  # samples[i] is ω̃ at t_{i − latency}
    on_time = [x0]  # on_time[i]: prior state at t_{i − latency}
    sig, bia, cov, inn = [], [], [], []
    for k in range(n):
        j = k - latency  # the measurement arriving now was taken at sample j
        x = on_time[k]
        y = np.zeros(3)
        if j >= 0 and taken[j]:
            x, y = filt.update(x, measurement[k])
        on_time[k] = x
        on_time.append(filt.propagate(x, samples[k]))
        now = x
        for i in range(k, k + latency):
            now = filt.propagate(now, samples[i])
        sig.append(filt.sigma(now))
        bia.append(now[1])
        cov.append(now[2])
        inn.append(y)
    return np.array(sig), np.array(bia), np.array(cov), np.array(inn)


def truth(n, h, omega_of_t, sigma0, bias_path, gyro_noise, scale=None):
    """True attitude (quaternions, n + 1) under a rate held over each period, and the gyro readings."""
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
