//! `garment_sim trial`: a virtual garment trial from the command line.

use anyhow::Result;
use garment_sim::run::Control;
use garment_sim::scene::system_file::SystemWriter;
use garment_sim::trial::{self, Overrides, Trial};
use std::path::PathBuf;
use std::sync::atomic::Ordering;

#[derive(clap::Args)]
pub struct TrialArgs {
    /// Trial file, e.g. config/trials/skirt_on_anny.yaml
    trial: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "out/trial")]
    out: PathBuf,
    #[command(flatten)]
    ov: Overrides,
    /// Write the linear system of these steps (indices from 0, sewing included,
    /// comma-separated) into OUT/system-STEP/, as `drape --write-system` does.
    #[arg(long, value_name = "STEP", value_delimiter = ',')]
    write_system: Vec<u64>,
}

pub fn trial(a: TrialArgs) -> Result<()> {
    let t = Trial::load(&a.trial)?;
    let ov = &a.ov;
    let (mut sim, g) = t.build(ov)?;
    sim.capture_systems(&a.write_system);
    let mut systems = SystemWriter::new(&a.out, &a.write_system);
    eprintln!("{}", t.headline(&sim, &g));
    std::fs::create_dir_all(&a.out)?;
    let stop = garment_sim::scene::run::stop_flag()?;
    let mut progress = crate::PhaseProgress::new(None);
    let outcome = trial::run_built(&t, ov, sim, g, &mut |s| {
        systems.observe(s.sim);
        progress.show(s);
        Ok(match stop.load(Ordering::Relaxed) {
            true => Control::Stop,
            false => Control::Continue,
        })
    })?;
    progress.finish();
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
