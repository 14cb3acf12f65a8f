//! The command line: parses, calls the library, reports.

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::io::IsTerminal;

mod cli;

#[derive(Parser)]
#[command(
    name = "garment_sim",
    version,
    about = "Measured-parameter woven-fabric cloth simulator (Charfi 2006, Baraff–Witkin)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run the simulation as a ROS 2 node (see docs/ros.md: topics, parameters,
    /// services). Options as in any ROS 2 node:
    /// `garment_sim node --ros-args -p publish_rate:=10.0 -r __ns:=/robot1`.
    Node {
        /// ROS arguments: --ros-args -p name:=value --params-file FILE -r from:=to
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        ros_args: Vec<String>,
    },
    /// Run a scene headless and write final.ply, energy.csv and summary.json.
    Drape(cli::drape::DrapeArgs),
    /// Read rosbag2 (MCAP) bags: info, export a cloth shape, repair after a crash.
    Bag {
        #[command(subcommand)]
        cmd: cli::bag::BagCmd,
    },
    /// Measure a fabric's damping from a motion capture of a free fall (thesis ch. 5).
    Identify(cli::identify::IdentifyArgs),
    /// Benchmark ms per step and real-time factor of the table drape.
    Bench(cli::bench::BenchArgs),
    /// Virtual Kawabata lab: KES-FB tensile, shear and bending tests on a simulated specimen.
    Kes(cli::lab::KesArgs),
    /// Fit the spring laws to raw KES curves (global least squares) and write a fabric file.
    FitKes(cli::lab::FitKesArgs),
    /// Drapemeter: drape coefficient and nodes of a circular specimen on a disk.
    Drapemeter(cli::lab::DrapemeterArgs),
    /// Cantilever bending test (Peirce; ASTM D1388): bending length and flexural rigidity of a strip.
    Cantilever(cli::lab::CantileverArgs),
    /// Virtual garment trial: sew a garment from its pattern onto a body, drape it and
    /// report the fit (garment.obj, garment.ply, fit.json, fit_strain.png, fit_pressure.png).
    Trial(cli::trial::TrialArgs),
    /// 3D shape of a drape from marked photos (thesis §6.3): camera poses, marks and
    /// the model deformed through them (reconstructed.ply, report.json, view_*.png).
    Reconstruct(cli::recon::ReconstructArgs),
    /// Distance between two shapes of a cloth (thesis eq. 6.2): mean and largest,
    /// with a map (compare.json, distance.png).
    Compare(cli::recon::CompareArgs),
}

fn main() {
    cli::lab::quiet_broken_pipe();
    let cli = Cli::parse();
    if let Err(e) = real_main(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// A run's progress on stderr, as its observer sees it: a bar (on a
/// terminal) or a line every tenth of the way per phase, named by the
/// phase or, for a run of one phase, by `label`.
pub(crate) struct PhaseProgress {
    label: Option<String>,
    bars: Vec<(garment_sim::run::Phase, Bar)>,
}

/// A phase's progress: `bar(done, of)`.
type Bar = Box<dyn FnMut(f64, f64)>;

impl PhaseProgress {
    pub(crate) fn new(label: Option<String>) -> PhaseProgress {
        PhaseProgress {
            label,
            bars: Vec::new(),
        }
    }

    /// Shows a step (a new phase ends the one before).
    pub(crate) fn show(&mut self, s: &garment_sim::run::Step) {
        if self.bars.last().is_none_or(|b| b.0 != s.phase) {
            self.finish();
            let name = self.label.clone();
            let name = name.unwrap_or_else(|| s.phase.name().into());
            self.bars.push((s.phase, Box::new(progress_printer(name))));
        }
        if let Some((_, bar)) = self.bars.last_mut() {
            bar(s.done, s.of);
        }
    }

    /// The run is over: its last phase's bar is full.
    pub(crate) fn finish(&mut self) {
        if let Some((_, bar)) = self.bars.last_mut() {
            bar(1.0, 1.0);
        }
    }
}

pub(crate) fn progress_printer(label: String) -> impl FnMut(f64, f64) {
    let tty = std::io::stderr().is_terminal();
    let bar = if tty {
        let b = indicatif::ProgressBar::new(1000);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        b.set_message(label.clone());
        Some(b)
    } else {
        None
    };
    let mut last_decile = -1i64;
    move |t, d| {
        let frac = if d > 0.0 { (t / d).min(1.0) } else { 1.0 };
        if let Some(b) = &bar {
            b.set_position((frac * 1000.0) as u64);
            if frac >= 1.0 {
                b.finish_and_clear();
            }
        } else {
            let dec = (frac * 10.0).floor() as i64;
            if dec != last_decile {
                last_decile = dec;
                eprintln!("{label}: t = {t:.3} s of {d:.3} s ({:.0} %)", 100.0 * frac);
            }
        }
    }
}

fn real_main(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Node { ros_args } => garment_sim::ros::node::run(&ros_args),
        Cmd::Drape(a) => cli::drape::drape(a),
        Cmd::Bag { cmd } => cli::bag::bag_cmd(cmd),
        Cmd::Identify(a) => cli::identify::identify(a),
        Cmd::Kes(a) => cli::lab::kes(a),
        Cmd::FitKes(a) => cli::lab::fit_kes(a),
        Cmd::Drapemeter(a) => cli::lab::drapemeter(a),
        Cmd::Cantilever(a) => cli::lab::cantilever(a),
        Cmd::Trial(a) => cli::trial::trial(a),
        Cmd::Bench(a) => cli::bench::bench(a),
        Cmd::Reconstruct(a) => cli::recon::reconstruct(a),
        Cmd::Compare(a) => cli::recon::compare(a),
    }
}
