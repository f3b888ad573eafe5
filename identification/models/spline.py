"""Cubic-spline basis for the spline-nonlinear IEKF (Best & Bogdanski, section 5, eq. 20-22).

A coefficient of a modal model that varies with the state or input it multiplies is a cubic spline
through ``p`` nodes whose ordinates ``gamma`` are parameters. The spline is linear in ``gamma``, so it
is written with fixed basis functions, ``c(x) = sum_i gamma_i * phi_i(x)``, ``phi_i`` the spline through
the unit vector ``e_i``. It is the natural cubic spline (C2, zero curvature at the end nodes, continued
linearly beyond them: eq. 20's outer regions) rather than the paper's variant split at a central node;
docs/identification_notes.md says why and how :meth:`SplineBasis.symbolic` keeps its graph small.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..choices import SPLINE_MAX_NODES as MAX_NODES
from ..choices import SPLINE_MIN_NODES as MIN_NODES
from ..errors import InputError

__all__ = ["SplineBasis", "resample", "covering_basis"]

# A range narrower than this, relative to its ends' magnitude, leaves the node
# spacing at the level of rounding noise in x: the basis would be meaningless.
_DEGENERATE_SPAN = 1e-9
_SAME_WIDTH = 1e-12  # relative spread of node spacings taken as evenly spaced


@dataclass(frozen=True, eq=False)
class SplineBasis:
    """Natural cubic-spline basis with linear extrapolation, over fixed nodes.

    Parameters
    ----------
    nodes : array_like, shape (p,)
        Node positions, strictly increasing and finite, ``3 <= p <= 9``.
        Evenly spaced nodes (the paper's choice) come from :meth:`uniform`;
        uneven spacing is allowed.

    Raises
    ------
    InputError
        On a wrong number of nodes, non-finite or not strictly increasing nodes.

    Examples
    --------
    >>> basis = SplineBasis.uniform(-1.0, 1.0, count=5)
    >>> basis.evaluate([0.25]).round(4)
    array([[ 0.0201, -0.1205,  0.6071,  0.567 , -0.0737]])
    """

    nodes: np.ndarray
    _width: np.ndarray = field(init=False, repr=False)
    _moments: np.ndarray = field(init=False, repr=False)
    _uniform: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        nodes = np.array(self.nodes, dtype=float)
        if nodes.ndim != 1:
            raise InputError(f"spline nodes must be a 1-D array (p,); got shape {nodes.shape}")
        if not MIN_NODES <= nodes.size <= MAX_NODES:
            raise InputError(
                f"a spline needs {MIN_NODES} to {MAX_NODES} nodes; got {nodes.size}"
            )
        if not np.all(np.isfinite(nodes)):
            raise InputError("spline nodes contain a non-finite value (NaN or inf)")
        width = np.diff(nodes)
        if np.any(width <= 0):
            raise InputError(f"spline nodes must be strictly increasing; got {nodes.tolist()}")
        nodes.setflags(write=False)
        width.setflags(write=False)
        moments = _natural_moments(width)
        moments.setflags(write=False)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "_width", width)
        object.__setattr__(self, "_moments", moments)
        # np.linspace leaves widths a few ulp apart; treating them as one width
        # in the symbolic form moves tau by rounding only and saves two selections.
        object.__setattr__(self, "_uniform", bool(np.ptp(width) <= _SAME_WIDTH * width.mean()))

    @classmethod
    def uniform(cls, lower: float, upper: float, count: int = 5) -> "SplineBasis":
        """Make a basis with ``count`` evenly spaced nodes from ``lower`` to ``upper``.

        Parameters
        ----------
        lower, upper : float
            The end nodes, ``lower < upper``.
        count : int, default 5
            Number of nodes.

        Returns
        -------
        SplineBasis
            The basis.

        Raises
        ------
        InputError
            If ``lower >= upper``, either is not finite, or ``count`` is out of range.
        """
        if not (np.isfinite(lower) and np.isfinite(upper)) or not lower < upper:
            raise InputError(f"a uniform spline needs finite lower < upper; got {lower}, {upper}")
        if int(count) != count:
            raise InputError(f"node count must be an integer; got {count}")
        if not MIN_NODES <= count <= MAX_NODES:
            raise InputError(f"a spline needs {MIN_NODES} to {MAX_NODES} nodes; got {count}")
        return cls(np.linspace(float(lower), float(upper), int(count)))

    @property
    def count(self) -> int:
        """Number of nodes ``p`` (and of basis functions)."""
        return int(self.nodes.size)

    def evaluate(self, x: Any) -> np.ndarray:
        """Evaluate the basis functions ``phi_i(x)`` at many points.

        Parameters
        ----------
        x : array_like, shape (N,) or scalar
            Points, anywhere on the real line (linear beyond the end nodes).

        Returns
        -------
        ndarray, shape (N, p)
            ``evaluate(x) @ gamma`` is the spline with node ordinates ``gamma``.

        Raises
        ------
        InputError
            If ``x`` is not 0-D or 1-D or holds a non-finite value.
        """
        x = np.asarray(x, dtype=float)
        if x.ndim > 1:
            raise InputError(f"x must be a scalar or 1-D (N,); got shape {x.shape}")
        x = np.atleast_1d(x)
        if not np.all(np.isfinite(x)):
            raise InputError("x contains a non-finite value (NaN or inf)")
        # Interval index, clamped so that points beyond the ends use the end intervals.
        k = np.searchsorted(self.nodes[1:-1], x, side="right")
        width = self._width[k]
        tau = (x - self.nodes[k]) / width
        a = np.clip(tau, 0.0, 1.0)
        cubic_left = width**2 / 6.0 * ((1.0 - a) ** 3 - (1.0 - tau))
        cubic_right = width**2 / 6.0 * (a**3 - tau)
        rows = np.arange(x.size)
        phi = cubic_left[:, None] * self._moments[k] + cubic_right[:, None] * self._moments[k + 1]
        phi[rows, k] += 1.0 - tau
        phi[rows, k + 1] += tau
        return phi

    def symbolic(self, x: Any) -> Any:
        """Express the basis functions in CasADi, of a scalar symbol.

        Build this once per variable and reuse it for every spline of that
        variable (``casadi.dot(phi, gamma)``): the interval selection is then
        shared by all of them.

        Parameters
        ----------
        x : casadi.SX or casadi.MX, scalar
            The variable the coefficients vary with.

        Returns
        -------
        casadi.SX or casadi.MX, shape (p, 1)
            ``phi_i(x)``; exact (including Jacobian and Hessian) everywhere.

        Raises
        ------
        InputError
            If ``x`` is not a scalar CasADi expression.
        """
        if not isinstance(x, (ca.SX, ca.MX)) or x.numel() != 1:
            raise InputError(f"x must be a scalar casadi SX or MX; got {type(x).__name__}")
        p = self.count
        # inside[k] is 1 exactly when x lies in interval k (end intervals open
        # outwards), 0 otherwise: products with it select without rounding.
        above = [x >= node for node in self.nodes[1:-1]]
        steps = [1.0, *above, 0.0]
        inside = [steps[k] - steps[k + 1] for k in range(p - 1)]

        def select(values: np.ndarray) -> Any:
            return sum(flag * float(value) for flag, value in zip(inside, values))

        if self._uniform:
            # One width: tau follows from the count of nodes passed, no selection needed.
            width = float(self._width.mean())
            tau = (x - float(self.nodes[0])) / width - sum(above)
        else:
            width = select(self._width)
            tau = (x - select(self.nodes[:-1])) / width
        rest = 1.0 - tau
        # a = clip(tau, 0, 1) by flags, not fmin/fmax: CasADi gives those a
        # half derivative at a tie, which would be wrong slope at the nodes.
        beyond = x > float(self.nodes[-1])
        a = ((x >= float(self.nodes[0])) - beyond) * tau + beyond
        scale = width**2 / 6.0
        cubic_left = scale * ((1.0 - a) ** 3 - rest)
        cubic_right = scale * (a**3 - tau)
        # Weights of the node values g_j and of the interior curvatures M_j.
        linear = [0.0] * p
        curvature = [0.0] * p
        for k in range(p - 1):
            linear[k] += inside[k] * rest
            linear[k + 1] += inside[k] * tau
            curvature[k] += inside[k] * cubic_left
            curvature[k + 1] += inside[k] * cubic_right
        phi = []
        for i in range(p):
            term = linear[i]
            for j in range(1, p - 1):  # end curvatures are zero: natural spline
                term += curvature[j] * float(self._moments[j, i])
            phi.append(term)
        return ca.vertcat(*phi)

    def symbolic_value(self, x: Any, gamma: Any) -> Any:
        """The spline ``sum_i gamma_i phi_i(x)`` as a CasADi expression.

        Parameters
        ----------
        x : casadi.SX or casadi.MX, scalar
            The variable the coefficient varies with.
        gamma : casadi.SX, casadi.MX or array_like, p elements
            Node ordinates (usually symbols: parameters of the filter state).

        Returns
        -------
        casadi.SX or casadi.MX, scalar
            The spline's value at ``x``.

        Raises
        ------
        InputError
            If ``gamma`` does not have ``p`` elements.
        """
        if not isinstance(gamma, (ca.SX, ca.MX, ca.DM)):
            gamma = ca.DM(np.asarray(gamma, dtype=float).reshape(-1))
        if gamma.numel() != self.count:
            raise InputError(f"gamma must have {self.count} elements (one per node); got {gamma.numel()}")
        return ca.dot(self.symbolic(x), ca.vec(gamma))


def _natural_moments(width: np.ndarray) -> np.ndarray:
    """Matrix ``(p, p)`` from node values to node curvatures of the natural spline.

    Continuity of slope at interior node j gives (de Boor, ch. IV)
    ``h_j-1 M_j-1 + 2 (h_j-1 + h_j) M_j + h_j M_j+1
    = 6 [(g_j+1 - g_j)/h_j - (g_j - g_j-1)/h_j-1]``; ``M_0 = M_p-1 = 0``.
    """
    p = width.size + 1
    system = np.zeros((p - 2, p - 2))
    right = np.zeros((p - 2, p))
    for row, j in enumerate(range(1, p - 1)):
        before, after = width[j - 1], width[j]
        system[row, row] = 2.0 * (before + after)
        if row > 0:
            system[row, row - 1] = before
        if row < p - 3:
            system[row, row + 1] = after
        right[row, j - 1] = 6.0 / before
        right[row, j] = -6.0 / before - 6.0 / after
        right[row, j + 1] = 6.0 / after
    moments = np.zeros((p, p))
    moments[1:-1] = np.linalg.solve(system, right)
    return moments


def resample(basis: SplineBasis, gamma: Any, new_basis: SplineBasis) -> np.ndarray:
    """Move a spline onto new nodes: new ordinates are the old spline at the new nodes.

    The node redistribution of the paper's section 5. The new spline equals
    the old one at the new nodes, and everywhere when the old one is straight
    or the new nodes contain the old ones and share their ends; otherwise a
    strongly curved coefficient moves by a few percent of its range
    (docs/identification_notes.md), which the following passes absorb.

    Parameters
    ----------
    basis : SplineBasis
        The basis ``gamma`` belongs to.
    gamma : array_like, shape (p,) or (p, m)
        Node ordinates of one spline, or of ``m`` splines sharing the basis.
    new_basis : SplineBasis
        The nodes to move to (any count from 3 to 9).

    Returns
    -------
    ndarray, shape (q,) or (q, m)
        Ordinates on ``new_basis`` (``q`` nodes).

    Raises
    ------
    InputError
        If ``gamma`` does not have ``p`` rows or holds a non-finite value.
    """
    gamma = np.asarray(gamma, dtype=float)
    if gamma.ndim not in (1, 2) or gamma.shape[0] != basis.count:
        raise InputError(
            f"gamma must have shape ({basis.count},) or ({basis.count}, m); got {gamma.shape}"
        )
    if not np.all(np.isfinite(gamma)):
        raise InputError("gamma contains a non-finite value (NaN or inf)")
    return basis.evaluate(new_basis.nodes) @ gamma


def covering_basis(
    samples: Any,
    count: int = 5,
    *,
    percentiles: tuple[float, float] = (0.5, 99.5),
    margin: float = 0.0,
) -> SplineBasis:
    """Evenly spaced basis whose end nodes cover the range a variable reached.

    The end nodes sit at two percentiles of the samples rather than at their
    minimum and maximum, so that a start-up transient of the filter or a single
    spike does not stretch the nodes over a range with almost no data. Samples
    beyond the end nodes are still modelled, on the linear continuation, and
    still inform the outer ordinates. ``percentiles=(0, 100)`` gives the full
    range; ``margin`` widens the range by that fraction of its span at each end.

    Parameters
    ----------
    samples : array_like, shape (N,)
        Values the variable took (a state's or input's time history).
    count : int, default 5
        Number of nodes ``p``, 3 to 9.
    percentiles : (float, float), default (0.5, 99.5)
        Percentiles (0 to 100) of the samples at the first and last node.
    margin : float, default 0.0
        Fraction of the covered span added beyond each end, ``>= 0``.

    Returns
    -------
    SplineBasis
        The basis of ``count`` nodes over the covered range.

    Raises
    ------
    InputError
        On non-finite or too few samples, bad options, or a degenerate range:
        one narrower than ``1e-9`` times the magnitude of its ends (a variable
        that did not move cannot carry a spline).

    Examples
    --------
    >>> covering_basis(np.linspace(-2.0, 2.0, 1001), 5, percentiles=(0, 100)).nodes
    array([-2., -1.,  0.,  1.,  2.])
    """
    samples = np.asarray(samples, dtype=float)
    if samples.ndim != 1 or samples.size < 2:
        raise InputError(f"samples must be 1-D with at least 2 values; got shape {samples.shape}")
    if not np.all(np.isfinite(samples)):
        raise InputError("samples contain a non-finite value (NaN or inf)")
    low_pct, high_pct = (float(value) for value in percentiles)
    if not 0.0 <= low_pct < high_pct <= 100.0:
        raise InputError(f"percentiles must satisfy 0 <= low < high <= 100; got {percentiles}")
    if not (np.isfinite(margin) and margin >= 0.0):
        raise InputError(f"margin must be a finite fraction >= 0; got {margin}")
    lower, upper = np.percentile(samples, [low_pct, high_pct])
    span = upper - lower
    if not span > _DEGENERATE_SPAN * max(abs(lower), abs(upper)):
        raise InputError(
            f"the samples' range {lower:.6g}..{upper:.6g} (percentiles {low_pct:g}..{high_pct:g}) "
            "is degenerate: the variable barely moved, so no spline can be placed over it"
        )
    return SplineBasis.uniform(lower - margin * span, upper + margin * span, count)
