//! `garment_sim trial`: a virtual garment trial from the command line.

use anyhow::Result;
use garment_sim::scene::run::Control;
use garment_sim::scene::system_file::SystemWriter;
use garment_sim::solver::LinearSolverKind;
use garment_sim::trial::{self, Phase, Trial, TrialOverrides};
use std::path::PathBuf;
use std::sync::atomic::Ordering;

#[derive(clap::Args)]
pub struct TrialArgs {
    /// Trial file, e.g. config/trials/skirt_on_anny.yaml
    trial: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "out/trial")]
    out: PathBuf,
    /// Grid spacing of the panels, m (default: the trial's).
    #[arg(long, allow_negative_numbers = true)]
    spacing: Option<f64>,
    /// Fixed time step, s (default: the trial's).
    #[arg(long, allow_negative_numbers = true)]
    dt: Option<f64>,
    /// Longest drape after sewing, s (default: the trial's settle.max_time).
    #[arg(long, allow_negative_numbers = true)]
    max_time: Option<f64>,
    /// Threads of the assembly, the PCG and the contacts.
    #[arg(long)]
    threads: Option<usize>,
    /// Keep the garment from passing through itself, true or false (default: the trial's
    /// `self_collision`, on in the shipped skirt trial).
    #[arg(long)]
    self_collision: Option<bool>,
    /// The body's vertices and edges meet the garment's triangles and edges too, true or
    /// false (default: the trial's `obstacle_edges`, off when absent; docs/self_collision.md).
    #[arg(long)]
    obstacle_edges: Option<bool>,
    /// Each cell's shear from both its diagonals, with the egg-crate guards, true or false
    /// (default: the trial's `cell_shear`, off when absent; docs/lab.md).
    #[arg(long)]
    cell_shear: Option<bool>,
    /// Relative tolerance of the PCG, in (0, 1) (default: the trial's `cg_tolerance`,
    /// 1e-6 when absent).
    #[arg(long, allow_negative_numbers = true)]
    cg_tolerance: Option<f64>,
    /// Linear solver: auto, pcg, sgs, amg or cholesky (default: the trial's `linear_solver`,
    /// auto when absent; docs/drape.md).
    #[arg(long)]
    solver: Option<LinearSolverKind>,
    /// Write the linear system of these steps (indices from 0, sewing included,
    /// comma-separated) into OUT/system-STEP/, as `drape --write-system` does.
    #[arg(long, value_name = "STEP", value_delimiter = ',')]
    write_system: Vec<u64>,
}

/// A phase's progress bar.
type Bar = Box<dyn FnMut(f64, f64)>;

pub fn trial(a: TrialArgs) -> Result<()> {
    let t = Trial::load(&a.trial)?;
    let ov = TrialOverrides {
        spacing: a.spacing,
        dt: a.dt,
        max_time: a.max_time,
        threads: a.threads,
        self_collision: a.self_collision,
        obstacle_edges: a.obstacle_edges,
        cell_shear: a.cell_shear,
        cg_tolerance: a.cg_tolerance,
        solver: a.solver,
    };
    let (mut sim, g) = t.build(&ov)?;
    sim.capture_systems(&a.write_system);
    let mut systems = SystemWriter::new(&a.out, &a.write_system);
    eprintln!("{}", t.headline(&sim, &g));
    std::fs::create_dir_all(&a.out)?;
    let stop = garment_sim::scene::run::stop_flag()?;
    let mut bars: Vec<(Phase, Bar)> = Vec::new();
    let outcome = trial::run_built(&t, &ov, sim, g, &mut |s| {
        systems.observe(s.sim);
        if bars.last().is_none_or(|b| b.0 != s.phase) {
            // the phase before is over
            if let Some((_, bar)) = bars.last_mut() {
                bar(1.0, 1.0);
            }
            bars.push((
                s.phase,
                Box::new(crate::progress_printer(s.phase.name().into())),
            ));
        }
        if let Some((_, bar)) = bars.last_mut() {
            bar(s.done, s.of);
        }
        if stop.load(Ordering::Relaxed) {
            Control::Stop
        } else {
            Control::Continue
        }
    })?;
    if let Some((_, bar)) = bars.last_mut() {
        bar(1.0, 1.0);
    }
    let written = systems.finish(outcome.sim.steps);
    let wrote = outcome.write(&t, &a.out);
    for line in outcome.summary(&t) {
        println!("{line}");
    }
    for w in outcome.warnings() {
        eprintln!("{w}");
    }
    wrote?;
    println!("wrote {}", a.out.display());
    let r = &outcome.fit.run;
    match &r.failure {
        // the outputs are those of the steps before the failed one
        Some(f) => Err(garment_sim::scene::run::written_before_failure(
            f,
            r.simulated_s,
            r.steps,
            &a.out,
        )),
        // a system that could not be written fails the command, after the rest
        None => written,
    }
}
