//! `garment_sim._native`: the library's trial and drape, called from Python.
//!
//! The Python package (`garment_sim/__init__.py`) wraps these functions: it
//! checks the keyword arguments, turns a dict into the trial file's text and
//! the raw arrays into NumPy arrays. A run holds no GIL while it steps: the
//! GIL is taken again only to call the progress callback and check for
//! signals, at most [`CADENCE_S`] apart (and at each new phase).

use garment_sim::run::{Control, Step};
use garment_sim::scene::HingesFile;
use garment_sim::scene::{Overrides, Scene};
use garment_sim::solver::LinearSolverKind;
use garment_sim::trial::{Trial, TrialOutcome};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pyo3::create_exception!(
    garment_sim,
    TrialError,
    PyException,
    "A trial or drape that could not be read, built or run; the message is the command line's."
);

/// The longest wait between two calls of the progress callback (and two
/// checks for Ctrl-C), s.
const CADENCE_S: f64 = 0.1;

/// The message the command line prints for `e` (after `error: `).
fn message(e: &anyhow::Error) -> String {
    format!("{e:#}")
}

fn trial_error(e: anyhow::Error) -> PyErr {
    TrialError::new_err(message(&e))
}

/// Calls `progress(phase, done, of)` with the GIL and checks for signals,
/// at most every [`CADENCE_S`] seconds or when the phase changes; a Python
/// error (a KeyboardInterrupt, the callback's own) is kept and stops the
/// run.
struct Reporter {
    progress: Option<Py<PyAny>>,
    last: Option<Instant>,
    phase: &'static str,
    pending: Option<PyErr>,
}

impl Reporter {
    fn new(progress: Option<Py<PyAny>>) -> Reporter {
        Reporter {
            progress,
            last: None,
            phase: "",
            pending: None,
        }
    }

    fn observe(&mut self, phase: &'static str, done: f64, of: f64) -> Control {
        if self.pending.is_some() {
            return Control::Stop;
        }
        let due = self
            .last
            .is_none_or(|t| t.elapsed() >= Duration::from_secs_f64(CADENCE_S));
        if !due && phase == self.phase {
            return Control::Continue;
        }
        self.last = Some(Instant::now());
        self.phase = phase;
        let r = Python::attach(|py| -> PyResult<()> {
            py.check_signals()?;
            if let Some(p) = &self.progress {
                p.call1(py, (phase, done, of))?;
                // a signal the callback raised (or received) is seen now
                py.check_signals()?;
            }
            Ok(())
        });
        match r {
            Ok(()) => Control::Continue,
            Err(e) => {
                self.pending = Some(e);
                Control::Stop
            }
        }
    }
}

fn solver_kind(s: Option<&str>) -> PyResult<Option<LinearSolverKind>> {
    s.map(|s| {
        s.parse::<LinearSolverKind>()
            .map_err(|e| TrialError::new_err(format!("solver: {e}")))
    })
    .transpose()
}

/// The trial at `path`, or the trial file's text `text` (YAML or JSON)
/// whose relative paths resolve against `path`'s folder.
/// Vertices as float64 little-endian bytes, 3 a vertex (NumPy reads them).
fn position_bytes<'py>(py: Python<'py>, x: &[[f64; 3]]) -> Bound<'py, PyBytes> {
    let v: Vec<u8> = x.iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
    PyBytes::new(py, &v)
}

/// Triangles as int64 little-endian bytes, 3 a triangle.
fn face_bytes<'py>(py: Python<'py>, t: &[[usize; 3]]) -> Bound<'py, PyBytes> {
    let v: Vec<u8> = (t.iter().flatten())
        .flat_map(|&i| (i as i64).to_le_bytes())
        .collect();
    PyBytes::new(py, &v)
}

fn load_trial(path: &Path, text: Option<&str>) -> anyhow::Result<Trial> {
    match text {
        None => Trial::load(path),
        Some(text) => {
            let file =
                garment_sim::trial::TrialFile::parse(text, &format!("trial {}", path.display()))?;
            Trial::from_file(file, path)
        }
    }
}

/// `f()`, a panic in it an error that says where it was (the command line
/// would abort there): one trial of a sweep that panics fails alone.
fn caught<T>(f: impl FnOnce() -> anyhow::Result<T>) -> anyhow::Result<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(p) => {
            let what = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic".into());
            Err(anyhow::anyhow!("panicked: {what}"))
        }
    }
}

/// A finished trial: its outcome, and the signal or callback error that
/// stopped it, if any.
#[pyclass(module = "garment_sim._native")]
struct NativeTrial {
    trial: Trial,
    outcome: TrialOutcome,
    interrupt: Option<PyErr>,
}

#[pymethods]
impl NativeTrial {
    /// fit.json's text.
    fn fit_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.outcome.fit)
            .map_err(|e| TrialError::new_err(e.to_string()))
    }

    /// The garment's vertices, float64 little-endian, 3 a vertex, m.
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        position_bytes(py, &self.outcome.positions())
    }

    /// The garment's triangles, int64 little-endian, 3 a triangle.
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        face_bytes(py, &self.outcome.triangles())
    }

    /// Writes every output file of the command line into `dir`.
    fn write(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        py.detach(|| self.outcome.write(&self.trial, &dir))
            .map_err(trial_error)
    }

    /// The failed step's error, as the command line prints it (with where
    /// the outputs of the steps before it went, `out`); None if the trial
    /// ran its course or was stopped.
    #[pyo3(signature = (out=None))]
    fn error(&self, out: Option<PathBuf>) -> Option<String> {
        let r = &self.outcome.fit.run;
        self.outcome.error().map(|e| match (&r.failure, out) {
            (Some(f), Some(out)) => message(&garment_sim::scene::run::written_before_failure(
                f,
                r.simulated_s,
                r.steps,
                &out,
            )),
            _ => message(&e),
        })
    }

    /// The exception that stopped the run (KeyboardInterrupt, or the
    /// progress callback's), once.
    fn take_interrupt(&mut self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.interrupt.take().map(|e| e.into_value(py).into_any())
    }
}

/// Runs the trial file at `path` (or the trial file's text `text`, its
/// relative paths against `path`'s folder) with the command line's
/// overrides; raises TrialError if it cannot be read or built, else returns
/// the outcome (whose `error()` says whether a step failed).
#[pyfunction]
#[pyo3(signature = (path, text=None, progress=None, spacing=None, dt=None, max_time=None,
    threads=None, self_collision=None, obstacle_edges=None, cell_shear=None,
    cg_tolerance=None, solver=None, hysteresis=None))]
#[allow(clippy::too_many_arguments)]
fn run_trial(
    py: Python<'_>,
    path: PathBuf,
    text: Option<String>,
    progress: Option<Py<PyAny>>,
    spacing: Option<f64>,
    dt: Option<f64>,
    max_time: Option<f64>,
    threads: Option<usize>,
    self_collision: Option<bool>,
    obstacle_edges: Option<bool>,
    cell_shear: Option<bool>,
    cg_tolerance: Option<f64>,
    solver: Option<String>,
    hysteresis: Option<bool>,
) -> PyResult<NativeTrial> {
    let ov = Overrides {
        spacing,
        dt,
        max_time,
        threads,
        self_collision,
        obstacle_edges,
        cell_shear,
        cg_tolerance,
        solver: solver_kind(solver.as_deref())?,
        hysteresis,
        duration: None,
        hinges: None,
    };
    let mut rep = Reporter::new(progress);
    let ran = {
        let rep = &mut rep;
        py.detach(move || {
            caught(|| {
                let t = load_trial(&path, text.as_deref())?;
                let outcome = garment_sim::trial::run_trial(&t, &ov, &mut |s: &Step| {
                    Ok(rep.observe(s.phase.name(), s.done, s.of))
                })?;
                Ok((t, outcome))
            })
        })
    };
    let interrupt = rep.pending.take();
    match ran {
        Ok(r) => {
            let (trial, outcome) = r;
            Ok(NativeTrial {
                trial,
                outcome,
                interrupt,
            })
        }
        // a signal during the build is the signal's
        Err(e) => Err(interrupt.unwrap_or_else(|| trial_error(e))),
    }
}

/// A finished drape of a scene, its outputs written.
#[pyclass(module = "garment_sim._native")]
struct NativeScene {
    summary: String,
    positions: Vec<[f64; 3]>,
    faces: Vec<[usize; 3]>,
    failure: Option<String>,
    interrupt: Option<PyErr>,
}

#[pymethods]
impl NativeScene {
    /// summary.json's text.
    fn summary_json(&self) -> String {
        self.summary.clone()
    }

    /// The cloth's vertices, float64 little-endian, 3 a vertex, m.
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        position_bytes(py, &self.positions)
    }

    /// The cloth's triangles, int64 little-endian, 3 a triangle.
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        face_bytes(py, &self.faces)
    }

    fn error(&self) -> Option<String> {
        self.failure.clone()
    }

    fn take_interrupt(&mut self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.interrupt.take().map(|e| e.into_value(py).into_any())
    }
}

/// Drapes the scene file at `path` (or the scene file's text `text`) with
/// the `drape` command's overrides and writes its outputs into `out`
/// (final.ply, final.png, energy.csv, summary.json).
#[pyfunction]
#[pyo3(signature = (path, out, text=None, progress=None, spacing=None, dt=None, duration=None,
    threads=None, self_collision=None, obstacle_edges=None, cell_shear=None,
    cg_tolerance=None, solver=None, hysteresis=None, hinges=None))]
#[allow(clippy::too_many_arguments)]
fn run_scene(
    py: Python<'_>,
    path: PathBuf,
    out: PathBuf,
    text: Option<String>,
    progress: Option<Py<PyAny>>,
    spacing: Option<f64>,
    dt: Option<f64>,
    duration: Option<f64>,
    threads: Option<usize>,
    self_collision: Option<bool>,
    obstacle_edges: Option<bool>,
    cell_shear: Option<bool>,
    cg_tolerance: Option<f64>,
    solver: Option<String>,
    hysteresis: Option<bool>,
    hinges: Option<String>,
) -> PyResult<NativeScene> {
    let hinges = hinges
        .map(|h| {
            serde_yaml::from_str::<HingesFile>(&h).map_err(|_| {
                TrialError::new_err(format!("hinges: {h:?}: skewed or mirror_symmetric"))
            })
        })
        .transpose()?;
    let ov = Overrides {
        spacing,
        dt,
        duration,
        solver: solver_kind(solver.as_deref())?,
        hysteresis,
        cg_tolerance,
        threads,
        self_collision,
        obstacle_edges,
        cell_shear,
        hinges,
        max_time: None,
    };
    let mut rep = Reporter::new(progress);
    let ran = {
        let rep = &mut rep;
        py.detach(move || {
            caught(|| {
                ov.check()?;
                let scene = match &text {
                    None => Scene::load(&path)?,
                    Some(text) => {
                        let what = format!("scene {}", path.display());
                        let file = garment_sim::scene::SceneFile::parse(text, &what)?;
                        Scene::from_file(file, &path)?
                    }
                };
                let o = garment_sim::scene::run::drape(&scene, &ov, &mut |s| {
                    Ok(rep.observe(s.phase.name(), s.done, s.of))
                })?;
                o.write(&out)?;
                let (sim, summary) = (o.sim, o.summary);
                let positions: Vec<[f64; 3]> = sim
                    .cloth
                    .positions()
                    .iter()
                    .map(|p| [p.x, p.y, p.z])
                    .collect();
                let faces = sim.cloth.triangles.clone();
                anyhow::Ok(NativeScene {
                    summary: serde_json::to_string_pretty(&summary)?,
                    positions,
                    faces,
                    failure: summary.failure.clone(),
                    interrupt: None,
                })
            })
        })
    };
    let interrupt = rep.pending.take();
    match ran {
        Ok(mut r) => {
            r.interrupt = interrupt;
            Ok(r)
        }
        Err(e) => Err(interrupt.unwrap_or_else(|| trial_error(e))),
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("TrialError", m.py().get_type::<TrialError>())?;
    m.add_class::<NativeTrial>()?;
    m.add_class::<NativeScene>()?;
    m.add_function(wrap_pyfunction!(run_trial, m)?)?;
    m.add_function(wrap_pyfunction!(run_scene, m)?)?;
    Ok(())
}
