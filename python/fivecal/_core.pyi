"""Type stubs of the C++ extension module fivecal._core."""
from typing import Any, Callable, Optional, Sequence

import numpy as np

class Machine:
    @staticmethod
    def from_json(text: str) -> Machine: ...
    @staticmethod
    def load(path: str) -> Machine: ...
    def to_json(self) -> str: ...
    name: str
    topology: str
    axis_names: str
    axes: list
    workpiece_chain: str
    tool_chain: str
    tip: np.ndarray
    tool_axis: np.ndarray
    num_parameters: int
    def parameter_names(self) -> list[str]: ...
    def parameter_index(self, name: str) -> int: ...
    def parameter_kind(self, name: str) -> str: ...
    def parameter_is_angular(self, name: str) -> bool: ...

def tool_poses(machine: Machine, theta: np.ndarray, axes: np.ndarray,
               directions: Optional[np.ndarray] = None, tip: Optional[np.ndarray] = None,
               with_axes: bool = True) -> tuple[np.ndarray, Optional[np.ndarray]]: ...
def inverse(machine: Machine, theta: np.ndarray, points: np.ndarray, tool_axes: Optional[np.ndarray],
            start: np.ndarray, directions: Optional[np.ndarray] = None) -> np.ndarray: ...
def machine_kinds() -> list[dict]: ...
def rotation_vectors(values: np.ndarray, form: str, order: str = "wxyz", sequence: str = "", unit: str = "rad",
                     tolerance: float = 1e-3) -> tuple[np.ndarray, list[str]]: ...
def rotations_from_vectors(vectors: np.ndarray, form: str, order: str = "wxyz", sequence: str = "",
                           unit: str = "rad") -> np.ndarray: ...

class Dataset:
    @staticmethod
    def from_json(text: str, require_observations: bool = True) -> Dataset: ...
    def to_json(self) -> str: ...
    def subset(self, indices: Sequence[int]) -> Dataset: ...
    # The dataset file's bytes handed to `write` piece by piece (streamed).
    def write_json(self, write: Callable[[bytes], Any], chunk_bytes: int = 1048576) -> None: ...
    # Everything but the observations, key -> JSON text (Parquet metadata).
    def head(self) -> dict[str, str]: ...
    @staticmethod
    def balls(machine: Machine, type: str, setup: str, axes: np.ndarray, directions: Optional[np.ndarray],
              tool_ball: np.ndarray, table_ball: np.ndarray, length: float, values: np.ndarray,
              sigma: Optional[np.ndarray] = None) -> Dataset: ...
    def columns(self) -> dict[str, np.ndarray]: ...
    machine: Machine
    tip_radius: float
    num_observations: int
    observation_types: list[str]

def simulate(spec_json: str) -> Dataset: ...
def observation_kinds() -> list[dict]: ...
def planned_contact(dataset: Dataset, entry_json: str) -> Optional[tuple[np.ndarray, np.ndarray]]: ...
# What the NC program writers ask of a plan's kinds (observations/nc_geometry.h)
def nc_kinds() -> list[dict]: ...
def planned_touch_contacts(dataset: Dataset, plan_json: str) -> list[Optional[tuple[np.ndarray, np.ndarray, float]]]: ...
def clearance_balls(dataset: Dataset) -> list[tuple[str, np.ndarray, float]]: ...
def probe_line_crossing(dataset: Dataset, type: str, target: str, p: np.ndarray,
                        d: np.ndarray) -> tuple[bool, float, np.ndarray]: ...
def prepared_rows(reset_peak: bool = False) -> dict: ...
def noise_classes() -> list[str]: ...
def noise_class_units() -> dict[str, str]: ...

class UnitResiduals:
    unit: str
    rows: int
    rms: float
    max_abs: float
    sigma: float
    dof: float

class Result:
    names: list[str]
    values: np.ndarray
    estimated: list[str]
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    residuals: np.ndarray
    residual_source: np.ndarray  # int64, one per residual row
    residual_vectors: np.ndarray
    points: np.ndarray
    rms: float
    max_abs: float
    sigma: float
    residual_units: list[UnitResiduals]
    condition_number: float
    rank: int
    unidentifiable: list[list[str]]
    converged: bool
    iterations: int
    message: str
    n_observations: int
    n_parameters: int
    outliers: list[int]
    robust_scale: float
    prior_std: list[float]
    informed: list[float]
    placement: list[float]
    undetermined: list[str]
    implausible: list[str]
    map_fit: bool
    class_scales: dict[str, float]
    chi2: float
    dof: int
    chi2_p: float
    adequate: bool
    adequacy: str
    finite: bool
    seeks_machine_errors: bool
    identified_machine_errors: int
    held: list[str]
    left_out: list[tuple[str, str]]
    @property
    def not_determined(self) -> list[dict]: ...  # family, machine, estimated, names, why
    @property
    def verdict(self) -> str: ...
    def to_json(self) -> str: ...

def identify(dataset: Dataset, estimate: Sequence[str], fix: Sequence[str], initial: dict,
             robust: str = "", robust_scale: float = 0.0, max_iterations: int = 200,
             allow_unidentifiable: bool = False, include_default_setup: bool = True,
             num_threads: int = 1, selection_tolerance: float = 0.01,
             priors: dict = ..., prior: bool = False, variance_components: bool = False,
             fit_path: str = "auto", setup_priors: bool = True) -> Result: ...
def resolve_estimate(dataset: Dataset, estimate: Sequence[str], fix: Sequence[str],
                     initial: dict, priors: dict = ...) -> list[str]: ...
def prior_classes() -> list[dict]: ...
def setup_parameter_unit(name: str) -> str: ...
def is_setup_parameter_name(name: str) -> bool: ...
def informed_threshold() -> float: ...
def predict_residuals(dataset: Dataset, values: dict) -> tuple[np.ndarray, list[int]]: ...

# ---- uncertainty (cpp/bindings/expose-uncertainty.cc) ----------------------------

class SimulationPlan:
    base: Dataset
    seed: int
    values: dict[str, float]
    sensitivity: np.ndarray
    input_sigma: np.ndarray
    input_observation: list[int]
    input_component: list[int]
    num_inputs: int
    @staticmethod
    def from_spec(spec_json: str) -> SimulationPlan: ...
    @staticmethod
    def from_dataset(dataset: Dataset, values: dict, noise: dict) -> SimulationPlan: ...
    def add_noise(self, seed: int) -> Dataset: ...
    def apply_input_deviations(self, deviation: np.ndarray) -> Dataset: ...

class MonteCarloResult:
    estimated: list[str]
    reference: np.ndarray
    truth: np.ndarray
    trials: int
    used: int
    not_converged: int
    failed: int
    threads: int
    seed: int
    seconds: float
    probability: float
    mean: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    low: np.ndarray
    high: np.ndarray
    symmetric_low: np.ndarray
    symmetric_high: np.ndarray
    gum_covariance: np.ndarray
    gum_std: np.ndarray
    gum_low: np.ndarray
    gum_high: np.ndarray
    gum_k: float
    tolerance: np.ndarray
    d_low: np.ndarray
    d_high: np.ndarray
    validated: list[bool]
    stable: list[bool]
    stability: np.ndarray
    std_ratio: np.ndarray
    significant_digits: int
    samples: np.ndarray
    trial_std: np.ndarray
    usable: list[int]
    def to_json(self, include_samples: bool = False) -> str: ...

def monte_carlo(plan: SimulationPlan, estimate: Sequence[str], fix: Sequence[str], initial: dict,
                robust: str = "", robust_scale: float = 0.0, max_iterations: int = 200,
                include_default_setup: bool = True, selection_tolerance: float = 0.01,
                trials: int = 10000, threads: int = 0, seed: int = 1, probability: float = 0.95,
                significant_digits: int = 2, blocks: int = 10,
                input_covariance: Optional[np.ndarray] = None, trial_std: bool = False,
                keep_samples: bool = True,
                progress: Optional[Callable[[int, int], object]] = None) -> MonteCarloResult: ...
def trial_seed(seed: int, trial: int) -> int: ...
def coverage_interval(values: Sequence[float], probability: float) -> tuple[float, float, float, float]: ...
def numerical_tolerance(u: float, significant_digits: int = 2) -> float: ...

class CoverageFactor:
    probability: float
    dof: float
    k: float
    k_joint: float
    outputs: int
    method: str

def coverage_factor(probability: float, dof: float = ..., outputs: int = 0, k: float = 0.0) -> CoverageFactor: ...
def normal_quantile(p: float) -> float: ...
def student_t_quantile(p: float, dof: float) -> float: ...
def chi_square_quantile(p: float, dof: float) -> float: ...
def f_quantile(p: float, dof1: float, dof2: float) -> float: ...

class PooledCovariance:
    covariance: np.ndarray
    mean: np.ndarray
    group_means: np.ndarray
    group_labels: list[int]
    group_sizes: list[int]
    dof: int

def pool_covariance(samples: np.ndarray, groups: Sequence[int]) -> PooledCovariance: ...

class GumResult:
    names: list[str]
    values: np.ndarray
    covariance: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    coverage: CoverageFactor
    expanded: np.ndarray
    def to_json(self) -> str: ...

def gum_propagate(C: np.ndarray, Ux: np.ndarray, names: Sequence[str], values: np.ndarray,
                  coverage: CoverageFactor, prior_term: np.ndarray = ...) -> GumResult: ...

class Sensitivity:
    names: list[str]
    values: np.ndarray
    C: np.ndarray
    input_rows: list[int]
    input_source: list[int]
    prior_term: np.ndarray

def sensitivity_matrix(dataset: Dataset, result: Result) -> Sensitivity: ...

class CyclesUncertainty:
    gum: GumResult
    inputs: PooledCovariance
    estimated: list[str]
    cycle_values: np.ndarray
    output_pooled: np.ndarray
    day: list[int]
    cycle: list[int]
    pooling: str
    def to_json(self) -> str: ...

def gum_from_cycles(cycles: Sequence[Dataset], day: Sequence[int], cycle: Sequence[int],
                    estimate: Sequence[str], fix: Sequence[str], initial: dict, pooling: str = "cycles",
                    probability: float = 0.95, coverage_factor: float = 0.0, reference: int = 0,
                    include_default_setup: bool = True) -> CyclesUncertainty: ...

class PooledStd:
    pooled_std: float
    dof: int
    group_std: list[float]
    group_size: list[int]

def pooled_std(groups: Sequence[Sequence[float]]) -> PooledStd: ...
def window_pooled_std(series: np.ndarray, window: int) -> PooledStd: ...

class GridStatistics:
    points: int
    cycles: int
    window: int
    mean: float
    total_std: float
    total_range: float
    point_pooled_std: np.ndarray
    max_pooled_std: float
    pooled_std: float
    pooled_dof: int
    point_means: np.ndarray
    surface_std: float
    surface_range: float
    cycle_means: np.ndarray
    drift_std: float
    drift_range: float
    point_std: np.ndarray
    point_std_pooled: float
    repeatability: float
    surface_component: float
    drift_component: float
    def to_json(self) -> str: ...

def analyze_grid(P: np.ndarray, window: int = 5) -> GridStatistics: ...

# ---- test design (expose-design.cc), sphere test, machining tests (expose-procedures.cc) ----

class PlanQuality:
    parameters: list[str]
    n_observations: int
    n_rows: int
    n_parameters: int
    n_machine: int
    condition_number: float
    rank: int
    log_det_per_parameter: float
    d_criterion: float
    d_std: float
    predicted_std: np.ndarray
    confounded: list[list[str]]
    def to_json(self) -> str: ...

class DesignResult:
    groups: list[int]
    observations: list[int]
    quality: PlanQuality
    reference: PlanQuality
    history: list[float]
    evaluations: int
    stopped: bool
    def to_json(self) -> str: ...

def characteristic_scale(machine: Machine, name: str, length: float = 400.0) -> float: ...
def plan_quality(dataset: Dataset, estimate: Sequence[str], fix: Sequence[str] = ..., values: dict = ...,
                 sigma: float = 0.0006, characteristic_length: float = 400.0,
                 include_default_setup: bool = True, subset: Optional[Sequence[int]] = None) -> PlanQuality: ...
def design_plan(dataset: Dataset, group: Sequence[int], estimate: Sequence[str], fix: Sequence[str] = ...,
                values: dict = ..., sigma: float = 0.0006, characteristic_length: float = 400.0, *, k: int,
                required: Sequence[int] = ..., criterion: str = "condition", method: str = "exchange",
                max_passes: int = 50, max_touches: int = 0,
                progress: Optional[Callable[[str, int, int, float], bool]] = None) -> DesignResult: ...
def candidate_plan(setup: Dataset, indexations: np.ndarray, directions: Optional[np.ndarray],
                   sphere_normals: np.ndarray, limits: dict, min_dot: float = -0.02,
                   targets: Sequence[str] = ...) -> tuple[str, list[int]]: ...

class SphereFit:
    center: np.ndarray
    radius: float
    residuals: np.ndarray
    out_of_sphericity: float
    max_residual: float
    min_residual: float
    std_residual: float
    rms: float
    iterations: int
    converged: bool

class SphereTestResult:
    sphere: str
    observations: list[int]
    points: np.ndarray
    fit: SphereFit
    size_error: float
    def to_json(self) -> str: ...

def sphere_points(rings: Sequence[tuple[float, int]] = ..., pole: np.ndarray = ...) -> np.ndarray: ...
def fit_sphere(points: np.ndarray, max_iterations: int = 50, tolerance: float = 1e-13) -> SphereFit: ...

class SphereCentreFit:
    center: np.ndarray
    residuals: np.ndarray
    rms: float
    iterations: int
    converged: bool

def fit_sphere_centre(points: np.ndarray, radius: float, start: np.ndarray, max_iterations: int = 50,
                      tolerance: float = 1e-12) -> SphereCentreFit: ...
def table_points(dataset: Dataset, values: dict, indices: Sequence[int]) -> np.ndarray: ...
def sphere_test(dataset: Dataset, sphere: str, values: dict) -> SphereTestResult: ...
def sphere_sensitivity(setup: Dataset, plan_json: str, sphere: str, names: Sequence[str], values: dict = ...,
                       characteristic_length: float = 400.0) -> list[dict]: ...

def spindle_equivalent(machine: Machine, name: str) -> str: ...
def spindle_names(machine: Machine, errors: Sequence[tuple[str, float]]) -> list[tuple[str, float]]: ...
def checked_rotary_axes(machine: Machine) -> list[str]: ...
def pivot_parameters(machine: Machine, axis: str, backlash: bool = True) -> list[str]: ...

class SphereCheckValue:
    name: str
    value: float
    std: float

class SphereCheckAxis:
    axis: str
    pivot: list[SphereCheckValue]
    has_backlash: bool
    backlash: SphereCheckValue

class SphereCheckResult:
    fit: Result
    sphere: str
    estimate: list[str]
    axes: list[SphereCheckAxis]
    change: list[SphereCheckValue]
    positions: np.ndarray
    centres_before: np.ndarray
    centres_after: np.ndarray
    dispersion_before: float
    dispersion_after: float
    condition_number: float
    informed: list[tuple[str, float]]

def sphere_check(dataset: Dataset, sphere: str = "", calibrated_stylus: bool = True, backlash: int = -1,
                 previous: dict[str, tuple[float, float]] = ...) -> SphereCheckResult: ...
def sphere_check_positions(machine: Machine, n: int,
                           limits: dict[str, tuple[float, float]] = ...) -> list[tuple[str, list[float]]]: ...
sphere_check_max_positions: int

class RTestGroup:
    name: str
    observations: list[int]
    deviations: np.ndarray
    ranges: np.ndarray

class RTestResult:
    tests: list[RTestGroup]
    identified: bool
    estimated: list[str]
    fit: Result

def rtest_location_errors(machine: Machine) -> list[str]: ...
def rtest_axis_roles(machine: Machine) -> dict[str, str]: ...
def rtest_sequence(machine: Machine, test: str, step: float, tilt: float,
                   tilt_range: tuple[float, float]) -> np.ndarray: ...
def rtest_path_commands(machine: Machine, rotary: np.ndarray, start: np.ndarray, table_ball: np.ndarray,
                        tool_ball: np.ndarray, chain: bool) -> np.ndarray: ...
def rtest(dataset: Dataset, identify: bool = True, estimate: Sequence[str] = ...) -> RTestResult: ...

class MachiningTest:
    id: str
    point: np.ndarray
    direction: np.ndarray
    pose: np.ndarray
    reference: np.ndarray
    measured: float
    def __init__(self, id: str, point: np.ndarray, direction: np.ndarray, pose: np.ndarray,
                 reference: Optional[np.ndarray] = None, measured: float = 0.0) -> None: ...

class MachiningResult:
    estimated: list[str]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    predicted: np.ndarray
    residuals: np.ndarray
    sigma: float
    condition_number: float
    rank: int
    converged: bool
    iterations: int
    def to_json(self) -> str: ...

def workpiece_setup_names() -> list[str]: ...
def zhang_zhang_tests(machine: Machine, L: float, H: float) -> list[MachiningTest]: ...
def zhang_zhang_first_order(L: float, H: float, a_delta: np.ndarray, a_xi: np.ndarray, c_delta: np.ndarray,
                            c_xi: np.ndarray) -> np.ndarray: ...
def machining_poses(machine: Machine, tests: Sequence[MachiningTest]) -> np.ndarray: ...
def predict_machining(machine: Machine, tests: Sequence[MachiningTest], values: dict) -> np.ndarray: ...
def machining_jacobian(machine: Machine, tests: Sequence[MachiningTest], names: Sequence[str],
                       values: dict) -> np.ndarray: ...
def identify_machining(machine: Machine, tests: Sequence[MachiningTest], estimate: Sequence[str], values: dict,
                       sigma: float = 0.0, max_iterations: int = 50) -> MachiningResult: ...

# LinuxCNC trt kinematics controller model (cpp/bindings/expose-controllers.cc)
def trt_pin_names(kins: str) -> list[str]: ...
def trt_forward(kins: str, pins: dict, joints: np.ndarray) -> np.ndarray: ...
def trt_inverse(kins: str, pins: dict, world: np.ndarray) -> np.ndarray: ...
def trt_match(machine: Machine, kins: str) -> dict: ...
def trt_joints(machine: Machine, kins: str, commands: np.ndarray) -> np.ndarray: ...
def trt_commands(machine: Machine, kins: str, joints: np.ndarray) -> np.ndarray: ...
def trt_fit(machine: Machine, kins: str, theta: np.ndarray, poses: np.ndarray,
            held: dict = ...) -> dict: ...
def controller_models() -> list[str]: ...
def controller_parameters(machine: Machine, model: str, directions: bool = ...,
                          tool_length: bool = ...) -> list[dict]: ...
def controller_absorb(machine: Machine, model: str, theta: np.ndarray, poses: np.ndarray,
                      directions: bool = ..., tool_length: bool = ..., held_pins: dict = ...) -> dict: ...
def verify_change(machine: Machine, previous_names: list, previous: np.ndarray, previous_covariance: np.ndarray,
                  change_names: list, change: np.ndarray, change_covariance: np.ndarray, now_names: list,
                  now: np.ndarray, now_covariance: np.ndarray, k: float = ...,
                  change_covariance: bool = ...) -> dict: ...
def fiveaxis_match(machine: Machine) -> dict: ...
def fiveaxis_forward(pivot_length: float, joints: np.ndarray) -> np.ndarray: ...
def fiveaxis_inverse(pivot_length: float, world: np.ndarray) -> np.ndarray: ...
def fiveaxis_joints(machine: Machine, commands: np.ndarray) -> np.ndarray: ...
def compensate_commands(machine: Machine, theta: np.ndarray, points: np.ndarray,
                        tool_axes: Optional[np.ndarray], nominal: np.ndarray,
                        directions: Optional[np.ndarray] = ..., orientation: bool = ...,
                        max_rotary_correction: float = ...) -> tuple[np.ndarray, list[bool]]: ...
def kinematics_table(machine: Machine, theta: np.ndarray) -> dict: ...
def table_tool_points(names: list[str], chains: list[str], types: list[str], directions: np.ndarray,
                      points: np.ndarray, tool_tip: np.ndarray, part_origin: np.ndarray,
                      part_rotation: np.ndarray, axes: np.ndarray) -> np.ndarray: ...
def vendor_names() -> list[str]: ...
def vendor_info(vendor: str) -> dict: ...
def vendor_values(vendor: str, machine: Machine, theta: np.ndarray, options: dict[str, str] = ...) -> dict: ...
def vendor_tool_points(vendor: str, machine: Machine, values: np.ndarray, axes: np.ndarray,
                       options: dict[str, str] = ...) -> np.ndarray: ...
def vendor_export(vendor: str, machine: Machine, theta: np.ndarray, covariance: np.ndarray, poses: np.ndarray,
                  options: dict[str, str] = ..., old_values: np.ndarray = ...) -> dict: ...
def vendor_to_theta(vendor: str, machine: Machine, values: np.ndarray, poses: np.ndarray,
                    options: dict[str, str] = ...) -> dict: ...

# ---- double ball bar (cpp/bindings/expose-procedures.cc; only what is stubbed so far) ----
class CircularTestResult:
    nominal_radius: float
    runs: list
    hysteresis: float
    has_hysteresis: bool
    diagnosis: object
    cyclic_pitch1: float
    cyclic_pitch2: float
    cyclic_pitches_tried1: int
    cyclic_pitches_tried2: int

def circular_test(runs: Sequence[tuple[np.ndarray, np.ndarray, int]], radius: float, feed: float = 0.0,
                  reversal_spikes: bool = True, spike_width: float = 3.0, lateral_play: bool = True,
                  straightness: bool = True, radial_play: bool = True, cyclic_pitch1: float = 0.0,
                  cyclic_pitch2: float = 0.0, significance: float = 3.0, search_cyclic_pitch1: bool = False,
                  search_cyclic_pitch2: bool = False) -> CircularTestResult: ...
def diagnosis_contribution(name: str, value: float, radius: float, spike_width: float = 3.0,
                           cyclic_pitch1: float = 0.0, cyclic_pitch2: float = 0.0) -> float: ...
def compensate_bar_temperature(readings: np.ndarray, nominal_length: float, alpha_bar: float, t_bar: float,
                               alpha_machine: float, t_machine: float, t_ref: float = 20.0) -> np.ndarray: ...

class WangFourPoint:
    singular_values: np.ndarray
    rank: int
    null_space: np.ndarray
    estimable: list[int]
    solved: bool
    values: np.ndarray

def wang_four_point(sensitivity: np.ndarray, scale: np.ndarray,
                    readings: Optional[np.ndarray] = None) -> WangFourPoint: ...
def bar_length_commands(machine: Machine, tool_ball: np.ndarray, table_ball: np.ndarray, length: float,
                        poses: np.ndarray) -> np.ndarray: ...

class ColumnWriter:
    """The columns of a columnar dataset, written block by block (writer.h)."""
    def __init__(self, dataset: Dataset) -> None: ...
    rows: int
    columns: list[tuple[str, str]]  # (name, "string" | "float64" | "int8")
    def write(self, begin: int, end: int) -> list[tuple]: ...
