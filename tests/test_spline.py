"""The cubic-spline basis against independent truth.

Truth comes from algebra (a cubic spline reproduces lines, so does its
linear continuation), from SciPy's natural cubic spline, and from CasADi's
automatic derivatives of the symbolic form. Tolerances: "algebra" means a few
dozen floating-point operations on numbers of order one, so ~1e-12 relative
leaves a margin of about a thousand over the measured ~1e-15.
"""

import doctest

import casadi as ca
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import vehid.identification.models.spline as spline_module
from vehid.identification import InputError, SplineBasis, covering_basis, resample

# Uniform sets exercise the symbolic fast path (one width), uneven ones the
# general selection; p = 3 has no interior comparison at all, p = 9 the most.
NODE_SETS = {
    "uniform3": np.linspace(-1.0, 1.0, 3),
    "uniform5": np.linspace(-1.0, 1.0, 5),
    "uniform9-wide": np.linspace(-7.0, 7.0, 9),
    "uneven4": np.array([-0.3, 0.1, 0.15, 2.0]),
    "uneven7": np.array([-2.0, -1.3, 0.1, 0.4, 2.5, 3.0, 4.1]),
}
ALGEBRA = 1e-12


@pytest.fixture(params=list(NODE_SETS), ids=list(NODE_SETS))
def basis(request):
    return SplineBasis(NODE_SETS[request.param])


def _points(basis, reach=3.0, n=601):
    """Points inside and beyond the nodes, the nodes themselves included."""
    lower, upper = basis.nodes[0], basis.nodes[-1]
    span = upper - lower
    return np.sort(np.r_[np.linspace(lower - reach * span, upper + reach * span, n), basis.nodes])


def _symbolic(basis):
    """Compiled-free CasADi function (x, gamma) -> value, d/dx, d2/dx2, d/dgamma, basis."""
    x = ca.SX.sym("x")
    gamma = ca.SX.sym("gamma", basis.count)
    value = basis.symbolic_value(x, gamma)
    return ca.Function(
        "spline",
        [x, gamma],
        [value, ca.jacobian(value, x), ca.hessian(value, x)[0], ca.jacobian(value, gamma), basis.symbolic(x)],
    )


def _evaluate_symbolic(basis, x, gamma):
    outputs = _symbolic(basis).map(x.size)(x, np.asarray(gamma, dtype=float))
    value, slope, curvature, d_gamma, phi = (np.array(out) for out in outputs)
    # map stacks each call's (1, p) gamma-Jacobian side by side.
    return value.ravel(), slope.ravel(), curvature.ravel(), d_gamma.reshape(x.size, -1), phi.T


# ------------------------------------------------------------------ algebra
def test_reproduces_constants_and_lines_inside_and_beyond(basis):
    x = _points(basis)
    for offset, slope in [(2.5, 0.0), (-0.7, 1.3), (0.0, -4.0)]:
        gamma = offset + slope * basis.nodes
        expected = offset + slope * x
        scale = np.abs(expected).max()
        np.testing.assert_allclose(basis.evaluate(x) @ gamma, expected, rtol=0, atol=ALGEBRA * scale)
        value, *_ = _evaluate_symbolic(basis, x, gamma)
        np.testing.assert_allclose(value, expected, rtol=0, atol=ALGEBRA * scale)


def test_partition_of_unity(basis):
    phi = basis.evaluate(_points(basis))
    np.testing.assert_allclose(phi.sum(axis=1), 1.0, rtol=0, atol=ALGEBRA)


def test_interpolates_unit_vectors_at_the_nodes(basis):
    # phi_i(node_j) = delta_ij; at a node tau is 0 or 1, so only rounding of
    # the weights (~1e-16) remains.
    np.testing.assert_allclose(basis.evaluate(basis.nodes), np.eye(basis.count), rtol=0, atol=1e-14)
    *_, phi = _evaluate_symbolic(basis, basis.nodes, np.zeros(basis.count))
    np.testing.assert_allclose(phi, np.eye(basis.count), rtol=0, atol=1e-14)


@pytest.mark.parametrize("count", range(3, 10))
@pytest.mark.parametrize("uneven", [False, True], ids=["uniform", "uneven"])
def test_equals_scipy_natural_spline_inside(count, uneven):
    rng = np.random.default_rng(100 + count)
    if uneven:
        nodes = np.sort(rng.uniform(-3.0, 5.0, count))
    else:
        nodes = np.linspace(-3.0, 5.0, count)
    basis = SplineBasis(nodes)
    gamma = rng.normal(size=count)
    truth = CubicSpline(nodes, gamma, bc_type="natural")
    x = np.r_[np.linspace(nodes[0], nodes[-1], 997), nodes]
    value, slope, curvature, *_ = _evaluate_symbolic(basis, x, gamma)
    np.testing.assert_allclose(basis.evaluate(x) @ gamma, truth(x), rtol=0, atol=ALGEBRA)
    np.testing.assert_allclose(value, truth(x), rtol=0, atol=ALGEBRA)
    # Derivatives divide by the node spacing once or twice; scale the bound by
    # the derivative's size (measured error ~1e-15 relative).
    for order, ours in [(1, slope), (2, curvature)]:
        reference = truth(x, order)
        np.testing.assert_allclose(ours, reference, rtol=0, atol=ALGEBRA * np.abs(reference).max())


def test_continuous_in_value_slope_and_curvature_at_interior_nodes(basis):
    # One-sided limits by exact CasADi derivatives a distance delta either side
    # of each node. A C2 spline moves its slope by at most 2 delta max|s''| and
    # its curvature by 2 delta max|s'''| over that gap, i.e. ~1e-9 relative;
    # 1e-7 also covers rounding. A jump that a C1-only spline would have in its
    # curvature is of order max|s''| and fails; the third derivative, which
    # does jump, shows that this test resolves jumps.
    rng = np.random.default_rng(7)
    gamma = rng.normal(size=basis.count)
    interior = basis.nodes[1:-1]
    delta = 1e-9 * np.diff(basis.nodes).min()
    left = _evaluate_symbolic(basis, interior - delta, gamma)
    right = _evaluate_symbolic(basis, interior + delta, gamma)
    dense = _evaluate_symbolic(basis, _points(basis, reach=0.0), gamma)
    for index in range(3):  # value, slope, curvature
        scale = np.abs(dense[index]).max()
        np.testing.assert_allclose(left[index], right[index], rtol=0, atol=1e-7 * scale)
    x = ca.SX.sym("x")
    third = ca.Function("third", [x], [ca.jacobian(ca.hessian(basis.symbolic_value(x, gamma), x)[0], x)])
    jumps = np.abs(np.array(third(interior + delta) - third(interior - delta))).ravel()
    assert jumps.max() > 1e-3 * np.abs(dense[2]).max()


def test_linear_beyond_the_end_nodes(basis):
    gamma = np.random.default_rng(11).normal(size=basis.count)
    truth = CubicSpline(basis.nodes, gamma, bc_type="natural")
    span = basis.nodes[-1] - basis.nodes[0]
    for end, direction in [(basis.nodes[0], -1.0), (basis.nodes[-1], 1.0)]:
        x = end + direction * span * np.array([1e-6, 0.3, 1.0, 10.0])
        value, slope, curvature, *_ = _evaluate_symbolic(basis, x, gamma)
        # Beyond the ends the curvature weights are constants: zero exactly.
        np.testing.assert_array_equal(curvature, 0.0)
        end_slope = truth(end, 1)
        line = truth(end) + end_slope * (x - end)
        scale = np.abs(line).max()
        np.testing.assert_allclose(slope, end_slope, rtol=0, atol=ALGEBRA * max(abs(end_slope), 1.0))
        np.testing.assert_allclose(value, line, rtol=0, atol=ALGEBRA * scale)
        np.testing.assert_allclose(basis.evaluate(x) @ gamma, line, rtol=0, atol=ALGEBRA * scale)


# ------------------------------------------------------ NumPy versus CasADi
def test_numpy_and_casadi_agree_everywhere(basis):
    x = _points(basis, reach=50.0, n=2001)
    gamma = np.random.default_rng(3).normal(size=basis.count)
    value, _, _, d_gamma, phi = _evaluate_symbolic(basis, x, gamma)
    reference = basis.evaluate(x)
    scale = np.abs(reference).max()  # grows linearly with the reach
    np.testing.assert_allclose(phi, reference, rtol=0, atol=ALGEBRA * scale)
    # The spline is linear in gamma, so its exact gamma-Jacobian is the basis.
    np.testing.assert_allclose(d_gamma, reference, rtol=0, atol=ALGEBRA * scale)
    np.testing.assert_allclose(value, reference @ gamma, rtol=0, atol=ALGEBRA * scale)


def test_mx_symbol_gives_the_same_basis():
    basis = SplineBasis(NODE_SETS["uneven7"])
    x = ca.MX.sym("x")
    function = ca.Function("phi", [x], [basis.symbolic(x)])
    points = _points(basis, n=101)
    phi = np.array(function.map(points.size)(points)).T
    np.testing.assert_allclose(phi, basis.evaluate(points), rtol=0, atol=ALGEBRA * np.abs(phi).max())


def test_expression_stays_lean():
    # Measured 105 instructions for p = 5 (CasADi 3.8): the interval flags are
    # built once and shared. Selecting four precomputed coefficients per
    # interval took 224 in a trial, so 130 catches that kind of regression.
    basis = SplineBasis.uniform(-1.0, 1.0, 5)
    x = ca.SX.sym("x")
    gamma = ca.SX.sym("gamma", 5)
    assert ca.Function("value", [x, gamma], [basis.symbolic_value(x, gamma)]).n_instructions() <= 130


# ------------------------------------------------------------- resampling
def test_resample_keeps_a_line_exactly():
    old = SplineBasis.uniform(-1.0, 1.0, 5)
    new = SplineBasis(np.array([-2.3, -0.2, 0.5, 0.9, 1.4, 4.0]))
    gamma = 0.4 - 1.7 * old.nodes
    moved = resample(old, gamma, new)
    x = _points(new)
    np.testing.assert_allclose(new.evaluate(x) @ moved, 0.4 - 1.7 * x, rtol=0, atol=ALGEBRA * 10.0)


def test_resample_onto_finer_nodes_with_the_same_ends_is_exact():
    # The old spline is itself the natural spline on any superset of its nodes.
    old = SplineBasis.uniform(-1.0, 1.0, 5)
    new = SplineBasis.uniform(-1.0, 1.0, 9)
    gamma = np.tanh(2.0 * old.nodes)
    x = _points(old)
    np.testing.assert_allclose(
        new.evaluate(x) @ resample(old, gamma, new), old.evaluate(x) @ gamma, rtol=0, atol=ALGEBRA
    )


@pytest.mark.parametrize(
    "lower, upper, count, documented",
    [(-1.5, 1.5, 5, 0.085), (-1.2, 1.2, 5, 0.031), (-1.0, 1.0, 7, 0.0057)],
)
def test_resample_error_on_a_curved_function_is_as_documented(lower, upper, count, documented):
    # The numbers quoted in resample's docstring, to their two printed digits.
    old = SplineBasis.uniform(-1.0, 1.0, 5)
    new = SplineBasis.uniform(lower, upper, count)
    gamma = np.tanh(2.0 * old.nodes)
    x = np.linspace(-1.0, 1.0, 4001)
    change = np.abs(new.evaluate(x) @ resample(old, gamma, new) - old.evaluate(x) @ gamma).max()
    assert change == pytest.approx(documented, rel=0.02)


def test_resample_handles_several_splines_and_rejects_bad_gamma():
    old = SplineBasis.uniform(0.0, 1.0, 4)
    new = SplineBasis.uniform(0.0, 2.0, 6)
    gammas = np.column_stack([old.nodes, np.ones(4)])
    moved = resample(old, gammas, new)
    assert moved.shape == (6, 2)
    np.testing.assert_allclose(moved, np.column_stack([new.nodes, np.ones(6)]), rtol=0, atol=ALGEBRA)
    with pytest.raises(InputError, match=r"shape \(4,\)"):
        resample(old, np.ones(5), new)
    with pytest.raises(InputError, match="non-finite"):
        resample(old, [0.0, np.nan, 0.0, 0.0], new)


# ------------------------------------------------------------ covering range
def test_covering_basis_uses_percentiles_and_ignores_a_spike():
    samples = np.r_[np.linspace(-2.0, 2.0, 10001), 100.0]
    basis = covering_basis(samples, 5)
    lower, upper = np.percentile(samples, [0.5, 99.5])
    assert upper < 2.0  # the spike did not move the last node
    np.testing.assert_allclose(basis.nodes, np.linspace(lower, upper, 5), rtol=0, atol=1e-15)
    full = covering_basis(samples, 3, percentiles=(0.0, 100.0))
    np.testing.assert_array_equal(full.nodes, [-2.0, 49.0, 100.0])


def test_covering_basis_margin_widens_both_ends():
    basis = covering_basis(np.linspace(1.0, 3.0, 11), 5, percentiles=(0.0, 100.0), margin=0.25)
    np.testing.assert_allclose(basis.nodes, np.linspace(0.5, 3.5, 5), rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    "samples, options, message",
    [
        (np.full(100, 3.0), {}, "degenerate"),
        (np.zeros(100), {}, "degenerate"),
        (1e6 + 1e-5 * np.linspace(0.0, 1.0, 100), {}, "degenerate"),  # span 1e-11 of the level
        (np.r_[np.zeros(999), 1.0], {}, "degenerate"),  # moved only beyond the 99.5th percentile
        (np.r_[0.0, np.nan, 1.0], {}, "non-finite"),
        (np.array([1.0]), {}, "at least 2"),
        (np.ones((5, 2)), {}, "1-D"),
        (np.linspace(0, 1, 9), {"percentiles": (50.0, 50.0)}, "percentiles"),
        (np.linspace(0, 1, 9), {"percentiles": (-1.0, 50.0)}, "percentiles"),
        (np.linspace(0, 1, 9), {"margin": -0.1}, "margin"),
        (np.linspace(0, 1, 9), {"margin": np.inf}, "margin"),
    ],
)
def test_covering_basis_refuses_bad_input(samples, options, message):
    with pytest.raises(InputError, match=message):
        covering_basis(samples, 5, **options)


# -------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "nodes, message",
    [
        ([0.0, 1.0], "3 to 9 nodes"),
        (np.arange(10.0), "3 to 9 nodes"),
        ([0.0, 2.0, 1.0], "strictly increasing"),
        ([0.0, 1.0, 1.0, 2.0], "strictly increasing"),
        ([0.0, np.nan, 2.0], "non-finite"),
        ([0.0, 1.0, np.inf], "non-finite"),
        (np.zeros((3, 3)), "1-D"),
    ],
)
def test_basis_refuses_bad_nodes(nodes, message):
    with pytest.raises(InputError, match=message):
        SplineBasis(nodes)


@pytest.mark.parametrize(
    "lower, upper, count, message",
    [
        (1.0, 1.0, 5, "lower < upper"),
        (2.0, 1.0, 5, "lower < upper"),
        (0.0, np.inf, 5, "lower < upper"),
        (0.0, 1.0, 2, "3 to 9 nodes"),
        (0.0, 1.0, 10, "3 to 9 nodes"),
        (0.0, 1.0, 4.5, "integer"),
    ],
)
def test_uniform_refuses_bad_options(lower, upper, count, message):
    with pytest.raises(InputError, match=message):
        SplineBasis.uniform(lower, upper, count)


def test_evaluation_refuses_bad_points_and_ordinates():
    basis = SplineBasis.uniform(0.0, 1.0, 5)
    with pytest.raises(InputError, match="non-finite"):
        basis.evaluate([0.5, np.nan])
    with pytest.raises(InputError, match="1-D"):
        basis.evaluate(np.zeros((2, 2)))
    with pytest.raises(InputError, match="scalar casadi"):
        basis.symbolic(0.5)
    with pytest.raises(InputError, match="scalar casadi"):
        basis.symbolic(ca.SX.sym("x", 2))
    with pytest.raises(InputError, match="5 elements"):
        basis.symbolic_value(ca.SX.sym("x"), ca.SX.sym("gamma", 4))


def test_basis_is_immutable():
    basis = SplineBasis.uniform(0.0, 1.0, 5)
    assert basis.count == 5
    with pytest.raises(AttributeError):
        basis.nodes = np.zeros(5)
    with pytest.raises(ValueError):
        basis.nodes[0] = -1.0  # read-only array


def test_docstring_examples_run():
    failed, attempted = doctest.testmod(spline_module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert attempted >= 2 and failed == 0
