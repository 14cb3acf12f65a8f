//! `garment_sim drape`: a scene run headless, its outputs and figures, with
//! an optional rosbag2 bag and a live view in Foxglove.

use anyhow::Result;
use garment_sim::run::{Control, Step};
use garment_sim::scene::run;
use garment_sim::scene::system_file::SystemWriter;
use garment_sim::scene::{Overrides, Scene};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct DrapeArgs {
    /// Scene file, e.g. config/scenes/table_drape.yaml
    pub scene: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    #[command(flatten)]
    pub ov: Overrides,
    /// Write the linear system of these steps (indices from 0, comma-separated) into
    /// OUT/system-STEP/: the matrix and right-hand side in Matrix Market, the constraint
    /// filter, the solve's first guess and answer per vertex in CSV (docs/benchmarks.md).
    #[arg(
        long,
        value_name = "STEP",
        value_delimiter = ',',
        conflicts_with = "bag"
    )]
    pub write_system: Vec<u64>,
    #[command(flatten)]
    pub bag: BagArgs,
    #[command(flatten)]
    pub live: LiveArgs,
}

/// Recording a drape as a rosbag2 bag.
#[derive(clap::Args)]
pub struct BagArgs {
    /// Record the drape into this new rosbag2 bag directory (MCAP + metadata.yaml).
    #[arg(long)]
    pub bag: Option<PathBuf>,
    /// Frames per simulated second in the bag (any rate ≥ 1/dt records every step).
    #[arg(long, default_value_t = 30.0)]
    pub bag_rate: f64,
    /// Chunk compression: zstd, lz4 or none.
    #[arg(long, default_value = "zstd")]
    pub bag_compression: garment_sim::bag::Compression,
    /// Chunk size, bytes (a crash loses at most the chunk being filled).
    #[arg(long, default_value_t = 1 << 20)]
    pub bag_chunk_size: u64,
}

/// Showing a drape live in Foxglove.
#[derive(clap::Args)]
pub struct LiveArgs {
    /// Serve a live view for Foxglove (Open connection → Foxglove WebSocket) on ADDR:PORT
    /// (without a value 127.0.0.1:8765; a bare PORT is on 127.0.0.1; put it after the scene).
    /// Waits for a viewer before the first step, paces the run and keeps serving the final
    /// state while a viewer stays connected (Ctrl-C ends it).
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1,
          default_missing_value = "127.0.0.1:8765", value_parser = garment_sim::live::parse_addr)]
    pub foxglove: Option<std::net::SocketAddr>,
    /// With --foxglove: simulated seconds per wall-clock second (1: real time; 0: as fast as
    /// the solver goes).
    #[arg(long, default_value_t = 1.0, requires = "foxglove")]
    pub pace: f64,
    /// With --foxglove: seconds to wait for a viewer to subscribe before the first step
    /// (default: until one does; 0: start at once).
    #[arg(long, value_name = "SECONDS", requires = "foxglove")]
    pub foxglove_wait: Option<f64>,
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
        let stop = garment_sim::scene::run::stop_flag()?;
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

/// Prints the drape's summary (the lines of `summary.json` a reader wants
/// first) and what was written to `out`.
fn print_summary(s: &run::Summary, out: &std::path::Path) {
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
    let by = s.steps_solved_by;
    println!(
        "solver iters     mean {:.2}, max {} (steps solved by the block-Jacobi PCG {}, the Gauss–Seidel PCG {}, the multigrid {}, the Cholesky {})",
        s.mean_solver_iterations, s.max_solver_iterations, by.pcg, by.sgs, by.amg, by.cholesky
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
    if let Some(o) = &s.self_collision {
        println!(
            "self-collision   {:.3} ms/step ({:.1} % of the step); contacts {:.1} per step \
             (most {}, {} at the end); {} colliding pairs, {} impact zones",
            o.ms_per_step,
            100.0 * o.share_of_step,
            o.mean_contacts,
            o.max_contacts,
            o.final_contacts,
            o.collisions,
            o.zones
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
}

/// Prints where the bag went and whether a signal stopped it; the bag's
/// error, if writing it failed.
fn report_bag(r: garment_sim::bag::DrapeRecorded, s: &run::Summary) -> Option<String> {
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
            if garment_sim::scene::run::interrupted_again() {
                " (interrupted again while it was being closed: it was finished first)"
            } else {
                ""
            }
        );
    }
    r.bag_error
}

/// Prints the live view's address and frames; after the run, serves its
/// final state while a viewer stays connected.
fn report_live(
    v: &garment_sim::live::LiveView,
    r: &garment_sim::live::LiveRun,
    s: &run::Summary,
    no_bag: bool,
    stop_ref: &std::sync::atomic::AtomicBool,
) {
    println!(
        "live view        {} ({} frames published)",
        v.url(),
        r.frames
    );
    if no_bag && stop_ref.load(std::sync::atomic::Ordering::Relaxed) {
        eprintln!("stopped by a signal at t = {:.4} s", s.simulated_s);
    }
    if v.clients() > 0 && !stop_ref.load(std::sync::atomic::Ordering::Relaxed) {
        eprintln!(
            "live view: the run is over; serving its final state while a viewer is connected (Ctrl-C to end)"
        );
        v.linger(stop_ref);
    }
}

/// Runs `drape`.
pub fn drape(a: DrapeArgs) -> Result<()> {
    let DrapeArgs {
        scene,
        out,
        ov,
        write_system,
        bag,
        live,
    } = a;
    let sc = Scene::load(&scene)?;
    let view = live
        .foxglove
        .map(|a| start_live_view(a, &live))
        .transpose()?;
    let stop = match bag.bag.is_some() || view.is_some() {
        true => Some(garment_sim::scene::run::stop_flag()?),
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
    let mut systems = SystemWriter::new(&out, &write_system);
    let mut progress = crate::PhaseProgress::new(Some(format!("drape {}", scene.display())));
    let mut also = |s: &Step| {
        systems.observe(s.sim);
        progress.show(s);
        match live_run.as_mut() {
            Some(r) => r.observe(s),
            None => Ok(Control::Continue),
        }
    };
    let mut sim = sc.build(&ov)?;
    sim.capture_systems(&write_system);
    let (outcome, recorded) = match &bag.bag {
        None => (run::drape_built(&sc, &ov, sim, &mut also)?, None),
        Some(dir) => {
            use garment_sim::bag as gb;
            let mut rec = gb::DrapeBag::new(dir);
            rec.rate_hz = bag.bag_rate;
            rec.options.compression = bag.bag_compression;
            rec.options.chunk_size = bag.bag_chunk_size;
            let (o, r) = gb::drape_recorded(&sc, &ov, sim, &rec, stop_ref, &mut also)?;
            (o, Some(r))
        }
    };
    progress.finish();
    outcome.write(&out)?;
    let s = outcome.summary;
    let written = systems.finish(s.steps);
    print_summary(&s, &out);
    let bag_error = recorded.and_then(|r| report_bag(r, &s));
    if let (Some(v), Some(r)) = (&view, &live_run) {
        report_live(v, r, &s, bag.bag.is_none(), stop_ref);
    }
    // the outputs (and the bag) cover the steps before a failed one
    let failed = s
        .failure
        .as_ref()
        .map(|f| run::written_before_failure(f, s.simulated_s, s.steps, &out));
    match (failed, bag_error) {
        (Some(f), Some(e)) => anyhow::bail!("{f}\n{e}"),
        (Some(f), None) => Err(f),
        // the outputs are written; the bag is not whole
        (None, Some(e)) => anyhow::bail!("{e}"),
        // the outputs are written; a system asked for is not
        (None, None) => written,
    }
}
