//! `garment_sim bench`: ms per step and real-time factor of a scene across
//! grids, steps and solvers.

use anyhow::{Context, Result};
use garment_sim::run::Run;
use garment_sim::scene::{Overrides, Scene};
use garment_sim::solver::LinearSolverKind;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Scene to benchmark.
    #[arg(long, default_value = "config/scenes/table_drape.yaml")]
    pub scene: PathBuf,
    /// Grid spacings, m (comma separated).
    #[arg(long, value_delimiter = ',', default_values_t = vec![0.02, 0.01, 0.005])]
    pub spacing: Vec<f64>,
    /// Time steps, s (comma separated).
    #[arg(long, value_delimiter = ',', default_values_t = vec![1e-3, 1e-4])]
    pub dt: Vec<f64>,
    /// Solvers (comma separated).
    #[arg(long, value_delimiter = ',', default_values = ["pcg", "cholesky", "auto"])]
    pub solver: Vec<LinearSolverKind>,
    /// Steps per measurement (after the warm-up).
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: u64,
    /// Repetitions of the same steps (each from the scene built and warmed up
    /// again); the median is reported.
    #[arg(long, default_value_t = 3, value_parser = crate::cli::lab::at_least_one)]
    pub repeat: usize,
    /// Simulated time before measuring (the cloth is mid-drape; at most
    /// 3 × steps are run), s.
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true,
              value_parser = crate::cli::lab::seconds)]
    pub warmup: f64,
    /// Threads of the assembly, the PCG and the contacts (default: one per core
    /// from 500 vertices; 1 for one core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Keep the cloth from passing through itself (off by default); each row
    /// is then followed by the self-collision pass's share of the step.
    #[arg(long)]
    pub self_collision: bool,
}

/// Prints the benchmark's heading and its table's column names.
fn print_heading(scene: &std::path::Path, steps: u64, repeat: usize, warmup: f64) {
    println!(
        "scene {} ; {} steps per run, median of {} runs of the same steps, after {} s of simulated \
         warm-up (at most 3 × steps; the window column gives the simulated times measured)",
        scene.display(),
        steps,
        repeat,
        warmup
    );
    println!(
        "{:>8} {:>9} {:>10} {:>8} {:>10} {:>9} {:>8} {:>9} {:>9} {:>8} {:>11} {:>7} {:>13}",
        "spacing",
        "grid",
        "dt",
        "solver",
        "ms/step",
        "assembly",
        "solve",
        "contacts",
        "RTF",
        "iters",
        "peak RSS MB",
        "threads",
        "window s"
    );
}

/// What the runs of one row measured.
struct Measured {
    /// Per run: ms per step in all, then in assembly, solve, contacts and
    /// self-collision (the step's own timers).
    ms: Vec<[f64; 5]>,
    /// Self-collision contacts and collisions per step (last run).
    own: [f64; 2],
    /// Solver iterations per step (last run).
    it: f64,
    /// The process's peak resident memory after the first run, MB.
    peak: f64,
}

/// Runs the same `steps` after `wsteps` of warm-up `repeat` times, each
/// from the scene built again (the first from `first`).
fn measure(
    sc: &Scene,
    ov: &Overrides,
    first: garment_sim::solver::Simulation,
    repeat: usize,
    wsteps: u64,
    steps: u64,
) -> Result<Measured> {
    let mut first = Some(first);
    let mut ms: Vec<[f64; 5]> = Vec::new();
    let mut own = [0.0; 2];
    let mut it = 0.0;
    // the process's peak after the first run (the later runs'
    // heaps, fragmented by the runs before, would add to it)
    let mut peak = f64::NAN;
    for _ in 0..repeat.max(1) {
        // every run measures the same steps: the scene built
        // and warmed up again (the runs are deterministic), so
        // the median compares like with like rather than
        // later, calmer stretches of the drape; the last
        // run's simulation is dropped before this one is built
        let mut sim = match first.take() {
            Some(sim) => sim,
            None => sc.build(ov)?,
        };
        let mut warm = Run::new();
        for _ in 0..wsteps {
            warm.step(&mut sim)?;
        }
        let mut run = Run::new();
        for _ in 0..steps {
            run.step(&mut sim)?;
        }
        let (wall, sp) = (run.wall_s(), &run.spent);
        own = [sp.self_contacts, sp.self_collisions].map(|p| p as f64 / steps as f64);
        let per = |x: f64| 1e3 * x / steps as f64;
        ms.push([
            per(wall),
            per(sp.split.assemble),
            per(sp.split.solve),
            per(sp.split.collide),
            per(sp.self_s),
        ]);
        it = sp.iterations as f64 / steps as f64;
        if peak.is_nan() {
            peak = peak_rss_mb();
        }
    }
    Ok(Measured { ms, own, it, peak })
}

/// Benchmarks one spacing, step and solver and prints its row (and the
/// self-collision's share when it is on).
fn bench_row(a: &BenchArgs, sc: &Scene, sp: f64, h: f64, so: LinearSolverKind) -> Result<()> {
    let (steps, repeat, warmup) = (a.steps, a.repeat, a.warmup);
    let ov = Overrides {
        spacing: Some(sp),
        dt: Some(h),
        solver: Some(so),
        threads: a.threads,
        self_collision: a.self_collision.then_some(true),
        ..Default::default()
    };
    // the first run's simulation (its grid and threads are the row's)
    let sim = sc.build(&ov)?;
    let (grid, used) = (format!("{}x{}", sim.cloth.nx, sim.cloth.ny), sim.threads());
    let wsteps = ((warmup / h).round() as u64).min(steps * 3);
    let window = format!(
        "{:.3}-{:.3}",
        wsteps as f64 * h,
        (wsteps + steps) as f64 * h
    );
    let Measured {
        mut ms,
        own,
        it,
        peak,
    } = match measure(sc, &ov, sim, repeat, wsteps, steps) {
        Ok(m) => m,
        Err(e) => {
            println!(
                "{:>8} {:>9} {:>10} {:>8}   failed: {e:#}",
                sp,
                grid,
                format!("{h:.4e}"),
                format!("{so:?}").to_lowercase()
            );
            return Ok(());
        }
    };
    // the median run, with its own phase split
    ms.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let med = ms[ms.len() / 2];
    println!(
        "{:>8} {:>9} {:>10} {:>8} {:>10.3} {:>9.3} {:>8.3} {:>9.3} {:>9.3} {:>8.1} {:>11.1} {:>7} {:>13}",
        sp,
        grid,
        format!("{h:.4e}"),
        format!("{so:?}").to_lowercase(),
        med[0],
        med[1],
        med[2],
        med[3],
        h * 1e3 / med[0],
        it,
        peak,
        used,
        window
    );
    if a.self_collision {
        println!(
            "{:>8} self-collision {:.3} ms/step, {:.1} % of the step; {:.1} contacts, \
             {:.2} collisions per step (last run)",
            "",
            med[4],
            100.0 * med[4] / med[0],
            own[0],
            own[1]
        );
    }
    Ok(())
}

/// Runs `bench`.
pub fn bench(a: BenchArgs) -> Result<()> {
    let sc = Scene::load(&a.scene).with_context(|| "bench needs a scene")?;
    print_heading(&a.scene, a.steps, a.repeat, a.warmup);
    for &sp in &a.spacing {
        for &h in &a.dt {
            for &so in &a.solver {
                bench_row(&a, &sc, sp, h, so)?;
            }
        }
    }
    Ok(())
}

/// Peak resident memory of this process so far (Linux VmHWM), MB.
fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map(|kb| kb / 1024.0)
        .unwrap_or(f64::NAN)
}
