"""garment_sim from Python: virtual garment trials and drapes.

``run_trial`` sews a garment onto a body and drapes it, as the command line's
``garment_sim trial`` does and with the same library code; ``run_scene``
drapes a scene as ``garment_sim drape`` does. ``python -m garment_sim sweep``
runs the product of a sweep file's axes on Dask (``garment_sim.sweep``).
See docs/python.md.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Dict, Mapping, Optional, Union

import numpy as np

from . import _native
from ._native import TrialError

__all__ = ["run_trial", "run_scene", "TrialResult", "SceneResult", "TrialError",
           "TRIAL_OVERRIDES", "SCENE_OVERRIDES"]

#: The keyword arguments of ``run_trial``: the command line's ``trial`` options.
TRIAL_OVERRIDES = ("spacing", "dt", "max_time", "threads", "self_collision",
                   "obstacle_edges", "cell_shear", "cg_tolerance", "solver", "hysteresis")
#: The keyword arguments of ``run_scene``: the command line's ``drape`` options.
SCENE_OVERRIDES = ("spacing", "dt", "duration", "threads", "self_collision",
                   "obstacle_edges", "cell_shear", "cg_tolerance", "solver",
                   "hysteresis", "hinges")

Progress = Callable[[str, float, float], Any]
PathLike = Union[str, "os.PathLike[str]"]


def _check(kind: str, overrides: Mapping[str, Any], allowed) -> Dict[str, Any]:
    for k in overrides:
        if k not in allowed:
            raise TypeError(f"{kind}() got an unexpected keyword argument {k!r} "
                            f"(overrides: {', '.join(allowed)})")
    return {k: v for k, v in overrides.items() if v is not None}


def _source(obj, base_dir: Optional[PathLike], what: str):
    """(path, text): a file's path and None, or for a dict a path in
    ``base_dir`` (or the working directory) that its relative paths resolve
    against, and its text (JSON, which YAML reads)."""
    if isinstance(obj, Mapping):
        base = Path(base_dir) if base_dir is not None else Path.cwd()
        return str(base.absolute() / f"<{what} dict>.yaml"), json.dumps(obj)
    if isinstance(obj, (str, os.PathLike)):
        if base_dir is not None:
            raise TypeError("base_dir= is for a dict; a file's paths resolve against its folder")
        return os.fspath(obj), None
    raise TypeError(f"{what}: a path or a dict, not {type(obj).__name__}")


class TrialResult:
    """A finished trial.

    ``fit`` is the fit report (fit.json) as a dict; ``positions`` the garment's
    vertices, float64 (n, 3), m; ``faces`` its triangles, int64 (m, 3);
    ``error`` the failed step's message (the outputs are then those of the
    steps before it), else None. ``write(dir)`` writes every file the command
    line writes.
    """

    def __init__(self, native):
        self._native = native
        self.fit: Dict[str, Any] = json.loads(native.fit_json())
        self.positions: np.ndarray = np.frombuffer(
            native.positions(), dtype="<f8").reshape(-1, 3).copy()
        self.faces: np.ndarray = np.frombuffer(
            native.faces(), dtype="<i8").reshape(-1, 3).copy()
        self.error: Optional[str] = native.error()

    @property
    def settled(self) -> bool:
        """Whether the garment came to rest within the drape's time."""
        return self.fit["run"].get("settle_time_s") is not None

    def write(self, dir: PathLike) -> None:
        """Writes fit.json, garment.obj / .ply, the pictures and the CSV files
        into ``dir`` (created if absent), as ``garment_sim trial --out dir``."""
        self._native.write(os.fspath(dir))

    def __repr__(self) -> str:
        r = self.fit.get("run", {})
        state = "failed" if self.error else ("settled" if self.settled else "not settled")
        return (f"<TrialResult {self.fit.get('garment')!r}: {state}, "
                f"{len(self.positions)} vertices, {r.get('steps')} steps>")


def run_trial(trial: Union[PathLike, Mapping[str, Any]], out: Optional[PathLike] = None,
              progress: Optional[Progress] = None, *, base_dir: Optional[PathLike] = None,
              **overrides: Any) -> TrialResult:
    """Sews a garment onto a body and drapes it: ``garment_sim trial``.

    ``trial``: a trial file's path, or its content as a dict (relative paths in
    it resolve against ``base_dir``, default the working directory).
    ``out``: a folder to write the command line's outputs into.
    ``progress(phase, done, of)``: called about ten times a second while the
    run steps, phase ``"sewing"``, ``"drape"``, ``"motion"`` or ``"dressing"``
    with the phase's progress ``done`` of ``of``.
    ``overrides``: the command line's options, ``spacing`` (m), ``dt`` (s),
    ``max_time`` (s), ``threads``, ``self_collision``, ``obstacle_edges``,
    ``cell_shear``, ``cg_tolerance``, ``solver`` (``"auto"``, ``"pcg"``,
    ``"sgs"``, ``"amg"``, ``"cholesky"``), ``hysteresis`` (False: the laws'
    hysteretic parts off, as ``--no-hysteresis``).

    The GIL is released while the simulation steps. Ctrl-C stops the run
    cleanly: the outputs of the steps taken are written to ``out`` and
    KeyboardInterrupt is raised. A trial that cannot be read or built, or
    whose step fails, raises TrialError with the command line's message
    (for a failed step after writing ``out``; the result is the exception's
    ``result`` attribute).
    """
    ov = _check("run_trial", overrides, TRIAL_OVERRIDES)
    path, text = _source(trial, base_dir, "trial")
    native = _native.run_trial(path, text, progress, **ov)
    result = TrialResult(native)
    if out is not None:
        result.write(out)
    stop = native.take_interrupt()
    if stop is not None:
        raise stop
    if result.error is not None:
        e = TrialError(native.error(None if out is None else os.fspath(out)))
        e.result = result  # type: ignore[attr-defined]
        raise e
    return result


class SceneResult:
    """A finished drape: ``summary`` (summary.json) as a dict, ``positions``
    float64 (n, 3) and ``faces`` int64 (m, 3) of the cloth at the end,
    ``error`` the failed step's message or None; ``write(dir)`` copies its
    outputs (final.ply, final.png, energy.csv, summary.json) into ``dir``."""

    def __init__(self, native, files: Path, keep: Optional[tempfile.TemporaryDirectory]):
        self.summary: Dict[str, Any] = json.loads(native.summary_json())
        self.positions: np.ndarray = np.frombuffer(
            native.positions(), dtype="<f8").reshape(-1, 3).copy()
        self.faces: np.ndarray = np.frombuffer(
            native.faces(), dtype="<i8").reshape(-1, 3).copy()
        self.error: Optional[str] = native.error()
        self._files = files
        self._keep = keep

    def write(self, dir: PathLike) -> None:
        """Copies the drape's output files into ``dir``."""
        d = Path(dir)
        if d.resolve() == self._files.resolve():
            return
        d.mkdir(parents=True, exist_ok=True)
        for f in self._files.iterdir():
            shutil.copy2(f, d / f.name)


def run_scene(scene: Union[PathLike, Mapping[str, Any]], out: Optional[PathLike] = None,
              progress: Optional[Progress] = None, *, base_dir: Optional[PathLike] = None,
              **overrides: Any) -> SceneResult:
    """Drapes a scene: ``garment_sim drape``.

    ``scene``: a scene file's path or its content as a dict (relative paths
    against ``base_dir`` or the working directory); ``out``: the folder of its
    outputs (a temporary one if None, kept while the result lives);
    ``progress(phase, done, of)`` with phase ``"drape"`` and simulated time
    ``done`` of ``of`` s; ``overrides``: ``spacing``, ``dt``, ``duration``,
    ``threads``, ``self_collision``, ``obstacle_edges``, ``cell_shear``,
    ``cg_tolerance``, ``solver``, ``hysteresis``, ``hinges`` (``"skewed"`` or
    ``"mirror_symmetric"``). Errors and Ctrl-C as for
    ``run_trial``.
    """
    ov = _check("run_scene", overrides, SCENE_OVERRIDES)
    path, text = _source(scene, base_dir, "scene")
    keep = None
    if out is None:
        keep = tempfile.TemporaryDirectory(prefix="garment_sim_scene_")
        out = keep.name
    native = _native.run_scene(path, os.fspath(out), text, progress, **ov)
    result = SceneResult(native, Path(out), keep)
    stop = native.take_interrupt()
    if stop is not None:
        raise stop
    if result.error is not None:
        e = TrialError(result.error)
        e.result = result  # type: ignore[attr-defined]
        raise e
    return result
