r"""Where the records show a joint held at rest under load: the evidence that proposes a `stiction` candidate.

A joint rests (`dynax.internal.rest_stretches`: its position still for a quarter second or more) under a
net torque when the nominal model, at the measured state, would accelerate it: the generalised force its
friction must supply there is

$$f_j = \big[M(q)\ddot q + h(q, \dot q) - B u\big]_j,$$

with $\dot q$ from a Savitzky-Golay fit of the measured positions over the shortest rest and $\ddot q$ its
finite difference, so that the mean over a stretch is the change of speed over it (the other joints may
move). A friction law of the speed alone holds nothing at rest, so a rest with $f_j$ of practical size is what
only a static friction level (`Stiction`) can take; a rest with $f_j \approx 0$ (a joint hanging in
equilibrium) says nothing about friction.

A rest is under load when the mean $f_j$ over the stretch reaches, in magnitude, `LOAD_FRACTION` of the
joint's RMS generalised force over the records: with encoder noise of a milliradian at 100 Hz a balanced rest
reads as up to 9 % of it, and a few percent of error in the nominal parameters adds as much again. The joint
rests under load when such stretches add up to `MIN_LOADED_REST_S` (one quarter-second stretch is one noisy
reading of the force held)."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._data._derivatives import savitzky_golay
from .._data._rest import rest_stretches, speed_noise_at_rest

LOAD_FRACTION = 0.1  # a rest is under load when the friction needed there reaches this share of the joint's RMS force
MIN_REST_S = 0.25  # the shortest stretch that counts as rest [s] (`rest_stretches`' `min_duration`)
# Rest under load must add up to two of the shortest rests: one quarter-second stretch is one noisy reading of
# the force held (with encoder noise of a milliradian at 100 Hz, up to a tenth of a joint's force scale).
MIN_LOADED_REST_S = 2 * MIN_REST_S


@dataclasses.dataclass(frozen=True)
class JointRests:
    """The rests of one joint in the records, and the friction the nominal model needs to hold them.

    **Fields:** `joint` (0-based), `coordinate` (e.g. `q2`), `stretches` (`(record, start_s, stop_s, held)`
    per rest under load, `held` the mean friction force needed there [N m or N]), `rest_s` (seconds of rest
    under load), `all_rest_s` (seconds of rest, loaded or not), `force_scale` (the joint's RMS generalised force),
    `speed_noise` (the measured speed's noise at rest, `dynax.internal.speed_noise_at_rest`: the velocity noise a
    window starts from).
    """

    joint: int
    coordinate: str
    stretches: tuple
    rest_s: float
    all_rest_s: float
    force_scale: float
    speed_noise: float

    @property
    def loaded(self) -> bool:
        """Whether the joint rests under load for `MIN_LOADED_REST_S` or more in all."""
        return self.rest_s >= MIN_LOADED_REST_S

    @property
    def held(self) -> float:
        """The largest friction force held at rest (mean over a stretch): the static level is at least this."""
        return max((abs(s[3]) for s in self.stretches), default=0.0)

    def to_json(self) -> dict:
        return {
            "joint": self.coordinate,
            "rest_s": self.rest_s,
            "all_rest_s": self.all_rest_s,
            "held": self.held,
            "force_scale": self.force_scale,
            "stretches": [{"record": r, "start_s": a, "stop_s": b, "held": h} for r, a, b, h in self.stretches],
        }


@eqx.filter_jit
def _inverse_dynamics(system, q, dq, ddq):
    return jax.vmap(system.inverse_dynamics)(q, dq, ddq)


def rests_under_load(system, trajectories) -> tuple[JointRests, ...]:
    """Per joint of the manipulator `system`, its rests in `trajectories` and the friction needed to hold them
    (see the module). Empty for a system without joints.

    **Returns:** a `JointRests` per joint.
    """
    if not getattr(system, "joints", ()):
        return ()
    n = system.n_joints
    B = np.asarray(system.input_matrix(), float)
    forces, needed, rests = [], [], []
    for i, tr in enumerate(trajectories):
        ts = np.asarray(tr.ts, float)
        xs = np.asarray(tr.xs, float)
        us = np.asarray(tr.us, float)
        # A fit over the shortest rest; the mean over a stretch then averages the second derivative's noise
        # away (its mean is the change of speed over the stretch, about zero), where a median would not.
        w = max(int(round(MIN_REST_S / float(np.median(np.diff(ts))))) | 1, 7)
        if len(ts) <= w:
            forces.append(np.zeros((len(ts), n)))
            needed.append(np.zeros((len(ts), n)))
            rests.append(())
            continue
        found = rest_stretches(tr, tuple(range(n)), min_duration=MIN_REST_S, record=tr.source or f"record {i + 1}")
        q = np.asarray(savitzky_golay(ts, xs[:, :n], window=w, order=3))
        dq = np.asarray(savitzky_golay(ts, xs[:, :n], window=w, order=3, deriv=1))
        ddq = np.gradient(dq, ts, axis=0)  # so that its mean over a stretch telescopes to the change of speed
        force = np.asarray(_inverse_dynamics(system, jnp.asarray(q), jnp.asarray(dq), jnp.asarray(ddq)))
        forces.append(force)
        needed.append(force - us @ B.T)
        rests.append(found)
    out = []
    for j in range(n):
        total = np.concatenate([f[:, j] for f in forces])
        scale = float(np.sqrt(np.mean(total**2))) if total.size else 0.0
        stretches, speeds, rest_s, all_s = [], [], 0.0, 0.0
        for tr, f, found in zip(trajectories, needed, rests):
            for r in found:
                if r.joint != j:
                    continue
                all_s += r.duration
                speeds.append(np.asarray(tr.xs, float)[r.start : r.stop, n + j])
                held = float(np.mean(f[r.start : r.stop, j]))
                if abs(held) >= LOAD_FRACTION * scale and scale > 0:
                    stretches.append((r.record, r.start_s, r.stop_s, held))
                    rest_s += r.duration
        noise = speed_noise_at_rest(np.concatenate(speeds)) if speeds else 0.0
        out.append(JointRests(j, system.joint_names[j], tuple(stretches), rest_s, all_s, scale, noise))
    return tuple(out)
