"""Simulation: `simulate` with its fixed-grid and adaptive methods, the RK4 solver, rollouts from many
starts and the error against horizon (`simulation_error`, `SimulationError`), predictions ahead."""

from ._predict import flight_error as flight_error
from ._predict import FLIGHT_UNITS as FLIGHT_UNITS
from ._predict import predict_ahead as predict_ahead
from ._sim_error import AlongStates as AlongStates
from ._sim_error import complete_state as complete_state
from ._sim_error import InputStates as InputStates
from ._sim_error import rollouts_from_starts as rollouts_from_starts
from ._sim_error import simulation_error as simulation_error
from ._sim_error import SimulationError as SimulationError
from ._sim_error import window_rollout as window_rollout
from ._sim_error import window_rollouts as window_rollouts
from ._sim_error import window_simulation_errors as window_simulation_errors
from ._simulate import Adaptive as Adaptive
from ._simulate import explicit_step as explicit_step
from ._simulate import FixedGrid as FixedGrid
from ._simulate import mask_diverged as mask_diverged
from ._simulate import sample_interval as sample_interval
from ._simulate import simulate as simulate
from ._simulate import Simulation as Simulation
from ._simulate import zoh_term as zoh_term
from ._solvers import RK4 as RK4
