//! Headless runs: advance a scene for its duration, record energies, detect
//! settling, and write `final.ply`, `final.png` (a picture of the end
//! state), `energy.csv` and `summary.json`.

use crate::run::{Control, Observe, Phase, Run, SolvedSteps, Step, TimeSplit};
use crate::scene::{Overrides, Scene};
use crate::solver::Simulation;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// One row of `energy.csv`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct EnergyRow {
    pub time: f64,
    pub kinetic: f64,
    pub gravity: f64,
    pub tension: f64,
    pub shear: f64,
    pub bending: f64,
    pub dissipated: f64,
    /// Mechanical energy lost since the start, `E(0) − E(t)` with
    /// `E = kinetic + gravity + elastic`: damping, hysteresis, contacts and the
    /// integrator's own dissipation (less any work done by moving pins or
    /// obstacles).
    pub lost: f64,
    pub rms_speed: f64,
}

/// What a run reports (printed, and written as `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub scene: String,
    pub fabric: String,
    pub vertices: usize,
    pub grid: [usize; 2],
    pub spacing_m: [f64; 2],
    pub dt_s: f64,
    pub linear_solver: String,
    /// The shear measure: `diagonals` (each diagonal alone, thesis eq. 4.34,
    /// the default) or `cells` (`cell_shear`: both diagonals of each cell,
    /// with the egg-crate guards).
    pub shear_measure: &'static str,
    /// A scene's hinge layout (`skewed` or `mirror_symmetric`; absent for
    /// other runs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hinges: Option<&'static str>,
    /// Threads of the assembly, the PCG and the contacts.
    pub threads: usize,
    pub simulated_s: f64,
    pub steps: u64,
    pub wall_s: f64,
    pub ms_per_step: f64,
    pub real_time_factor: f64,
    pub mean_solver_iterations: f64,
    pub max_solver_iterations: usize,
    /// Steps whose answer each linear solve gave (`auto` chooses per step).
    pub steps_solved_by: SolvedSteps,
    /// First time after which the rms speed stays below `settle_speed_m_s`;
    /// `null` if it never settles within the run.
    pub settle_time_s: Option<f64>,
    pub settle_speed_m_s: f64,
    pub final_energies: EnergyRow,
    pub time_split_ms_per_step: TimeSplit,
    /// Vertices in contact with an obstacle at the last step, and of those
    /// the ones static friction held.
    pub final_contacts: usize,
    pub final_contacts_held: usize,
    /// The cloth against itself (absent when self-collision is off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub self_collision: Option<SelfSummary>,
    /// Why the run ended before its duration: the step that failed, with
    /// its error (a failed step changes nothing, so the summary, the energies
    /// and the final state are those of the steps before it). Absent when the
    /// run went to its end or was stopped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
}

/// What the self-collision pass did over a run.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct SelfSummary {
    /// Its time per step, ms, and its share of the step.
    pub ms_per_step: f64,
    pub share_of_step: f64,
    /// Pairs within the thickness pushed apart: per step on average, most
    /// in one step, at the last step.
    pub mean_contacts: f64,
    pub max_contacts: usize,
    pub final_contacts: usize,
    /// Pairs whose paths crossed, over the run (each stopped by an impulse
    /// or an impact zone), and the rigid impact zones formed.
    pub collisions: usize,
    pub zones: usize,
}

/// Runs a built simulation for `duration` seconds, sampling energies at
/// `rate` Hz; a step that fails is an error.
pub fn run(
    sim: &mut Simulation,
    duration: f64,
    rate: f64,
    settle_speed: f64,
    observe: Observe,
) -> Result<(Vec<EnergyRow>, Summary)> {
    let (rows, summary) = run_to_failure(sim, duration, rate, settle_speed, observe)?;
    failed(summary.failure.clone())?;
    Ok((rows, summary))
}

/// A run's failure (`Summary::failure`, `RunStats::failure`) as an error.
pub fn failed(failure: Option<String>) -> Result<()> {
    match failure {
        Some(f) => Err(anyhow::anyhow!(f)),
        None => Ok(()),
    }
}

/// What `drape` and `trial` say after writing the outputs of a run whose
/// step failed (`failure`, then how far the outputs in `out` go).
pub fn written_before_failure(failure: &str, t: f64, steps: u64, out: &Path) -> anyhow::Error {
    anyhow::anyhow!(
        "{failure}\nthe run up to t = {t:.4} s ({steps} steps) is written to {}",
        out.display()
    )
}

/// As [`run`], through the run interface ([`crate::run`]): `observe` sees
/// the state before the first step and after each step (phase
/// [`Phase::Drape`], `done` of `duration`), and a step that fails ends the
/// run with what was done before it: the energies sampled so far (and the
/// state the failed step left unchanged) are returned, and
/// `Summary::failure` says which step failed and why. An observer's error
/// is still an error.
pub fn run_to_failure(
    sim: &mut Simulation,
    duration: f64,
    rate: f64,
    settle_speed: f64,
    observe: Observe,
) -> Result<(Vec<EnergyRow>, Summary)> {
    let planned = (duration / sim.params().dt).round() as u64;
    let every = ((1.0 / rate) / sim.params().dt).round().max(1.0) as u64;
    let mut rows = vec![row(sim)];
    let e0 = sim.energies().total();
    let t0 = sim.time;
    let mut last_fast: Option<f64> = if sim.rms_speed() >= settle_speed {
        Some(0.0)
    } else {
        None
    };
    let mut run = Run::new();
    fn step(sim: &Simulation, t0: f64, duration: f64) -> Step<'_> {
        Step {
            sim,
            phase: Phase::Drape,
            done: sim.time - t0,
            of: duration,
        }
    }
    let mut stop = observe(&step(sim, t0, duration))? == Control::Stop;
    // an energy row with the energy lost since the start
    let sample = |sim: &Simulation| EnergyRow {
        lost: e0 - sim.energies().total(),
        ..row(sim)
    };
    let mut failure = None;
    for k in 1..=planned {
        if stop {
            break;
        }
        if let Err(e) = run.step(sim) {
            failure = Some(e.to_string());
            if rows.last().is_some_and(|r| r.time != sim.time) {
                rows.push(sample(sim));
            }
            break;
        }
        if sim.rms_speed() >= settle_speed {
            last_fast = Some(sim.time);
        }
        stop = observe(&step(sim, t0, duration))? == Control::Stop;
        if k % every == 0 || k == planned || stop {
            rows.push(sample(sim));
        }
    }
    let settle = match last_fast {
        None => Some(0.0),
        Some(t) if t < sim.time - 1e-12 => Some(t),
        _ => None,
    };
    let last = *rows.last().expect("at least one row");
    Ok((
        rows,
        summarize(sim, &run, settle_speed, settle, last, failure),
    ))
}

/// The summary of `run`'s steps on `sim`.
fn summarize(
    sim: &Simulation,
    run: &Run,
    settle_speed: f64,
    settle: Option<f64>,
    last: EnergyRow,
    failure: Option<String>,
) -> Summary {
    let wall = run.wall_s();
    let (steps, sp) = (run.steps, &run.spent);
    let n = steps.max(1) as f64;
    Summary {
        scene: String::new(),
        fabric: sim.fabric.name.clone(),
        vertices: sim.cloth.len(),
        grid: [sim.cloth.nx, sim.cloth.ny],
        spacing_m: [sim.cloth.lc, sim.cloth.lt],
        dt_s: sim.params().dt,
        linear_solver: format!("{:?}", sim.params().linear_solver).to_lowercase(),
        shear_measure: if sim.params().cell_shear {
            "cells"
        } else {
            "diagonals"
        },
        hinges: None,
        threads: sim.threads(),
        simulated_s: sim.time,
        steps,
        wall_s: wall,
        ms_per_step: 1e3 * wall / n,
        real_time_factor: if wall > 0.0 {
            sim.time / wall
        } else {
            f64::INFINITY
        },
        mean_solver_iterations: sp.iterations as f64 / n,
        max_solver_iterations: sp.max_iterations,
        steps_solved_by: sp.solved_by,
        settle_time_s: settle,
        settle_speed_m_s: settle_speed,
        final_energies: last,
        time_split_ms_per_step: sp.split_ms_per_step(steps),
        final_contacts: sim.last.contacts,
        final_contacts_held: sim.last.stuck,
        self_collision: sim.params().self_collision.then_some(SelfSummary {
            ms_per_step: 1e3 * sp.self_s / n,
            share_of_step: if sp.total_s > 0.0 {
                sp.self_s / sp.total_s
            } else {
                0.0
            },
            mean_contacts: sp.self_contacts as f64 / n,
            max_contacts: sp.self_max_contacts,
            final_contacts: sim.last.self_contacts,
            collisions: sp.self_collisions,
            zones: sp.self_zones,
        }),
        failure,
    }
}

pub fn row(sim: &Simulation) -> EnergyRow {
    let e = sim.energies();
    EnergyRow {
        time: sim.time,
        kinetic: e.kinetic,
        gravity: e.gravity,
        tension: e.tension,
        shear: e.shear,
        bending: e.bending,
        dissipated: e.dissipated_damping,
        lost: 0.0,
        rms_speed: sim.rms_speed(),
    }
}

/// A scene's drape as it ended: the simulation, its energies over the run
/// and its summary; [`DrapeOutcome::write`] writes them.
pub struct DrapeOutcome {
    pub sim: Simulation,
    pub rows: Vec<EnergyRow>,
    pub summary: Summary,
    /// The scene's name (its file's `name`, else its file name).
    pub name: String,
}

/// Builds a scene and runs it through the run interface ([`run_to_failure`]):
/// a step that fails ends the run with what was done before it
/// (`Summary::failure` says which step failed and why, for the caller to
/// report); a bad file or setting is an error at once.
pub fn drape(scene: &Scene, ov: &Overrides, observe: Observe) -> Result<DrapeOutcome> {
    let sim = scene.build(ov)?;
    drape_built(scene, ov, sim, observe)
}

/// [`drape`] on a simulation already built from `scene` and `ov`.
pub fn drape_built(
    scene: &Scene,
    ov: &Overrides,
    mut sim: Simulation,
    observe: Observe,
) -> Result<DrapeOutcome> {
    let (rows, mut summary) = run_to_failure(
        &mut sim,
        scene.duration(ov),
        scene.file.output_rate,
        scene.file.settle_speed,
        observe,
    )?;
    summary.scene = scene.path.display().to_string();
    summary.hinges = Some(scene.hinges(ov).name());
    let name = match scene.file.name.as_str() {
        "" => scene
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        n => n.to_string(),
    };
    Ok(DrapeOutcome {
        sim,
        rows,
        summary,
        name,
    })
}

impl DrapeOutcome {
    /// Writes `final.ply`, `final.png` (a picture of the end state),
    /// `energy.csv` and `summary.json` into `out` (made if need be).
    pub fn write(&self, out: &Path) -> Result<()> {
        std::fs::create_dir_all(out)
            .with_context(|| format!("cannot create output directory {}", out.display()))?;
        write_ply(&self.sim, &out.join("final.ply"))?;
        crate::pictures::render::Picture::from_simulation(&self.sim, &self.name)
            .save_png(&out.join("final.png"))?;
        write_energy_csv(&self.rows, &out.join("energy.csv"))?;
        let js = serde_json::to_string_pretty(&self.summary)?;
        crate::io::write_atomic(&out.join("summary.json"), |w| w.write_all(js.as_bytes()))
    }

    /// The error of the step that ended the run early, if one failed.
    pub fn error(&self) -> Option<anyhow::Error> {
        self.summary
            .failure
            .as_ref()
            .map(|f| anyhow::anyhow!("{f}"))
    }
}

/// ASCII PLY: vertices in grid order (x y z, u v material coordinates), faces.
pub fn write_ply(sim: &Simulation, path: &Path) -> Result<()> {
    let c = &sim.cloth;
    crate::io::write_atomic(path, |w| {
        writeln!(w, "ply\nformat ascii 1.0\ncomment garment_sim cloth, vertices in grid order (index = j*nx + i), nx = {}, ny = {}, metres", c.nx, c.ny)?;
        writeln!(w, "element vertex {}\nproperty double x\nproperty double y\nproperty double z\nproperty double u\nproperty double v", c.len())?;
        writeln!(
            w,
            "element face {}\nproperty list uchar int vertex_indices\nend_header",
            c.triangles.len()
        )?;
        for (p, m) in c.positions().iter().zip(&c.material) {
            writeln!(w, "{} {} {} {} {}", p.x, p.y, p.z, m[0], m[1])?;
        }
        for t in &c.triangles {
            writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
        }
        Ok(())
    })
}

pub fn write_energy_csv(rows: &[EnergyRow], path: &Path) -> Result<()> {
    crate::io::write_atomic(path, |w| {
        writeln!(
            w,
            "time_s,kinetic_J,gravity_J,tension_J,shear_J,bending_J,dissipated_damping_J,lost_total_J,rms_speed_m_s"
        )?;
        for r in rows {
            writeln!(
                w,
                "{},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e}",
                r.time,
                r.kinetic,
                r.gravity,
                r.tension,
                r.shear,
                r.bending,
                r.dissipated,
                r.lost,
                r.rms_speed
            )?;
        }
        Ok(())
    })
}

static STOP: Mutex<Option<Arc<AtomicBool>>> = Mutex::new(None);

/// SIGINT and SIGTERM received so far.
static SIGNALS: AtomicUsize = AtomicUsize::new(0);

/// Bags open for writing ([`Recording`]).
static RECORDING: AtomicUsize = AtomicUsize::new(0);

/// The process-wide stop flag, set by SIGINT or SIGTERM (handlers installed
/// on the first call). A second SIGINT/SIGTERM exits the process at once
/// (status 1), so a stuck run can still be interrupted, except while a bag
/// is open ([`Recording`]): then the second one only stops the run as the
/// first did, the bag is finished (summary, `metadata.yaml`) and the program
/// says so ([`interrupted_again`]); a third exits at once, leaving the bag
/// readable up to its last chunk for `bag repair`.
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let mut g = STOP.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(f) = g.as_ref() {
        return Ok(f.clone());
    }
    let f = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        let flag = f.clone();
        let handler = move || {
            // atomics and _exit only: async-signal-safe
            let before = SIGNALS.fetch_add(1, Ordering::SeqCst);
            flag.store(true, Ordering::SeqCst);
            let tolerated = if RECORDING.load(Ordering::SeqCst) > 0 {
                2
            } else {
                1
            };
            if before >= tolerated {
                signal_hook::low_level::exit(1);
            }
        };
        // SAFETY: the handler only touches atomics and calls _exit, both
        // async-signal-safe
        unsafe { signal_hook::low_level::register(sig, handler) }?;
    }
    *g = Some(f.clone());
    Ok(f)
}

/// Whether more than one SIGINT/SIGTERM arrived (the later ones while a bag
/// was open, see [`stop_flag`]).
pub fn interrupted_again() -> bool {
    SIGNALS.load(Ordering::SeqCst) > 1
}

/// Held while a bag is open for writing (its recorder owns one): a second
/// SIGINT/SIGTERM then lets the bag be finished instead of exiting.
#[derive(Debug)]
pub struct Recording(());

impl Recording {
    pub fn start() -> Recording {
        RECORDING.fetch_add(1, Ordering::SeqCst);
        Recording(())
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        RECORDING.fetch_sub(1, Ordering::SeqCst);
    }
}
