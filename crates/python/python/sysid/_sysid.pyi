"""Type stubs of the compiled module (crates/python/src/lib.rs)."""

from typing import Any, Callable, Dict, List, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from ._result import FitResult, ProfileResult

Scale = Literal["linear", "parameter"]
Sensitivities = Literal["auto", "forward", "adjoint"]
Array = npt.ArrayLike

class SysidError(Exception):
    """What a model or a method cannot do, with the command line's message."""

def methods() -> List[str]:
    """The method names :meth:`Problem.fit` accepts, the default first."""

class Problem:
    """A parameter estimation problem: a PEtab problem, a model file with its data, or a
    system of the benchmark catalogue."""

    @staticmethod
    def from_petab(path: str) -> "Problem": ...
    @staticmethod
    def from_model(path: str, data: Optional[str] = None) -> "Problem": ...
    @staticmethod
    def from_catalogue(name: str, seed: int = 1) -> "Problem": ...
    def with_integrator(
        self,
        rtol: Optional[float] = None,
        atol: Optional[float] = None,
        scheme: Optional[Literal["dopri5", "dop853", "rk4", "rodas4", "rodas5p", "bdf", "auto"]] = None,
        fixed_step: Optional[float] = None,
    ) -> "Problem": ...
    @property
    def name(self) -> str: ...
    @property
    def parameter_names(self) -> List[str]: ...
    @property
    def nominal(self) -> np.ndarray: ...
    @property
    def bounds(self) -> Tuple[np.ndarray, np.ndarray]: ...
    @property
    def scales(self) -> List[Literal["lin", "log"]]: ...
    @property
    def experiments(self) -> List[str]: ...
    def to_parameter_scale(self, x: Array) -> np.ndarray: ...
    def to_linear_scale(self, z: Array) -> np.ndarray: ...
    def nll(self, x: Array, scale: Scale = "linear") -> float: ...
    def nll_and_gradient(
        self, x: Array, scale: Scale = "linear", sensitivities: Sensitivities = "auto"
    ) -> Tuple[float, np.ndarray]: ...
    def objective(self, x: Array, scale: Scale = "linear") -> float: ...
    def objective_and_gradient(
        self, x: Array, scale: Scale = "linear", sensitivities: Sensitivities = "auto"
    ) -> Tuple[float, np.ndarray]: ...
    def fisher(self, x: Array, scale: Scale = "linear") -> np.ndarray: ...
    def residuals_and_jacobian(
        self, x: Array, scale: Scale = "linear"
    ) -> Tuple[np.ndarray, np.ndarray]: ...
    def simulate(
        self,
        times: Array,
        x: Optional[Array] = None,
        experiment: Union[int, str, None] = None,
        scale: Scale = "linear",
    ) -> Dict[str, np.ndarray]: ...
    def fit(
        self,
        method: Optional[str] = None,
        starts: Optional[int] = None,
        seed: int = 1,
        sampling: Literal["uniform", "latin-hypercube"] = "uniform",
        include_nominal: bool = True,
        max_iterations: Optional[int] = None,
        gtol: Optional[float] = None,
        max_integrations: Optional[int] = None,
        max_seconds: Optional[float] = None,
        fix: Optional[Dict[str, float]] = None,
        start: Optional[Dict[str, float]] = None,
        coarse_first: bool = True,
        progress: Optional[Callable[[Dict[str, Any]], Any]] = None,
        trials: Optional[Callable[[Dict[str, Any]], Any]] = None,
    ) -> FitResult: ...
    def profile(
        self,
        method: Optional[str] = None,
        only: Optional[Sequence[str]] = None,
        simultaneous: bool = False,
        max_points: int = 60,
        max_iterations: Optional[int] = None,
        progress: Optional[Callable[[Dict[str, Any]], Any]] = None,
    ) -> ProfileResult: ...
