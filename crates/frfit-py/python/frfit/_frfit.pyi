"""Type stubs of the frfit extension module (see the package docstring)."""

from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, "PathLike[str]"]
_Band = Union[str, Tuple[Optional[float], Optional[float]], None]
_Delay = Union[str, float, None]
_Modes = Union[str, int, Sequence[float], None]

class FrfitError(ValueError): ...

class FrfData:
    def __init__(
        self,
        freq_hz: npt.ArrayLike,
        G: npt.ArrayLike,
        var: Optional[npt.ArrayLike] = None,
        var_noise: Optional[npt.ArrayLike] = None,
        units: Optional[str] = None,
    ) -> None: ...
    @classmethod
    def from_control(cls, frd: Any) -> "FrfData": ...
    @classmethod
    def from_network(cls, ntwk: Any, param: str = "s") -> "FrfData": ...
    @property
    def freq_hz(self) -> npt.NDArray[np.float64]: ...
    @property
    def omega(self) -> npt.NDArray[np.float64]: ...
    @property
    def G(self) -> npt.NDArray[np.complex128]: ...
    @property
    def var(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def var_noise(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def distortion(self) -> Optional[Dict[str, float]]: ...
    @property
    def ny(self) -> int: ...
    @property
    def nu(self) -> int: ...
    @property
    def n_lines(self) -> int: ...
    @property
    def units(self) -> Optional[str]: ...
    @property
    def metadata(self) -> Dict[str, str]: ...
    @property
    def comments(self) -> List[str]: ...
    @property
    def source(self) -> Optional[str]: ...
    def save(self, path: _Path) -> None: ...
    def __len__(self) -> int: ...

class Mode:
    f_hz: float
    zeta: float
    f_hz_std: Optional[float]
    zeta_std: Optional[float]
    rank: int

class StateSpace:
    A: npt.NDArray[np.float64]
    B: npt.NDArray[np.float64]
    C: npt.NDArray[np.float64]
    D: npt.NDArray[np.float64]
    discrete: Optional[Tuple[npt.NDArray[np.float64], ...]]
    dt: Optional[float]
    delay_s: float
    derivative_order: int
    hold: str
    n_states: int
    formula: str
    crosstalk: Optional[npt.NDArray[np.float64]]
    dynamics: List[Dict[str, Any]]
    def save(self, path: _Path) -> None: ...
    def to_control(self, warn: bool = True) -> Any: ...
    def to_dict(self) -> Dict[str, Any]: ...

class Model:
    modes: List[Mode]
    ny: int
    nu: int
    delay_s: float
    delay_s_std: Optional[float]
    delay_fitted: bool
    hold: str
    derivative_order: int
    order: int
    units: Optional[str]
    band_hz: Optional[Tuple[float, float]]
    rigid_body: bool
    feedthrough: Optional[npt.NDArray[np.float64]]
    dynamics: List[Dict[str, Any]]
    convergence: str
    converged: bool
    chain: List[str]
    notes: List[str]
    summary: Optional[Dict[str, Any]]
    def response(self, freq_hz: npt.ArrayLike) -> npt.NDArray[np.complex128]: ...
    def state_space(self, rank_tol: float = 0.0, discrete_fs: Optional[float] = None) -> StateSpace: ...
    def to_control(self, warn: bool = True) -> Any: ...
    def save(self, path: _Path) -> None: ...
    def export_state_space(self, path: _Path, discrete_fs: Optional[float] = None, rank_tol: float = 0.0) -> None: ...
    def to_json(self) -> str: ...

class ErrorStats:
    median_rel: float
    p95_rel: float
    residual_to_noise: float

class Step:
    effect: str
    accepted: bool
    evidence: str
    params: Dict[str, Any]
    uncertainty: Optional[Dict[str, Any]]
    f_statistic: float
    f_critical: float
    added_params: int
    before: ErrorStats
    after: ErrorStats
    superseded_by: Optional[int]
    held_out: Optional[Tuple[float, float]]

class Diagnosis:
    model: Model
    initial_model: Model
    test_predictions: Optional[Tuple[Prediction, Prediction]]
    steps: List[Step]
    verdict: str
    verdict_evidence: str
    initial_errors: ErrorStats
    final_errors: ErrorStats
    summary: Dict[str, Any]
    def report(self, dir: _Path) -> None: ...

class Validation:
    verdict: str
    not_invalidated: bool
    alpha: float
    gamma_max: float
    gamma_median: float
    lines_invalidated_at_zero: int
    freq_hz: npt.NDArray[np.float64]
    gamma: npt.NDArray[np.float64]
    disturbance_bound: npt.NDArray[np.float64]
    model_error: npt.NDArray[np.float64]
    beyond_model_uncertainty: Optional[Dict[str, Any]]
    model_bound: Optional[npt.NDArray[np.float64]]
    gamma_beyond_model: Optional[npt.NDArray[np.float64]]
    result: Dict[str, Any]
    def report(self, dir: _Path) -> None: ...

class Reduction:
    hankel_singular_values: npt.NDArray[np.float64]
    bounds: npt.NDArray[np.float64]
    rigid_order: int
    stable_order: int
    model: Optional[Model]
    error_bound: Optional[float]
    measured_error: Optional[float]

class Prediction:
    nrmse: npt.NDArray[np.float64]
    noise_floor: npt.NDArray[np.float64]
    freq_hz: npt.NDArray[np.float64]
    records: int
    def report(self, dir: _Path) -> None: ...

def predict(
    model: Model,
    u: npt.ArrayLike,
    y: npt.ArrayLike,
    fs: float,
    period: Optional[int] = None,
    drop_periods: int = 0,
    lines: Optional[Sequence[int]] = None,
) -> Prediction: ...
def read(path: _Path) -> FrfData: ...
def nonparametric(
    u: npt.ArrayLike,
    y: npt.ArrayLike,
    fs: float,
    period: Optional[int] = None,
    drop_periods: int = 0,
    lines: Optional[Sequence[int]] = None,
    line_threshold_db: float = 40.0,
    realizations: Optional[int] = None,
) -> FrfData: ...
def fit(
    data: FrfData,
    band: _Band = None,
    init: Optional[str] = None,
    refine: Optional[str] = None,
    hold: Optional[str] = None,
    delay: _Delay = None,
    modes: _Modes = None,
    method: str = "riv",
    weighting: str = "auto",
    frf_type: str = "displacement",
    order: Optional[int] = None,
    bands: Optional[str] = None,
    band_weights: Optional[str] = None,
) -> Model: ...
def diagnose(
    data: FrfData,
    band: _Band = None,
    init: Optional[str] = None,
    refine: Optional[str] = None,
    hold: Optional[str] = None,
    delay: _Delay = None,
    modes: _Modes = None,
    method: str = "riv",
    weighting: str = "auto",
    frf_type: str = "displacement",
    order: Optional[int] = None,
    fs: Optional[float] = None,
    start: Optional[Model] = None,
    test_records: Optional[Tuple[npt.ArrayLike, npt.ArrayLike]] = None,
    test_period: Optional[int] = None,
) -> Diagnosis: ...
def validate(
    model: Model,
    data: FrfData,
    alpha: float = 0.99,
    method: str = "closed-form",
    fit_data: Optional[FrfData] = None,
) -> Validation: ...
def reduce(model: Model, order: Optional[int] = None) -> Reduction: ...
def load_model(path: _Path) -> Model: ...
def simulate_random_modal(
    ny: int = 4,
    nu: int = 4,
    modes: int = 10,
    lines: int = 4000,
    band: Tuple[float, float] = (50.0, 2000.0),
    noise: float = 1e-3,
    rigid_body: bool = False,
    close_pairs: float = 0.1,
    damping: Tuple[float, float] = (0.002, 0.02),
    seed: int = 1,
) -> Tuple[FrfData, FrfData, Dict[str, Any]]: ...
