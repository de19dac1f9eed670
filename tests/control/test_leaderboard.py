"""The RealAIGym acrobot leaderboard: the scoring by hand on tiny cases, the plant against dynax's Acrobot,
the perturbation draws, the saved from-rest controller (swing-up, round trip) and the CLI's refusals."""

import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import dynax
from dynax import control

POLICY = pathlib.Path(__file__).parents[2] / "experiments" / "results" / "leaderboard" / "acrobot_policy.npz"


def _lab_costs(ts, xs, us):
    """A transcription of the lab's scoring of a simulated episode: `Simulator.simulate` records N + 1
    times and states and N applied torques, `save_trajectory` cuts the columns to the shortest, and
    `leaderboard.py`'s `get_swingup_time(method="height", has_to_stay=True)`, `get_energy`,
    `get_torque_cost`, `get_tau_smoothness` and `get_velocity_cost` read the rows (torques as
    (shoulder, elbow), the shoulder's zero)."""
    n = min(len(ts), len(xs), len(us))
    T, X = np.asarray(ts)[:n], np.asarray(xs)[:n]
    U = np.stack([np.zeros(n), np.asarray(us)[:n]], axis=1)
    up = -0.2 * np.cos(X[:, 0]) - 0.3 * np.cos(X[:, 0] + X[:, 1]) > 0.9 * (0.2 + 0.3)
    time_index = len(T) - 1
    for i in range(len(up) - 2, 0, -1):
        if up[i]:
            time_index = i
        else:
            break
    energy = sum(np.sum(np.abs(np.diff(X[:, j]) * U[:-1, j])) for j in range(2))
    delta_t = np.diff(T)
    torque = np.einsum("ij, i, jk, ik", U[:-1], delta_t, np.eye(2), U[:-1])
    smooth = np.std(np.diff(U[:, 0])) + np.std(np.diff(U[:, 1]))
    velocity = np.einsum("ij, i, jk, ik", X[:-1, 2:], delta_t, np.eye(2), X[:-1, 2:])
    return np.array([T[time_index], energy, torque, smooth, velocity]), T[time_index] < T[-1]


def test_performance_costs_by_hand_on_a_tiny_episode():
    plant = control.LeaderboardPlant.nominal()
    # six states, five torques: the lab scores the first five rows; down, half, up, up, up, (down)
    # -> up from sample 2; sample 4 is not visited by the lab's loop, sample 5 not saved
    q1 = np.array([0.0, 1.5, np.pi, np.pi - 0.1, 0.0, 0.0])
    q2 = np.array([0.0, 0.3, 0.1, 0.0, 0.0, 0.0])
    xs = np.stack([q1, q2, [0.0, 2.0, 1.0, -1.0, 0.5, 7.0], [0.0, -1.0, 3.0, 0.0, 0.0, 7.0]], axis=1)
    us = np.array([1.0, -2.0, 0.5, 0.0, 4.0])
    ts = np.arange(6) * 0.002
    perf = control.performance_costs(control.Rollout(jnp.asarray(ts), jnp.asarray(xs), jnp.asarray(us)), plant)
    expected_costs, success = _lab_costs(ts, xs, us)
    # and by hand: only rows 0-4 count, the last torque only in the smoothness
    assert expected_costs[0] == ts[2] and success
    assert expected_costs[1] == pytest.approx(0.3 * 1.0 + 0.2 * 2.0 + 0.1 * 0.5, rel=1e-12)  # |dq2 u|
    assert expected_costs[2] == pytest.approx((1.0 + 4.0 + 0.25) * 0.002, rel=1e-12)
    assert expected_costs[3] == pytest.approx(np.std([-3.0, 2.5, -0.5, 4.0]), rel=1e-12)
    assert expected_costs[4] == pytest.approx((0.0 + 5.0 + 10.0 + 1.0) * 0.002, rel=1e-12)
    np.testing.assert_allclose(np.asarray(perf.costs), expected_costs, rtol=1e-12)
    assert bool(perf.success)
    expected = 1 - np.mean(np.tanh(np.pi * expected_costs / np.array([20, 60, 20, 0.1, 400])))
    assert float(perf.score) == pytest.approx(expected, rel=1e-12)
    # down at the last sample the lab's loop visits: no success, score 0 whatever the costs
    xs_fail = xs.copy()
    xs_fail[3] = 0.0
    fail = control.performance_costs(control.Rollout(jnp.asarray(ts), jnp.asarray(xs_fail), jnp.asarray(us)), plant)
    assert not _lab_costs(ts, xs_fail, us)[1]
    assert not bool(fail.success) and float(fail.score) == 0.0 and float(fail.costs[0]) == ts[-2]


def test_recorded_torque_is_the_applied_one():
    # a controller asking for more than the limit: the lab records (and scores) the limited torque
    rollout = control.simulate_leaderboard(lambda t, x: jnp.array([10.0]), rules=control.LeaderboardRules(t_final=0.01))
    np.testing.assert_array_equal(np.asarray(rollout.us), 6.0)


def test_family_scores_by_hand():
    rules = control.LeaderboardRules(n_sizes=3, repetitions=4, pulse_runs=2)
    cases = control.robustness_cases(rules)
    counts = np.bincount(cases.family, minlength=6)
    assert list(counts) == [30, 12, 12, 3, 3, 2]
    success = np.zeros(len(cases.family), bool)
    success[:15] = True  # half the model cases
    noisy = np.flatnonzero(cases.family == 1)
    success[noisy[:4]] = True  # first size: 4 of 4
    success[noisy[4:6]] = True  # second size: 2 of 4 (not more than half)
    success[np.flatnonzero(cases.family == 4)[:1]] = True
    scores = control.family_scores(cases, success)
    np.testing.assert_allclose(scores, [0.5, 1 / 3, 0.0, 0.0, 1 / 3, 0.0])


def test_ends_upright_wraps_angles():
    xs = jnp.array(
        [[np.pi + 0.3, 0.3, 0.9, -0.9], [-np.pi, 2 * np.pi, 0, 0], [3 * np.pi, 0.36, 0, 0], [np.pi, 0, 1.1, 0]]
    )
    assert list(np.asarray(control.ends_upright(xs))) == [True, True, False, False]


def test_plant_matches_dynax_acrobot_without_rotor_or_friction():
    # The leaderboard plant written from the lab's equations against dynax's base-parameter Acrobot.
    p = control.NOMINAL_PLANT
    acrobot = dynax.Acrobot.from_physical(
        m1=p["m1"], m2=p["m2"], l1=p["l1"], lc1=p["r1"], lc2=p["r2"], I1=p["I1"], I2=p["I2"], b1=0.0, b2=0.0, g=p["g"]
    )
    plant = control.LeaderboardPlant.nominal()
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = jnp.asarray(rng.normal(size=4) * 2)
        u = float(rng.normal())
        np.testing.assert_allclose(
            plant.vector_field(x, jnp.array([0.0, u])),
            acrobot.vector_field(0.0, x, jnp.array([u])),
            rtol=1e-10,
            atol=1e-12,
        )


def test_rotor_inertia_and_friction_enter_as_the_lab_writes_them():
    plant = control.LeaderboardPlant.nominal(Ir=1e-4, cf1=0.1, b2=0.05)
    x = jnp.array([0.3, -0.2, 0.5, -1.0])
    gr, Ir = 6.0, 1e-4
    p = control.NOMINAL_PLANT
    c2 = np.cos(-0.2)
    m = np.array(
        [
            [
                p["I1"] + p["I2"] + p["m2"] * 0.04 + 2 * p["m2"] * 0.2 * p["r2"] * c2 + gr**2 * Ir + Ir,
                p["I2"] + p["m2"] * 0.2 * p["r2"] * c2 - gr * Ir,
            ],
            [p["I2"] + p["m2"] * 0.2 * p["r2"] * c2 - gr * Ir, p["I2"] + gr**2 * Ir],
        ]
    )
    plain = control.LeaderboardPlant.nominal(Ir=1e-4)
    # friction is a torque: M (a_plain - a) = F
    diff = m @ np.asarray(plain.acceleration(x, jnp.zeros(2)) - plant.acceleration(x, jnp.zeros(2)))
    np.testing.assert_allclose(diff, [0.1 * np.arctan(100 * 0.5), 0.05 * -1.0], rtol=1e-10)


def test_pulses_follow_the_rules():
    rules = control.LeaderboardRules()
    rng = np.random.default_rng(3)
    for _ in range(20):
        mu, sigma, amp = control.pulse_schedule(rules, rng)
        assert mu.shape == sigma.shape == amp.shape == (2, 3)
        assert np.all(np.diff(np.sort(mu.ravel())) >= 1.0) and mu.min() >= 1.0 and mu.max() <= 10.0
        assert np.all((sigma >= 0.05) & (sigma <= 0.1))
        assert np.all((np.abs(amp) >= 0.5) & (np.abs(amp) <= 5.0))


def test_zero_controller_never_swings_up():
    perf = control.performance(lambda t, x: jnp.zeros(1))
    assert not bool(perf.success) and float(perf.score) == 0.0


def test_saved_policy_swings_up_from_rest_and_balances():
    controller = dynax.control.load_controller(POLICY).to_benchmark()
    rollout = control.simulate_leaderboard(controller)
    perf = control.performance_costs(rollout, control.LeaderboardPlant.nominal())
    assert bool(perf.success) and float(perf.score) > 0.3
    assert bool(control.ends_upright(rollout.xs[-1], (0.01, 0.01, 0.05, 0.05)))
    assert float(jnp.max(jnp.abs(rollout.us))) <= 6.0


def test_load_save_round_trip_gives_identical_actions(tmp_path):
    robot = dynax.control.load_controller(POLICY)
    controller = robot.to_benchmark()
    path = controller.save(tmp_path / "again.npz")
    again = dynax.control.load_controller(path)
    rollout = control.simulate_leaderboard(controller)
    xs = np.asarray(rollout.xs)
    # the numpy controller reproduces the JAX one on the recorded states, call by call, twice
    for c in (robot, again):
        c.reset()
        us = np.array([c(k * 0.002, xs[k])[0] for k in range(1500)])
        np.testing.assert_allclose(us, np.asarray(rollout.us[:1500]), rtol=0, atol=1e-9)
    robot.reset()
    again.reset()
    assert all(robot(0.0, xs[k])[0] == again(0.0, xs[k])[0] for k in range(50))


def test_load_controller_refuses_bad_files(tmp_path):
    with pytest.raises(dynax.UsageError):
        dynax.control.load_controller(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, header=np.asarray('{"format": "other"}'))
    with pytest.raises(dynax.DataError, match="format"):
        dynax.control.load_controller(bad)
    truncated = tmp_path / "truncated.npz"  # a saved controller cut short, as by a failed copy
    truncated.write_bytes(POLICY.read_bytes()[:300])
    with pytest.raises(dynax.DataError, match="not a saved dynax controller"):
        dynax.control.load_controller(truncated)


@pytest.mark.parametrize(
    "argv",
    [
        ["control", "evaluate", "missing.npz"],
        ["control", "acrobot", "--out", "policy.json"],
        ["control", "acrobot", "--out", "p.npz", "--starts", "0"],
        ["control", "acrobot", "--out", "p.npz", "--horizon", "nan"],
        ["control", "acrobot", "--out", "p.npz", "--horizon", "inf"],
        ["control", "acrobot", "--out", "p.npz", "--horizon", "20"],  # past the 10 s episode
        ["control", "acrobot", "--out", "no/such/dir/p.npz"],
        ["control", "acrobot", "--out", "p.npz", "--reference", "missing.npz"],
        ["control"],
    ],
)
def test_cli_refuses_bad_input_with_exit_2(tmp_path, monkeypatch, capsys, argv):
    from dynax.internal import cli_main as main

    monkeypatch.chdir(tmp_path)
    try:
        code = main(argv)
    except SystemExit as e:  # argparse's own refusals
        code = e.code
    assert code == 2
    assert "error" in capsys.readouterr().err
    assert not (tmp_path / "p.npz").exists()


def _reference_knots(spacing=0.02, dt=0.002, policy=POLICY):
    us = dynax.control.load_controller(policy).u_ref
    per_knot = round(spacing / dt)
    knots = np.concatenate([us[per_knot::per_knot], us[-1:]])
    return jnp.asarray(np.arctanh(np.clip(knots / 6.0, -0.999999, 0.999999))), len(us) * dt


def test_score_surrogate_matches_the_reference_costs_computed_apart():
    from dynax.internal import knot_matrix, score_surrogate

    w, horizon = _reference_knots()
    saved = dynax.control.load_controller(POLICY)
    x, u = saved.x_ref, saved.u_ref  # the reference's states and torques at 2 ms, as saved
    plant = control.LeaderboardPlant.nominal()
    design = control.SwingUpDesign(horizon=horizon)
    interp = knot_matrix(round(horizon / 0.002), 0.002, 0.02, w.shape[0])
    surrogate, costs = score_surrogate(plant, w, interp, 0.002, design)
    costs = np.asarray(costs)
    # the costs by the lab's formulas on the saved arrays, in numpy; the episode at rest after them
    up = -0.2 * np.cos(x[:, 0]) - 0.3 * np.cos(x[:, 0] + x[:, 1]) > 0.45
    t_up = 0.002 * (len(up) - np.argmin(up[::-1]))  # from the last sample below the line on
    energy = np.sum(np.abs(np.diff(x[:, 1]) * u[:-1]))
    changes = np.concatenate([np.diff(u), np.zeros(4999 - (len(u) - 1))])
    expected = [energy, np.sum(u**2) * 0.002, np.std(changes), np.sum(x[:, 2:] ** 2) * 0.002]
    assert abs(costs[0] - t_up) < 0.05  # the time below the line, through a sigmoid of the height
    np.testing.assert_allclose(costs[1:], expected, rtol=0.02)
    terms = np.tanh(np.pi * np.array([t_up, *expected]) / np.array([20, 60, 20, 0.1, 400]))
    assert float(surrogate) == pytest.approx(np.mean(terms), abs=0.005)


def test_polish_on_constraint_restores_and_keeps_the_hand_over():
    from dynax.internal import hand_over_residuals, knot_matrix, polish_on_constraint

    # a 2 s reference of the basin-hopping search: the saved 1.5 s one is so sensitive to its early
    # torques that the projected steps leave its constraint (its collocation is kept as it is)
    w, horizon = _reference_knots(policy=POLICY.parent / "global_search" / "best_policy.npz")
    plant = control.LeaderboardPlant.nominal()
    design = control.SwingUpDesign(horizon=horizon, polish_feasibility=12, polish_iterations=4)
    interp = knot_matrix(round(horizon / 0.01), 0.01, 0.02, w.shape[0])
    # a small knock off the constraint: Gauss-Newton brings it back, the projected steps keep it there
    w0 = jnp.stack([w, w + 0.03 * jnp.asarray(np.random.default_rng(0).normal(size=w.shape))])
    before = np.asarray(jax.vmap(lambda v: jnp.sum(hand_over_residuals(plant, v, interp, 0.01, 6.0) ** 2))(w0))
    _, feasible, end, _, _ = polish_on_constraint(plant, w0, interp, 0.01, design)
    assert before[1] > 1e-4
    assert np.all(np.asarray(feasible) < 1e-12)  # Gauss-Newton restores the constraint
    assert np.all(np.asarray(end) < 1e-3)  # and the projected steps stay near it (each one corrected)


def test_tracking_the_estimators_view_follows_the_reference_exactly(tmp_path):
    # the lead and the velocities from position differences make the estimate differ from the
    # reference; compared with the reference as the estimate sees it, the nominal closed loop has
    # no feedback and is the reference, state by state and torque by torque
    saved = dynax.control.load_controller(POLICY)
    x_ref, u_ref = jnp.asarray(saved.x_ref), jnp.asarray(saved.u_ref)
    n = u_ref.shape[0]
    gaps = []
    from dynax.internal import cli_main

    assert cli_main(["control", "acrobot", "--out", str(tmp_path / "cli.npz"), "--reference", str(POLICY)]) == 0
    from_cli = dynax.control.load_controller(tmp_path / "cli.npz")  # the feedback designed around the reference
    np.testing.assert_array_equal(from_cli.u_ref, saved.u_ref)
    for track in (1, 0):
        design = control.SwingUpDesign(track_estimate=track, lead=0.02)
        controller = control.design_swing_up(design=design, reference=(x_ref, u_ref))
        rollout = control.simulate_leaderboard(controller)
        gaps.append(float(jnp.max(jnp.abs(rollout.us[:n] - u_ref))))
        if track:
            np.testing.assert_allclose(np.asarray(rollout.xs[:n]), np.asarray(x_ref), rtol=0, atol=1e-8)
            robot = dynax.control.load_controller(controller.save(tmp_path / "view.npz"))
            xs = np.asarray(rollout.xs)
            us = np.array([robot(k * 0.002, xs[k])[0] for k in range(n + 20)])
            np.testing.assert_allclose(us, np.asarray(rollout.us[: n + 20]), rtol=0, atol=1e-9)
    assert gaps[0] < 1e-8 < 0.01 < gaps[1]  # without the view the feedback acts on the estimate's lag
