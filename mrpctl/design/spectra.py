"""Spectra of ẋ = A₀x + Σₖ Aₖ x(t − τₖ): rightmost roots, spectral abscissa, stable delay intervals, plots.

The characteristic roots are the zeros of det M(s), M(s) = sI − A₀ − Σₖ Aₖ e^{−sτₖ}. They are
approximated by the eigenvalues of a Chebyshev collocation of the infinitesimal generator of the
delay equation on [−τ_max, 0] (Breda, Maset & Vermiglio 2005), and each approximation is then
corrected by Newton steps on det M(s) = 0 itself, so the roots returned are those of the exact
equation, not of the discretisation. What is checked, and reported, for each answer:

* per root, the backward error σ_min(M(s)) / (|s| + ‖A₀‖ + Σ‖Aₖ‖) and a radius: the circle of
  that radius about the root winds around det M exactly ``multiplicity`` times (argument principle,
  evaluated in floating point along an adaptively refined contour);
* for the whole list, a count: every characteristic root with Re s > ``count_line`` lies in a
  rectangle (|s| <= ‖A₀‖ + Σ‖Aₖ‖ e^{−Re(s) τₖ} for a root), and the winding number of det M along
  its boundary is compared with the roots listed right of that line (with multiplicity). When they
  agree no root right of the line was missed and the spectral abscissa is ``certified``.

Floating-point evaluation of det M is not interval arithmetic: the count is a numerical
certificate (adaptive refinement until the phase moves by less than π/4 between samples, checked
against the midpoint), not a proof in exact arithmetic.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import finite_array, finite_scalar, integer, readonly
from mrpctl.design._common import balancing, similarity, system_matrices
from mrpctl.design.margin import DelayMargin, delay_margin
from mrpctl.errors import DimensionError, SpecificationError

__all__ = [
    "DelayStabilityMap",
    "DelaySystem",
    "Spectrum",
    "characteristic_roots",
    "delay_stability_map",
    "delay_system",
    "plot_spectrum",
    "spectral_abscissa",
]

#: Default number of rightmost (distinct) roots returned.
DEFAULT_COUNT = 10
#: Fewest Chebyshev intervals of the collocation.
_MIN_NODES = 24
#: Most Chebyshev intervals (the generator is n(N + 1) square: memory and time grow as N² and N³).
_MAX_NODES = 400
#: Newton (or Schröder) corrections per root.
_NEWTON_STEPS = 40
#: Backward error below which a corrected root is accepted.
_BACKWARD_ERROR = 1e-9
#: Phase step (rad) above which a contour segment is halved.
_PHASE_STEP = math.pi / 4
#: Halvings of one contour segment before the count is declared unresolved (a root on the contour).
_MAX_DEPTH = 40


@dataclass(frozen=True, eq=False)
class DelaySystem:
    """ẋ = A₀x + Σₖ Aₖ x(t − τₖ), checked: finite real (n, n) matrices and delays τₖ >= 0.

    Attributes
    ----------
    A0 : numpy.ndarray
        (n, n) matrix of the undelayed state.
    A : tuple of numpy.ndarray
        (n, n) matrices of the delayed states, one per delay.
    tau : tuple of float
        The delays τₖ (s), same length as ``A``.
    """

    A0: np.ndarray = field(repr=False)
    A: tuple[np.ndarray, ...] = field(repr=False)
    tau: tuple[float, ...]

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A0.shape[0])

    @property
    def tau_max(self) -> float:
        """The largest delay (0.0 without delays)."""
        return max(self.tau, default=0.0)

    def matrix(self, s: complex) -> np.ndarray:
        """M(s) = sI − A₀ − Σₖ Aₖ e^{−sτₖ}."""
        m = s * np.eye(self.n) - self.A0
        for a, t in zip(self.A, self.tau, strict=True):
            m = m - a * np.exp(-s * t)
        return np.asarray(m, dtype=complex)

    @property
    def norm_sum(self) -> float:
        """‖A₀‖₂ + Σₖ ‖Aₖ‖₂."""
        return float(np.linalg.norm(self.A0, 2) + sum(np.linalg.norm(a, 2) for a in self.A))


def delay_system(A0: Any, A: Any, tau: Any) -> DelaySystem:
    """Check and build ẋ = A₀x + Σₖ Aₖ x(t − τₖ).

    Parameters
    ----------
    A0 : array_like
        (n, n) matrix (a scalar is read as 1×1).
    A : array_like or sequence of array_like
        One (n, n) matrix (one delay), a sequence of them, or a (k, n, n) array.
    tau : float or sequence of float
        The delays (s), >= 0, one per matrix of ``A``.

    Raises
    ------
    DimensionError
        When A0 is not square, a delayed matrix does not match it, or the number of delays differs
        from the number of delayed matrices.
    SpecificationError
        When an entry is NaN, inf or complex, or a delay is negative or not finite.
    """
    a0 = finite_array("A0", A0)
    if a0.ndim == 0:
        a0 = a0.reshape(1, 1)
    if a0.ndim != 2 or a0.shape[0] != a0.shape[1] or a0.shape[0] == 0:
        raise DimensionError(f"A0: expected a square (n, n) matrix but found shape {a0.shape}")
    n = a0.shape[0]
    raw = _matrix_list(A, n)
    mats = []
    for k, item in enumerate(raw):
        m = finite_array(f"A[{k}]", item)
        if m.ndim == 0:
            m = m.reshape(1, 1)
        if m.shape != (n, n):
            raise DimensionError(f"A[{k}]: expected shape {(n, n)} (the shape of A0) but found {m.shape}")
        mats.append(readonly(m))
    taus_raw = np.atleast_1d(np.asarray(tau, dtype=object))
    if taus_raw.ndim != 1:
        raise DimensionError(f"tau: expected a scalar or a sequence of delays but found shape {taus_raw.shape}")
    taus = tuple(finite_scalar(f"tau[{k}]", t) for k, t in enumerate(taus_raw.tolist()))
    if len(taus) != len(mats):
        raise DimensionError(f"tau: expected {len(mats)} delays (one per delayed matrix A[k]) but found {len(taus)}")
    for k, t in enumerate(taus):
        if t < 0.0:
            raise SpecificationError(f"tau[{k}] must be >= 0 (a delay), got {t}")
    return DelaySystem(A0=readonly(a0), A=tuple(mats), tau=taus)


def _matrix_list(A: Any, n: int) -> list[Any]:
    """The delayed matrices as a list: one matrix, a sequence of them, or a (k, n, n) array."""
    if isinstance(A, list | tuple):
        if not A:
            return []
        dims = [np.ndim(item) for item in A]
        if all(d == 1 for d in dims):
            return [A]  # the rows of one matrix
        if all(d == 0 for d in dims) and n != 1:
            return [A]  # a flat row: refused by the shape check
        return list(A)
    return [A] if np.ndim(A) <= 2 else list(np.asarray(A))


@dataclass(frozen=True, eq=False)
class Spectrum:
    """Rightmost characteristic roots of a delay system, Newton-corrected and counted.

    Attributes
    ----------
    system : DelaySystem
    roots : numpy.ndarray
        (m,) distinct roots (1/s), rightmost first (Re descending, then Im descending).
    multiplicities : numpy.ndarray
        (m,) winding number of det M on a circle of radius ``radii`` about each root (0 when the
        circle could not be resolved).
    radii : numpy.ndarray
        (m,) radius (1/s) of that circle: an enclosure of the root.
    backward_errors : numpy.ndarray
        (m,) σ_min(M(s)) / (|s| + ‖A₀‖ + Σ‖Aₖ‖) at each root.
    count_line : float
        Re s of the vertical line right of which the roots were counted (1/s).
    counted : int or None
        Roots (with multiplicity) of det M right of ``count_line`` by the argument principle; None
        when the contour could not be resolved.
    nodes : int
        Chebyshev intervals N of the collocation that gave the starting points.
    """

    system: DelaySystem
    roots: np.ndarray = field(repr=False)
    multiplicities: np.ndarray = field(repr=False)
    radii: np.ndarray = field(repr=False)
    backward_errors: np.ndarray = field(repr=False)
    count_line: float
    counted: int | None
    nodes: int

    @property
    def abscissa(self) -> float:
        """The spectral abscissa max Re s (1/s)."""
        return float(self.roots[0].real)

    @property
    def rightmost(self) -> complex:
        """The rightmost root (the one with Im >= 0 of a pair)."""
        return complex(self.roots[0])

    @property
    def listed(self) -> int:
        """Roots listed right of ``count_line``, with multiplicity."""
        return int(np.sum(self.multiplicities[self.roots.real > self.count_line]))

    @property
    def certified(self) -> bool:
        """True when the count right of ``count_line`` equals the roots listed there, every listed
        root's circle wound with multiplicity >= 1 and every backward error is below 1e-9."""
        return (
            self.counted is not None
            and self.counted == self.listed
            and bool(np.all(self.multiplicities >= 1))
            and bool(np.all(self.backward_errors <= _BACKWARD_ERROR))
        )

    @property
    def stable(self) -> bool:
        """True when the spectral abscissa is negative (exponential stability)."""
        return self.abscissa < 0.0

    def __str__(self) -> str:
        verdict = "certified" if self.certified else "NOT certified"
        lines = [
            f"spectral abscissa {self.abscissa:.10g} 1/s ({'stable' if self.stable else 'unstable'}); "
            f"count right of Re s = {self.count_line:.6g}: {self.counted} by the argument principle, "
            f"{self.listed} listed ({verdict}; N = {self.nodes})"
        ]
        for s, m, r, e in zip(self.roots, self.multiplicities, self.radii, self.backward_errors, strict=True):
            sign = "+" if s.imag >= 0 else "-"
            lines.append(f"  {s.real:.12g} {sign} {abs(s.imag):.12g}j  x{m}  (within {r:.2g}, backward error {e:.1e})")
        return "\n".join(lines)


def characteristic_roots(
    A0: Any, A: Any = (), tau: Any = (), *, count: int = DEFAULT_COUNT, nodes: int | None = None
) -> Spectrum:
    """The ``count`` rightmost characteristic roots of ẋ = A₀x + Σₖ Aₖ x(t − τₖ).

    Chebyshev collocation of the generator on [−τ_max, 0] with N intervals (N grows until the
    collocation resolves every root that can lie right of the counting line, up to 400), Newton
    (and Schröder, for multiple roots) corrections on det M(s) = 0, a winding-number enclosure of
    each root, and an argument-principle count of the roots right of a line below the listed ones
    (module docstring). Complex roots come in conjugate pairs; both are listed.

    Parameters
    ----------
    A0 : array_like
        (n, n) undelayed matrix.
    A : array_like or sequence of array_like, optional
        Delayed matrices (none: the spectrum of A₀).
    tau : float or sequence of float, optional
        Delays (s), >= 0.
    count : int, optional
        Number of distinct rightmost roots wanted (default 10; a conjugate partner of the last is
        added).
    nodes : int, optional
        Fix the number N of Chebyshev intervals (default: chosen from the system's norms).

    Returns
    -------
    Spectrum

    Raises
    ------
    DimensionError, SpecificationError
        Bad matrices or delays ([`delay_system`][mrpctl.design.spectra.delay_system]), or a bad
        ``count`` / ``nodes``.

    Examples
    --------
    >>> import math
    >>> sp = characteristic_roots(0.0, -1.0, math.pi / 2)  # ẋ = −x(t − π/2): roots ±i on the axis
    >>> round(abs(sp.abscissa), 12), round(sp.rightmost.imag, 12)
    (0.0, 1.0)
    """
    system = delay_system(A0, A, tau)
    count = integer("count", count, minimum=1)
    if nodes is not None:
        nodes = integer("nodes", nodes, minimum=2, maximum=_MAX_NODES)
    return _spectrum(system, count, nodes)


def spectral_abscissa(A0: Any, A: Any = (), tau: Any = (), *, nodes: int | None = None) -> float:
    """max Re s over the characteristic roots (1/s).

    See [`characteristic_roots`][mrpctl.design.spectra.characteristic_roots].

    Raises
    ------
    ArithmeticError
        When the count does not confirm the rightmost roots (the abscissa would not be certain).
    """
    spectrum = characteristic_roots(A0, A, tau, count=4, nodes=nodes)
    if not spectrum.certified:
        raise ArithmeticError(f"the rightmost roots could not be confirmed by the argument principle:\n{spectrum}")
    return spectrum.abscissa


def decoupled_blocks(*matrices: np.ndarray) -> list[np.ndarray]:
    """Index sets of the diagonal blocks that the square matrices share (connected components of the
    graph with an edge i–j wherever some matrix has a nonzero (i, j) or (j, i) entry)."""
    n = matrices[0].shape[0]
    link = np.zeros((n, n), dtype=bool)
    for m in matrices:
        link |= (m != 0) | (m.T != 0)
    seen = np.zeros(n, dtype=bool)
    blocks = []
    for i in range(n):
        if seen[i]:
            continue
        stack, members = [i], []
        seen[i] = True
        while stack:
            j = stack.pop()
            members.append(j)
            for k in np.flatnonzero(link[j] & ~seen):
                seen[k] = True
                stack.append(int(k))
        blocks.append(np.array(sorted(members)))
    return blocks


def _spectrum(system: DelaySystem, count: int, nodes: int | None) -> Spectrum:
    blocks = decoupled_blocks(system.A0, *system.A)
    if len(blocks) > 1:
        return _merged(system, blocks, count, nodes)
    return _spectrum_block(system, count, nodes)


def _merged(system: DelaySystem, blocks: list[np.ndarray], count: int, nodes: int | None) -> Spectrum:
    """The spectrum of a block-diagonal system: the union of the blocks' spectra (each certified alone)."""
    parts = []
    for idx in blocks:
        sub = DelaySystem(
            A0=readonly(system.A0[np.ix_(idx, idx)]),
            A=tuple(readonly(a[np.ix_(idx, idx)]) for a in system.A),
            tau=system.tau,
        )
        parts.append(_spectrum_block(sub, count, nodes))
    line = max(p.count_line for p in parts)
    roots = np.concatenate([p.roots for p in parts])
    mult = np.concatenate([p.multiplicities for p in parts])
    radii = np.concatenate([p.radii for p in parts])
    # identical blocks give the same root: merge (multiplicities add)
    merged: list[list[Any]] = []
    for s, m, r in zip(roots, mult, radii, strict=True):
        for entry in merged:
            if abs(entry[0] - s) <= 1e-9 * (1.0 + abs(s)):
                entry[1] += m
                entry[2] = max(entry[2], r)
                break
        else:
            merged.append([complex(s), int(m), float(r)])
    merged.sort(key=lambda e: (-e[0].real, -e[0].imag))
    complete = [e for e in merged if e[0].real > line]  # every root right of the common line
    keep = complete
    if len(complete) > count:
        edge = complete[count - 1][0].real
        keep = [e for e in complete if e[0].real >= edge - 1e-12 * (1.0 + abs(edge))]
        dropped = [e[0].real for e in complete if e not in keep]
        if dropped:
            line = 0.5 * (keep[-1][0].real + max(dropped))
    out = np.array([e[0] for e in keep], dtype=complex)
    ok = all(p.certified for p in parts)
    listed_line = line
    listed = int(sum(e[1] for e in keep))
    return Spectrum(
        system=system,
        roots=readonly(out, dtype=complex),
        multiplicities=readonly(np.array([e[1] for e in keep], dtype=int), dtype=int),
        radii=readonly(np.array([e[2] for e in keep])),
        backward_errors=readonly(np.array([_backward(system, s) for s in out])),
        count_line=float(listed_line),
        counted=listed if ok else None,
        nodes=max(p.nodes for p in parts),
    )


def _spectrum_block(system: DelaySystem, count: int, nodes: int | None) -> Spectrum:
    delayed = [(a, t) for a, t in zip(system.A, system.tau, strict=True) if t > 0.0]
    a0 = system.A0 + sum((a for a, t in zip(system.A, system.tau, strict=True) if t == 0.0), np.zeros_like(system.A0))
    tau_max = max((t for _, t in delayed), default=0.0)
    n = system.n
    if not delayed:
        eig = np.linalg.eigvals(a0)
        groups = _group(eig.astype(complex), 1e-9 * max(1.0, float(np.max(np.abs(eig)))))
        roots = np.array([g[0] for g in groups], dtype=complex)
        mult = np.array([g[1] for g in groups], dtype=int)
        order = np.lexsort((-roots.imag, -roots.real))
        roots, mult = roots[order], mult[order]
        back = np.array([_backward(system, s) for s in roots])
        return Spectrum(
            system=system,
            roots=readonly(roots, dtype=complex),
            multiplicities=readonly(mult, dtype=int),
            radii=readonly(np.zeros(len(roots))),
            backward_errors=readonly(back),
            count_line=-math.inf,
            counted=n,
            nodes=0,
        )
    # normalised time t' = t/τ_max and a power-of-two balancing: same roots (times 1/τ_max), better scaled
    mag = sum((np.abs(a) for a, _ in delayed), np.zeros_like(a0))
    scale = balancing(a0, mag)
    b0 = tau_max * similarity(a0, scale)
    bk = [(tau_max * similarity(a, scale), t / tau_max) for a, t in delayed]
    norm = float(np.linalg.norm(b0, 2) + sum(np.linalg.norm(a, 2) for a, _ in bk))
    big = max(norm, 1.0)
    n_nodes = nodes if nodes is not None else max(_MIN_NODES, math.ceil(2 * big + 10))
    while True:
        candidates = _collocation_eigenvalues(b0, bk, n_nodes)
        roots, mult, radii = _correct(b0, bk, candidates, count, big)
        line = _count_line(roots, candidates, big)
        counted = _count_right_of(b0, bk, line, _reach(b0, bk, line))
        listed = int(np.sum(mult[roots.real > line]))
        # the collocation resolves roots with |s τ_max| up to about N/1.5; a root missed shows in the count
        need = min(_MAX_NODES, math.ceil(1.5 * float(np.max(np.abs(roots), initial=0.0)) + 10))
        agreed = counted == listed and bool(np.all(mult >= 1))
        if nodes is not None or (agreed and n_nodes >= need):
            break
        wanted = min(_MAX_NODES, max(need, n_nodes if agreed else 2 * n_nodes))
        if wanted <= n_nodes:
            break
        n_nodes = wanted
    roots_s = roots / tau_max
    back = np.array([_backward(system, s) for s in roots_s])
    return Spectrum(
        system=system,
        roots=readonly(roots_s, dtype=complex),
        multiplicities=readonly(mult, dtype=int),
        radii=readonly(radii / tau_max),
        backward_errors=readonly(back),
        count_line=float(line / tau_max),
        counted=counted,
        nodes=n_nodes,
    )


def _chebyshev(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes θ_j = (cos(jπ/m) − 1)/2 on [−1, 0] (θ_0 = 0) and the differentiation matrix on them."""
    x = np.cos(np.pi * np.arange(m + 1) / m)
    c = np.hstack([2.0, np.ones(m - 1), 2.0]) * (-1.0) ** np.arange(m + 1)
    dx = x[:, None] - x[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(m + 1))
    d = d - np.diag(d.sum(axis=1))
    return (x - 1.0) / 2.0, 2.0 * d


def _lagrange_row(theta: np.ndarray, point: float) -> np.ndarray:
    """Values at ``point`` of the Lagrange basis on the Chebyshev points ``theta`` (barycentric form)."""
    m = len(theta) - 1
    w = (-1.0) ** np.arange(m + 1)
    w[0] *= 0.5
    w[-1] *= 0.5
    diff = point - theta
    hit = np.abs(diff) <= 1e-15
    if np.any(hit):
        row = np.zeros(m + 1)
        row[int(np.argmax(hit))] = 1.0
        return row
    terms = w / diff
    return terms / terms.sum()


def _collocation_eigenvalues(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], m: int) -> np.ndarray:
    """Eigenvalues of the collocated generator of the unit-τ_max system (dimension n(m + 1))."""
    n = b0.shape[0]
    theta, d = _chebyshev(m)
    gen = np.kron(d, np.eye(n))
    first = np.zeros((n, n * (m + 1)))
    first[:, :n] += b0
    for a, t in bk:
        first += np.kron(_lagrange_row(theta, -t), a)
    gen[:n, :] = first
    return np.linalg.eigvals(gen)


def _matrices(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], s: complex) -> tuple[np.ndarray, ...]:
    """M(s), M'(s), M''(s) of the normalised system."""
    n = b0.shape[0]
    m = s * np.eye(n) - b0
    m1 = np.eye(n, dtype=complex)
    m2 = np.zeros((n, n), dtype=complex)
    for a, t in bk:
        e = a * np.exp(-s * t)
        m = m - e
        m1 = m1 + t * e
        m2 = m2 - t * t * e
    return np.asarray(m, dtype=complex), m1, m2


def _sigma_min(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], s: complex) -> float:
    return float(np.linalg.svd(_matrices(b0, bk, s)[0], compute_uv=False)[-1])


def _newton(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], s: complex, big: float) -> tuple[complex, float]:
    """Newton on det M with a multiplicity estimate; (root, σ_min(M(root)) / (|root| + scale)).

    g = (log det M)' = tr(M⁻¹M') and h = (log det M)'' = tr(M⁻¹M'') − tr((M⁻¹M')²); near a root of
    multiplicity m, g ≈ m/(s − s₀) and −h ≈ m/(s − s₀)², so m ≈ g²/(−h) and the step −m/g converges
    quadratically for multiple roots too (m = 1 is Newton's step). The iteration stops when the
    step stops shrinking (rounding level).
    """
    n = b0.shape[0]
    previous = math.inf
    for k in range(_NEWTON_STEPS):
        m, m1, m2 = _matrices(b0, bk, s)
        try:
            x = np.linalg.solve(m, np.hstack((m1, m2)))
        except np.linalg.LinAlgError:
            break  # M(s) exactly singular: s is a root
        x1, x2 = x[:, :n], x[:, n:]
        g = complex(np.trace(x1))
        h = complex(np.trace(x2) - np.trace(x1 @ x1))
        if not (np.isfinite(g) and np.isfinite(h)) or g == 0:
            break
        mult = 1
        if h != 0:
            ratio = (g * g / -h).real
            if np.isfinite(ratio):
                mult = int(min(max(round(ratio), 1), n))
        step = -mult / g
        size = abs(step)
        if size > 0.5 * (1.0 + abs(s)):
            step *= 0.5 * (1.0 + abs(s)) / size
        s = s + step
        if size <= 1e-14 * (1.0 + abs(s)) or (k > 4 and size >= previous):
            break
        previous = size
    return s, _sigma_min(b0, bk, s) / (abs(s) + big)


def _group(values: np.ndarray, tol: float) -> list[tuple[complex, int]]:
    """Cluster values closer than ``tol``: (mean, size)."""
    groups: list[list[complex]] = []
    for v in values:
        for g in groups:
            if abs(g[0] - v) <= tol:
                g.append(complex(v))
                break
        else:
            groups.append([complex(v)])
    return [(complex(np.mean(g)), len(g)) for g in groups]


def _correct(
    b0: np.ndarray, bk: list[tuple[np.ndarray, float]], candidates: np.ndarray, count: int, big: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton-correct the rightmost candidates; distinct roots, their winding multiplicities and radii."""
    order = np.argsort(-candidates.real)
    take = candidates[order[: 2 * count + 8]]
    take = take[take.imag >= -1e-12 * (1.0 + np.abs(take))]  # one of each pair; conjugates added below
    found: list[complex] = []
    for z in take:
        s, err = _newton(b0, bk, complex(z.real, max(z.imag, 0.0)), big)
        if err > _BACKWARD_ERROR:
            continue
        if abs(s.imag) <= 1e-10 * (1.0 + abs(s)):
            s = complex(s.real, 0.0)
        found.append(s)
    distinct = [g[0] for g in _group(np.array(found, dtype=complex), 1e-7 * big)]
    everything: list[complex] = []
    for s in distinct:
        everything.append(s)
        if s.imag != 0.0:
            everything.append(s.conjugate())
    everything.sort(key=lambda z: (-z.real, -z.imag))
    if len(everything) > count:
        cut = everything[count - 1]
        keep = everything[:count]
        if cut.imag > 0.0:
            keep.append(cut.conjugate())
        everything = keep
    roots = np.array(everything, dtype=complex)
    mult = np.zeros(len(roots), dtype=int)
    radii = np.zeros(len(roots))
    for i, s in enumerate(roots):
        others = [abs(s - z) for j, z in enumerate(roots) if j != i]
        gap = min(others, default=1.0)
        rho = min(0.3 * gap, max(1e-5 * (1.0 + abs(s)), 1e-9 * big))
        winding = _winding(b0, bk, _circle(s, rho))
        mult[i] = max(winding, 0) if winding is not None else 0
        radii[i] = rho
    return roots, mult, radii


def _circle(center: complex, radius: float, points: int = 16) -> list[complex]:
    return [
        center + radius * complex(math.cos(2 * math.pi * k / points), math.sin(2 * math.pi * k / points))
        for k in range(points)
    ]


def _phases(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], points: np.ndarray) -> np.ndarray:
    """det M(s) / |det M(s)| at every point (0 where det M vanishes), in one batched evaluation."""
    n = b0.shape[0]
    m = points[:, None, None] * np.eye(n) - b0
    for a, t in bk:
        m = m - np.exp(-points * t)[:, None, None] * a
    sign, _ = np.linalg.slogdet(m)
    return np.asarray(sign, dtype=complex)


def _winding(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], polygon: list[complex]) -> int | None:
    """Winding number of det M along the closed polygon; None when it cannot be resolved.

    Segments are halved until the phase moves by less than π/4 along each and the two halves
    add up to the whole (so no turn of 2π hides in one segment), at most 40 times.
    """
    pts = np.array([*polygon, polygon[0]], dtype=complex)
    ph = _phases(b0, bk, pts)
    for _ in range(_MAX_DEPTH):
        if np.any(ph == 0):
            return None
        mids = 0.5 * (pts[:-1] + pts[1:])
        pm = _phases(b0, bk, mids)
        if np.any(pm == 0):
            return None
        whole = np.angle(ph[1:] / ph[:-1])
        left = np.angle(pm / ph[:-1])
        right = np.angle(ph[1:] / pm)
        ok = (np.abs(whole) < _PHASE_STEP) & (np.abs(left) < _PHASE_STEP) & (np.abs(left + right - whole) < 1e-9)
        if np.all(ok):
            return round(float(np.sum(whole)) / (2.0 * math.pi))
        bad = np.flatnonzero(~ok)
        pts = np.insert(pts, bad + 1, mids[bad])
        ph = np.insert(ph, bad + 1, pm[bad])
        if len(pts) > 2_000_000:
            return None
    return None


def _reach(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], line: float) -> float:
    """Bound on |s| of every root with Re s >= line: ‖A₀‖ + Σ‖Aₖ‖ e^{−line τₖ} (normalised units)."""
    return float(np.linalg.norm(b0, 2) + sum(np.linalg.norm(a, 2) * math.exp(-line * t) for a, t in bk))


def _count_line(roots: np.ndarray, candidates: np.ndarray, big: float) -> float:
    """A vertical line below the listed roots and above the next candidate (half way in the gap)."""
    lowest = float(np.min(roots.real)) if len(roots) else float(np.max(candidates.real))
    below = candidates.real[candidates.real < lowest - 1e-6 * big]
    if below.size:
        return 0.5 * (lowest + float(np.max(below)))
    return lowest - 0.1 * big


def _count_right_of(b0: np.ndarray, bk: list[tuple[np.ndarray, float]], line: float, reach: float) -> int | None:
    """Argument-principle count of the roots with Re s > line (they lie in |s| <= reach)."""
    edge = 1.05 * reach + 1.0
    right = max(edge, line + 1.0)
    polygon = [complex(line, -edge), complex(right, -edge), complex(right, edge), complex(line, edge)]
    # split the long edges so the adaptive refinement starts from a fine enough polyline
    pieces = max(8, int(4 * edge * max((t for _, t in bk), default=1.0)))
    dense: list[complex] = []
    for a, b in zip(polygon, [*polygon[1:], polygon[0]], strict=True):
        dense.extend(a + (b - a) * k / pieces for k in range(pieces))
    return _winding(b0, bk, dense)


def _backward(system: DelaySystem, s: complex) -> float:
    return float(np.linalg.svd(system.matrix(s), compute_uv=False)[-1]) / (abs(s) + max(system.norm_sum, 1e-300))


# ------------------------------------------------------------------------------ delay intervals
@dataclass(frozen=True, eq=False)
class DelayStabilityMap:
    """Every stable delay interval of ẋ = A x + A_d x(t − τ), checked against the spectrum.

    Attributes
    ----------
    margin : DelayMargin
        The exact crossing analysis ([`delay_margin`][mrpctl.design.delay_margin]): its
        ``crossings`` are the stability crossing set (ω, τ₀ + k·2π/ω, direction) and its
        ``stable_intervals`` every stable interval.
    checks : tuple of (float, float, bool)
        (τ, spectral abscissa, certified) at the middle of every interval between consecutive
        stability switches (and past the last one): stable intervals must give a negative abscissa,
        the others a positive one.
    """

    margin: DelayMargin
    checks: tuple[tuple[float, float, bool], ...]

    @property
    def stable_intervals(self) -> tuple[tuple[float, float], ...]:
        """The delay intervals (s) on which the system is exponentially stable."""
        return self.margin.stable_intervals

    @property
    def consistent(self) -> bool:
        """True when every check's abscissa has the sign its interval says and was certified."""
        return all(ok and ((a < 0.0) == self.margin.is_stable(t)) for t, a, ok in self.checks)

    def __str__(self) -> str:
        lines = [str(self.margin)]
        lines.extend(
            f"  check tau = {t:.6g} s: abscissa {a:.6g} 1/s ({'certified' if ok else 'not certified'})"
            for t, a, ok in self.checks
        )
        lines.append("  the spectrum agrees with every interval" if self.consistent else "  SPECTRUM DISAGREES")
        return "\n".join(lines)


def delay_stability_map(A: Any, A_d: Any, *, checks: int = 12) -> DelayStabilityMap:
    """All stable τ-intervals of ẋ = A x + A_d x(t − τ) (not only the first), each checked by the spectrum.

    The intervals and the crossing set come from the exact crossing method
    ([`delay_margin`][mrpctl.design.delay_margin]); this function adds an independent check: the
    certified spectral abscissa ([`characteristic_roots`][mrpctl.design.spectra.characteristic_roots])
    at the middle of the first ``checks`` intervals between consecutive stability switches.

    Parameters
    ----------
    A, A_d : array_like
        (n, n) matrices.
    checks : int, optional
        How many intervals to check (default 12).
    """
    checks = integer("checks", checks, minimum=0)
    margin = delay_margin(A, A_d)
    a, a_d = system_matrices(A, A_d)
    edges = sorted({0.0, *[e for iv in margin.stable_intervals for e in iv if math.isfinite(e)]})
    points = [0.5 * (lo + hi) for lo, hi in itertools.pairwise(edges) if hi > lo]
    last = edges[-1]
    points.append(last * 1.25 + 0.1 if math.isfinite(last) else 1.0)
    out = []
    for t in points[:checks]:
        if t <= 0.0:
            continue
        spectrum = characteristic_roots(a, a_d, t, count=4)
        out.append((float(t), spectrum.abscissa, spectrum.certified))
    return DelayStabilityMap(margin=margin, checks=tuple(out))


# ------------------------------------------------------------------------------ plot
def plot_spectrum(spectrum: Spectrum, *, ax: Any = None, title: str | None = None) -> Any:
    """Draw the roots in the complex plane (Re, Im), the counting line and the imaginary axis.

    Parameters
    ----------
    spectrum : Spectrum
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (a new figure otherwise).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    # deferred: matplotlib (about 0.5 s to import), only when a figure is drawn
    from matplotlib.figure import Figure

    if not isinstance(spectrum, Spectrum):
        raise SpecificationError(f"spectrum must be a Spectrum, got {type(spectrum).__name__}")
    if ax is None:
        fig = Figure(figsize=(6.0, 4.5))
        ax = fig.add_subplot(1, 1, 1)
    else:
        fig = ax.figure
    roots = spectrum.roots
    ax.axvline(0.0, color="0.6", lw=0.8)
    if math.isfinite(spectrum.count_line):
        ax.axvline(
            spectrum.count_line, color="C1", ls="--", lw=0.8, label=f"counted right of Re s = {spectrum.count_line:.3g}"
        )
    ax.plot(roots.real, roots.imag, "x", color="C0", ms=7, label="characteristic roots")
    for s, m in zip(roots, spectrum.multiplicities, strict=True):
        if m > 1:
            ax.annotate(f"×{m}", (s.real, s.imag), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel("Re s (1/s)")
    ax.set_ylabel("Im s (rad/s)")
    ax.set_title(title or f"spectral abscissa {spectrum.abscissa:.4g} 1/s")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    return fig
