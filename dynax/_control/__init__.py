"""Control: LQR (differentiable Riccati solvers), Drake's Spong swing-up controller, closed loops, PGPE."""

from ._lqr import (
    discrete_lqr as discrete_lqr,
    linearise as linearise,
    LQR as LQR,
    lqr as lqr,
    wrap_angle as wrap_angle,
)
from ._riccati import solve_continuous_are as solve_continuous_are, solve_discrete_are as solve_discrete_are
from ._linear_design import ctrb as ctrb, dlqr as dlqr, lqe as lqe, lqr_matrices as lqr_matrices, obsv as obsv
from ._swing_up import (
    AbstractSwitchingRule as AbstractSwitchingRule,
    balancing_lqr as balancing_lqr,
    CostToGoThreshold as CostToGoThreshold,
    DRAKE_SPONG_PARAMETERS as DRAKE_SPONG_PARAMETERS,
    SmoothActivation as SmoothActivation,
    SPONG_PARAMETER_NAMES as SPONG_PARAMETER_NAMES,
    SpongController as SpongController,
)
from ._closed_loop import (
    ClosedLoop as ClosedLoop,
    is_upright as is_upright,
    simulate_closed_loop as simulate_closed_loop,
    swing_up_reward as swing_up_reward,
    swing_up_time as swing_up_time,
    upright_error as upright_error,
)
from ._pgpe import (
    AbstractFitnessShaping as AbstractFitnessShaping,
    BaselineNormalisation as BaselineNormalisation,
    CentredRank as CentredRank,
    clipup as clipup,
    evaluate_population as evaluate_population,
    PGPE as PGPE,
    PGPEHistory as PGPEHistory,
    PGPEState as PGPEState,
    population_sharding as population_sharding,
    run_pgpe as run_pgpe,
    sweep_pgpe as sweep_pgpe,
)
from ._swing_up_task import random_starts as random_starts, SwingUpTask as SwingUpTask
from ._region_of_attraction import estimate_region_of_attraction as estimate_region_of_attraction, RegionOfAttraction as RegionOfAttraction
from ._leaderboard import (
    AbstractBenchmarkController as AbstractBenchmarkController,
    as_benchmark_controller as as_benchmark_controller,
    Case as Case,
    COST_NAMES as COST_NAMES,
    ends_upright as ends_upright,
    Family as Family,
    family_scores as family_scores,
    LeaderboardPlant as LeaderboardPlant,
    LeaderboardRules as LeaderboardRules,
    MODEL_PARAMETERS as MODEL_PARAMETERS,
    NOMINAL_PLANT as NOMINAL_PLANT,
    nominal_case as nominal_case,
    performance as performance,
    performance_costs as performance_costs,
    Performance as Performance,
    pulse_schedule as pulse_schedule,
    robustness as robustness,
    Robustness as Robustness,
    robustness_cases as robustness_cases,
    RobustnessCases as RobustnessCases,
    Rollout as Rollout,
    simulate_leaderboard as simulate_leaderboard,
    Stateless as Stateless,
)
from ._from_rest import (
    balance_lqr as balance_lqr,
    design_swing_up as design_swing_up,
    end_upright as end_upright,
    load_controller as load_controller,
    optimise_swing_up as optimise_swing_up,
    RobotController as RobotController,
    SwingUpDesign as SwingUpDesign,
    SwingUpFromRest as SwingUpFromRest,
    tvlqr as tvlqr,
)
