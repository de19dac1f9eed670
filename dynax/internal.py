"""Building blocks below the pipeline's verbs: `dynax.internal`.

The regressors, filters, covariance helpers, rollouts, solvers, statistics and command-line pieces
that dynax's own tests, experiments and benchmarks call, each under a plain name. A user's programme
needs `dynax` (the verbs and types), `dynax.synthetic` and `dynax.control`; these names serve whoever
checks or measures how dynax works, and they may be regrouped between releases. The code lives in
private modules, one concept per file; this module only re-exports it, in pipeline order.
"""

# Utilities: progress, distributed arrays.
from ._distributed import (
    global_array as global_array,
    leading_sharding as leading_sharding,
    multi_process as multi_process,
    replicate as replicate,
    replicate_in_jit as replicate_in_jit,
)
from ._progress import (
    bar_token as bar_token,
    PROGRESS_MODE as PROGRESS_MODE,
    progress_enabled as progress_enabled,
    report as progress_report,
)

# Data: filters, derivatives, file parsing, data checks.
from ._data import (
    backward_difference as backward_difference,
    butterworth_filtfilt as butterworth_filtfilt,
    central_difference as central_difference,
    parse_assignments as parse_assignments,
    resample as resample,
    savitzky_golay as savitzky_golay,
)
from ._data._io import MAX_MAGNITUDE as MAX_MAGNITUDE
from ._data._velocities import velocity_gain as velocity_gain

# Model: constants and frame helpers of the systems.
from ._model._helicopter import (
    euler_from_quaternion as euler_from_quaternion,
    quaternion_angle as quaternion_angle,
    quaternion_from_euler as quaternion_from_euler,
    RICH_FEATURES as RICH_FEATURES,
    TEMPEST_COEFFICIENTS as TEMPEST_COEFFICIENTS,
    TEMPEST_FEATURES as TEMPEST_FEATURES,
)
from ._model._two_link import DRAKE_DEFAULTS as DRAKE_DEFAULTS

# Simulate: the fixed-grid step, rollouts of measured windows.
from ._simulate import explicit_step as explicit_step, zoh_term as zoh_term
from ._sim_error import (
    complete_state as complete_state,
    rollouts_from_starts as rollouts_from_starts,
    window_rollout as window_rollout,
    window_rollouts as window_rollouts,
)

# Engine: solvers and covariances.
from ._fit import (
    clustered_covariance as clustered_covariance,
    jackknife_covariance as jackknife_covariance,
    levenberg_marquardt as levenberg_marquardt,
    OptaxLBFGS as OptaxLBFGS,
    serial_covariance as serial_covariance,
    StrictTrustRegion as StrictTrustRegion,
)
from ._fit._covariance import bartlett_lags as bartlett_lags, serial_bandwidth as serial_bandwidth
from ._fit._engine import dense_forward as dense_forward

# Identify: regressors, the stacked equations, per-record parts, the refinement's pieces.
from ._identify import (
    consistency_conditions as consistency_conditions,
    dynamic_regressor as dynamic_regressor,
    energy_regressor as energy_regressor,
    friction_power_regressor as friction_power_regressor,
    parameter_names as parameter_names,
    with_friction as with_friction,
)
from ._identify._angle_zeros import record_angle_zeros as record_angle_zeros, shifted as shifted
from ._identify._consistency import min_mass_eigenvalue as min_mass_eigenvalue
from ._identify._defaults import with_velocities_from_positions as with_velocities_from_positions
from ._identify._least_squares import (
    jointly_determined as jointly_determined,
    POORLY_DETERMINED as POORLY_DETERMINED,
)
from ._identify._record_friction import compare_records as compare_records
from ._identify._refine import record_residual_scale as record_residual_scale
from ._identify._regressors import parameter_vector as parameter_vector
from ._identify._validation import CONCENTRATED as CONCENTRATED

# Identify, vehicles: the criteria's fits and window rollouts.
from ._identify._vehicle import (
    auto_stride as auto_stride,
    fit_backprop as fit_backprop,
    fit_frequency as fit_frequency,
    fit_lagged as fit_lagged,
    fit_one_step as fit_one_step,
    initial_helicopter as initial_helicopter,
    lagged_loss as lagged_loss,
    lagged_loss_gradient_norm as lagged_loss_gradient_norm,
    lagged_loss_of as lagged_loss_of,
    prediction_error as prediction_error,
    STATE_GROUPS as STATE_GROUPS,
)
from ._identify._vehicle._frequency import HOVER_DERIVATIVES as HOVER_DERIVATIVES
from ._identify._vehicle._windows import (
    horizon_steps as horizon_steps,
    rollout as vehicle_rollout,
    valid_starts as valid_starts,
)

# Diagnose: candidates, windows and refits, statistics, horizons, the sparse search.
from ._diagnose import feature_library as feature_library, search_period as search_period, stlsq as stlsq
from ._diagnose._candidates import (
    held_partners as held_partners,
    look_alikes as look_alikes,
    structurally_absorbed as structurally_absorbed,
    structurally_equivalent as structurally_equivalent,
)
from ._diagnose._diagnose import stage_reporter as stage_reporter
from ._diagnose._discovery import propose as propose
from ._diagnose._fit import (
    Family as Family,
    fit_configurations as fit_configurations,
    make_windows as make_windows,
    nominal_parameter_names as nominal_parameter_names,
    window_errors as window_errors,
)
from ._diagnose._horizon import (
    position_spread as position_spread,
    predictability_horizon as predictability_horizon,
    relative_position_error as relative_position_error,
)
from ._diagnose._library import named_equivalent as named_equivalent, physical_readings as physical_readings
from ._diagnose._probe import cross_validated_ridge as cross_validated_ridge, folds_by_run as folds_by_run
from ._diagnose._residuals import acceleration_residuals as acceleration_residuals, exact_delays as exact_delays
from ._diagnose._selection import (
    judge_round as judge_round,
    look_alike_tests as look_alike_tests,
    on_physical_side as on_physical_side,
)
from ._diagnose._statistics import (
    benjamini_hochberg as benjamini_hochberg,
    decorrelation_lag as decorrelation_lag,
    detectable_gain as detectable_gain,
    helps_on_most_runs as helps_on_most_runs,
    holm as holm,
    log_ratio_differences as log_ratio_differences,
    paired_block_test as paired_block_test,
    PairedTest as PairedTest,
)
from ._diagnose._verdict import (
    decide as decide_verdict,
    MIN_PRACTICAL_GAIN as MIN_PRACTICAL_GAIN,
    power_of as power_of,
    PRACTICAL_R2 as PRACTICAL_R2,
)
from ._diagnose._validation import fit_percent as fit_percent, residual_tests as residual_tests

# Command line: the entry point, its parser, its output helpers.
from ._cli._diagnose import stage_log as stage_log, summary as diagnosis_summary
from ._cli._main import build_parser as build_parser, main as cli_main
from ._cli._nominal import (
    nominal_from_data as nominal_from_data,
    nominal_system as nominal_system,
    split_term_coefficients as split_term_coefficients,
)
from ._cli._output import staged_directory as staged_directory, write_json as write_json

# Helpers whose private modules still spell them with an underscore: the plain name here is the one
# their modules take once those modules are renamed (and these lines become plain re-exports).
from ._cli._identify import jointly_determined_cell as jointly_determined_cell
from ._diagnose._problem import candidate_family as candidate_family, names_to_refit as names_to_refit
from ._identify._equations import dynamic_rows as dynamic_rows, stacked_equations as stacked_equations
from ._identify._identify import named_parameters as named_parameters
from ._identify._least_squares import tsqr_r as tsqr_r
from ._identify._refine import ml_weights as ml_weights
from ._identify._simulation_fit import (
    segment_clustered_covariance as segment_clustered_covariance,
    record_jackknife_covariance as record_jackknife_covariance,
    simulation_segments as simulation_segments,
)
from ._identify._vehicle._criteria import (
    normal_equations as normal_equations,
    ridge_solve as ridge_solve,
    window_starts as window_starts,
    with_theta as with_theta,
)
from ._model._extensions._terms import float_scalar as float_scalar


# Helpers of the pipeline's stages (data, model, identification, validation, diagnosis).
from ._data import split_at_gaps as split_at_gaps
from ._data._flight import FlightNotes as FlightNotes, usable_segments as usable_segments
from ._progress import progress_mode as progress_mode
from ._model import (
    base_parameters_from_physical as base_parameters_from_physical,
    hover_state as hover_state,
)
from ._model._extensions import (
    AbstractInputTerm as AbstractInputTerm,
    AbstractVehicleTerm as AbstractVehicleTerm,
    Discovered as Discovered,
    Feature as Feature,
)
from ._identify import (
    check_consistency as check_consistency,
    choose_filter as choose_filter,
    consistent_least_squares as consistent_least_squares,
    ConsistentParametrisation as ConsistentParametrisation,
    ConsistentSystem as ConsistentSystem,
    FilterChoice as FilterChoice,
    measurement_noise_std as measurement_noise_std,
    noise_floor_and_band as noise_floor_and_band,
    OutputErrorStatistics as OutputErrorStatistics,
    poorly_determined as poorly_determined,
    record_friction as record_friction,
    record_offsets as record_offsets,
    RecordFriction as RecordFriction,
    RecordOffsets as RecordOffsets,
    refine_by_simulation as refine_by_simulation,
    RefinementStatistics as RefinementStatistics,
    split_for_validation as split_for_validation,
)
from ._identify._refine import delta_method_covariance as delta_method_covariance
from ._identify._vehicle import frequency_responses as frequency_responses
from ._metrics import (
    CrossCorrelationTest as CrossCorrelationTest,
    horizon_fit as horizon_fit,
    kfold_splits as kfold_splits,
    leave_one_out_splits as leave_one_out_splits,
    WhitenessTest as WhitenessTest,
)
from ._diagnose import (
    LOOK_ALIKES as LOOK_ALIKES,
    Proposal as Proposal,
    sparse_search as sparse_search,
    SparseFit as SparseFit,
    Structure as Structure,
    structure_test as structure_test,
    write_report as write_report,
)

# Control: the leaderboard's rollout and the swing-up reference's pieces.
from ._control._from_rest import (
    collocation_reference as collocation_reference,
    end_upright_residuals as end_upright_residuals,
    knot_matrix as knot_matrix,
    open_loop_rollout as open_loop_rollout,
    reference_search as reference_search,
)
from ._control._leaderboard import leaderboard_rollout as leaderboard_rollout
from ._diagnose._quadrotor import body_frame_records as body_frame_records, quadrotor_flight_errors as quadrotor_flight_errors

# Aliased re-exports (`x as y`) count as exports only through `__all__`, so it lists every name.
__all__ = [
    "collocation_reference",
    "end_upright_residuals",
    "knot_matrix",
    "open_loop_rollout",
    "reference_search",
    "leaderboard_rollout",
    "body_frame_records",
    "quadrotor_flight_errors",
    "delta_method_covariance",
    "AbstractInputTerm",
    "AbstractVehicleTerm",
    "check_consistency",
    "OutputErrorStatistics",
    "RefinementStatistics",
    "write_report",
    "split_at_gaps",
    "FlightNotes",
    "usable_segments",
    "progress_mode",
    "base_parameters_from_physical",
    "hover_state",
    "Discovered",
    "Feature",
    "choose_filter",
    "consistent_least_squares",
    "ConsistentParametrisation",
    "ConsistentSystem",
    "FilterChoice",
    "measurement_noise_std",
    "noise_floor_and_band",
    "poorly_determined",
    "record_friction",
    "record_offsets",
    "RecordFriction",
    "RecordOffsets",
    "refine_by_simulation",
    "split_for_validation",
    "frequency_responses",
    "CrossCorrelationTest",
    "horizon_fit",
    "kfold_splits",
    "leave_one_out_splits",
    "WhitenessTest",
    "LOOK_ALIKES",
    "Proposal",
    "sparse_search",
    "SparseFit",
    "Structure",
    "structure_test",
    "decide_verdict", "MIN_PRACTICAL_GAIN", "PairedTest", "power_of", "PRACTICAL_R2",
    "acceleration_residuals", "auto_stride", "backward_difference", "bar_token", "bartlett_lags",
    "benjamini_hochberg", "build_parser", "butterworth_filtfilt", "candidate_family", "central_difference",
    "cli_main", "clustered_covariance", "compare_records", "complete_state", "CONCENTRATED",
    "consistency_conditions", "cross_validated_ridge", "decorrelation_lag", "dense_forward", "detectable_gain",
    "diagnosis_summary", "DRAKE_DEFAULTS", "dynamic_regressor", "dynamic_rows", "energy_regressor",
    "euler_from_quaternion", "exact_delays", "explicit_step", "Family", "feature_library", "fit_backprop",
    "fit_configurations", "fit_frequency", "fit_lagged", "fit_one_step", "fit_percent", "float_scalar",
    "folds_by_run", "friction_power_regressor", "global_array", "held_partners", "helps_on_most_runs", "holm",
    "horizon_steps", "HOVER_DERIVATIVES", "initial_helicopter", "jackknife_covariance", "jointly_determined",
    "jointly_determined_cell", "judge_round", "lagged_loss", "lagged_loss_gradient_norm", "lagged_loss_of",
    "leading_sharding", "levenberg_marquardt", "log_ratio_differences", "look_alike_tests", "look_alikes",
    "make_windows", "MAX_MAGNITUDE", "min_mass_eigenvalue", "ml_weights", "multi_process", "named_equivalent",
    "named_parameters", "names_to_refit", "nominal_from_data", "nominal_parameter_names", "nominal_system",
    "normal_equations", "on_physical_side", "OptaxLBFGS", "paired_block_test", "parameter_names",
    "parameter_vector", "parse_assignments", "physical_readings", "POORLY_DETERMINED", "position_spread",
    "predictability_horizon", "prediction_error", "progress_enabled", "PROGRESS_MODE", "progress_report", "propose",
    "quaternion_angle", "quaternion_from_euler", "record_angle_zeros", "record_jackknife_covariance",
    "record_residual_scale", "relative_position_error", "replicate", "replicate_in_jit", "resample",
    "residual_tests", "RICH_FEATURES", "ridge_solve", "rollouts_from_starts", "savitzky_golay", "search_period",
    "segment_clustered_covariance", "serial_bandwidth", "serial_covariance", "shifted", "simulation_segments",
    "split_term_coefficients", "stacked_equations", "stage_log", "stage_reporter", "staged_directory",
    "STATE_GROUPS", "stlsq", "StrictTrustRegion", "structurally_absorbed", "structurally_equivalent",
    "TEMPEST_COEFFICIENTS", "TEMPEST_FEATURES", "tsqr_r", "valid_starts", "vehicle_rollout", "velocity_gain",
    "window_errors", "window_rollout", "window_rollouts", "window_starts", "with_friction", "with_theta",
    "with_velocities_from_positions", "write_json", "zoh_term"
]
