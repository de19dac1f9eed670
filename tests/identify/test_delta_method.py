"""The refinement's standard errors through its consistent parametrisation (the delta method)."""

import numpy as np

from dynax.internal import delta_method_covariance


def test_an_undetermined_unknown_leaves_the_parameters_that_do_not_depend_on_it_their_errors():
    # theta = J phi with phi_2 undetermined (NaN row and column, as the output-error fit reports it):
    # theta_0 does not depend on phi_2 and keeps its variance; theta_1 and theta_2 do, and are undetermined.
    # A plain J C J' gave every parameter NaN (0 * NaN is NaN), which told a user that no parameter of a
    # four-record refinement was determined.
    rng = np.random.default_rng(0)
    jac = np.array([[2.0, 0.5, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 3.0]])
    root = rng.normal(size=(3, 3))
    phi = root @ root.T
    phi[2, :] = phi[:, 2] = np.nan
    out = delta_method_covariance(jac, phi)
    expected = jac[:1, :2] @ phi[:2, :2] @ jac[:1, :2].T
    np.testing.assert_allclose(out[0, 0], expected[0, 0], rtol=1e-12)
    assert np.all(np.isnan(out[1:, :])) and np.all(np.isnan(out[:, 1:]))
    # with every unknown determined it is the plain product
    full = root @ root.T
    np.testing.assert_allclose(delta_method_covariance(jac, full), jac @ full @ jac.T, rtol=1e-12)
