"""Type stubs of garment_sim (the Python package of docs/python.md)."""

import os
from pathlib import Path
from typing import Any, Callable, Dict, Mapping, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

PathLike = Union[str, "os.PathLike[str]"]
Progress = Callable[[str, float, float], Any]

TRIAL_OVERRIDES: Tuple[str, ...]
SCENE_OVERRIDES: Tuple[str, ...]

class TrialError(Exception):
    """A trial or drape that could not be read, built or run; its message is
    the command line's. ``result`` holds the outcome of a run whose step
    failed (the steps before it)."""

    result: Union["TrialResult", "SceneResult"]

class TrialResult:
    """A finished trial."""

    fit: Dict[str, Any]
    """The fit report, as fit.json holds it."""
    positions: npt.NDArray[np.float64]
    """The garment's vertices, (n, 3), m."""
    faces: npt.NDArray[np.int64]
    """The garment's triangles, (m, 3), indices into ``positions``."""
    error: Optional[str]
    """The failed step's message, or None."""
    @property
    def settled(self) -> bool: ...
    def write(self, dir: PathLike) -> None:
        """Writes every output of ``garment_sim trial --out dir``."""

class SceneResult:
    """A finished drape."""

    summary: Dict[str, Any]
    positions: npt.NDArray[np.float64]
    faces: npt.NDArray[np.int64]
    error: Optional[str]
    def write(self, dir: PathLike) -> None: ...

def run_trial(
    trial: Union[PathLike, Mapping[str, Any]],
    out: Optional[PathLike] = None,
    progress: Optional[Progress] = None,
    *,
    base_dir: Optional[PathLike] = None,
    spacing: Optional[float] = None,
    dt: Optional[float] = None,
    max_time: Optional[float] = None,
    threads: Optional[int] = None,
    self_collision: Optional[bool] = None,
    obstacle_edges: Optional[bool] = None,
    cell_shear: Optional[bool] = None,
    cg_tolerance: Optional[float] = None,
    solver: Optional[str] = None,
    hysteresis: Optional[bool] = None,
) -> TrialResult:
    """Sews a garment onto a body and drapes it, as ``garment_sim trial``."""

def run_scene(
    scene: Union[PathLike, Mapping[str, Any]],
    out: Optional[PathLike] = None,
    progress: Optional[Progress] = None,
    *,
    base_dir: Optional[PathLike] = None,
    spacing: Optional[float] = None,
    dt: Optional[float] = None,
    duration: Optional[float] = None,
    threads: Optional[int] = None,
    self_collision: Optional[bool] = None,
    obstacle_edges: Optional[bool] = None,
    cell_shear: Optional[bool] = None,
    cg_tolerance: Optional[float] = None,
    solver: Optional[str] = None,
    hysteresis: Optional[bool] = None,
    hinges: Optional[str] = None,
) -> SceneResult:
    """Drapes a scene, as ``garment_sim drape``."""
