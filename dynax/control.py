"""Control: LQR, Drake's Spong controller, closed loops, PGPE, and the RealAIGym acrobot leaderboard.

The leaderboard: `LeaderboardPlant`, `LeaderboardRules`, `simulate_leaderboard`, `performance`,
`robustness` (with `Performance`, `Robustness`, `Family`, `robustness_cases`); the from-rest
swing-up: `design_swing_up`, `SwingUpDesign`, `SwingUpFromRest`, `load_controller`,
`RobotController`, and its reference's search `swing_up_reference`, `search_reference`,
`ReferenceSearch`, `PumpingStarts`, `CollocationStage`. The names the top level already exports
(`dynax.lqr`, ...) are here too.
"""

from ._control import (
    AbstractBenchmarkController as AbstractBenchmarkController,
)
from ._control import (
    AbstractFitnessShaping as AbstractFitnessShaping,
)
from ._control import (
    AbstractSwitchingRule as AbstractSwitchingRule,
)
from ._control import (
    as_benchmark_controller as as_benchmark_controller,
)
from ._control import (
    balance_lqr as balance_lqr,
)
from ._control import (
    balancing_lqr as balancing_lqr,
)
from ._control import (
    BaselineNormalisation as BaselineNormalisation,
)
from ._control import (
    Case as Case,
)
from ._control import (
    CentredRank as CentredRank,
)
from ._control import (
    clipup as clipup,
)
from ._control import (
    ClosedLoop as ClosedLoop,
)
from ._control import CollocationStage as CollocationStage
from ._control import (
    COST_NAMES as COST_NAMES,
)
from ._control import (
    CostToGoThreshold as CostToGoThreshold,
)
from ._control import (
    ctrb as ctrb,
)
from ._control import (
    design_swing_up as design_swing_up,
)
from ._control import (
    discrete_lqr as discrete_lqr,
)
from ._control import (
    dlqr as dlqr,
)
from ._control import (
    DRAKE_SPONG_PARAMETERS as DRAKE_SPONG_PARAMETERS,
)
from ._control import (
    end_upright as end_upright,
)
from ._control import (
    ends_upright as ends_upright,
)
from ._control import (
    estimate_region_of_attraction as estimate_region_of_attraction,
)
from ._control import (
    evaluate_population as evaluate_population,
)
from ._control import (
    Family as Family,
)
from ._control import (
    family_scores as family_scores,
)
from ._control import (
    is_upright as is_upright,
)
from ._control import (
    LeaderboardPlant as LeaderboardPlant,
)
from ._control import (
    LeaderboardRules as LeaderboardRules,
)
from ._control import (
    linearise as linearise,
)
from ._control import (
    load_controller as load_controller,
)
from ._control import (
    lqe as lqe,
)
from ._control import (
    LQR as LQR,
)
from ._control import (
    lqr as lqr,
)
from ._control import (
    lqr_matrices as lqr_matrices,
)
from ._control import (
    MODEL_PARAMETERS as MODEL_PARAMETERS,
)
from ._control import (
    nominal_case as nominal_case,
)
from ._control import (
    NOMINAL_PLANT as NOMINAL_PLANT,
)
from ._control import (
    obsv as obsv,
)
from ._control import (
    optimise_swing_up as optimise_swing_up,
)
from ._control import (
    Performance as Performance,
)
from ._control import (
    performance as performance,
)
from ._control import (
    performance_costs as performance_costs,
)
from ._control import (
    PGPE as PGPE,
)
from ._control import (
    PGPEHistory as PGPEHistory,
)
from ._control import (
    PGPEState as PGPEState,
)
from ._control import (
    population_sharding as population_sharding,
)
from ._control import (
    pulse_schedule as pulse_schedule,
)
from ._control import PumpingStarts as PumpingStarts
from ._control import (
    random_starts as random_starts,
)
from ._control import ReferenceSearch as ReferenceSearch
from ._control import (
    RegionOfAttraction as RegionOfAttraction,
)
from ._control import (
    RegionSampling as RegionSampling,
)
from ._control import (
    RobotController as RobotController,
)
from ._control import (
    Robustness as Robustness,
)
from ._control import (
    robustness as robustness,
)
from ._control import (
    robustness_cases as robustness_cases,
)
from ._control import (
    RobustnessCases as RobustnessCases,
)
from ._control import (
    Rollout as Rollout,
)
from ._control import (
    run_pgpe as run_pgpe,
)
from ._control import search_reference as search_reference
from ._control import (
    simulate_closed_loop as simulate_closed_loop,
)
from ._control import (
    simulate_leaderboard as simulate_leaderboard,
)
from ._control import (
    SmoothActivation as SmoothActivation,
)
from ._control import (
    solve_continuous_are as solve_continuous_are,
)
from ._control import (
    solve_discrete_are as solve_discrete_are,
)
from ._control import (
    SPONG_PARAMETER_NAMES as SPONG_PARAMETER_NAMES,
)
from ._control import (
    SpongController as SpongController,
)
from ._control import (
    Stateless as Stateless,
)
from ._control import (
    sweep_pgpe as sweep_pgpe,
)
from ._control import swing_up_reference as swing_up_reference
from ._control import (
    swing_up_reward as swing_up_reward,
)
from ._control import (
    swing_up_time as swing_up_time,
)
from ._control import (
    SwingUpDesign as SwingUpDesign,
)
from ._control import (
    SwingUpFromRest as SwingUpFromRest,
)
from ._control import (
    SwingUpTask as SwingUpTask,
)
from ._control import (
    tvlqr as tvlqr,
)
from ._control import (
    upright_error as upright_error,
)
from ._control import (
    wrap_angle as wrap_angle,
)
