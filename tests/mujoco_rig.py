"""A double pendulum made by another simulator: MuJoCo, for data that dynax's model and integrator did not make.

MuJoCo builds the arm from bodies (a mass and its inertia about its centre, placed along the link),
turns each hinge's `armature` (a motor's reflected rotor inertia), `damping` (viscous friction) and
`frictionloss` (dry friction) into its own equations, and integrates them with its own RK4. Its dry
friction is not a smoothed sign but a constraint solved at every step: a joint sticks while the
other torques stay below the friction and slides against it when they exceed it (softened by the
constraint's default impedance). So identification and diagnosis on these records meet a friction
law, a parametrisation and an integrator that are not their own.

Only the base parameters below are dynax's, written out here from the bodies by hand (Spong's
equations, with the hinges' armature on the mass matrix's diagonal): `theta1 = I1 + m2 l1^2 + a1`
with `I1 = Ic1 + m1 lc1^2`, `theta2 = Ic2 + m2 lc2^2`, `theta3 = m2 l1 lc2`, `theta4 = g (m1 lc1 +
m2 l1)`, `theta5 = g m2 lc2`, viscous `theta6 = b1`, `theta7 = b2`, Coulomb `fc1 = f1`, `fc2 = f2`,
and the elbow's armature `Ir2 = a2` (added to `M22` alone, which is dynax's `RotorInertia(1)`).
"""

import numpy as np

G = 9.81
# About the DFKI rig's size (its base parameters within 5 % of the lab's model_3.0: theta1 0.054,
# theta2 0.054, theta3 0.036, theta4 2.36, theta5 1.78), with a geared motor's rotor inertia
# (36 x 1e-4 kg m^2 reflected) and dry friction at each joint.
RIG = dict(
    m1=0.6,
    l1=0.2,
    lc1=0.19,
    Ic1=0.0012,
    m2=0.62,
    lc2=0.29,
    Ic2=0.0015,
    b1=0.005,
    b2=0.004,
    a1=0.0036,
    a2=0.0036,
    f1=0.15,
    f2=0.10,
)
STATES = ("q1", "q2", "dq1", "dq2")
INPUTS = ("tau1", "tau2")


def mjcf(p: dict, timestep: float = 0.0005, inputs: tuple[str, ...] = INPUTS) -> str:
    """The arm as MJCF: both hinges about +y (q = 0 hangs down, q2 relative to link 1), driven by
    `inputs` (`("tau1", "tau2")`, or `("tau2",)`: the acrobot)."""
    motors = "\n".join(
        f'    <motor name="{name}" joint="{joint}"/>'
        for name, joint in (("tau1", "shoulder"), ("tau2", "elbow"))
        if name in inputs
    )

    def joint(name, b, a, f):
        return f'<joint name="{name}" type="hinge" axis="0 1 0" damping="{b}" armature="{a}" frictionloss="{f}"/>'

    return f"""
<mujoco model="double_pendulum_rig">
  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>
  <option timestep="{timestep}" integrator="RK4" gravity="0 0 -{G}">
    <flag contact="disable" energy="disable"/>
  </option>
  <worldbody>
    <body name="link1">
      {joint("shoulder", p["b1"], p["a1"], p["f1"])}
      <inertial pos="0 0 -{p["lc1"]}" mass="{p["m1"]}" diaginertia="{p["Ic1"]} {p["Ic1"]} {p["Ic1"]}"/>
      <body name="link2" pos="0 0 -{p["l1"]}">
        {joint("elbow", p["b2"], p["a2"], p["f2"])}
        <inertial pos="0 0 -{p["lc2"]}" mass="{p["m2"]}" diaginertia="{p["Ic2"]} {p["Ic2"]} {p["Ic2"]}"/>
      </body>
    </body>
  </worldbody>
  <actuator>
{motors}
  </actuator>
</mujoco>"""


def base_parameters(p: dict) -> dict:
    """The arm's parameters in dynax's names (see the module's docstring), computed here, not by dynax."""
    i1 = p["Ic1"] + p["m1"] * p["lc1"] ** 2
    return dict(
        theta1=i1 + p["m2"] * p["l1"] ** 2 + p["a1"],
        theta2=p["Ic2"] + p["m2"] * p["lc2"] ** 2,
        theta3=p["m2"] * p["l1"] * p["lc2"],
        theta4=G * (p["m1"] * p["lc1"] + p["m2"] * p["l1"]),
        theta5=G * p["m2"] * p["lc2"],
        theta6=p["b1"],
        theta7=p["b2"],
        fc1=p["f1"],
        fc2=p["f2"],
        Ir2=p["a2"],
    )


def multisine(ts, seed: int, scale: float = 0.6) -> np.ndarray:
    """Two torques, each five sines (0.3 to 2.3 Hz, random phases): at `scale` 0.6 about 0.45 and 0.25 N m
    rms, swinging the arm to about 1 rad as most DFKI runs do (0.1 to 0.5 N m rms, 0.4 to 1.9 rad).
    The acrobot's elbow torque is the second."""
    rng = np.random.default_rng(seed)
    freqs = np.array([0.3, 0.7, 1.1, 1.7, 2.3])
    out = []
    for amplitude in (0.9, 0.5):
        phases = rng.uniform(0, 2 * np.pi, size=freqs.size)
        out.append(
            sum(
                amplitude / (1 + k) * np.sin(2 * np.pi * f * np.asarray(ts) + ph)
                for k, (f, ph) in enumerate(zip(freqs, phases))
            )
        )
    return scale * np.stack(out, axis=1)


def record(
    p: dict,
    duration: float,
    seed: int,
    *,
    dt: float = 0.002,
    scale: float = 0.6,
    velocity_noise: float = 0.15,
    torque_noise: float = 0.02,
    position_noise: float = 1e-4,
    inputs: tuple[str, ...] = INPUTS,
):
    """Simulate the arm from rest under `multisine` torques (held over each MuJoCo step, set at its
    midpoint) and sample every `dt`, with sensor noise at the DFKI rig's level (velocity estimate
    0.15 rad/s, current-based torque 0.02 N m, encoder 1e-4 rad, 1-sigma). The recorded torque of a
    sample is the mean torque over the interval it starts. `inputs` as for `mjcf`.
    **Returns:** `(ts, xs, us, clean_xs)`."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf(p, inputs=inputs))
    data = mujoco.MjData(model)
    sub = int(round(dt / model.opt.timestep))
    n = int(round(duration / dt))
    fine = multisine(model.opt.timestep * (np.arange(n * sub) + 0.5), seed, scale)[:, [INPUTS.index(i) for i in inputs]]
    xs = np.empty((n, 4))
    for k in range(n):
        xs[k, :2], xs[k, 2:] = data.qpos, data.qvel
        for j in range(sub):
            data.ctrl[:] = fine[k * sub + j]
            mujoco.mj_step(model, data)
    us = fine.reshape(n, sub, len(inputs)).mean(axis=1)
    rng = np.random.default_rng(seed + 100)
    noisy = xs + np.concatenate([position_noise * rng.normal(size=(n, 2)), velocity_noise * rng.normal(size=(n, 2))], 1)
    return dt * np.arange(n), noisy, us + torque_noise * rng.normal(size=us.shape), xs


def window_rmse(p: dict, ts, xs, us, starts, horizons_s, inputs: tuple[str, ...] = INPUTS) -> np.ndarray:
    """MuJoCo's own open-loop position RMSE (q1 and q2 pooled) at each horizon, from the measured state at each of
    `starts` under the recorded torques (held over each sample), as `dynax.simulation_error` measures a model."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf(p, inputs=inputs))
    data = mujoco.MjData(model)
    dt = float(np.median(np.diff(ts)))
    sub = int(round(dt / model.opt.timestep))
    steps = np.maximum(np.round(np.asarray(horizons_s) / dt).astype(int), 1)
    squares = np.zeros(len(steps))
    for k in np.asarray(starts):
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = xs[k, :2], xs[k, 2:]
        at = {}
        for i in range(1, steps.max() + 1):
            data.ctrl[:] = us[k + i - 1]
            for _ in range(sub):
                mujoco.mj_step(model, data)
            at[i] = np.array(data.qpos)
        squares += [np.mean((at[s] - xs[k + s, :2]) ** 2) for s in steps]
    return np.sqrt(squares / len(starts))
