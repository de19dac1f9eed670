"""Building blocks below the pipeline's verbs: `dynax.internal`.

The regressors, filters, covariance helpers, rollouts, solvers, statistics and command-line pieces
that dynax's own tests, experiments and benchmarks call, each under a plain name. A user's programme
needs `dynax` (the verbs and types), `dynax.synthetic` and `dynax.control`; these names serve whoever
checks or measures how dynax works, and they may be regrouped between releases. The code lives in
private modules, one concept per file; this module only re-exports it, in pipeline order.
"""

# Utilities: progress, distributed arrays.
# Command line: the entry point, its parser, its output helpers.
from ._cli._diagnose import stage_log as stage_log
from ._cli._diagnose import summary as diagnosis_summary

# Helpers whose private modules still spell them with an underscore: the plain name here is the one
# their modules take once those modules are renamed (and these lines become plain re-exports).
from ._cli._identify import jointly_determined_cell as jointly_determined_cell
from ._cli._identify import method_from_args as method_from_args
from ._cli._main import build_parser as build_parser
from ._cli._main import main as cli_main
from ._cli._nominal import (
    nominal_from_data as nominal_from_data,
)
from ._cli._nominal import (
    nominal_system as nominal_system,
)
from ._cli._nominal import (
    split_term_coefficients as split_term_coefficients,
)
from ._cli._notes import collecting as command_warnings
from ._cli._output import staged_directory as staged_directory
from ._cli._output import write_json as write_json
from ._compiled_code import map_usage as map_usage
from ._compiled_code import release_compiled_code as release_compiled_code
from ._control._closed_loop import closed_loop_rollout as closed_loop_rollout

# Control: the leaderboard's rollout and the swing-up reference's pieces.
from ._control._collocation import collocate as collocate
from ._control._collocation import collocation_costs as collocation_costs
from ._control._collocation import defect_jacobian as defect_jacobian
from ._control._collocation import Transcription as Transcription
from ._control._from_rest import (
    collocation_reference as collocation_reference,
)
from ._control._from_rest import (
    end_upright_residuals as end_upright_residuals,
)
from ._control._from_rest import (
    estimator_view as estimator_view,
)
from ._control._from_rest import (
    hand_over_residuals as hand_over_residuals,
)
from ._control._from_rest import (
    knot_matrix as knot_matrix,
)
from ._control._from_rest import (
    open_loop_rollout as open_loop_rollout,
)
from ._control._from_rest import (
    polish_on_constraint as polish_on_constraint,
)
from ._control._from_rest import (
    reference_search as reference_search,
)
from ._control._from_rest import (
    score_surrogate as score_surrogate,
)
from ._control._leaderboard import leaderboard_rollout as leaderboard_rollout

# Data: filters, derivatives, file parsing, data checks.
from ._data import (
    backward_difference as backward_difference,
)
from ._data import (
    butterworth_filtfilt as butterworth_filtfilt,
)
from ._data import (
    central_difference as central_difference,
)
from ._data import DataCheck as DataCheck
from ._data import (
    parse_assignments as parse_assignments,
)
from ._data import (
    resample as resample,
)
from ._data import Rest as Rest
from ._data import rest_stretches as rest_stretches
from ._data import (
    savitzky_golay as savitzky_golay,
)
from ._data import speed_noise_at_rest as speed_noise_at_rest
from ._data import speeds_zeroed_at_rest as speeds_zeroed_at_rest

# Helpers of the pipeline's stages (data, model, identification, validation, diagnosis).
from ._data import split_at_gaps as split_at_gaps
from ._data._derivatives import input_resampling as input_resampling
from ._data._derivatives import sample_times_from_positions as sample_times_from_positions
from ._data._flight import check_input_levels as check_input_levels
from ._data._flight import FlightChecks as FlightChecks
from ._data._flight import FlightNotes as FlightNotes
from ._data._flight import input_levels as input_levels
from ._data._flight import motors_running_run as motors_running_run
from ._data._flight import usable_segments as usable_segments
from ._data._flight_kinematics import attitude_angles as attitude_angles
from ._data._flight_kinematics import rate_frame_misfits as rate_frame_misfits
from ._data._flight_kinematics import signed_reading_fix as signed_reading_fix
from ._data._flight_kinematics import signed_reading_misfits as signed_reading_misfits
from ._data._flight_kinematics import thrust_frame_slopes as thrust_frame_slopes
from ._data._io import MAX_MAGNITUDE as MAX_MAGNITUDE
from ._data._motor_order import flight_signature as flight_signature
from ._data._motor_order import motor_order as motor_order
from ._data._motor_order import motor_signature as motor_signature
from ._data._motor_order import MotorNumbering as MotorNumbering
from ._data._motor_order import MotorSignature as MotorSignature
from ._data._motor_order import order_text as order_text
from ._data._motor_order import PERMUTATIONS as PERMUTATIONS
from ._data._motor_order import warn_if_numbered_otherwise as warn_if_numbered_otherwise
from ._data._sampling import steady_ticks as steady_ticks
from ._data._sanity import GLITCH_STEPS as GLITCH_STEPS
from ._data._sanity import median_reach as median_reach
from ._data._sanity import typical_step_covers as typical_step_covers
from ._data._screens import screens_off as screens_off
from ._data._spectra import choose_filter as choose_filter
from ._data._spectra import filter_rule as filter_rule
from ._data._spectra import FilterChoice as FilterChoice
from ._data._spectra import measurement_noise_std as measurement_noise_std
from ._data._spectra import noise_floor_and_band as noise_floor_and_band
from ._data._spectra import position_fit_window as position_fit_window
from ._data._spectra import trim_and_decimation as trim_and_decimation
from ._data._spectra import velocities_from_positions as velocities_from_positions
from ._data._spectra import with_velocities_from_positions as with_velocities_from_positions
from ._data._velocities import check_trajectory_velocities as check_trajectory_velocities
from ._data._velocities import gain_surely_within as gain_surely_within
from ._data._velocities import MAX_GAIN_ERROR as MAX_VELOCITY_GAIN_ERROR
from ._data._velocities import velocity_gain as velocity_gain
from ._data._velocities import velocity_lag as velocity_lag
from ._data._velocities import VelocityLag as VelocityLag

# Diagnose: candidates, windows and refits, statistics, horizons, the sparse search.
from ._diagnose import Discovery as Discovery
from ._diagnose import feature_library as feature_library
from ._diagnose import FeatureRegression as FeatureRegression
from ._diagnose import JointRests as JointRests
from ._diagnose import (
    LOOK_ALIKES as LOOK_ALIKES,
)
from ._diagnose import (
    Proposal as Proposal,
)
from ._diagnose import rests_under_load as rests_under_load
from ._diagnose import search_period as search_period
from ._diagnose import (
    sparse_search as sparse_search,
)
from ._diagnose import SparseSearch as SparseSearch
from ._diagnose import (
    SparseStatistics as SparseStatistics,
)
from ._diagnose import (
    Stability as Stability,
)
from ._diagnose import stlsq as stlsq
from ._diagnose import (
    Structure as Structure,
)
from ._diagnose import (
    structure_test as structure_test,
)
from ._diagnose import (
    write_report as write_report,
)
from ._diagnose._candidates import candidate_scales as candidate_scales
from ._diagnose._candidates import (
    held_partners as held_partners,
)
from ._diagnose._candidates import (
    look_alikes as look_alikes,
)
from ._diagnose._candidates import stiction_not_proposed as stiction_not_proposed
from ._diagnose._candidates import (
    structurally_absorbed as structurally_absorbed,
)
from ._diagnose._candidates import (
    structurally_equivalent as structurally_equivalent,
)
from ._diagnose._diagnose import stage_reporter as stage_reporter
from ._diagnose._discovery import DiscoverySearch as DiscoverySearch
from ._diagnose._discovery import HeldOutTest as HeldOutTest
from ._diagnose._discovery import propose as propose
from ._diagnose._fit import (
    Family as Family,
)
from ._diagnose._fit import (
    fit_configurations as fit_configurations,
)
from ._diagnose._fit import (
    make_windows as make_windows,
)
from ._diagnose._fit import (
    movable_parameters as movable_parameters,
)
from ._diagnose._fit import (
    nominal_parameter_names as nominal_parameter_names,
)
from ._diagnose._fit import (
    window_errors as window_errors,
)
from ._diagnose._forward import first_screening as first_screening
from ._diagnose._library import named_equivalent as named_equivalent
from ._diagnose._library import physical_readings as physical_readings
from ._diagnose._probe import cross_validated_ridge as cross_validated_ridge
from ._diagnose._probe import folds_by_run as folds_by_run
from ._diagnose._problem import candidate_family as candidate_family
from ._diagnose._problem import cross_fit_folds as cross_fit_folds
from ._diagnose._problem import flight_state_scale as flight_state_scale
from ._diagnose._problem import Fold as Fold
from ._diagnose._problem import names_to_refit as names_to_refit
from ._diagnose._problem import overlapping_fit_windows as overlapping_fit_windows
from ._diagnose._problem import prepare_problem as prepare_problem
from ._diagnose._problem import Problem as Problem
from ._diagnose._problem import vehicle_state_groups as vehicle_state_groups
from ._diagnose._quadrotor import (
    body_frame_records as body_frame_records,
)
from ._diagnose._quadrotor import body_frame_system as body_frame_system
from ._diagnose._quadrotor import moment_parameters as moment_parameters
from ._diagnose._quadrotor import quadrotor_candidates as quadrotor_candidates
from ._diagnose._quadrotor import (
    quadrotor_flight_errors as quadrotor_flight_errors,
)
from ._diagnose._quadrotor import quadrotor_refit_names as quadrotor_refit_names
from ._diagnose._quadrotor import score_flights as score_flights
from ._diagnose._quadrotor import short_horizon_note as short_horizon_note
from ._diagnose._quadrotor import thrust_parameters as thrust_parameters
from ._diagnose._quadrotor import WorldFrameQuadrotor as WorldFrameQuadrotor
from ._diagnose._records import horizon_errors as horizon_errors
from ._diagnose._records import horizon_grid as horizon_grid
from ._diagnose._residuals import acceleration_residuals as acceleration_residuals
from ._diagnose._residuals import applied_inputs as applied_inputs
from ._diagnose._residuals import exact_delays as exact_delays
from ._diagnose._residuals import interval_increments as interval_increments
from ._diagnose._residuals import padded_length as padded_length
from ._diagnose._residuals import predicted_accelerations as predicted_accelerations
from ._diagnose._residuals import sg_window as sg_window
from ._diagnose._residuals import shared_length as shared_length
from ._diagnose._rollout_screening import rankable as rankable
from ._diagnose._rollout_screening import rollout_screen as rollout_screen
from ._diagnose._rollout_screening import with_rollout_evidence as with_rollout_evidence
from ._diagnose._selection import (
    judge_round as judge_round,
)
from ._diagnose._selection import (
    look_alike_tests as look_alike_tests,
)
from ._diagnose._selection import (
    on_physical_side as on_physical_side,
)
from ._diagnose._selection import (
    Refitted as Refitted,
)
from ._diagnose._statistics import (
    benjamini_hochberg as benjamini_hochberg,
)
from ._diagnose._statistics import (
    decorrelation_lag as decorrelation_lag,
)
from ._diagnose._statistics import (
    detectable_gain as detectable_gain,
)
from ._diagnose._statistics import (
    detectable_shift as detectable_shift,
)
from ._diagnose._statistics import (
    helps_on_most_runs as helps_on_most_runs,
)
from ._diagnose._statistics import (
    holm as holm,
)
from ._diagnose._statistics import (
    length_for_shift as length_for_shift,
)
from ._diagnose._statistics import (
    log_ratio_differences as log_ratio_differences,
)
from ._diagnose._statistics import (
    paired_block_test as paired_block_test,
)
from ._diagnose._statistics import (
    PairedTest as PairedTest,
)
from ._diagnose._summaries import merge_repeated_causes as merge_repeated_causes
from ._diagnose._validation import fit_percent as fit_percent
from ._diagnose._validation import residual_tests as residual_tests
from ._diagnose._verdict import (
    decide as decide_verdict,
)
from ._diagnose._verdict import (
    MIN_PRACTICAL_GAIN as MIN_PRACTICAL_GAIN,
)
from ._diagnose._verdict import (
    power_of as power_of,
)
from ._diagnose._verdict import (
    PRACTICAL_R2 as PRACTICAL_R2,
)
from ._distributed import (
    global_array as global_array,
)
from ._distributed import (
    leading_sharding as leading_sharding,
)
from ._distributed import (
    multi_process as multi_process,
)
from ._distributed import (
    replicate as replicate,
)
from ._distributed import (
    replicate_in_jit as replicate_in_jit,
)

# Engine: solvers and covariances, the statistics types.
from ._fit import AbstractStatistics as AbstractStatistics
from ._fit import (
    clustered_covariance as clustered_covariance,
)
from ._fit import (
    jackknife_covariance as jackknife_covariance,
)
from ._fit import (
    levenberg_marquardt as levenberg_marquardt,
)
from ._fit import (
    OptaxLBFGS as OptaxLBFGS,
)
from ._fit import (
    serial_covariance as serial_covariance,
)
from ._fit import Statistics as Statistics
from ._fit import (
    StrictTrustRegion as StrictTrustRegion,
)
from ._fit._covariance import bartlett_lags as bartlett_lags
from ._fit._covariance import serial_bandwidth as serial_bandwidth
from ._fit._engine import dense_forward as dense_forward
from ._identify import (
    check_consistency as check_consistency,
)
from ._identify import Consistency as Consistency

# Identify: regressors, the stacked equations, per-record parts, the refinement's pieces.
from ._identify import (
    consistency_conditions as consistency_conditions,
)
from ._identify import (
    consistent_least_squares as consistent_least_squares,
)
from ._identify import (
    ConsistentParametrisation as ConsistentParametrisation,
)
from ._identify import (
    ConsistentSystem as ConsistentSystem,
)
from ._identify import (
    dynamic_regressor as dynamic_regressor,
)
from ._identify import (
    energy_regressor as energy_regressor,
)
from ._identify import (
    friction_power_regressor as friction_power_regressor,
)
from ._identify import (
    JointStaticFriction as JointStaticFriction,
)
from ._identify import (
    OutputErrorStatistics as OutputErrorStatistics,
)
from ._identify import (
    parameter_names as parameter_names,
)
from ._identify import (
    poorly_determined as poorly_determined,
)
from ._identify import (
    record_friction as record_friction,
)
from ._identify import (
    record_offsets as record_offsets,
)
from ._identify import (
    RecordFriction as RecordFriction,
)
from ._identify import (
    RecordOffsets as RecordOffsets,
)
from ._identify import (
    refine_by_simulation as refine_by_simulation,
)
from ._identify import (
    RefinementStatistics as RefinementStatistics,
)
from ._identify import (
    RestUnderLoad as RestUnderLoad,
)
from ._identify import (
    split_for_validation as split_for_validation,
)
from ._identify import (
    StaticFriction as StaticFriction,
)
from ._identify import (
    with_friction as with_friction,
)
from ._identify._angle_zeros import record_angle_zeros as record_angle_zeros
from ._identify._angle_zeros import shifted as shifted
from ._identify._consistency import consistent_parametrisation as consistent_parametrisation
from ._identify._consistency import min_mass_eigenvalue as min_mass_eigenvalue
from ._identify._equations import dynamic_rows as dynamic_rows
from ._identify._equations import stacked_equations as stacked_equations
from ._identify._least_squares import (
    jointly_determined as jointly_determined,
)
from ._identify._least_squares import least_squares as least_squares
from ._identify._least_squares import (
    POORLY_DETERMINED as POORLY_DETERMINED,
)
from ._identify._least_squares import tsqr_r as tsqr_r
from ._identify._ls_stage import least_squares_seen as least_squares_seen
from ._identify._ls_stage import partway_search_seen as partway_search_seen
from ._identify._ls_stage import PartwayStretch as PartwayStretch
from ._identify._ls_stage import records_less_offsets as records_less_offsets
from ._identify._method import FitSettings as FitSettings
from ._identify._method import Fitted as Fitted
from ._identify._method import IdentifyJob as IdentifyJob
from ._identify._method import Prepared as Prepared
from ._identify._record_friction import compare_records as compare_records
from ._identify._refine import DEFAULT_RECORD_WEIGHTS as DEFAULT_RECORD_WEIGHTS
from ._identify._refine import delta_method_covariance as delta_method_covariance
from ._identify._refine import ml_weights as ml_weights
from ._identify._refine import motion_records as motion_records
from ._identify._refine import record_residual_scale as record_residual_scale
from ._identify._refine import RECORD_WEIGHTS as RECORD_WEIGHTS
from ._identify._refine import refinement_options as refinement_options
from ._identify._refine import TimedInputs as TimedInputs
from ._identify._refine import with_neighbour_inputs as with_neighbour_inputs
from ._identify._regressors import parameter_vector as parameter_vector
from ._identify._result import warn_if_refinement_left_equations as warn_if_refinement_left_equations
from ._identify._simulation_fit import named_parameters as named_parameters
from ._identify._simulation_fit import (
    record_jackknife_covariance as record_jackknife_covariance,
)
from ._identify._simulation_fit import (
    segment_clustered_covariance as segment_clustered_covariance,
)
from ._identify._simulation_fit import (
    simulation_segments as simulation_segments,
)
from ._identify._stages import all_rests_left_out as all_rests_left_out
from ._identify._stages import refinement_method as refinement_method
from ._identify._stages import rest_search_off as rest_search_off
from ._identify._static_friction import joint_levels as joint_levels
from ._identify._static_friction import record_rests as record_rests
from ._identify._static_friction import rests_under_load as static_friction_rests  # diagnose's takes the plain name
from ._identify._static_friction import slow_rows as slow_rows
from ._identify._validation import CONCENTRATED as CONCENTRATED
from ._identify._validation import HeldOut as HeldOut

# Identify, vehicles: the criteria's fits and window rollouts.
from ._identify._vehicle import (
    auto_stride as auto_stride,
)
from ._identify._vehicle import (
    fit_backprop as fit_backprop,
)
from ._identify._vehicle import (
    fit_frequency as fit_frequency,
)
from ._identify._vehicle import (
    fit_lagged as fit_lagged,
)
from ._identify._vehicle import (
    fit_one_step as fit_one_step,
)
from ._identify._vehicle import frequency_responses as frequency_responses
from ._identify._vehicle import (
    initial_helicopter as initial_helicopter,
)
from ._identify._vehicle import (
    lagged_loss as lagged_loss,
)
from ._identify._vehicle import (
    lagged_loss_gradient_norm as lagged_loss_gradient_norm,
)
from ._identify._vehicle import (
    lagged_loss_of as lagged_loss_of,
)
from ._identify._vehicle import (
    prediction_error as prediction_error,
)
from ._identify._vehicle import (
    recorded_loss as recorded_loss,
)
from ._identify._vehicle import (
    STATE_GROUPS as STATE_GROUPS,
)
from ._identify._vehicle import VehicleStatistics as VehicleStatistics
from ._identify._vehicle._criteria import (
    AbstractVehicleCriterion as AbstractVehicleCriterion,
)
from ._identify._vehicle._criteria import (
    normal_equations as normal_equations,
)
from ._identify._vehicle._criteria import (
    ridge_solve as ridge_solve,
)
from ._identify._vehicle._criteria import (
    window_starts as window_starts,
)
from ._identify._vehicle._criteria import (
    with_theta as with_theta,
)
from ._identify._vehicle._frequency import HOVER_DERIVATIVES as HOVER_DERIVATIVES
from ._identify._vehicle._windows import (
    horizon_steps as horizon_steps,
)
from ._identify._vehicle._windows import (
    rollout as vehicle_rollout,
)
from ._identify._vehicle._windows import (
    valid_starts as valid_starts,
)
from ._model import AbstractBodyModel as AbstractBodyModel
from ._model import (
    base_parameters_from_physical as base_parameters_from_physical,
)
from ._model import (
    hover_state as hover_state,
)
from ._model._extensions import (
    AbstractInputTerm as AbstractInputTerm,
)
from ._model._extensions import (
    AbstractVehicleTerm as AbstractVehicleTerm,
)
from ._model._extensions import (
    Discovered as Discovered,
)
from ._model._extensions import (
    Feature as Feature,
)
from ._model._extensions import (
    MotorLag as MotorLag,
)
from ._model._extensions import (
    PlanarRotorDrag as PlanarRotorDrag,
)
from ._model._extensions._terms import float_scalar as float_scalar

# Model: constants and frame helpers of the systems.
from ._model._helicopter import (
    euler_from_quaternion as euler_from_quaternion,
)
from ._model._helicopter import (
    quaternion_angle as quaternion_angle,
)
from ._model._helicopter import (
    quaternion_from_euler as quaternion_from_euler,
)
from ._model._helicopter import (
    RICH_FEATURES as RICH_FEATURES,
)
from ._model._helicopter import (
    TEMPEST_COEFFICIENTS as TEMPEST_COEFFICIENTS,
)
from ._model._helicopter import (
    TEMPEST_FEATURES as TEMPEST_FEATURES,
)
from ._model._linear_in_parameters import (
    AbstractLinearInParameters as AbstractLinearInParameters,
)
from ._model._linear_in_parameters import (
    identification_hooks as identification_hooks,
)
from ._model._two_link import DRAKE_DEFAULTS as DRAKE_DEFAULTS
from ._progress import (
    bar_token as bar_token,
)
from ._progress import (
    progress_enabled as progress_enabled,
)
from ._progress import (
    PROGRESS_MODE as PROGRESS_MODE,
)
from ._progress import progress_mode as progress_mode
from ._progress import ProgressBar as ProgressBar
from ._progress import (
    report as progress_report,
)
from ._simulate import (
    complete_state as complete_state,
)

# Simulate: the fixed-grid step, rollouts of measured windows.
from ._simulate import explicit_step as explicit_step
from ._simulate import (
    rollouts_from_starts as rollouts_from_starts,
)
from ._simulate import Simulation as Simulation
from ._simulate import (
    window_rollout as window_rollout,
)
from ._simulate import (
    window_rollouts as window_rollouts,
)
from ._simulate import (
    window_simulation_errors as window_simulation_errors,
)
from ._simulate import zoh_term as zoh_term
from ._simulate._predict import group_errors as group_errors
from ._simulate._predict import stable_substeps as stable_substeps
from ._simulate._simulate import fixed_grid_rollout as fixed_grid_rollout
from ._validate import (
    CrossCorrelationTest as CrossCorrelationTest,
)
from ._validate import (
    horizon_fit as horizon_fit,
)
from ._validate import (
    kfold_splits as kfold_splits,
)
from ._validate import (
    leave_one_out_splits as leave_one_out_splits,
)
from ._validate import (
    position_spread as position_spread,
)
from ._validate import (
    predictability_horizon as predictability_horizon,
)
from ._validate import (
    relative_position_error as relative_position_error,
)
from ._validate import (
    WhitenessTest as WhitenessTest,
)

# Aliased re-exports (`x as y`) count as exports only through `__all__`, so it lists every name.
__all__ = [
    "AbstractBodyModel",
    "AbstractInputTerm",
    "AbstractLinearInParameters",
    "AbstractStatistics",
    "AbstractVehicleCriterion",
    "AbstractVehicleTerm",
    "acceleration_residuals",
    "all_rests_left_out",
    "applied_inputs",
    "attitude_angles",
    "auto_stride",
    "backward_difference",
    "bar_token",
    "bartlett_lags",
    "base_parameters_from_physical",
    "benjamini_hochberg",
    "body_frame_records",
    "body_frame_system",
    "build_parser",
    "butterworth_filtfilt",
    "candidate_family",
    "candidate_scales",
    "central_difference",
    "check_consistency",
    "check_input_levels",
    "check_trajectory_velocities",
    "choose_filter",
    "cli_main",
    "closed_loop_rollout",
    "clustered_covariance",
    "collocate",
    "collocation_costs",
    "collocation_reference",
    "command_warnings",
    "compare_records",
    "complete_state",
    "CONCENTRATED",
    "Consistency",
    "consistency_conditions",
    "consistent_least_squares",
    "consistent_parametrisation",
    "ConsistentParametrisation",
    "ConsistentSystem",
    "cross_fit_folds",
    "cross_validated_ridge",
    "CrossCorrelationTest",
    "DataCheck",
    "decide_verdict",
    "decorrelation_lag",
    "DEFAULT_RECORD_WEIGHTS",
    "defect_jacobian",
    "delta_method_covariance",
    "dense_forward",
    "detectable_gain",
    "detectable_shift",
    "diagnosis_summary",
    "Discovered",
    "Discovery",
    "DiscoverySearch",
    "DRAKE_DEFAULTS",
    "dynamic_regressor",
    "dynamic_rows",
    "end_upright_residuals",
    "energy_regressor",
    "estimator_view",
    "euler_from_quaternion",
    "exact_delays",
    "explicit_step",
    "Family",
    "Feature",
    "feature_library",
    "FeatureRegression",
    "filter_rule",
    "FilterChoice",
    "first_screening",
    "fit_backprop",
    "fit_configurations",
    "fit_frequency",
    "fit_lagged",
    "fit_one_step",
    "fit_percent",
    "FitSettings",
    "Fitted",
    "fixed_grid_rollout",
    "flight_signature",
    "flight_state_scale",
    "FlightChecks",
    "FlightNotes",
    "float_scalar",
    "Fold",
    "folds_by_run",
    "frequency_responses",
    "friction_power_regressor",
    "gain_surely_within",
    "GLITCH_STEPS",
    "global_array",
    "group_errors",
    "hand_over_residuals",
    "held_partners",
    "HeldOut",
    "HeldOutTest",
    "helps_on_most_runs",
    "holm",
    "horizon_errors",
    "horizon_fit",
    "horizon_grid",
    "horizon_steps",
    "HOVER_DERIVATIVES",
    "hover_state",
    "identification_hooks",
    "IdentifyJob",
    "initial_helicopter",
    "input_levels",
    "input_resampling",
    "interval_increments",
    "jackknife_covariance",
    "joint_levels",
    "jointly_determined",
    "jointly_determined_cell",
    "JointRests",
    "JointStaticFriction",
    "judge_round",
    "kfold_splits",
    "knot_matrix",
    "lagged_loss",
    "lagged_loss_gradient_norm",
    "lagged_loss_of",
    "leaderboard_rollout",
    "leading_sharding",
    "least_squares",
    "least_squares_seen",
    "leave_one_out_splits",
    "levenberg_marquardt",
    "length_for_shift",
    "log_ratio_differences",
    "look_alike_tests",
    "look_alikes",
    "LOOK_ALIKES",
    "make_windows",
    "MAX_MAGNITUDE",
    "MAX_VELOCITY_GAIN_ERROR",
    "measurement_noise_std",
    "median_reach",
    "merge_repeated_causes",
    "method_from_args",
    "min_mass_eigenvalue",
    "MIN_PRACTICAL_GAIN",
    "ml_weights",
    "moment_parameters",
    "motion_records",
    "motor_order",
    "motor_signature",
    "MotorLag",
    "MotorNumbering",
    "motors_running_run",
    "MotorSignature",
    "movable_parameters",
    "multi_process",
    "named_equivalent",
    "named_parameters",
    "names_to_refit",
    "noise_floor_and_band",
    "nominal_from_data",
    "nominal_parameter_names",
    "nominal_system",
    "normal_equations",
    "on_physical_side",
    "open_loop_rollout",
    "OptaxLBFGS",
    "order_text",
    "OutputErrorStatistics",
    "overlapping_fit_windows",
    "padded_length",
    "paired_block_test",
    "PairedTest",
    "parameter_names",
    "parameter_vector",
    "parse_assignments",
    "partway_search_seen",
    "PartwayStretch",
    "PERMUTATIONS",
    "physical_readings",
    "PlanarRotorDrag",
    "polish_on_constraint",
    "poorly_determined",
    "POORLY_DETERMINED",
    "position_fit_window",
    "position_spread",
    "power_of",
    "PRACTICAL_R2",
    "predictability_horizon",
    "predicted_accelerations",
    "prediction_error",
    "prepare_problem",
    "Prepared",
    "Problem",
    "progress_enabled",
    "PROGRESS_MODE",
    "map_usage",
    "release_compiled_code",
    "progress_mode",
    "progress_report",
    "ProgressBar",
    "Proposal",
    "propose",
    "quadrotor_candidates",
    "quadrotor_flight_errors",
    "quadrotor_refit_names",
    "quaternion_angle",
    "quaternion_from_euler",
    "rankable",
    "rate_frame_misfits",
    "record_angle_zeros",
    "record_friction",
    "record_jackknife_covariance",
    "record_offsets",
    "record_residual_scale",
    "record_rests",
    "RECORD_WEIGHTS",
    "recorded_loss",
    "RecordFriction",
    "RecordOffsets",
    "records_less_offsets",
    "reference_search",
    "refine_by_simulation",
    "refinement_method",
    "refinement_options",
    "RefinementStatistics",
    "Refitted",
    "relative_position_error",
    "replicate",
    "replicate_in_jit",
    "resample",
    "residual_tests",
    "Rest",
    "rest_search_off",
    "rest_stretches",
    "rests_under_load",
    "RestUnderLoad",
    "RICH_FEATURES",
    "ridge_solve",
    "rollout_screen",
    "rollouts_from_starts",
    "sample_times_from_positions",
    "savitzky_golay",
    "score_flights",
    "score_surrogate",
    "screens_off",
    "search_period",
    "segment_clustered_covariance",
    "serial_bandwidth",
    "serial_covariance",
    "sg_window",
    "shared_length",
    "shifted",
    "short_horizon_note",
    "signed_reading_fix",
    "signed_reading_misfits",
    "Simulation",
    "simulation_segments",
    "slow_rows",
    "sparse_search",
    "SparseSearch",
    "SparseStatistics",
    "speed_noise_at_rest",
    "speeds_zeroed_at_rest",
    "split_at_gaps",
    "split_for_validation",
    "split_term_coefficients",
    "Stability",
    "stable_substeps",
    "stacked_equations",
    "stage_log",
    "stage_reporter",
    "staged_directory",
    "STATE_GROUPS",
    "static_friction_rests",
    "StaticFriction",
    "Statistics",
    "steady_ticks",
    "stiction_not_proposed",
    "stlsq",
    "StrictTrustRegion",
    "structurally_absorbed",
    "structurally_equivalent",
    "Structure",
    "structure_test",
    "TEMPEST_COEFFICIENTS",
    "TEMPEST_FEATURES",
    "thrust_frame_slopes",
    "thrust_parameters",
    "TimedInputs",
    "Transcription",
    "trim_and_decimation",
    "tsqr_r",
    "typical_step_covers",
    "usable_segments",
    "valid_starts",
    "vehicle_rollout",
    "vehicle_state_groups",
    "VehicleStatistics",
    "velocities_from_positions",
    "velocity_gain",
    "velocity_lag",
    "VelocityLag",
    "warn_if_numbered_otherwise",
    "warn_if_refinement_left_equations",
    "WhitenessTest",
    "window_errors",
    "window_rollout",
    "window_rollouts",
    "window_simulation_errors",
    "window_starts",
    "with_friction",
    "with_neighbour_inputs",
    "with_rollout_evidence",
    "with_theta",
    "with_velocities_from_positions",
    "WorldFrameQuadrotor",
    "write_json",
    "write_report",
    "zoh_term",
]
