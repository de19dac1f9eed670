"""The sampled region of attraction of the saturated balancing LQR."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import dynax
from dynax.control import balancing_lqr, estimate_region_of_attraction, RegionSampling


def test_region_of_attraction_of_the_balancing_lqr():
    system = dynax.Acrobot()
    controller = balancing_lqr(system)
    levels = jnp.array([0.5, 2.0, 10.0, 1e3, 1e5])
    sampling = RegionSampling(levels=levels, n_directions=16, horizon=3.0, control_rate=50.0)
    roa = eqx.filter_jit(estimate_region_of_attraction)(system, controller, jax.random.PRNGKey(0), sampling=sampling)
    fraction = np.asarray(roa.converged_fraction)
    # Close to upright every sampled state is caught; far away (cost-to-go 1e5) none is.
    assert fraction[0] == 1.0 and fraction[-1] == 0.0
    assert np.all(np.diff(fraction) <= 0)
    # Drake's hand-over threshold (1000) is far outside the region the saturated LQR attracts from
    # arbitrary directions: the swing-up only works because it arrives along a favourable manifold.
    assert 0.5 <= float(roa.rho) < 1e3
    # Weaker actuation shrinks the region.
    weak = eqx.filter_jit(estimate_region_of_attraction)(
        system,
        controller,
        jax.random.PRNGKey(0),
        torque_limit=2.0,
        sampling=sampling,
    )
    assert float(weak.rho) < float(roa.rho)
    assert np.all(np.asarray(weak.converged_fraction) <= fraction)
