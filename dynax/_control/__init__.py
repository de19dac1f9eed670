"""Control: LQR (differentiable Riccati solvers), Drake's Spong swing-up controller, closed loops, PGPE."""

from ._closed_loop import (
    ClosedLoop as ClosedLoop,
)
from ._closed_loop import (
    is_upright as is_upright,
)
from ._closed_loop import (
    simulate_closed_loop as simulate_closed_loop,
)
from ._closed_loop import (
    swing_up_reward as swing_up_reward,
)
from ._closed_loop import (
    swing_up_time as swing_up_time,
)
from ._closed_loop import (
    upright_error as upright_error,
)
from ._collocation import CollocationStage as CollocationStage
from ._collocation import PumpingStarts as PumpingStarts
from ._collocation import ReferenceSearch as ReferenceSearch
from ._collocation import search_reference as search_reference
from ._from_rest import (
    balance_lqr as balance_lqr,
)
from ._from_rest import (
    design_swing_up as design_swing_up,
)
from ._from_rest import (
    end_upright as end_upright,
)
from ._from_rest import (
    load_controller as load_controller,
)
from ._from_rest import (
    optimise_swing_up as optimise_swing_up,
)
from ._from_rest import (
    RobotController as RobotController,
)
from ._from_rest import swing_up_reference as swing_up_reference
from ._from_rest import (
    SwingUpDesign as SwingUpDesign,
)
from ._from_rest import (
    SwingUpFromRest as SwingUpFromRest,
)
from ._from_rest import (
    tvlqr as tvlqr,
)
from ._leaderboard import (
    AbstractBenchmarkController as AbstractBenchmarkController,
)
from ._leaderboard import (
    as_benchmark_controller as as_benchmark_controller,
)
from ._leaderboard import (
    Case as Case,
)
from ._leaderboard import (
    COST_NAMES as COST_NAMES,
)
from ._leaderboard import (
    ends_upright as ends_upright,
)
from ._leaderboard import (
    Family as Family,
)
from ._leaderboard import (
    family_scores as family_scores,
)
from ._leaderboard import (
    LeaderboardPlant as LeaderboardPlant,
)
from ._leaderboard import (
    LeaderboardRules as LeaderboardRules,
)
from ._leaderboard import (
    MODEL_PARAMETERS as MODEL_PARAMETERS,
)
from ._leaderboard import (
    nominal_case as nominal_case,
)
from ._leaderboard import (
    NOMINAL_PLANT as NOMINAL_PLANT,
)
from ._leaderboard import (
    Performance as Performance,
)
from ._leaderboard import (
    performance as performance,
)
from ._leaderboard import (
    performance_costs as performance_costs,
)
from ._leaderboard import (
    pulse_schedule as pulse_schedule,
)
from ._leaderboard import (
    Robustness as Robustness,
)
from ._leaderboard import (
    robustness as robustness,
)
from ._leaderboard import (
    robustness_cases as robustness_cases,
)
from ._leaderboard import (
    RobustnessCases as RobustnessCases,
)
from ._leaderboard import (
    Rollout as Rollout,
)
from ._leaderboard import (
    simulate_leaderboard as simulate_leaderboard,
)
from ._leaderboard import (
    Stateless as Stateless,
)
from ._linear_design import ctrb as ctrb
from ._linear_design import dlqr as dlqr
from ._linear_design import lqe as lqe
from ._linear_design import lqr_matrices as lqr_matrices
from ._linear_design import obsv as obsv
from ._lqr import (
    discrete_lqr as discrete_lqr,
)
from ._lqr import (
    linearise as linearise,
)
from ._lqr import (
    LQR as LQR,
)
from ._lqr import (
    lqr as lqr,
)
from ._lqr import (
    wrap_angle as wrap_angle,
)
from ._pgpe import (
    AbstractFitnessShaping as AbstractFitnessShaping,
)
from ._pgpe import (
    BaselineNormalisation as BaselineNormalisation,
)
from ._pgpe import (
    CentredRank as CentredRank,
)
from ._pgpe import (
    clipup as clipup,
)
from ._pgpe import (
    evaluate_population as evaluate_population,
)
from ._pgpe import (
    PGPE as PGPE,
)
from ._pgpe import (
    PGPEHistory as PGPEHistory,
)
from ._pgpe import (
    PGPEState as PGPEState,
)
from ._pgpe import (
    population_sharding as population_sharding,
)
from ._pgpe import (
    run_pgpe as run_pgpe,
)
from ._pgpe import (
    sweep_pgpe as sweep_pgpe,
)
from ._region_of_attraction import (
    estimate_region_of_attraction as estimate_region_of_attraction,
)
from ._region_of_attraction import (
    RegionOfAttraction as RegionOfAttraction,
)
from ._region_of_attraction import (
    RegionSampling as RegionSampling,
)
from ._riccati import solve_continuous_are as solve_continuous_are
from ._riccati import solve_discrete_are as solve_discrete_are
from ._swing_up import (
    AbstractSwitchingRule as AbstractSwitchingRule,
)
from ._swing_up import (
    balancing_lqr as balancing_lqr,
)
from ._swing_up import (
    CostToGoThreshold as CostToGoThreshold,
)
from ._swing_up import (
    DRAKE_SPONG_PARAMETERS as DRAKE_SPONG_PARAMETERS,
)
from ._swing_up import (
    SmoothActivation as SmoothActivation,
)
from ._swing_up import (
    SPONG_PARAMETER_NAMES as SPONG_PARAMETER_NAMES,
)
from ._swing_up import (
    SpongController as SpongController,
)
from ._swing_up_task import random_starts as random_starts
from ._swing_up_task import SwingUpTask as SwingUpTask
