//! Headless runs: advance a scene for its duration, record energies, detect
//! settling, and write `final.ply`, `final.png` (a picture of the end
//! state), `energy.csv` and `summary.json`.

use crate::scene::{Overrides, Scene};
use crate::solver::{Simulation, SolvedBy};
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

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

/// Steps by the linear solve that gave their answer.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct SolvedSteps {
    /// The block-Jacobi PCG.
    pub pcg: u64,
    /// The PCG preconditioned by symmetric block Gauss–Seidel (`sgs`).
    pub sgs: u64,
    /// The multigrid PCG.
    pub amg: u64,
    /// The Cholesky factor.
    pub cholesky: u64,
}

impl SolvedSteps {
    fn count(&mut self, by: SolvedBy) {
        match by {
            SolvedBy::Pcg => self.pcg += 1,
            SolvedBy::Sgs => self.sgs += 1,
            SolvedBy::Amg => self.amg += 1,
            SolvedBy::Cholesky => self.cholesky += 1,
        }
    }
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

#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct TimeSplit {
    pub assemble: f64,
    pub solve: f64,
    pub collide: f64,
}

/// Progress callback: (simulated time, duration).
pub type Progress<'a> = &'a mut dyn FnMut(f64, f64);

/// What an [`Observer`] tells the run to do next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    Continue,
    /// End the run now (the summary covers the steps done).
    Stop,
}

/// Called with the state before the first step and after every step (to
/// record it, or to stop the run).
pub type Observer<'a> = &'a mut dyn FnMut(&Simulation) -> Result<Control>;

/// Runs a built simulation for `duration` seconds, sampling energies at
/// `rate` Hz; a step that fails is an error.
pub fn run(
    sim: &mut Simulation,
    duration: f64,
    rate: f64,
    settle_speed: f64,
    progress: Progress,
) -> Result<(Vec<EnergyRow>, Summary)> {
    let (rows, summary) = run_to_failure(sim, duration, rate, settle_speed, progress, &mut |_| {
        Ok(Control::Continue)
    })?;
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

/// As [`run`], calling `observer` before the first step and after each
/// step, and a step that fails ends the run with what was done before it:
/// the energies sampled so far (and the state the failed step left
/// unchanged) are returned, and `Summary::failure` says which step failed
/// and why. An observer's error is still an error.
pub fn run_to_failure(
    sim: &mut Simulation,
    duration: f64,
    rate: f64,
    settle_speed: f64,
    progress: Progress,
    observer: Observer,
) -> Result<(Vec<EnergyRow>, Summary)> {
    let mut steps = (duration / sim.params().dt).round() as u64;
    let every = ((1.0 / rate) / sim.params().dt).round().max(1.0) as u64;
    let mut rows = vec![row(sim)];
    let e0 = sim.energies().total();
    let mut last_fast: Option<f64> = if sim.rms_speed() >= settle_speed {
        Some(0.0)
    } else {
        None
    };
    let mut iters = 0usize;
    let mut max_iters = 0usize;
    let mut solved_by = SolvedSteps::default();
    let mut split = TimeSplit::default();
    let mut own = SelfSummary::default();
    let mut own_s = 0.0;
    let mut total_s = 0.0;
    let start = Instant::now();
    let mut stop = observer(sim)? == Control::Stop;
    if stop {
        steps = 0;
    }
    // an energy row with the energy lost since the start
    let sample = |sim: &Simulation| EnergyRow {
        lost: e0 - sim.energies().total(),
        ..row(sim)
    };
    let mut failure = None;
    // the steps done: all those planned unless the run stops or fails
    let planned = steps;
    for k in 1..=planned {
        let st = match sim.step() {
            Ok(st) => st,
            Err(e) => {
                failure = Some(format!("step {k} (t = {:.4} s): {e:#}", sim.time));
                steps = k - 1;
                if rows.last().is_some_and(|r| r.time != sim.time) {
                    rows.push(sample(sim));
                }
                break;
            }
        };
        iters += st.iterations;
        max_iters = max_iters.max(st.iterations);
        solved_by.count(st.solved_by);
        split.assemble += st.assemble_s;
        split.solve += st.solve_s;
        split.collide += st.collide_s;
        own_s += st.self_s;
        total_s += st.total_s;
        own.mean_contacts += st.self_contacts as f64;
        own.max_contacts = own.max_contacts.max(st.self_contacts);
        own.collisions += st.self_collisions;
        own.zones += st.self_zones;
        if sim.rms_speed() >= settle_speed {
            last_fast = Some(sim.time);
        }
        if observer(sim)? == Control::Stop {
            stop = true;
        }
        if k % every == 0 || k == planned || stop {
            rows.push(sample(sim));
            progress(sim.time, duration);
        }
        if stop {
            steps = k;
            break;
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let n = steps.max(1) as f64;
    let settle = match last_fast {
        None => Some(0.0),
        Some(t) if t < sim.time - 1e-12 => Some(t),
        _ => None,
    };
    let summary = Summary {
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
        mean_solver_iterations: iters as f64 / n,
        max_solver_iterations: max_iters,
        steps_solved_by: solved_by,
        settle_time_s: settle,
        settle_speed_m_s: settle_speed,
        final_energies: *rows.last().expect("at least one row"),
        time_split_ms_per_step: TimeSplit {
            assemble: 1e3 * split.assemble / n,
            solve: 1e3 * split.solve / n,
            collide: 1e3 * split.collide / n,
        },
        final_contacts: sim.last.contacts,
        final_contacts_held: sim.last.stuck,
        self_collision: sim.params().self_collision.then_some(SelfSummary {
            ms_per_step: 1e3 * own_s / n,
            share_of_step: if total_s > 0.0 { own_s / total_s } else { 0.0 },
            mean_contacts: own.mean_contacts / n,
            final_contacts: sim.last.self_contacts,
            ..own
        }),
        failure,
    };
    Ok((rows, summary))
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

/// Runs a scene file headless and writes its outputs into `out`. A step
/// that fails ends the run, and the outputs of the steps before it are
/// written all the same: `Summary::failure` (also in `summary.json`) says
/// which step failed and why, for the caller to report.
pub fn drape(
    scene: &Scene,
    ov: &Overrides,
    out: &Path,
    progress: Progress,
) -> Result<(Simulation, Summary)> {
    let sim = scene.build(ov)?;
    drape_with(scene, ov, sim, out, progress, &mut |_| {
        Ok(Control::Continue)
    })
}

/// As [`drape`], for a simulation already built from `scene` and `ov`, with
/// an [`Observer`] called before the first step and after each step.
pub fn drape_with(
    scene: &Scene,
    ov: &Overrides,
    mut sim: Simulation,
    out: &Path,
    progress: Progress,
    observer: Observer,
) -> Result<(Simulation, Summary)> {
    let (rows, mut summary) = run_to_failure(
        &mut sim,
        scene.duration(ov),
        scene.file.output_rate,
        scene.file.settle_speed,
        progress,
        observer,
    )?;
    summary.scene = scene.path.display().to_string();
    summary.hinges = Some(scene.hinges(ov).name());
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output directory {}", out.display()))?;
    write_ply(&sim, &out.join("final.ply"))?;
    let name = match scene.file.name.as_str() {
        "" => scene
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        n => n.to_string(),
    };
    crate::pictures::render::Picture::from_simulation(&sim, &name)
        .save_png(&out.join("final.png"))?;
    write_energy_csv(&rows, &out.join("energy.csv"))?;
    let js = serde_json::to_string_pretty(&summary)?;
    crate::io::write_atomic(&out.join("summary.json"), |w| w.write_all(js.as_bytes()))?;
    Ok((sim, summary))
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
