"""Contiguous parts of a record: what an estimate is worth where residuals are coloured and the model approximate.

A covariance from the curvature of a fit (the Gauss-Newton ``(J' W J)^-1``,
a filter's ``P``) assumes white residuals and a model structure that holds
the system. On measured records neither is true: residuals are coloured and
part of them is model error, whose effect on the estimate depends on which
manoeuvres a record happens to hold. What an estimate is worth is then best
measured on the record itself, by how it moves when parts of the record are
left out.

**Blocks.** :func:`block_edges` cuts ``N`` samples into ``K`` contiguous
blocks of near-equal length; :func:`block_plan` chooses ``K``: at most
:data:`DEFAULT_BLOCKS`, each block at least as long as the residuals'
integrated correlation time (:func:`integrated_correlation_time`), and no
plan where fewer than :data:`MIN_BLOCKS` such blocks fit. Blocks longer than
the correlation time keep the dependence inside them, as the block
resampling of dependent data requires (Kuensch 1989).

**Delete-one-block jackknife.** With ``theta_(k)`` the estimate without
block ``k`` (Efron 1982, ch. 3; for blocks, Kuensch 1989),
``cov = (K - 1) / K sum_k (theta_(k) - mean)(theta_(k) - mean)'``
(:func:`jackknife_covariance`). The replicates come from refits
(:func:`refit_replicates`: any estimator, one refit per block) or, for a
least-squares fit, from one Gauss-Newton step per deleted block from the
estimate (:func:`one_step_replicates`), which costs no refit: with the
curvature without the block, the one-step jackknife (Shao and Tu 1995); with
the whole record's, the jackknife linearised, whose covariance is the block
sandwich ``H^-1 S H^-1`` of the blocks' scores, the cluster covariance that
Bester, Conley and Hansen (2011) study for a dependent series cut into a
fixed number of blocks.

**Few blocks.** The jackknife variance of ``K`` blocks carries ``K - 1``
degrees of freedom, so ``theta +/- z std`` would cover less than its level
(Bester, Conley and Hansen 2011 use ``t(K - 1)`` quantiles with ``K`` fixed
blocks of a dependent series). The covariance is scaled by
``(t(K - 1) / z)^2`` at the stated level (:func:`interval_scale`): the
normal interval every consumer builds from a standard deviation is then the
``t`` interval.

**Do parts agree?** :func:`pair_agreement` counts the pairs of parts whose
estimates differ by less than ``z sqrt(s_i^2 + s_j^2)`` (the two-sided test
of equal means at the level: about 95 % of pairs agree where the error bars
are honest and the model holds over the whole record); :func:`homogeneity`
tests all parts at once (Cochran's Q). :func:`segment_consistency` gathers
both for several quantities into a :class:`SegmentConsistency`, which names
the quantities whose parts agree in fewer than :data:`AGREEMENT_SHARE` of
their pairs and whose Q rejects one common value at :data:`HOMOGENEITY_LEVEL`.

References: B. Efron, *The Jackknife, the Bootstrap and Other Resampling
Plans*, SIAM 1982. H. R. Kuensch, "The jackknife and the bootstrap for
general stationary observations", Ann. Statist. 17(3), 1217-1241, 1989.
J. Shao and D. Tu, *The Jackknife and Bootstrap*, Springer 1995.
C. A. Bester, T. G. Conley and C. B. Hansen, "Inference with dependent data
using cluster covariance estimators", J. Econometrics 165(2), 137-151, 2011.
W. G. Cochran, "The combination of estimates from different experiments",
Biometrics 10(1), 101-129, 1954.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..errors import InputError
from ..frozen import freeze
from ..models.delta_method import normal_quantile

__all__ = [
    "DEFAULT_BLOCKS",
    "MIN_BLOCKS",
    "AGREEMENT_SHARE",
    "HOMOGENEITY_LEVEL",
    "homogeneity",
    "integrated_correlation_time",
    "block_edges",
    "block_plan",
    "gram_matrix",
    "interval_scale",
    "jackknife_covariance",
    "REPLICATE_FORMS",
    "one_step_replicates",
    "refit_replicates",
    "UncertaintyMethod",
    "BlockJackknife",
    "block_jackknife",
    "formal_method",
    "Agreement",
    "pair_agreement",
    "QuantityConsistency",
    "SegmentConsistency",
    "segment_consistency",
]

#: Blocks of the jackknife where the record is long enough. Measured on two real logs of a race car
#: (benchmarks/segment_consistency.py): with 8, every quantity's disjoint parts agreed in at least 80 % of
#: their pairs with bars at most twice the parts' spread; with 10, the understeer gradients of 20 s parts
#: agreed in 5 (one-step) or 3 (linearised) of 6 pairs; with 6, the scheduled family's bars on 110 s parts
#: were 2.05 times their spread. Few fixed blocks also keep dependence at the scale of a manoeuvre inside
#: them (Bester, Conley and Hansen 2011).
DEFAULT_BLOCKS = 8
#: Fewest blocks of a jackknife: with fewer, its variance has under three degrees of freedom and the
#: t interval widens by more than 1.6 times (t(3) = 3.18 against z = 1.96).
MIN_BLOCKS = 4
#: Share of the pairs of parts that must agree within their intervals for a quantity to hold over the record.
AGREEMENT_SHARE = 0.8
#: Level of the joint test that the parts share one value (Cochran's Q): a quantity is named as not
#: holding only where its pairs agree in fewer than :data:`AGREEMENT_SHARE` and this test rejects too. With
#: three parts one pair in three disagrees by chance in some 14 % of honest cases; the joint test keeps a
#: model that holds from being named in more than about 1 % per quantity.
HOMOGENEITY_LEVEL = 0.01


def integrated_correlation_time(residuals: Any) -> np.ndarray:
    """Each column's integrated autocorrelation time ``1 + 2 sum rho_k`` (in samples), at least one.

    ``N`` samples of a series with that time carry the information of about ``N / tau`` independent
    ones. The sum runs over the lags up to the first whose autocorrelation is no longer positive (the
    initial positive sequence: beyond it the estimates are noise around zero) and at most a tenth of
    the record, so that a slow drift does not count the whole record as one sample.
    """
    residuals = np.asarray(residuals, dtype=float)
    residuals = residuals.reshape(-1, 1) if residuals.ndim == 1 else residuals
    n = residuals.shape[0]
    times = np.ones(residuals.shape[1])
    if n < 20:
        return times
    centred = residuals - residuals.mean(axis=0)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spectrum = np.fft.rfft(centred, size, axis=0)
    autocovariance = np.fft.irfft(np.abs(spectrum) ** 2, size, axis=0)[: n // 10 + 1]
    for j in range(residuals.shape[1]):
        if autocovariance[0, j] <= 0:
            continue
        rho = autocovariance[1:, j] / autocovariance[0, j]
        stop = int(np.argmax(rho <= 0)) if np.any(rho <= 0) else rho.size
        times[j] = max(1.0, 1.0 + 2.0 * float(np.sum(rho[:stop])))
    return times


def block_edges(n_samples: int, count: int) -> np.ndarray:
    """Edges ``(count + 1,)`` of ``count`` contiguous blocks of ``n_samples``, lengths differing by at most one."""
    n_samples, count = int(n_samples), int(count)
    if count < 1 or n_samples < count:
        raise InputError(f"{n_samples} samples cannot be cut into {count} blocks")
    return (np.arange(count + 1) * n_samples) // count


def block_plan(n_samples: int, *, min_length: float, most: int = DEFAULT_BLOCKS,
               fewest: int = MIN_BLOCKS) -> np.ndarray | None:
    """The jackknife's block edges: as many blocks as fit, up to ``most``, each at least ``min_length`` samples.

    None where fewer than ``fewest`` blocks of that length fit (the record is too short to measure
    the spread of its estimate on itself).
    """
    if most < fewest or fewest < 2:
        raise InputError(f"a block plan needs 2 <= fewest <= most; got fewest {fewest}, most {most}")
    length = max(float(min_length), 1.0)
    count = min(int(most), int(n_samples // length))
    return block_edges(n_samples, count) if count >= fewest else None


def interval_scale(degrees_of_freedom: int, level: float = 0.95) -> float:
    """``t(dof) / z`` at a two-sided ``level``: the factor that turns ``z std`` into the ``t`` interval."""
    if not 0 < level < 1:
        raise InputError(f"a confidence level lies between 0 and 1; got {level!r}")
    if degrees_of_freedom < 1:
        raise InputError(f"a t quantile needs at least one degree of freedom; got {degrees_of_freedom}")
    from scipy.special import ndtri, stdtrit  # scipy.stats's quantiles without its import time

    quantile = 0.5 + level / 2
    return float(stdtrit(degrees_of_freedom, quantile) / ndtri(quantile))


def jackknife_covariance(replicates: Any) -> np.ndarray:
    """``(K - 1) / K sum_k (r_k - mean)(r_k - mean)'`` of ``K`` delete-one replicates (K, n).

    For a sample mean (``r_k`` the mean without observation ``k``) it is ``s^2 / K``, the textbook
    variance of the mean (Efron 1982, eq. 3.2).
    """
    replicates = np.asarray(replicates, dtype=float)
    if replicates.ndim == 1:
        replicates = replicates[:, None]
    count = replicates.shape[0]
    if count < 2:
        raise InputError("a jackknife needs at least two replicates")
    if not np.all(np.isfinite(replicates)):
        raise InputError("a jackknife replicate is not finite")
    deviations = replicates - replicates.mean(axis=0)
    covariance = (count - 1) / count * deviations.T @ deviations
    return 0.5 * (covariance + covariance.T)


def gram_matrix(columns: np.ndarray, rows_per_block: int = 1024) -> np.ndarray:
    """``columns' columns`` summed over blocks of rows.

    A block of about a thousand rows is a product BLAS runs on one thread:
    on a shared two-core machine the threaded product of the whole long
    array took 2-4 times as long (0.8 against 1.6-4 ms at 50,000 x 17).
    """
    gram = np.zeros((columns.shape[1], columns.shape[1]))
    for start in range(0, columns.shape[0], rows_per_block):
        block = columns[start:start + rows_per_block]
        gram += block.T @ block
    return gram


def _triangle(rows: np.ndarray) -> np.ndarray:
    """The R of a QR factorisation of ``rows`` (at most as many rows as columns): ``R' R = rows' rows``."""
    if rows.shape[0] == 0:
        return np.zeros((0, rows.shape[1]))
    return np.linalg.qr(rows, mode="r")


#: The two forms of Gauss-Newton replicates (:func:`one_step_replicates`).
REPLICATE_FORMS = ("linearised", "one-step")


def one_step_replicates(estimate: Any, block_jacobians: Sequence[np.ndarray], block_gradients: Any, *,
                        form: str = "linearised") -> np.ndarray:
    """One Gauss-Newton step per deleted block from ``estimate`` on the other blocks' errors.

    Parameters
    ----------
    estimate : array_like (n,)
        The estimate on the whole record.
    block_jacobians : sequence of ndarray (rows_k, n)
        Each block's weighted error Jacobian ``W^(1/2) J_k``: its Gram matrix is the block's
        Gauss-Newton curvature ``H_k = J_k' W J_k``.
    block_gradients : array_like (K, n)
        Each block's gradient ``g_k = J_k' W e_k`` of half the weighted sum of squares of its errors ``e_k``.
    form : {"linearised", "one-step"}
        The curvature of the step: ``"linearised"`` the whole record's, ``(K - 1) / K H`` (the
        jackknife to first order: its covariance is the block sandwich
        ``K / (K - 1) H^-1 sum_k (g_k - mean)(g_k - mean)' H^-1``, the cluster covariance of Bester,
        Conley and Hansen 2011 with contiguous blocks as clusters); ``"one-step"`` the curvature
        without the block, ``H_(k) = sum_{j != k} H_j`` (exact on a linear fit).

    Returns
    -------
    ndarray (K, n)
        The replicates ``theta - C_k^-1 (G - g_k)``, ``C_k`` the form's curvature and
        ``G = sum_j g_j``. Where the estimate is not the whole record's minimiser (a filter's
        estimate), ``G`` is not zero and the replicates share its step, which the jackknife's
        centring removes.

    Notes
    -----
    Columns are equilibrated. Where the curvatures have condition numbers below 1e10, their normal
    equations are solved (their rounding, condition times eps, stays below 1e-6 relative);
    otherwise they are factorised from the blocks' triangular factors, so the condition number is
    not squared. The one-step form fails where a parameter is determined by block ``k`` alone
    (``H_(k)`` singular: no replicate without that block exists), InputError naming it; with many
    parameters that each few blocks determine (the knots of a scheduled model), its steps grow
    without bound near that limit, which the linearised form does not (benchmarks/segment_consistency.py).
    """
    if form not in REPLICATE_FORMS:
        raise InputError(f"unknown replicate form {form!r}; use one of {', '.join(REPLICATE_FORMS)}")
    estimate = np.asarray(estimate, dtype=float).ravel()
    gradients = np.asarray(block_gradients, dtype=float)
    count, size = len(block_jacobians), estimate.size
    if count < 2 or gradients.shape != (count, size):
        raise InputError(f"one-step replicates need at least two blocks with gradients ({count}, {size}); "
                         f"got {gradients.shape}")
    scale = np.sqrt(sum(np.sum(np.square(block), axis=0) for block in block_jacobians))
    scale = np.where(scale > 0, scale, 1.0)
    scaled_blocks = [np.asarray(block, dtype=float) / scale for block in block_jacobians]
    scaled = gradients / scale
    steps = scaled.sum(axis=0)[None, :] - scaled
    curvatures = [gram_matrix(block) for block in scaled_blocks]
    whole = sum(curvatures)
    if form == "linearised":
        curvature = np.broadcast_to((count - 1) / count * whole, (count, size, size))
    else:
        curvature = whole[None, :, :] - np.array(curvatures)
    values = np.linalg.eigvalsh(curvature)
    if np.all(values[:, 0] > 1e-10 * values[:, -1]):
        return estimate - np.linalg.solve(curvature, steps[:, :, None])[:, :, 0] / scale
    factors = [_triangle(block) for block in scaled_blocks]
    replicates = np.empty((count, size))
    for k in range(count):
        kept = factors if form == "linearised" else [factor for j, factor in enumerate(factors) if j != k]
        upper = _triangle(np.vstack(kept))
        diagonal = np.zeros(size)
        diagonal[: upper.shape[0]] = np.abs(np.diag(upper))
        if np.min(diagonal) <= 1e-10 * max(float(np.max(diagonal)), 1e-300):
            raise InputError(f"without block {k + 1} of {count} the record no longer determines parameter "
                             f"{int(np.argmin(diagonal)) + 1}: no jackknife replicate leaves that block out"
                             if form == "one-step" else
                             f"the record does not determine parameter {int(np.argmin(diagonal)) + 1}")
        # C_k = R'R from the blocks' triangular factors: the condition number is not squared
        shrink = count / (count - 1) if form == "linearised" else 1.0
        replicates[k] = estimate - shrink * np.linalg.solve(upper, np.linalg.solve(upper.T, steps[k])) / scale
    return replicates


def refit_replicates(refit: Callable[[tuple[slice, ...]], Any], edges: Any) -> tuple[np.ndarray, tuple[int, ...]]:
    """The estimate refitted without each block: ``refit(kept)`` with ``kept`` the slices of the other samples.

    ``kept`` holds one slice before the deleted block and one after it (either may be empty and is
    then left out), so an estimator of several records can take them as two. ``refit`` returns the
    parameter vector, or None where it fails (diverged, too little data): such a block is counted in
    the second value, the blocks whose refits failed. A jackknife of fewer replicates than blocks
    understates the spread where the failures are the influential blocks: the caller decides.
    """
    edges = np.asarray(edges, dtype=int)
    n_samples = int(edges[-1])
    replicates, failed = [], []
    for k in range(edges.size - 1):
        kept = tuple(part for part in (slice(0, int(edges[k])), slice(int(edges[k + 1]), n_samples))
                     if part.stop > part.start)
        theta = refit(kept)
        if theta is None or not np.all(np.isfinite(np.asarray(theta, dtype=float))):
            failed.append(k)
        else:
            replicates.append(np.asarray(theta, dtype=float).ravel())
    return np.array(replicates), tuple(failed)


@dataclass(frozen=True)
class UncertaintyMethod:
    """How a covariance was obtained (JSON ``uncertainty_method``).

    Attributes
    ----------
    name : str
        ``"block-jackknife"``, or ``"formal"`` where the record was too short for it (``reason``
        says why; the covariance is then the fit's curvature under white residuals).
    form : str or None
        ``"linearised"`` or ``"one-step"`` (one Gauss-Newton step per deleted block, with the whole
        record's curvature or the curvature without the block) or ``"refits"``.
    blocks : int or None
        Number of contiguous blocks ``K``.
    block_seconds : (float, float) or None
        Shortest and longest block, in seconds where the sample interval is known, else samples
        (``block_samples``).
    degrees_of_freedom : int or None
        ``K - 1``.
    std_scale : float
        The factor ``t(K - 1) / z`` already applied to every standard deviation.
    level : float
        The level at which that factor makes the normal interval the ``t`` interval.
    correlation_time_s : float or None
        The residuals' longest integrated correlation time (seconds), which the blocks exceed.
    note : str or None
        What else entered the covariance (a filter's fluctuation along a pass).
    reason : str or None
        Why a formal covariance stands where a jackknife was asked.
    """

    name: str
    form: str | None = None
    blocks: int | None = None
    block_samples: tuple[int, int] | None = None
    block_seconds: tuple[float, float] | None = None
    degrees_of_freedom: int | None = None
    std_scale: float = 1.0
    level: float = 0.95
    correlation_time_s: float | None = None
    note: str | None = None
    reason: str | None = None

    def describe(self) -> str:
        """One sentence for a text summary."""
        if self.name != "block-jackknife":
            return f"{self.name} covariance" + (f" ({self.reason})" if self.reason else "")
        span = self.block_seconds if self.block_seconds is not None else self.block_samples
        unit = "s" if self.block_seconds is not None else "samples"
        length = f"{span[0]:.3g}" if span[0] == span[1] else f"{span[0]:.3g}-{span[1]:.3g}"
        text = (f"delete-one-block jackknife ({self.form}) over {self.blocks} contiguous blocks of {length} {unit}, "
                f"std times t({self.degrees_of_freedom})/z = {self.std_scale:.3f}")
        return text + (f"; {self.note}" if self.note else "")

    def with_note(self, note: str) -> "UncertaintyMethod":
        from dataclasses import replace

        return replace(self, note=note)

    def as_dict(self) -> dict[str, Any]:
        """The JSON entry: every field, and ``description`` (:meth:`describe`)."""
        return {"name": self.name, "form": self.form, "blocks": self.blocks,
                "block_samples": None if self.block_samples is None else list(self.block_samples),
                "block_seconds": None if self.block_seconds is None else list(self.block_seconds),
                "degrees_of_freedom": self.degrees_of_freedom, "std_scale": self.std_scale, "level": self.level,
                "correlation_time_s": self.correlation_time_s, "note": self.note, "reason": self.reason,
                "description": self.describe()}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "UncertaintyMethod":
        """Inverse of :meth:`as_dict` (``description`` is derived, not read)."""
        fields = {key: values.get(key) for key in ("name", "form", "blocks", "degrees_of_freedom",
                                                   "correlation_time_s", "note", "reason")}
        for key in ("block_samples", "block_seconds"):
            if values.get(key) is not None:
                fields[key] = tuple(values[key])
        return cls(**fields, std_scale=float(values.get("std_scale", 1.0)), level=float(values.get("level", 0.95)))


def formal_method(reason: str) -> UncertaintyMethod:
    """The method of a covariance from the fit's curvature alone, and why no jackknife measured it."""
    return UncertaintyMethod(name="formal", reason=reason)


@dataclass(frozen=True, eq=False)
class BlockJackknife:
    """A delete-one-block jackknife: the covariance (scaled for few blocks), its replicates, blocks and method."""

    covariance: np.ndarray
    replicates: np.ndarray
    edges: np.ndarray
    method: UncertaintyMethod

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


def block_jackknife(replicates: Any, edges: Any, *, form: str, level: float = 0.95, dt: float | None = None,
                    correlation_time: float | None = None) -> BlockJackknife:
    """The jackknife covariance of ``replicates`` over the blocks ``edges``, scaled by ``(t(K - 1) / z)^2``.

    ``dt`` (s) states the blocks and the correlation time (samples) in seconds in the method.
    """
    replicates = np.asarray(replicates, dtype=float)
    edges = np.asarray(edges, dtype=int)
    count = replicates.shape[0]
    scale = interval_scale(count - 1, level)
    covariance = jackknife_covariance(replicates) * scale**2
    lengths = np.diff(edges)
    samples = (int(lengths.min()), int(lengths.max()))
    method = UncertaintyMethod(
        name="block-jackknife", form=form, blocks=int(lengths.size), block_samples=samples,
        block_seconds=None if dt is None else (round(samples[0] * dt, 9), round(samples[1] * dt, 9)),
        degrees_of_freedom=count - 1, std_scale=scale, level=level,
        correlation_time_s=None if correlation_time is None or dt is None else round(float(correlation_time) * dt, 9))
    return BlockJackknife(covariance, replicates, edges, method)


@dataclass(frozen=True)
class Agreement:
    """How many pairs of parts agree within their intervals: ``|x_i - x_j| <= z sqrt(s_i^2 + s_j^2)``."""

    pairs: int
    agreeing: int
    disagreeing: tuple[tuple[int, int], ...]
    level: float

    @property
    def share(self) -> float:
        return self.agreeing / self.pairs if self.pairs else 1.0


def pair_agreement(values: Any, stds: Any, *, level: float = 0.95) -> Agreement:
    """Pairs of estimates that agree within their ``level`` intervals (module docstring).

    A pair with a non-finite value or std (a part that could not be identified) is not judged: it
    counts neither way.
    """
    values = np.asarray(values, dtype=float).ravel()
    stds = np.asarray(stds, dtype=float).ravel()
    if values.shape != stds.shape:
        raise InputError(f"{values.size} estimates need as many standard deviations; got {stds.size}")
    z = normal_quantile(level)
    known = np.isfinite(values) & np.isfinite(stds)
    pairs = [(i, j) for i, j in itertools.combinations(range(values.size), 2) if known[i] and known[j]]
    disagreeing = tuple((i, j) for i, j in pairs if abs(values[i] - values[j]) > z * np.hypot(stds[i], stds[j]))
    return Agreement(len(pairs), len(pairs) - len(disagreeing), disagreeing, level)


def homogeneity(values: Any, stds: Any) -> tuple[float, int, float]:
    """Cochran's Q of estimates with standard deviations: ``(Q, dof, p)`` that they share one value.

    ``Q = sum_i (x_i - m)^2 / s_i^2`` about the inverse-variance weighted mean ``m``; where they share
    one value and their standard deviations hold, ``Q`` is chi-square with ``P - 1`` degrees of freedom
    (Cochran 1954). Parts without a finite estimate or std are left out; fewer than two: ``(0, 0, 1)``.
    """
    from scipy.special import chdtrc  # the chi-square survival function, without scipy.stats's import time

    values = np.asarray(values, dtype=float).ravel()
    stds = np.asarray(stds, dtype=float).ravel()
    known = np.isfinite(values) & np.isfinite(stds) & (stds > 0)
    if np.count_nonzero(known) < 2:
        return 0.0, 0, 1.0
    weights = 1.0 / stds[known] ** 2
    mean = float(np.sum(weights * values[known]) / np.sum(weights))
    statistic = float(np.sum(weights * (values[known] - mean) ** 2))
    dof = int(np.count_nonzero(known)) - 1
    return statistic, dof, float(chdtrc(dof, statistic))


@dataclass(frozen=True, eq=False)
class QuantityConsistency:
    """One quantity's estimates on each part, their standard deviations, how many pairs agree and the
    joint test's p-value (:func:`homogeneity`).

    ``unit`` is that of ``values``; ``label``, ``display_unit`` and ``display_factor`` say how a
    warning names and shows them.
    """

    name: str
    values: np.ndarray
    stds: np.ndarray
    unit: str
    agreement: Agreement
    homogeneity_p: float = 1.0
    label: str | None = None
    display_unit: str | None = None
    display_factor: float = 1.0

    def __post_init__(self) -> None:
        for name in ("values", "stds"):  # the parts' estimates stay as measured
            object.__setattr__(self, name, freeze(np.asarray(getattr(self, name), dtype=float)))

    def holds(self, share: float, level: float = HOMOGENEITY_LEVEL) -> bool:
        """Whether the parts agree: in at least ``share`` of their pairs, or by the joint test at ``level``."""
        return self.agreement.share >= share or self.homogeneity_p >= level

    def span_text(self) -> str:
        """``33.5-41.6 kN/rad``: the parts' range in the display unit."""
        finite = self.values[np.isfinite(self.values)] * self.display_factor
        low, high = (float(finite.min()), float(finite.max())) if finite.size else (np.nan, np.nan)
        unit = self.display_unit if self.display_unit is not None else self.unit
        return f"{low:.3g}-{high:.3g}{(' ' + unit) if unit and unit != '-' else ''}"


@dataclass(frozen=True, eq=False)
class SegmentConsistency:
    """Estimates of several quantities on disjoint parts of one record, and whether they agree.

    Attributes
    ----------
    spans : tuple of (float, float)
        Each part's start and end, in the caller's time (seconds of the record's own time base).
    quantities : tuple of QuantityConsistency
    level : float
        Level of the intervals.
    min_share : float
        Share of agreeing pairs a quantity needs to hold over the record (:data:`AGREEMENT_SHARE`).
    method : UncertaintyMethod or None
        How each part's standard deviations were obtained.
    """

    spans: tuple[tuple[float, float], ...]
    quantities: tuple[QuantityConsistency, ...]
    level: float = 0.95
    min_share: float = AGREEMENT_SHARE
    method: UncertaintyMethod | None = None

    @property
    def failing(self) -> tuple[QuantityConsistency, ...]:
        """The quantities whose parts agree in fewer than :attr:`min_share` of their pairs and fail the joint
        test at :data:`HOMOGENEITY_LEVEL`."""
        return tuple(q for q in self.quantities if not q.holds(self.min_share))

    @property
    def consistent(self) -> bool:
        return not self.failing

    def warning(self, subject: str = "the model") -> str | None:
        """One line naming every quantity whose parts disagree, or None where all hold."""
        failing = self.failing
        if not failing:
            return None
        named = "; ".join(f"{q.label or q.name} {q.span_text()} ({q.agreement.agreeing} of {q.agreement.pairs} "
                          "pairs agree)" for q in failing)
        return (f"{subject} does not hold over the whole log: {named} across {len(self.spans)} parts, beyond their "
                f"{100 * self.level:g} % intervals (JSON segments; identify on a part with --segment, or a model "
                "that follows what changes between them)")

    def text_lines(self) -> list[str]:
        """One line per quantity: each part's estimate +/- 2 std in the display unit, and the pairs agreeing."""
        starts = ", ".join(f"{start:g}-{end:g}" for start, end in self.spans)
        lines = [f"parts of the log ({starts}): estimate +/- 2 sigma each; pairs agreeing within "
                 f"{100 * self.level:g} %"]
        for q in self.quantities:
            cells = " | ".join("-" if not np.isfinite(value) else
                               f"{value * q.display_factor:.4g} +/- {2 * std * q.display_factor:.2g}"
                               for value, std in zip(q.values, q.stds))
            unit = q.display_unit if q.display_unit is not None else q.unit
            lines.append(f"  {q.label or q.name:<27} {cells} {unit}  ({q.agreement.agreeing} of {q.agreement.pairs})")
        return lines

    def as_dict(self) -> dict[str, Any]:
        """The JSON entry ``segments``: each part's span and estimates, each quantity's agreement."""

        def number(value: float) -> float | None:
            return float(value) if np.isfinite(value) else None

        parts = [{"start_s": float(start), "end_s": float(end),
                  "estimates": {q.name: {"value": number(q.values[i]), "std": number(q.stds[i]), "unit": q.unit}
                                for q in self.quantities}}
                 for i, (start, end) in enumerate(self.spans)]
        agreement = {q.name: {"pairs": q.agreement.pairs, "agreeing": q.agreement.agreeing,
                              "share": q.agreement.share, "homogeneity_p": q.homogeneity_p,
                              "holds": q.holds(self.min_share),
                              "disagreeing_pairs": [[i + 1, j + 1] for i, j in q.agreement.disagreeing]}
                     for q in self.quantities}
        return {"parts": parts, "agreement": agreement, "consistent": self.consistent, "level": self.level,
                "min_share": self.min_share,
                "rule": (f"a pair of parts agrees where its estimates differ by at most z sqrt(s1^2 + s2^2) at "
                         f"{100 * self.level:g} %; a quantity holds where at least {100 * self.min_share:g} % of its "
                         f"pairs agree, or where Cochran's Q does not reject one common value at "
                         f"{100 * HOMOGENEITY_LEVEL:g} %"),
                "uncertainty_method": None if self.method is None else self.method.as_dict()}


def segment_consistency(spans: Sequence[tuple[float, float]], estimates: Mapping[str, Mapping[str, Any]], *,
                        level: float = 0.95, min_share: float = AGREEMENT_SHARE,
                        method: UncertaintyMethod | None = None) -> SegmentConsistency:
    """Whether estimates from disjoint parts agree, quantity by quantity.

    Parameters
    ----------
    spans : sequence of (float, float)
        Each part's start and end time.
    estimates : mapping
        Quantity name -> ``{"values": (P,), "stds": (P,), "unit": str}`` and optionally
        ``label``, ``display_unit`` and ``display_factor`` (for the warning's text).
    level, min_share : float
        Level of the intervals; share of pairs that must agree.
    method : UncertaintyMethod, optional
        How the parts' standard deviations were obtained (kept with the result).
    """
    if len(spans) < 2:
        raise InputError("a consistency check needs at least two parts")
    if not 0 < min_share <= 1:
        raise InputError(f"the share of agreeing pairs lies in (0, 1]; got {min_share!r}")
    quantities = []
    for name, entry in estimates.items():
        values = np.asarray(entry["values"], dtype=float).ravel()
        stds = np.asarray(entry["stds"], dtype=float).ravel()
        if values.size != len(spans):
            raise InputError(f"{name}: {values.size} estimates for {len(spans)} parts")
        quantities.append(QuantityConsistency(
            name=name, values=values, stds=stds, unit=str(entry.get("unit", "-")),
            agreement=pair_agreement(values, stds, level=level), homogeneity_p=homogeneity(values, stds)[2],
            label=entry.get("label"),
            display_unit=entry.get("display_unit"),
            display_factor=float(entry.get("display_factor", 1.0))))
    return SegmentConsistency(tuple((float(a), float(b)) for a, b in spans), tuple(quantities), level, min_share,
                              method)
