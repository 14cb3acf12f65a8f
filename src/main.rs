//! The command line: parses, calls the library, reports.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use garment_sim::run;
use garment_sim::scene::{Overrides, Scene};
use garment_sim::solver::LinearSolverKind;
use std::io::IsTerminal;
use std::path::PathBuf;

mod cli_lab;
mod cli_trial;

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
    Drape {
        /// Scene file, e.g. config/scenes/table_drape.yaml
        scene: PathBuf,
        /// Output directory.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Grid spacing (both directions), m.
        #[arg(long, allow_negative_numbers = true)]
        spacing: Option<f64>,
        /// Fixed time step, s.
        #[arg(long, allow_negative_numbers = true)]
        dt: Option<f64>,
        /// Simulated duration, s.
        #[arg(long, allow_negative_numbers = true)]
        duration: Option<f64>,
        /// Linear solver: auto (default: the block-Jacobi PCG while it converges in fewer
        /// iterations than the break-even count, else a single-precision Cholesky factor as
        /// the PCG's preconditioner), pcg (block-Jacobi), amg (PCG with smoothed-aggregation
        /// multigrid) or cholesky (exact, double precision).
        #[arg(long)]
        solver: Option<LinearSolverKind>,
        /// Turn the hysteretic parts of the laws off.
        #[arg(long)]
        no_hysteresis: bool,
        /// Relative tolerance of the PCG, in (0, 1).
        #[arg(long, allow_negative_numbers = true)]
        cg_tolerance: Option<f64>,
        /// Threads of the assembly, the PCG and the contacts (default: one per core
        /// from 500 vertices; 1 for one core).
        #[arg(long)]
        threads: Option<usize>,
        #[command(flatten)]
        bag: BagArgs,
        #[command(flatten)]
        live: LiveArgs,
    },
    /// Read rosbag2 (MCAP) bags: info, export a cloth shape, repair after a crash.
    Bag {
        #[command(subcommand)]
        cmd: BagCmd,
    },
    /// Measure a fabric's damping from a motion capture of a free fall (thesis ch. 5).
    Identify {
        /// Capture file: C3D, or CSV (frame,time,<label>_x,_y,_z,...; metres).
        capture: PathBuf,
        /// Fabric file whose laws give the spring forces.
        #[arg(long)]
        fabric: PathBuf,
        /// Capture of a falling ball (first marker) giving the vertical.
        #[arg(long)]
        vertical: Option<PathBuf>,
        /// Upward direction in the capture's coordinates, e.g. 0,0,1 or 0,1,0
        /// (instead of --vertical; default: the capture's +z is up).
        #[arg(long, allow_hyphen_values = true)]
        up: Option<String>,
        /// Viscous window in frames, e.g. 40..100 (default: from the mean-speed curve).
        #[arg(long)]
        window: Option<String>,
        /// Marker grid, e.g. 11x11.
        #[arg(long, default_value = "11x11")]
        grid: String,
        /// Marker spacing, m.
        #[arg(long, default_value_t = 0.05, allow_negative_numbers = true)]
        spacing: f64,
        /// Markers are stored warp-major (index i*ny + j) instead of grid order (j*nx + i).
        #[arg(long)]
        warp_major: bool,
        /// Output directory (report.json, fabric with the measured damping).
        #[arg(long, default_value = "out/identify")]
        out: PathBuf,
    },
    /// Benchmark ms per step and real-time factor of the table drape.
    Bench {
        /// Scene to benchmark.
        #[arg(long, default_value = "config/scenes/table_drape.yaml")]
        scene: PathBuf,
        /// Grid spacings, m (comma separated).
        #[arg(long, value_delimiter = ',', default_values_t = vec![0.02, 0.01, 0.005])]
        spacing: Vec<f64>,
        /// Time steps, s (comma separated).
        #[arg(long, value_delimiter = ',', default_values_t = vec![1e-3, 1e-4])]
        dt: Vec<f64>,
        /// Solvers (comma separated).
        #[arg(long, value_delimiter = ',', default_values = ["pcg", "cholesky", "auto"])]
        solver: Vec<LinearSolverKind>,
        /// Steps per measurement (after the warm-up of the same count).
        #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
        steps: u64,
        /// Repetitions; the median is reported.
        #[arg(long, default_value_t = 3, value_parser = cli_lab::at_least_one)]
        repeat: usize,
        /// Simulated time before measuring (the cloth is mid-drape; at most
        /// 3 × steps are run), s.
        #[arg(long, default_value_t = 0.2, allow_negative_numbers = true,
              value_parser = cli_lab::seconds)]
        warmup: f64,
        /// Threads of the assembly, the PCG and the contacts (default: one per core
        /// from 500 vertices; 1 for one core).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Virtual Kawabata lab: KES-FB tensile, shear and bending tests on a simulated specimen.
    Kes(cli_lab::KesArgs),
    /// Fit the spring laws to raw KES curves (global least squares) and write a fabric file.
    FitKes(cli_lab::FitKesArgs),
    /// Drapemeter: drape coefficient and nodes of a circular specimen on a disk.
    Drapemeter(cli_lab::DrapemeterArgs),
    /// Cantilever bending test (Peirce; ASTM D1388): bending length and flexural rigidity of a strip.
    Cantilever(cli_lab::CantileverArgs),
    /// Virtual garment trial: sew a garment from its pattern onto a body, drape it and
    /// report the fit (garment.obj, garment.ply, fit.json, fit_strain.png, fit_pressure.png).
    Trial(cli_trial::TrialArgs),
}

/// Recording a drape as a rosbag2 bag.
#[derive(clap::Args)]
struct BagArgs {
    /// Record the drape into this new rosbag2 bag directory (MCAP + metadata.yaml).
    #[arg(long)]
    bag: Option<PathBuf>,
    /// Frames per simulated second in the bag (any rate ≥ 1/dt records every step).
    #[arg(long, default_value_t = 30.0)]
    bag_rate: f64,
    /// Chunk compression: zstd, lz4 or none.
    #[arg(long, default_value = "zstd")]
    bag_compression: garment_sim::bag::Compression,
    /// Chunk size, bytes (a crash loses at most the chunk being filled).
    #[arg(long, default_value_t = 1 << 20)]
    bag_chunk_size: u64,
}

/// Showing a drape live in Foxglove.
#[derive(clap::Args)]
struct LiveArgs {
    /// Serve a live view for Foxglove (Open connection → Foxglove WebSocket) on ADDR:PORT
    /// (without a value 127.0.0.1:8765; a bare PORT is on 127.0.0.1; put it after the scene).
    /// Waits for a viewer before the first step, paces the run and keeps serving the final
    /// state while a viewer stays connected (Ctrl-C ends it).
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1,
          default_missing_value = "127.0.0.1:8765", value_parser = garment_sim::live::parse_addr)]
    foxglove: Option<std::net::SocketAddr>,
    /// With --foxglove: simulated seconds per wall-clock second (1: real time; 0: as fast as
    /// the solver goes).
    #[arg(long, default_value_t = 1.0, requires = "foxglove")]
    pace: f64,
    /// With --foxglove: seconds to wait for a viewer to subscribe before the first step
    /// (default: until one does; 0: start at once).
    #[arg(long, value_name = "SECONDS", requires = "foxglove")]
    foxglove_wait: Option<f64>,
}

#[derive(Subcommand)]
enum BagCmd {
    /// Topics, message counts, duration, and whether the file is complete.
    Info {
        /// Bag directory (or its .mcap file).
        bag: PathBuf,
    },
    /// Write the cloth shape of one frame as PLY or OBJ, or a picture of it (PNG).
    Export {
        /// Bag directory (or its .mcap file).
        bag: PathBuf,
        /// Simulated time, s: the last frame at or before it.
        #[arg(long, conflicts_with = "last", required_unless_present = "last",
              allow_negative_numbers = true, value_parser = cli_lab::seconds)]
        time: Option<f64>,
        /// The last frame.
        #[arg(long)]
        last: bool,
        /// ply, obj or png (the cloth and the obstacles drawn from three views).
        #[arg(long, default_value = "ply")]
        format: garment_sim::bag::ShapeFormat,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
        /// Point cloud topic.
        #[arg(long, default_value = "/cloth/points")]
        points_topic: String,
        /// Mesh marker topic (triangles).
        #[arg(long, default_value = "/cloth/mesh")]
        mesh_topic: String,
    },
    /// Rebuild summary, indexes and metadata.yaml of a bag cut short by a crash.
    Repair {
        /// Bag directory (or its .mcap file).
        bag: PathBuf,
    },
}

fn bag_cmd(cmd: BagCmd) -> Result<()> {
    use garment_sim::bag;
    match cmd {
        BagCmd::Info { bag: dir } => print!("{}", bag::info(&dir)?),
        BagCmd::Export {
            bag: dir,
            time,
            last,
            format,
            out,
            points_topic,
            mesh_topic,
        } => {
            let when = match (time, last) {
                (Some(t), false) => bag::ExportTime::At(t),
                _ => bag::ExportTime::Last,
            };
            let shape = bag::shape_at(&dir, when, &points_topic, &mesh_topic)?;
            bag::write_shape(&shape, format, &out)?;
            println!(
                "wrote {} (t = {:.6} s, {} vertices, {} triangles)",
                out.display(),
                shape.time_s,
                shape.vertices.len(),
                shape.faces.len()
            );
        }
        BagCmd::Repair { bag: dir } => {
            let r = bag::repair(&dir)?;
            if r.was_complete {
                println!(
                    "{}: complete; metadata.yaml rewritten",
                    r.bag.file.display()
                );
            } else {
                if let bag::Ending::Truncated { offset, reason } = &r.ending {
                    println!("{}: cut at byte {offset} ({reason})", r.bag.file.display());
                }
                for (offset, why) in &r.dropped_chunks {
                    println!("dropped the chunk at byte {offset}: {why}");
                }
                println!(
                    "repaired: {} messages in {} chunks kept, {} bytes of an incomplete chunk dropped; summary, indexes and metadata.yaml rebuilt",
                    r.bag.message_count, r.bag.chunks, r.bytes_dropped
                );
                if let Some(b) = &r.backup {
                    println!("the damaged file is kept as {}", b.display());
                }
            }
        }
    }
    Ok(())
}

fn main() {
    cli_lab::quiet_broken_pipe();
    let cli = Cli::parse();
    if let Err(e) = real_main(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
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

/// Starts the live view of `drape --foxglove`, tells how to open it and
/// waits for a viewer as `args` says.
fn start_live_view(
    addr: std::net::SocketAddr,
    args: &LiveArgs,
) -> Result<garment_sim::live::LiveView> {
    use std::time::Duration;
    if let Some(w) = args.foxglove_wait {
        anyhow::ensure!(
            w.is_finite() && w >= 0.0,
            "--foxglove-wait {w}: must be ≥ 0 s"
        );
    }
    anyhow::ensure!(
        args.pace == 0.0 || (args.pace.is_finite() && args.pace >= 1e-3),
        "--pace {}: must be 0 (as fast as possible) or at least 0.001",
        args.pace
    );
    let view = garment_sim::live::LiveView::start(addr, "world")?;
    eprintln!("live view: {}", view.url());
    eprintln!(
        "  in Foxglove: Open connection → Foxglove WebSocket → {}, then a 3D panel showing /cloth/mesh (fixed frame: world)",
        view.url()
    );
    eprintln!("  or in a browser: {}", view.app_url());
    if !view.addr().ip().is_loopback() {
        eprintln!(
            "  warning: {} is reachable from the network and has no authentication",
            view.addr()
        );
    }
    if args.foxglove_wait != Some(0.0) {
        match args.foxglove_wait {
            Some(w) => eprintln!("waiting up to {w} s for a viewer to subscribe (Ctrl-C to stop)"),
            None => eprintln!("waiting for a viewer to subscribe (Ctrl-C to stop)"),
        }
        let stop = garment_sim::run::stop_flag()?;
        let timeout = args.foxglove_wait.map(Duration::from_secs_f64);
        if view.wait_for_subscriber(timeout, Duration::from_millis(500), &stop) {
            eprintln!("viewer subscribed: running");
        } else if stop.load(std::sync::atomic::Ordering::Relaxed) {
            anyhow::bail!("stopped by a signal before the run started");
        } else {
            eprintln!("no viewer subscribed: running anyway");
        }
    }
    Ok(view)
}

fn real_main(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Node { ros_args } => garment_sim::ros::node::run(&ros_args),
        Cmd::Drape {
            scene,
            out,
            spacing,
            dt,
            duration,
            solver,
            no_hysteresis,
            cg_tolerance,
            threads,
            bag,
            live,
        } => {
            let sc = Scene::load(&scene)?;
            let ov = Overrides {
                spacing,
                dt,
                duration,
                solver,
                hysteresis: if no_hysteresis { Some(false) } else { None },
                cg_tolerance,
                threads,
            };
            let view = live
                .foxglove
                .map(|a| start_live_view(a, &live))
                .transpose()?;
            let stop = match bag.bag.is_some() || view.is_some() {
                true => Some(garment_sim::run::stop_flag()?),
                false => None,
            };
            let no_stop = std::sync::atomic::AtomicBool::new(false);
            let stop_ref = stop.as_deref().unwrap_or(&no_stop);
            let mut live_run = match &view {
                Some(v) => {
                    let opts = garment_sim::live::LiveOptions {
                        rate_hz: sc.file.output_rate,
                        pace: live.pace,
                        end_time: sc.duration(&ov),
                    };
                    Some(garment_sim::live::LiveRun::new(v, opts, stop_ref)?)
                }
                None => None,
            };
            let mut also = |s: &garment_sim::solver::Simulation| match live_run.as_mut() {
                Some(r) => r.observe(s),
                None => Ok(run::Control::Continue),
            };
            let mut pr = progress_printer(format!("drape {}", scene.display()));
            let (s, recorded) = match &bag.bag {
                None if view.is_none() => (run::drape(&sc, &ov, &out, &mut pr)?.1, None),
                None => {
                    let sim = sc.build(&ov)?;
                    (
                        run::drape_with(&sc, &ov, sim, &out, &mut pr, &mut also)?.1,
                        None,
                    )
                }
                Some(dir) => {
                    use garment_sim::bag as gb;
                    let mut rec = gb::DrapeBag::new(dir);
                    rec.rate_hz = bag.bag_rate;
                    rec.options.compression = bag.bag_compression;
                    rec.options.chunk_size = bag.bag_chunk_size;
                    let r = gb::drape_recorded_with(
                        &sc, &ov, &out, &mut pr, &rec, stop_ref, &mut also,
                    )?;
                    (r.summary.clone(), Some(r))
                }
            };
            let e = &s.final_energies;
            println!("scene            {}", s.scene);
            println!("fabric           {}", s.fabric);
            println!(
                "grid             {} × {} ({} vertices), spacing {:.4} × {:.4} m",
                s.grid[0], s.grid[1], s.vertices, s.spacing_m[0], s.spacing_m[1]
            );
            println!(
                "solver           {}, dt = {} s, {} thread{}",
                s.linear_solver,
                s.dt_s,
                s.threads,
                if s.threads == 1 { "" } else { "s" }
            );
            println!(
                "simulated        {:.3} s in {} steps",
                s.simulated_s, s.steps
            );
            println!(
                "wall time        {:.2} s ({:.3} ms/step, real-time factor {:.3})",
                s.wall_s, s.ms_per_step, s.real_time_factor
            );
            println!(
                "  per step       assemble {:.3} ms, solve {:.3} ms, collide {:.3} ms",
                s.time_split_ms_per_step.assemble,
                s.time_split_ms_per_step.solve,
                s.time_split_ms_per_step.collide
            );
            println!(
                "solver iters     mean {:.2}, max {}",
                s.mean_solver_iterations, s.max_solver_iterations
            );
            match s.settle_time_s {
                Some(t) => println!(
                    "settle time      {t:.3} s (rms speed < {} m/s from then on)",
                    s.settle_speed_m_s
                ),
                None => println!(
                    "settle time      not settled (rms speed ≥ {} m/s at the end)",
                    s.settle_speed_m_s
                ),
            }
            if s.final_contacts > 0 {
                println!(
                    "contacts         {} vertices at the end, {} held by static friction",
                    s.final_contacts, s.final_contacts_held
                );
            }
            println!(
                "final energies   kinetic {:.3e} J, tension {:.3e} J, shear {:.3e} J, bending {:.3e} J, dissipated (damping) {:.3e} J",
                e.kinetic, e.tension, e.shear, e.bending, e.dissipated
            );
            println!(
                "wrote            {}/final.ply, final.png, energy.csv, summary.json",
                out.display()
            );
            let mut bag_error = None;
            if let Some(r) = recorded {
                if let Some(b) = &r.bag {
                    println!(
                        "bag              {} ({} frames, {} messages, {:.2} MiB, {:.1} ms per frame = {:.2} % of the wall time{})",
                        b.dir.display(),
                        r.frames,
                        b.message_count,
                        b.bytes as f64 / (1024.0 * 1024.0),
                        1e3 * r.record_s / r.frames.max(1) as f64,
                        100.0 * r.record_s / s.wall_s.max(1e-12),
                        if r.stopped {
                            ", stopped by a signal: bag finished"
                        } else {
                            ""
                        }
                    );
                }
                if r.stopped && r.bag.is_some() {
                    eprintln!(
                        "stopped by a signal at t = {:.4} s; the bag is complete{}",
                        s.simulated_s,
                        if garment_sim::run::interrupted_again() {
                            " (interrupted again while it was being closed: it was finished first)"
                        } else {
                            ""
                        }
                    );
                }
                bag_error = r.bag_error;
            }
            if let (Some(v), Some(r)) = (&view, &live_run) {
                println!(
                    "live view        {} ({} frames published)",
                    v.url(),
                    r.frames
                );
                if bag.bag.is_none() && stop_ref.load(std::sync::atomic::Ordering::Relaxed) {
                    eprintln!("stopped by a signal at t = {:.4} s", s.simulated_s);
                }
                if v.clients() > 0 && !stop_ref.load(std::sync::atomic::Ordering::Relaxed) {
                    eprintln!(
                        "live view: the run is over; serving its final state while a viewer is connected (Ctrl-C to end)"
                    );
                    v.linger(stop_ref);
                }
            }
            match bag_error {
                // the outputs are written; the bag is not whole
                Some(e) => anyhow::bail!("{e}"),
                None => Ok(()),
            }
        }
        Cmd::Bag { cmd } => bag_cmd(cmd),
        Cmd::Identify {
            capture,
            fabric,
            vertical,
            up,
            window,
            grid,
            spacing,
            warp_major,
            out,
        } => identify_cmd(
            capture, fabric, vertical, up, window, grid, spacing, warp_major, out,
        ),
        Cmd::Kes(a) => cli_lab::kes(a),
        Cmd::FitKes(a) => cli_lab::fit_kes(a),
        Cmd::Drapemeter(a) => cli_lab::drapemeter(a),
        Cmd::Cantilever(a) => cli_lab::cantilever(a),
        Cmd::Trial(a) => cli_trial::trial(a),
        Cmd::Bench {
            scene,
            spacing,
            dt,
            solver,
            steps,
            repeat,
            warmup,
            threads,
        } => {
            let sc = Scene::load(&scene).with_context(|| "bench needs a scene")?;
            println!(
                "scene {} ; {} steps per run, median of {} runs, after {} s of simulated warm-up",
                scene.display(),
                steps,
                repeat,
                warmup
            );
            println!(
                "{:>8} {:>9} {:>10} {:>8} {:>10} {:>9} {:>8} {:>9} {:>9} {:>8} {:>11} {:>7}",
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
                "threads"
            );
            for &sp in &spacing {
                for &h in &dt {
                    for &so in &solver {
                        let ov = Overrides {
                            spacing: Some(sp),
                            dt: Some(h),
                            solver: Some(so),
                            threads,
                            ..Default::default()
                        };
                        let mut sim = sc.build(&ov)?;
                        let wsteps = (warmup / h).round() as u64;
                        // per run: ms per step in all, then in assembly, solve
                        // and contacts (the step's own timers)
                        let mut ms: Vec<[f64; 4]> = Vec::new();
                        let mut it = 0.0;
                        let measured = (|| -> Result<()> {
                            for _ in 0..wsteps.min(steps * 3) {
                                sim.step()?;
                            }
                            for _ in 0..repeat.max(1) {
                                let t = std::time::Instant::now();
                                let mut iters = 0;
                                let mut phase = [0.0; 3];
                                for _ in 0..steps {
                                    let st = sim.step()?;
                                    iters += st.iterations;
                                    phase[0] += st.assemble_s;
                                    phase[1] += st.solve_s;
                                    phase[2] += st.collide_s;
                                }
                                let per = |x: f64| 1e3 * x / steps as f64;
                                ms.push([
                                    per(t.elapsed().as_secs_f64()),
                                    per(phase[0]),
                                    per(phase[1]),
                                    per(phase[2]),
                                ]);
                                it = iters as f64 / steps as f64;
                            }
                            Ok(())
                        })();
                        if let Err(e) = measured {
                            println!(
                                "{:>8} {:>9} {:>10} {:>8}   failed: {e:#}",
                                sp,
                                format!("{}x{}", sim.cloth.nx, sim.cloth.ny),
                                format!("{h:.4e}"),
                                format!("{so:?}").to_lowercase()
                            );
                            continue;
                        }
                        // the median run, with its own phase split
                        ms.sort_by(|a, b| a[0].total_cmp(&b[0]));
                        let med = ms[ms.len() / 2];
                        println!(
                            "{:>8} {:>9} {:>10} {:>8} {:>10.3} {:>9.3} {:>8.3} {:>9.3} {:>9.3} {:>8.1} {:>11.1} {:>7}",
                            sp,
                            format!("{}x{}", sim.cloth.nx, sim.cloth.ny),
                            format!("{h:.4e}"),
                            format!("{so:?}").to_lowercase(),
                            med[0],
                            med[1],
                            med[2],
                            med[3],
                            h * 1e3 / med[0],
                            it,
                            peak_rss_mb(),
                            sim.threads()
                        );
                    }
                }
            }
            Ok(())
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn identify_cmd(
    capture: PathBuf,
    fabric: PathBuf,
    vertical: Option<PathBuf>,
    up: Option<String>,
    window: Option<String>,
    grid: String,
    spacing: f64,
    warp_major: bool,
    out: PathBuf,
) -> Result<()> {
    use garment_sim::lab::identify::{identify_file, IdentifyOptions, MarkerGrid};
    let (nx, ny) = grid
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .filter(|&(a, b)| a >= 2 && b >= 2)
        .with_context(|| format!("--grid {grid:?}: expected NXxNY, e.g. 11x11"))?;
    if !(spacing.is_finite() && spacing > 0.0) {
        anyhow::bail!("--spacing {spacing}: must be > 0 m");
    }
    let window = match window {
        Some(w) => Some(
            w.split_once("..")
                .and_then(|(a, b)| {
                    Some((
                        a.trim().parse::<usize>().ok()?,
                        b.trim().parse::<usize>().ok()?,
                    ))
                })
                .with_context(|| format!("--window {w:?}: expected START..END in frames"))?,
        ),
        None => None,
    };
    let fab = garment_sim::io::load_fabric(&fabric)?;
    let opts = IdentifyOptions {
        grid: MarkerGrid {
            nx,
            ny,
            spacing: [spacing, spacing],
        },
        window,
        up: match up {
            None => None,
            Some(text) => {
                let v: Vec<f64> = text
                    .split(',')
                    .map(|c| c.trim().parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| anyhow::anyhow!("--up {text:?}: expected three numbers x,y,z"))?;
                if v.len() != 3 {
                    anyhow::bail!("--up {text:?}: expected three numbers x,y,z");
                }
                Some(nalgebra::Vector3::new(v[0], v[1], v[2]))
            }
        },
        ..Default::default()
    };
    let rep = identify_file(&capture, vertical.as_deref(), &fab, &opts, warp_major)?;
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    std::fs::write(out.join("report.json"), serde_json::to_string_pretty(&rep)?)?;
    let r = &rep.result;
    let mut file = fab.file.clone();
    // the joint fit is the answer (exact on exact data); the ordered fits are
    // the thesis' tables, biased where the dissipations are correlated
    let m = r.measured;
    if !r.resolved[0] {
        anyhow::bail!("the capture does not determine alpha (singular fit): check the window and the marker grid");
    }
    file.damping.alpha = m[0];
    if r.resolved[1] {
        file.damping.beta_bend = m[1];
    }
    if r.resolved[2] {
        file.damping.beta_shear = m[2];
    }
    if r.resolved[3] {
        file.damping.beta_tension = m[3];
    }
    file.notes = format!(
        "{}\nDamping measured by `garment_sim identify {}` (window {}..{} of {} frames at {} Hz).",
        file.notes.trim_end(),
        capture.display(),
        r.window.0,
        r.window.1,
        rep.frames,
        rep.rate_hz
    );
    let fab_out = out.join("fabric_measured.yaml");
    std::fs::write(&fab_out, serde_yaml::to_string(&file)?)?;
    let plots = garment_sim::lab::identify::write_plots(r, &out)?;
    println!(
        "capture          {} ({} frames, {} markers at {} Hz)",
        rep.capture, rep.frames, rep.markers, rep.rate_hz
    );
    println!(
        "gaps filled      {} marker positions in {} sweeps (thesis Algorithm 1)",
        rep.missing_markers_filled, rep.gap_fill_sweeps
    );
    if let Some(v) = rep.vertical_from_ball {
        println!(
            "vertical         ({:.5}, {:.5}, {:.5}) from the ball drop",
            v[0], v[1], v[2]
        );
    }
    println!(
        "viscous window   frames {}..{}{}",
        r.window.0,
        r.window.1,
        if r.window_chosen_automatically {
            " (from the mean-speed curve)"
        } else {
            ""
        }
    );
    println!("measured (± one standard error):");
    for (k, (name, unit)) in [
        ("alpha", "1/s"),
        ("beta_f", "s"),
        ("beta_c", "s"),
        ("beta_t", "s"),
    ]
    .iter()
    .enumerate()
    {
        if r.resolved[k] && r.measured_se[k].is_finite() {
            println!(
                "  {name:<8} {:>12.4e} ± {:.1e} {unit}",
                m[k], r.measured_se[k]
            );
        } else if r.resolved[k] {
            println!("  {name:<8} {:>12.4e} {unit} (trajectory fit)", m[k]);
        } else {
            println!("  {name:<8} not resolved by this capture (the fabric's own value is kept)");
        }
    }
    if let Some(t) = &r.trajectory {
        println!(
            "trajectory fit, frames {}..{} ({} simulations): {:.4e}, {:.4e}, {:.4e}, {:.4e}; rms {:.2e} m; \
             markers moved by a 15 % change: {:.1e}, {:.1e}, {:.1e}, {:.1e} m; resolved {:?}",
            t.frames.0,
            t.frames.1,
            t.simulations,
            t.theta[0],
            t.theta[1],
            t.theta[2],
            t.theta[3],
            t.rms_m,
            t.effect_15pc_m[0],
            t.effect_15pc_m[1],
            t.effect_15pc_m[2],
            t.effect_15pc_m[3],
            t.resolved
        );
    }
    println!(
        "all four jointly: {:.4e}, {:.4e}, {:.4e}, {:.4e} (condition number {:.2e})",
        r.global[0], r.global[1], r.global[2], r.global[3], r.global_condition_number
    );
    println!("ordered fits (thesis §5.4.3, Tables 5.1 and 5.2):");
    println!(
        "{:<14} {:>12} {:>12} {:>16}",
        "parameter", "mean", "std", "error decrease"
    );
    for e in [&r.alpha, &r.beta_bend, &r.beta_shear, &r.beta_tension] {
        println!(
            "{:<14} {:>12.4e} {:>12.4e} {:>15.2}%",
            e.name,
            e.mean,
            e.std,
            100.0 * e.error_decrease
        );
    }
    println!(
        "wrote            {}/report.json, {}",
        out.display(),
        fab_out.display()
    );
    for p in plots {
        println!("plot             {}", p.display());
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
