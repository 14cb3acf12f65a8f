//! Command-line front ends of the lab subcommands (`kes`, `fit-kes`,
//! `drapemeter`): argument structs and one function each; the work is in
//! [`garment_sim::lab`].

use anyhow::{bail, Context, Result};
use garment_sim::fabric::Fabric;
use garment_sim::lab::kes_lab::{self, Direction, KesTest, LabOptions, LabReport};
use std::path::PathBuf;

/// `garment_sim kes`: virtual KES-FB tests on a simulated specimen.
#[derive(clap::Args)]
pub struct KesArgs {
    /// Fabric file, e.g. config/fabrics/acrylic.yaml
    pub fabric: PathBuf,
    /// Test to run (tensile, shear or bending).
    #[arg(long, required_unless_present = "all")]
    pub test: Option<KesTest>,
    /// Thread direction along the gauge.
    #[arg(long, default_value = "warp")]
    pub dir: Direction,
    /// Run every test in both directions and write one report.
    #[arg(long, conflicts_with = "test")]
    pub all: bool,
    /// Output directory (CSV curves, PNG plots, report.json).
    #[arg(long, default_value = "out/kes")]
    pub out: PathBuf,
    /// Grid spacing along the 5 cm gauge of the tensile and shear specimens, m.
    #[arg(long, default_value_t = LabOptions::default().fb1_spacing)]
    pub spacing: f64,
    /// Grid spacing along the 1 cm gauge of the bending specimen, m.
    #[arg(long, default_value_t = LabOptions::default().fb2_spacing)]
    pub bending_spacing: f64,
    /// Grid spacing along the 20 cm clamps, m.
    #[arg(long, default_value_t = LabOptions::default().width_spacing)]
    pub width_spacing: f64,
    /// Fixed time step, s.
    #[arg(long, default_value_t = LabOptions::default().dt)]
    pub dt: f64,
}

pub fn kes(a: KesArgs) -> Result<()> {
    let fabric = Fabric::load(&a.fabric)?;
    let opt = LabOptions {
        fb1_spacing: a.spacing,
        fb2_spacing: a.bending_spacing,
        width_spacing: a.width_spacing,
        dt: a.dt,
    };
    let jobs: Vec<(KesTest, Direction)> = if a.all {
        KesTest::ALL
            .iter()
            .flat_map(|&t| Direction::ALL.iter().map(move |&d| (t, d)))
            .collect()
    } else {
        vec![(a.test.context("--test or --all is required")?, a.dir)]
    };
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let mut runs = Vec::new();
    for (t, d) in jobs {
        let label = format!("kes {} {}", t.name(), d.name());
        let mut pr = crate::progress_printer(label);
        let run = kes_lab::run_test(&fabric, t, d, &opt, &mut |f| pr(f, 1.0))?;
        kes_lab::write_outputs(&run, &a.out)?;
        print!("{}", kes_lab::format_run(&run));
        runs.push(run);
    }
    let curves = a.out.join("curves.csv");
    std::fs::write(&curves, kes_lab::curves_csv(&runs))
        .with_context(|| format!("cannot write {}", curves.display()))?;
    let report = LabReport {
        fabric: fabric.name.clone(),
        options: opt,
        runs,
    };
    let rp = a.out.join("report.json");
    std::fs::write(&rp, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", rp.display()))?;
    println!(
        "wrote            {}/report.json, curves.csv, <test>_<dir>.csv and .png",
        a.out.display()
    );
    if report.runs.is_empty() {
        bail!("no test ran");
    }
    Ok(())
}
