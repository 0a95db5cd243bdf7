"""The state and the gain in their two forms, and the one place they are converted.

**Physical form** (what a GN&C engineer and Basilisk use): the attitude σ = σ_BN (MRP,
dimensionless), the body rate ω = ω_BN in body components (rad/s), and the PD law

    u = −P_σ σ − P_ω ω        (N m)

with the attitude gain P_σ (N m) and the rate gain P_ω (N m s), positive for a restoring
torque: the sign convention of Basilisk's ``mrpFeedback`` (its ``K`` and ``P``,
L_r = −K σ_BR − P ω_BR with ω_r = 0). Here P_σ and P_ω may be per-axis (diagonal) or full
3×3 matrices: [`PDGains`][mrpctl.conventions.PDGains].

**Paper form** (the seed paper's, used inside the engines): the state x = [σ; ω/4] ∈ R⁶
(paper Eq. 6) and the gain K ∈ R³ˣ⁶ of u = K x (N m), K = [4 J K₁, 4 J K₂] for the loop
gains of σ̈ = K₁ σ + K₂ σ̇ (``design/conventions.md``).

**The conversions** (every one in this module, each exact in floating point: a negation and a
multiplication or division by 4, a power of two, change no bit unless a value overflows or
underflows; the sign of a zero entry flips with the negation, so K → (P_σ, P_ω) → K keeps
every bit, and P_σ = 70.11 I₃ gives the −0.0 off-diagonal entries of −70.11 I₃):

    x = [σ; ω/4],            (σ, ω) = (x[0:3], 4 x[3:6])
    K = [−P_σ, −4 P_ω],      P_σ = −K[:, 0:3],  P_ω = −K[:, 3:6] / 4
    P_σ = −4 J K₁,           P_ω = −J K₂          (through K = [4 J K₁, 4 J K₂])

The paper's K = [−70.11 I₃, −163.08 I₃] is P_σ = 70.11 I₃ N m, P_ω = 40.77 I₃ N m s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._validation import finite_array, readonly
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.spacecraft import Spacecraft

__all__ = [
    "RATE_SCALE",
    "STATE_PORTS",
    "PDGains",
    "feedback_gain",
    "gain_from_parts",
    "gain_from_pd",
    "gain_parts",
    "initial_state",
    "pd_from_gain",
    "physical_function",
    "physical_port_names",
    "state",
    "state_parts",
]

#: The paper's state holds ω / RATE_SCALE: x = [σ; ω/4].
RATE_SCALE = 4.0


# ---------------------------------------------------------------------------------- the state
def state(sigma: Any, omega: Any) -> np.ndarray:
    """x = [σ; ω/4] from σ (..., 3) and ω (..., 3) in rad/s; shape (..., 6)."""
    sigma = finite_array("sigma", sigma, (None, 3))
    omega = finite_array("omega", omega, (None, 3))
    sigma, omega = np.broadcast_arrays(sigma, omega)
    return np.concatenate((sigma, omega / RATE_SCALE), axis=-1)


def state_parts(x: Any) -> tuple[np.ndarray, np.ndarray]:
    """(σ, ω) from x = [σ; ω/4], shape (..., 6); ω in rad/s."""
    x = finite_array("x", x, (None, 6))
    return x[..., 0:3], RATE_SCALE * x[..., 3:6]


def initial_state(x0: Any = None, sigma0: Any = None, omega0: Any = None, *, batch: bool = False) -> np.ndarray:
    """The initial state x0 = [σ₀; ω₀/4] from the paper's form ``x0`` or the physical ``sigma0``, ``omega0``.

    Parameters
    ----------
    x0 : array_like, optional
        (6,) (or, with ``batch``, (N, 6)) states x = [σ; ω/4], returned as given (checked).
    sigma0 : array_like, optional
        (3,) (or (N, 3)) initial MRPs σ₀ (dimensionless), instead of ``x0``.
    omega0 : array_like, optional
        (3,) (or (N, 3)) initial body rates ω₀ (rad/s), with ``sigma0``; default zero (at rest).
    batch : bool, keyword-only
        Allow leading run axes (N, ...); σ₀ and ω₀ broadcast against each other.

    Raises
    ------
    SpecificationError
        When both forms or neither are given, ``omega0`` without ``sigma0``, or a value is not finite.
    DimensionError
        On a wrong shape (the error names ``x0``, ``sigma0`` or ``omega0``).
    """
    physical = sigma0 is not None or omega0 is not None
    if x0 is not None and physical:
        given = "sigma0" if sigma0 is not None else "omega0"
        raise SpecificationError(
            f"x0 and {given}: give the initial state once, as x0 = [sigma; omega/4] or as sigma0 and omega0 (rad/s)"
        )
    if x0 is not None:
        return finite_array("x0", x0, (None, 6) if batch else (6,))
    if not physical:
        raise SpecificationError("x0: give the initial state, as x0 = [sigma; omega/4] or as sigma0 and omega0 (rad/s)")
    if sigma0 is None:
        raise SpecificationError(
            "sigma0: omega0 needs sigma0, the initial MRPs (give sigma0 = [0, 0, 0] for the origin)"
        )
    shape: tuple[int | None, ...] = (None, 3) if batch else (3,)
    sigma = finite_array("sigma0", sigma0, shape)
    omega = np.zeros(3) if omega0 is None else finite_array("omega0", omega0, shape)
    if sigma.ndim > 2 or omega.ndim > 2:
        raise DimensionError(f"sigma0, omega0: expected shape (3,) or (N, 3) but found {sigma.shape} and {omega.shape}")
    try:
        sigma, omega = np.broadcast_arrays(sigma, omega)
    except ValueError as exc:
        raise DimensionError(
            f"sigma0, omega0: one per run or one shared, but found shapes {sigma.shape} and {omega.shape}"
        ) from exc
    return state(sigma, omega)


# ---------------------------------------------------------------------------------- the gain
def _gain_block(name: str, value: Any, *, positive: bool) -> np.ndarray:
    """A 3×3 gain block from a scalar (times I₃), 3 per-axis values (diagonal) or a 3×3 matrix."""
    array = finite_array(name, value)
    if array.shape == (3, 3):
        return array
    if array.shape not in ((), (3,)):
        raise DimensionError(
            f"{name}: expected a scalar, 3 per-axis values or a 3x3 matrix but found shape {array.shape}"
        )
    if positive and np.any(array <= 0.0):
        raise SpecificationError(
            f"{name} must be > 0 (u = -P_sigma sigma - P_omega omega, the sign convention of Basilisk's mrpFeedback: "
            f"positive gains restore), got {array.tolist()}; mrpctl's paper-form K = [-P_sigma, -4 P_omega] has "
            "the negative entries"
        )
    return float(array) * np.eye(3) if array.ndim == 0 else np.diag(array)


@dataclass(frozen=True, eq=False, init=False)
class PDGains:
    """Physical PD gains of u = −P_σ σ − P_ω ω (Basilisk's ``mrpFeedback`` convention).

    A scalar or per-axis gain must be > 0, a restoring torque in this sign convention (a
    negative value is usually mrpctl's paper-form K, whose entries are −P_σ and −4 P_ω). A 3×3
    matrix is taken as given, any finite entries (a designed, coupled gain): whether the loop is
    stable is what [`mrpctl.design`][mrpctl.design] and ``mrpctl verify`` certify.

    Parameters
    ----------
    attitude : float or array_like
        The attitude gain P_σ (N m; per unit MRP): a scalar (P I₃), 3 per-axis values
        (diagonal) or a 3×3 matrix.
    rate : float or array_like
        The rate gain P_ω (N m s, on ω in rad/s), in the same forms.

    Attributes
    ----------
    attitude, rate : numpy.ndarray
        (3, 3) read-only P_σ (N m) and P_ω (N m s).

    Examples
    --------
    >>> gains = PDGains(attitude=70.11, rate=40.77)       # the paper's K, physically
    >>> gains.gain()[0, [0, 3]]
    array([ -70.11, -163.08])
    """

    attitude: np.ndarray = field(repr=False)
    rate: np.ndarray = field(repr=False)

    def __init__(self, attitude: Any, rate: Any) -> None:
        object.__setattr__(self, "attitude", readonly(_gain_block("attitude", attitude, positive=True)))
        object.__setattr__(self, "rate", readonly(_gain_block("rate", rate, positive=True)))

    @classmethod
    def from_gain(cls, K: Any) -> PDGains:
        """The physical gains of the paper-form K (3, 6): P_σ = −K[:, 0:3], P_ω = −K[:, 3:6] / 4 (exact)."""
        attitude, rate = gain_parts(finite_array("K", K, (3, 6)))
        return cls(attitude=attitude, rate=rate)

    @classmethod
    def from_loop_gains(cls, spacecraft: Spacecraft, K1: Any, K2: Any) -> PDGains:
        """The physical gains of the loop gains of σ̈ = K₁ σ + K₂ σ̇: P_σ = −4 J K₁, P_ω = −J K₂."""
        return cls.from_gain(gain_from_pd(spacecraft, K1, K2))

    def gain(self) -> np.ndarray:
        """The paper-form (3, 6) K = [−P_σ, −4 P_ω] of u = K x on x = [σ; ω/4] (N m; exact)."""
        return readonly(gain_from_parts(self.attitude, self.rate))

    @property
    def is_diagonal(self) -> bool:
        """True when both gains act on each axis alone (no off-diagonal entry)."""
        return bool(
            np.array_equal(self.attitude, np.diag(np.diag(self.attitude)))
            and np.array_equal(self.rate, np.diag(np.diag(self.rate)))
        )

    def __str__(self) -> str:
        if self.is_diagonal:
            attitude, rate = np.diag(self.attitude).tolist(), np.diag(self.rate).tolist()
            return f"PD gains u = -P_sigma sigma - P_omega omega: P_sigma = {attitude} N m, P_omega = {rate} N m s"
        return (
            f"PD gains u = -P_sigma sigma - P_omega omega: P_sigma = {self.attitude.tolist()} N m, "
            f"P_omega = {self.rate.tolist()} N m s"
        )


def feedback_gain(K: Any) -> np.ndarray:
    """The paper-form (3, 6) gain K of u = K x from K itself (checked: finite, (3, 6)) or a
    [`PDGains`][mrpctl.conventions.PDGains] (K = [−P_σ, −4 P_ω])."""
    if isinstance(K, PDGains):
        return np.array(K.gain())
    return finite_array("K", K, (3, 6))


def gain_parts(K: Any) -> tuple[np.ndarray, np.ndarray]:
    """(P_σ, P_ω) = (−K[..., 0:3], −K[..., 3:6] / 4) of paper-form gains K (..., 3, 6): the attitude
    gains (N m) and rate gains (N m s) of u = −P_σ σ − P_ω ω, each (..., 3, 3); exact."""
    k = finite_array("K", K, (None, 3, 6))
    return -k[..., 0:3], -k[..., 3:6] / RATE_SCALE


def gain_from_parts(attitude: Any, rate: Any) -> np.ndarray:
    """K = [−P_σ, −4 P_ω] (..., 3, 6) from attitude gains P_σ and rate gains P_ω (..., 3, 3) (the inverse
    of [`gain_parts`][mrpctl.conventions.gain_parts]; exact)."""
    p_sigma = finite_array("attitude", attitude, (None, 3, 3))
    p_omega = finite_array("rate", rate, (None, 3, 3))
    return np.concatenate((-p_sigma, -RATE_SCALE * p_omega), axis=-1)


def gain_from_pd(spacecraft: Spacecraft, K1: Any, K2: Any) -> np.ndarray:
    """K = [4 J K₁, 4 J K₂] from the loop gains of σ̈ = K₁ σ + K₂ σ̇ (each 3×3 or 3-vector)."""
    k1 = _loop_block("K1", K1)
    k2 = _loop_block("K2", K2)
    return 4.0 * spacecraft.inertia @ np.hstack((k1, k2))


def pd_from_gain(spacecraft: Spacecraft, K: Any) -> tuple[np.ndarray, np.ndarray]:
    """(K₁, K₂) = J⁻¹ K / 4 split into its σ and σ̇ blocks (the inverse of
    [`gain_from_pd`][mrpctl.conventions.gain_from_pd]); K may be a [`PDGains`][mrpctl.conventions.PDGains]."""
    loop = spacecraft.inertia_inverse @ feedback_gain(K) / 4.0
    return loop[:, 0:3], loop[:, 3:6]


def _loop_block(name: str, value: Any) -> np.ndarray:
    array = finite_array(name, value)
    if array.shape == (3,):
        return np.diag(array)
    return finite_array(name, array, (3, 3))


# ------------------------------------------------------------------- ports of CasADi Functions
#: The ports of the loop's CasADi Functions ([`mrpctl.loop.closed_loop_functions`][mrpctl.loop.closed_loop_functions])
#: that carry paper-form states x = [σ; ω/4], one 6-row block per state (the predictor's 12-row delay-line entries
#: hold the measurement and the model copy): what [`physical_function`][mrpctl.conventions.physical_function] splits.
STATE_PORTS = frozenset(
    {
        "x",
        "xdot",
        "x_meas",
        "x_next",
        "x_delayed",
        "x_end",
        "x_true",
        "x_hat",
        "y",
        "z",
        "z_delayed",
        "z_next",
        "measurement",
        "measurements",
        "states",
        "history",
        "ring",
    }
)


def physical_port_names(name: str, rows: int) -> tuple[str, ...]:
    """The physical ports of a state port ``name`` with ``rows`` rows: σ and ω per 6-row state block.

    ``x`` → ``sigma``, ``omega``; ``x_<s>`` → ``sigma_<s>``, ``omega_<s>``; ``xdot`` → ``sigma_dot``,
    ``omega_dot``; any other name → ``<name>_sigma``, ``<name>_omega``. A second block (the predictor's
    model copy z in a 12-row delay-line entry) adds ``z_`` to both names (``sigma_delayed``,
    ``omega_delayed``, ``z_sigma_delayed``, ``z_omega_delayed``).
    """
    if rows % 6 or rows == 0:
        raise DimensionError(f"{name}: a state port holds 6-row blocks [sigma; omega/4], got {rows} rows")
    if name == "xdot":
        pair = ("sigma_dot", "omega_dot")
    elif name == "x" or name.startswith("x_"):
        pair = ("sigma" + name[1:], "omega" + name[1:])
    else:
        pair = (f"{name}_sigma", f"{name}_omega")
    names: list[str] = []
    for block in range(rows // 6):
        names += [("z_" * block) + each for each in pair]
    return tuple(names)


def physical_function(function: ca.Function) -> ca.Function:
    """``function`` with every state port (``STATE_PORTS``) split into σ (3 rows)
    and ω (3 rows, rad/s; ω̇ in rad/s² for ``xdot``), same name, the other ports unchanged.

    Inside, x = [σ; ω/4] is formed from the inputs and ω = 4 x[3:6] from the outputs: both exact, so the
    result equals ``function`` on the converted values bit for bit. Memory vectors (``memory``) stay as
    they are (the controller's own layout; the predictor's holds its model copy z = [σ; ω/4]).
    """
    inputs: list[Any] = []
    input_names: list[str] = []
    arguments: list[Any] = []
    for i in range(function.n_in()):
        name = function.name_in(i)
        rows, columns = function.size_in(i)
        if name not in STATE_PORTS:
            symbol = ca.MX.sym(name, rows, columns)
            inputs.append(symbol)
            input_names.append(name)
            arguments.append(symbol)
            continue
        names = physical_port_names(name, rows)
        blocks = []
        for k in range(0, len(names), 2):
            sigma = ca.MX.sym(names[k], 3, columns)
            omega = ca.MX.sym(names[k + 1], 3, columns)
            inputs += [sigma, omega]
            input_names += [names[k], names[k + 1]]
            blocks += [sigma, omega / RATE_SCALE]
        arguments.append(ca.vertcat(*blocks))
    results = function.call(arguments)
    outputs: list[Any] = []
    output_names: list[str] = []
    for i, value in enumerate(results):
        name = function.name_out(i)
        if name not in STATE_PORTS:
            outputs.append(value)
            output_names.append(name)
            continue
        names = physical_port_names(name, function.size_out(i)[0])
        for k in range(0, len(names), 2):
            start = 3 * k
            outputs += [value[start : start + 3, :], RATE_SCALE * value[start + 3 : start + 6, :]]
            output_names += [names[k], names[k + 1]]
    return ca.Function(function.name(), inputs, outputs, input_names, output_names)
