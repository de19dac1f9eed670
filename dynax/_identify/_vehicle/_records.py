"""What `identify` runs before and after a vehicle criterion's fit: the flights joined into the one
body-frame record the criteria fit (`join_flights`), and the held-out flights scored by the vehicle
horizon error (`FlightHeldOut`: `flight_error` at the validation's horizons)."""

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from ..._data._trajectory import Trajectory
from ..._errors import UsageError
from ..._simulate._predict import flight_error
from ..._simulate._sim_error import SimulationError
from .._validation import HeldOut


def join_flights(system, flights: Sequence[Trajectory], who: str = "fit_quadrotor") -> tuple[Trajectory, np.ndarray]:
    """The flights in the coordinates the vehicle criteria fit (`system.body_frame`: a quadrotor's
    body-frame form, a helicopter's records as they are) joined into one record on one uniform time
    grid (the first flight's start, the flights' median interval), and the sample indices where each
    flight after the first begins (the breaks).

    All flights must share one sample interval (to 1 %) and one set of inputs; `who` names the caller
    in the errors.
    """
    flights = list(flights)
    return _joined(flights, _body_frame(system, flights, who))


def _body_frame(system, flights: list[Trajectory], who: str) -> list[Trajectory]:
    """Each flight in `system`'s fitted coordinates, checked: uniformly sampled at one interval, one set of inputs."""
    if not flights:
        raise UsageError(f"{who}: no flights given")
    dts = []
    for i, f in enumerate(flights):
        if len(f) < 2 or not f.is_uniform:
            raise UsageError(
                f"{who}: flight {i} ({f.source or 'unnamed'}) must be uniformly sampled with at "
                "least 2 samples (dynax.load_flight resamples; dynax.usable_segments cuts)"
            )
        dts.append(f.dt)
    dt = float(np.median(dts))
    off = [i for i, d in enumerate(dts) if abs(d - dt) > 0.01 * dt]
    if off:
        raise UsageError(
            f"{who}: flight {off[0]} is sampled every {dts[off[0]]:.6g} s, the others every {dt:.6g} s; "
            "resample it first"
        )
    inputs = {tuple(f.input_names) for f in flights}
    if len(inputs) > 1:
        raise UsageError(f"{who}: the flights have different inputs {sorted(inputs)}")
    try:
        return [system.body_frame(f) for f in flights]
    except UsageError as error:
        raise UsageError(f"{who}: {error}") from None


def _joined(flights: list[Trajectory], body: list[Trajectory]) -> tuple[Trajectory, np.ndarray]:
    """The `body`-frame flights on one uniform time grid, and where each after the first begins."""
    dt = float(np.median([f.dt for f in flights]))
    lengths = np.array([len(b) for b in body])
    xs = jnp.concatenate([b.xs for b in body])
    us = jnp.concatenate([b.us for b in body])
    ts = float(np.asarray(flights[0].ts)[0]) + dt * np.arange(xs.shape[0])
    joined = Trajectory(ts, xs, us, body[0].state_names, body[0].input_names, "helicopter", "joined flights")
    return joined, np.cumsum(lengths)[:-1]


def vehicle_record(system, records: list[Trajectory], breaks) -> tuple[Trajectory, tuple[int, ...] | None]:
    """The one record a vehicle criterion fits and its breaks. One record the criteria fit as it is
    (`system.body_frame` returns it: a helicopter's) is that record with the `breaks` given; otherwise
    the records in `system`'s fitted coordinates are joined on one uniform time grid (`join_flights`:
    a quadrotor's flight, even one, is fitted on its median interval), each record after the first
    a break (with several records, no `breaks` may be given: they index one record)."""
    given = None if breaks is None else tuple(int(b) for b in breaks)
    if len(records) > 1 and given:
        raise UsageError(
            f"identify: `breaks` index one record; {len(records)} records are joined with a break where "
            "each begins: give them joined, or without breaks"
        )
    body = _body_frame(system, records, "identify")
    if len(records) == 1 and body[0] is records[0]:
        return records[0], given
    joined, starts = _joined(records, body)
    return joined, given if len(records) == 1 else tuple(int(b) for b in starts)


class FlightHeldOut(HeldOut):
    """The held-out flights of a vehicle fit, scored by the vehicle horizon error: `flight_error`
    (open-loop position, velocity, attitude and body-rate errors per group, MAE and RMSE) at the
    validation's horizons, each rounded to whole samples of the flights' interval."""

    def validate(self, model) -> SimulationError | None:
        """`flight_error` of `model` on the held-out flights, or `None` where there are none."""
        if not self.records:
            return None
        dt = float(np.median([r.dt for r in self.records]))
        steps = tuple(sorted({max(int(round(h / dt)), 1) for h in self.horizons_s}))
        return flight_error(model, self.records, steps)
