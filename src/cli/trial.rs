//! `garment_sim trial`: a virtual garment trial from the command line.

use anyhow::Result;
use garment_sim::pictures::render::{full_scale, FieldPicture, Surface};
use garment_sim::scene::system_file::SystemWriter;
use garment_sim::solver::LinearSolverKind;
use garment_sim::trial::{self, Trial, TrialOverrides};
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
    if t.file.dressing.is_some() {
        anyhow::ensure!(
            a.write_system.is_empty(),
            "--write-system: not for a dressing trial ({})",
            a.trial.display()
        );
        return dress(&t, &ov, &a);
    }
    let (mut sim, g) = t.build(&ov)?;
    sim.capture_systems(&a.write_system);
    let mut systems = SystemWriter::new(&a.out, &a.write_system);
    eprintln!(
        "garment {}: {} panels, {} seams ({} stitches), {} vertices, {:.0} g of {}; body {} \
         triangles; dt = {} s",
        t.garment.name,
        g.panels.len(),
        g.seams.len(),
        g.cloth.seams.len(),
        g.cloth.len(),
        1e3 * g.cloth.total_mass(),
        sim.fabric.name,
        t.body.mesh.as_ref().map_or(0, |m| m.1.len()),
        sim.params().dt
    );
    std::fs::create_dir_all(&a.out)?;
    let stop = garment_sim::scene::run::stop_flag()?;
    let mut sew = crate::progress_printer("sewing".into());
    let mut drape = crate::progress_printer("drape".into());
    let mut motion = crate::progress_printer("motion".into());
    let mut moving = false;
    let body = trial::body_handle(&sim);
    let stats = trial::run_to_failure(
        &mut sim,
        body,
        &t.file.sewing,
        &t.file.settle,
        a.max_time,
        &mut |s, phase, x, of| {
            systems.observe(s);
            match phase {
                "sewing" => sew(x, of),
                "motion" => {
                    if !moving {
                        // the drape is over
                        drape(1.0, 1.0);
                        moving = true;
                    }
                    motion(x, of)
                }
                _ => drape(x, of),
            }
        },
        &|| stop.load(Ordering::Relaxed),
    )?;
    let written = systems.finish(sim.steps);
    if moving {
        motion(1.0, 1.0);
    } else {
        drape(1.0, 1.0);
    }
    let (fit, vf, on_body) = trial::fit(&sim, &g, &t, stats);
    trial::write_trace(&fit.run, &a.out.join("trial.csv"))?;
    trial::write_wrench(&fit.run, &a.out.join("body_wrench.csv"))?;
    if let Some(p) = &on_body {
        trial::write_body_ply(p, &a.out.join("body_pressure.ply"))?;
    }
    trial::write_obj(&sim, &g, &a.out.join("garment.obj"))?;
    trial::write_ply(&sim, &vf, &a.out.join("garment.ply"))?;
    let json = serde_json::to_string_pretty(&fit)?;
    garment_sim::io::write_atomic(&a.out.join("fit.json"), |w| w.write_all(json.as_bytes()))?;
    let cloth = Surface {
        vertices: sim.cloth.x.iter().map(|p| [p.x, p.y, p.z]).collect(),
        triangles: sim.cloth.triangles.clone(),
    };
    let body = vec![Surface::from_obstacle(trial::body_now(&sim, &t))];
    let info = vec![
        format!("fabric {}", sim.fabric.name),
        format!(
            "{} vertices at {:.1} cm",
            sim.cloth.len(),
            100.0 * sim.cloth.lc
        ),
        format!("t = {:.2} s", sim.time),
    ];
    let strain_pic = FieldPicture {
        title: format!("{}: stretch", t.garment.name),
        info: info.clone(),
        cloth: cloth.clone(),
        full: full_scale(&vf.stretch, 0.001),
        field: vf.stretch.clone(),
        label: ("stretch (warp, weft, bias)".into(), "%".into()),
        label_scale: 100.0,
        obstacles: body.clone(),
        size: (1500, 800),
    };
    strain_pic.save_png(&a.out.join("fit_strain.png"))?;
    let pressure_pic = FieldPicture {
        title: format!("{}: pressure on the body", t.garment.name),
        info,
        cloth,
        full: full_scale(&vf.pressure, 1.0),
        field: vf.pressure.clone(),
        label: ("pressure".into(), "Pa".into()),
        label_scale: 1.0,
        obstacles: body,
        size: (1500, 800),
    };
    pressure_pic.save_png(&a.out.join("fit_pressure.png"))?;
    let r = &fit.run;
    println!(
        "{}: sewn in {:.2} s, {}; {} steps, {:.1} s wall ({:.1} ms/step: assemble {:.1}, solve {:.1} ({:.1} iterations), contacts {:.1})",
        t.garment.name,
        r.sewing_s,
        match r.settle_time_s {
            Some(s) => format!("settled {s:.2} s after sewing"),
            None => format!("NOT settled (rms speed {:.4} m/s)", r.final_rms_speed_m_s),
        },
        r.steps,
        r.wall_s,
        r.ms_per_step,
        r.time_split_ms_per_step.assemble,
        r.time_split_ms_per_step.solve,
        r.mean_solver_iterations,
        r.time_split_ms_per_step.collide
    );
    if let (Some(m), Some(play)) = (&r.motion, r.motion_s) {
        let c = &m.time_split_ms_per_step;
        println!(
            "the body's motion: {} steps, {:.1} s wall for {:.2} s (real-time factor {:.2}; {:.1} ms/step: \
             assemble {:.1}, solve {:.1}, the body's contacts {:.1} ({:.0} %), its wrench {:.2})",
            m.steps,
            m.wall_s,
            play,
            play / m.wall_s.max(1e-12),
            m.ms_per_step,
            c.assemble,
            c.solve,
            c.collide,
            100.0 * c.collide / m.ms_per_step.max(1e-12),
            m.body_wrench_ms_per_step
        );
    }
    println!(
        "weight {:.3} N, force on the body {:.3} N over {:.1} cm² (mean pressure {:.1} Pa, peak {:.1} Pa); largest seam gap {:.2} mm; {} vertices inside the body",
        fit.weight_n,
        fit.contact_force_magnitude_n,
        1e4 * fit.contact_area_m2,
        fit.mean_pressure_pa,
        fit.peak_pressure_pa,
        fit.largest_seam_gap_mm,
        fit.body_penetrations
    );
    if let Some(bw) = &fit.body_wrench {
        let (f, m) = (bw.mean_force_n, bw.mean_torque_nm);
        // the sewing's first steps slam the panels onto the body: its peak
        // is named apart from the garment's as sewn
        let after = bw
            .peak_force_after_sewing_n
            .zip(bw.peak_force_after_sewing_time_s);
        // the run's peak is a sewing step's unless it is the one after sewing
        let sewing = match after {
            Some((_, t)) if t == bw.peak_force_time_s => String::new(),
            _ => format!(
                " (while sewing {:.3} N at t = {:.2} s)",
                bw.peak_force_n, bw.peak_force_time_s
            ),
        };
        let after = match after {
            Some((f, t)) => format!("peak force after sewing {f:.3} N at t = {t:.2} s"),
            None => "no step after sewing".to_string(),
        };
        println!(
            "on the body (mean of the last {} s): force ({:.3}, {:.3}, {:.3}) N ({:.3} of the \
             weight downward), torque ({:.4}, {:.4}, {:.4}) N m; {after}{sewing}",
            trial::WRENCH_MEAN_S,
            f[0],
            f[1],
            f[2],
            bw.mean_down_over_weight,
            m[0],
            m[1],
            m[2],
        );
    }
    if let Some(bp) = &fit.body_pressure {
        println!(
            "pressure on the body: {} vertices over {:.1} cm², peak {:.1} Pa, Σ pressure × area \
             {:.4} N (normal force {:.4} N)",
            bp.loaded_vertices,
            1e4 * bp.loaded_area_m2,
            bp.peak_pressure_pa,
            bp.pressure_integral_n,
            bp.normal_force_n
        );
    }
    for (name, gf) in &fit.girths {
        if let Some(e) = gf.ease_cm {
            println!(
                "  {name} (z = {:.2} m): body {:.1} cm, garment {:.1} cm, ease {e:.1} cm",
                gf.height_m,
                gf.body_cm.unwrap_or(0.0),
                gf.garment_cm.unwrap_or(0.0)
            );
        }
    }
    for w in &fit.warnings {
        eprintln!("warning: {w}");
    }
    println!("wrote {}", a.out.display());
    match &fit.run.failure {
        // the outputs are those of the steps before the failed one
        Some(f) => Err(garment_sim::scene::run::written_before_failure(
            f,
            fit.run.simulated_s,
            fit.run.steps,
            &a.out,
        )),
        // a system that could not be written fails the command, after the rest
        None => written,
    }
}

/// A trial with a `dressing` section: sewn on the body, then a gripper pulls
/// a sleeve over the arm (docs/bodies.md).
fn dress(t: &Trial, ov: &TrialOverrides, a: &TrialArgs) -> Result<()> {
    std::fs::create_dir_all(&a.out)?;
    let stop = garment_sim::scene::run::stop_flag()?;
    let mut sew = crate::progress_printer("sewing".into());
    let mut dress = crate::progress_printer("dressing".into());
    let wall = std::time::Instant::now();
    let mut t0 = f64::NAN;
    let mut so_far = Vec::new();
    // pictures at the first step and as the gripper passes each quarter of
    // its path: dressing_0.png … dressing_4.png
    let mut shot = 0;
    let mut shot_err: Option<anyhow::Error> = None;
    let ran = garment_sim::trial::dressing::run_trial(
        t,
        ov,
        &mut |_, _, x, of| sew(x, of),
        &mut |sim, d, row| {
            if t0.is_nan() {
                t0 = sim.time - sim.params().dt;
            }
            so_far.push(*row);
            let due = if shot == 0 {
                t0
            } else {
                d.t_move + (d.t_arrive - d.t_move) * (shot as f64 / 4.0)
            };
            if shot <= 4 && sim.time >= due - 1e-9 {
                let title = format!(
                    "{}: t = {:.2} s, progress {:.0} %, force on the arm {:.1} N",
                    t.garment.name,
                    sim.time,
                    100.0 * row.progress,
                    row.arm_force_n
                );
                let png = a.out.join(format!("dressing_{shot}.png"));
                if let Err(e) = garment_sim::pictures::render::Picture::from_simulation(sim, &title)
                    .save_png(&png)
                {
                    shot_err.get_or_insert(e);
                }
                shot += 1;
            }
            dress(sim.time - t0, d.t_end - t0)
        },
        &|| stop.load(Ordering::Relaxed),
    );
    let mut run = match ran {
        Ok(run) => run,
        Err(e) => {
            // what was recorded before the failure is kept
            if !so_far.is_empty() {
                let csv = a.out.join("dressing.csv");
                garment_sim::trial::dressing::write_csv(&so_far, &csv)?;
                eprintln!(
                    "the dressing stopped after {} steps; their rows are in {}",
                    so_far.len(),
                    csv.display()
                );
            }
            return Err(e);
        }
    };
    dress(1.0, 1.0);
    let wall_s = wall.elapsed().as_secs_f64();
    let (sim, g, rows) = (&run.sim, &run.garment, &run.rows);
    let mut stats = run.sewing.clone();
    let n = stats.steps + rows.len() as u64;
    stats.dressing_s = Some(sim.time - stats.sewing_s);
    stats.simulated_s = sim.time;
    stats.steps = n;
    stats.wall_s = wall_s;
    stats.ms_per_step = 1e3 * wall_s / n.max(1) as f64;
    stats.final_rms_speed_m_s = sim.rms_speed();
    let (mut fit, vf, on_body) = trial::fit(sim, g, t, stats);
    fit.dressing = Some(run.report.clone());
    garment_sim::trial::dressing::write_csv(rows, &a.out.join("dressing.csv"))?;
    garment_sim::trial::dressing::write_png(rows, &t.garment.name, &a.out.join("dressing.png"))?;
    if let Some(p) = &on_body {
        trial::write_body_ply(p, &a.out.join("body_pressure.ply"))?;
    }
    trial::write_obj(sim, g, &a.out.join("garment.obj"))?;
    trial::write_ply(sim, &vf, &a.out.join("garment.ply"))?;
    let json = serde_json::to_string_pretty(&fit)?;
    garment_sim::io::write_atomic(&a.out.join("fit.json"), |w| w.write_all(json.as_bytes()))?;
    let r = &mut run.report;
    println!(
        "{}: {} arm, wrist to shoulder {:.3} m{}; {} of {} vertices, {} held by the gripper; \
         {} dressing steps in {:.1} s wall ({:.1} ms/step)",
        t.garment.name,
        match r.arm {
            garment_sim::trial::dressing::Side::Left => "left",
            garment_sim::trial::dressing::Side::Right => "right",
        },
        r.arm_length_m,
        match r.hand {
            garment_sim::trial::dressing::Hand::Mesh => "",
            garment_sim::trial::dressing::Hand::Hull => ", the hand as its convex hull",
        },
        match r.grip {
            garment_sim::trial::dressing::Grip::Cuff => "cuff",
            garment_sim::trial::dressing::Grip::Armhole => "armhole",
        },
        r.cuff_vertices,
        r.gripped_vertices,
        r.steps,
        wall_s,
        r.ms_per_step
    );
    println!(
        "progress {:.3} m ({:.1} % of wrist to shoulder), held opening's centroid {:.1} cm from \
         the shoulder point (the gripper's ring tilted {:.0}° there), the sleeve's cuff {:.3} m \
         from the wrist; peak force on the arm \
         {:.3} N at t = {:.2} s (on the hand {:.3} N; past the wrist {:.3} N at t = {:.2} s, \
         {:.1} cm from the wrist), on the body {:.3} N, on the gripper {:.3} N; {} vertices \
         inside the body",
        r.final_progress_m,
        100.0 * r.final_progress,
        100.0 * r.final_distance_to_shoulder_m,
        r.path_end_tilt_deg,
        r.final_sleeve_end_progress_m,
        r.peak_arm_force_n,
        r.peak_arm_force_time_s,
        r.peak_hand_force_n,
        r.peak_wrist_to_shoulder_force_n,
        r.peak_wrist_to_shoulder_force_time_s,
        100.0 * r.peak_wrist_to_shoulder_force_at_m,
        r.peak_body_force_n,
        r.peak_gripper_force_n,
        fit.body_penetrations
    );
    if let (Some(f), Some(ts)) = (r.force_limit_n, r.safety_stop_s) {
        println!(
            "safety stop: the garment pulled on the gripper with more than {f} N at t = {ts:.3} s; \
             the gripper stopped there"
        );
    }
    for w in &fit.warnings {
        eprintln!("warning: {w}");
    }
    if r.stopped_early {
        eprintln!(
            "stopped by a signal at t = {:.4} s, {:.0} % of the way through the dressing: \
             the outputs hold the {} steps taken",
            sim.time,
            100.0 * (sim.time - run.dressing.t_move).max(0.0)
                / (run.dressing.t_end - run.dressing.t_move),
            rows.len()
        );
    }
    println!("wrote {}", a.out.display());
    // a picture that could not be written fails the command, once every
    // other output is written
    match shot_err {
        Some(e) => Err(e.context("writing the dressing's pictures")),
        None => Ok(()),
    }
}
