"""Type stubs of the C++ extension module fivecal._core."""
from typing import Optional, Sequence

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
               directions: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]: ...
def inverse(machine: Machine, theta: np.ndarray, points: np.ndarray, tool_axes: Optional[np.ndarray],
            start: np.ndarray, directions: Optional[np.ndarray] = None) -> np.ndarray: ...

class Dataset:
    @staticmethod
    def from_json(text: str, require_observations: bool = True) -> Dataset: ...
    def to_json(self) -> str: ...
    def subset(self, indices: Sequence[int]) -> Dataset: ...
    machine: Machine
    tip_radius: float
    num_observations: int
    observation_types: list[str]

def simulate(spec_json: str) -> Dataset: ...

class Result:
    names: list[str]
    values: np.ndarray
    estimated: list[str]
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    residuals: np.ndarray
    residual_source: list[int]
    residual_vectors: np.ndarray
    points: np.ndarray
    rms: float
    max_abs: float
    sigma: float
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
    def to_json(self) -> str: ...

def identify(dataset: Dataset, estimate: Sequence[str], fix: Sequence[str], initial: dict,
             robust: str = "", robust_scale: float = 0.0, max_iterations: int = 200,
             allow_unidentifiable: bool = False, include_default_setup: bool = True,
             num_threads: int = 1, selection_tolerance: float = 0.01) -> Result: ...
def resolve_estimate(dataset: Dataset, estimate: Sequence[str], fix: Sequence[str],
                     initial: dict) -> list[str]: ...
def predict_residuals(dataset: Dataset, values: dict) -> tuple[np.ndarray, list[int]]: ...
