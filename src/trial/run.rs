//! A trial's run, from its file to its outputs: [`run_trial`] builds the
//! garment on the body, runs its phases ([`Phase`]) with one observer that
//! sees every step and can stop the run, measures the fit and gives a
//! [`TrialOutcome`] that writes itself to a folder ([`TrialOutcome::write`]).
//! The command line, the Python package and the tests run trials through it.

use super::body_forces::{self, BodyPressure, Wrench};
use super::dressing::{self, Dressing, DressingReport, DressingRow};
use super::{
    body_handle, body_now, fit, write_body_ply, write_obj, write_ply, write_trace, write_wrench,
    Fit, Overrides, PhaseCost, RunStats, SettleFile, SewingFile, Trial, VertexFit,
    STANDARD_GRAVITY,
};
use crate::collision::Obstacle;
use crate::garment::Garment;
use crate::pictures::glb::{write_glb, GlbScene};
use crate::pictures::render::{full_scale, FieldPicture, Picture, Surface};
use crate::run::{Control, Observe, Phase, Run, Spent, Step};
use crate::set::Handle;
use crate::solver::{Params, Simulation};
use anyhow::{Context, Result};
use nalgebra::Vector3;
use std::path::Path;
use std::time::Instant;

/// Sews and drapes (and plays the body's motion), the phases of the
/// module's documentation; a step that fails is an error.
pub fn run(
    sim: &mut Simulation,
    sew: &SewingFile,
    st: &SettleFile,
    max_time: Option<f64>,
    observe: Observe,
) -> Result<RunStats> {
    sew_and_drape(sim, None, sew, st, max_time, observe)?.into_result()
}

/// [`run`], recording the garment's wrench on obstacle `body` after every
/// step ([`RunStats::wrench`]); a step that fails ends the trial with what
/// was done before it: the sewing's own settings (no gravity, stiffer seams)
/// are undone, no later phase runs, and [`RunStats::failure`] says which step
/// failed and why (for a caller that writes the trial's outputs all the
/// same; [`RunStats::into_result`] makes it an error). A bad setting is an
/// error at once.
pub fn sew_and_drape(
    sim: &mut Simulation,
    body: Option<Handle<Obstacle>>,
    sew: &SewingFile,
    st: &SettleFile,
    max_time: Option<f64>,
    observe: Observe,
) -> Result<RunStats> {
    let max_time = max_time.unwrap_or(st.max_time);
    check_phases(sew, st, max_time)?;
    let mut r = Recorder::new(sim, body);
    let mut stopped = false;
    let sewing_s = sewing(sim, sew, &mut r, observe, &mut stopped)?;
    let mut settle = None;
    if r.failure.is_none() && !stopped {
        settle = drape(sim, st, sewing_s, max_time, &mut r, observe, &mut stopped)?;
    }
    let (mut motion_s, mut motion) = (None, None);
    if r.failure.is_none() && !stopped {
        if let Some((s, cost)) = play_motion(sim, &mut r, observe, &mut stopped)? {
            motion_s = Some(s);
            motion = Some(cost);
        }
    }
    let wall = r.run.wall_s();
    let all = r.cost((&Spent::default(), 0.0), r.run.steps, wall);
    Ok(RunStats {
        sewing_s,
        settle_time_s: settle,
        simulated_s: sim.time,
        motion_s,
        dressing_s: None,
        steps: r.run.steps,
        wall_s: wall,
        ms_per_step: all.ms_per_step,
        time_split_ms_per_step: all.time_split_ms_per_step,
        final_rms_speed_m_s: sim.rms_speed(),
        mean_solver_iterations: all.mean_solver_iterations,
        body_wrench_ms_per_step: all.body_wrench_ms_per_step,
        motion,
        trace: r.trace,
        wrench: r.wrench,
        failure: r.failure,
        stopped,
    })
}

/// The phases' settings, each within its bounds.
fn check_phases(sew: &SewingFile, st: &SettleFile, max_time: f64) -> Result<()> {
    use crate::limits::check_range;
    check_range(
        "sewing.duration",
        sew.duration,
        0.0,
        60.0,
        "s",
        "a sewing phase of at most a minute",
    )?;
    check_range(
        "sewing.drag",
        sew.drag,
        0.0,
        1e3,
        "1/s",
        "mass-proportional damping",
    )?;
    check_range(
        "sewing.stiffness_factor",
        sew.stiffness_factor,
        1e-3,
        1e3,
        "",
        "a factor on the seams' stiffness",
    )?;
    for (what, v, lo, hi, unit, why) in [
        (
            "sewing.friction",
            sew.friction,
            0.0,
            2.0,
            "",
            "a Coulomb coefficient",
        ),
        (
            "sewing.closed",
            sew.closed,
            0.0,
            0.1,
            "m",
            "a seam gap at which the sewing ends",
        ),
        (
            "sewing.max_force",
            sew.max_force,
            0.1,
            1e3,
            "garment weights",
            "the stitches' pull in all while sewing",
        ),
    ] {
        if let Some(v) = v {
            check_range(what, v, lo, hi, unit, why)?;
        }
    }
    check_range(
        "settle.max_time",
        max_time,
        0.0,
        600.0,
        "s",
        "at most 10 minutes simulated",
    )?;
    check_range("settle.speed", st.speed, 1e-6, 1.0, "m/s", "an rms speed")?;
    Ok(check_range(
        "settle.hold",
        st.hold,
        0.0,
        10.0,
        "s",
        "a hold time",
    )?)
}

/// Steps the simulation through the run interface and keeps the trial's
/// figures: the steps' costs ([`Run`]), the trace every 0.05 s, the wrench
/// on the body, the first failure.
struct Recorder {
    run: Run,
    wrench_s: f64,
    every: u64,
    body: Option<Handle<Obstacle>>,
    trace: Vec<[f64; 4]>,
    wrench: Vec<(f64, Wrench)>,
    failure: Option<String>,
}

impl Recorder {
    fn new(sim: &Simulation, body: Option<Handle<Obstacle>>) -> Recorder {
        Recorder {
            run: Run::new(),
            wrench_s: 0.0,
            every: ((0.05 / sim.params().dt).round() as u64).max(1),
            body,
            trace: Vec::new(),
            wrench: Vec::new(),
            failure: None,
        }
    }

    /// One step; false (and the failure kept) if it failed.
    fn step(&mut self, sim: &mut Simulation) -> bool {
        let s = match self.run.step(sim) {
            Ok(s) => s,
            Err(e) => {
                self.failure = Some(e.to_string());
                return false;
            }
        };
        let t_w = Instant::now();
        if let Some(w) = self.body.and_then(|b| body_forces::wrench(sim, b)) {
            self.wrench.push((sim.time, w));
        }
        self.wrench_s += t_w.elapsed().as_secs_f64();
        if self.run.steps.is_multiple_of(self.every) {
            self.trace.push([
                sim.time,
                sim.rms_speed(),
                s.contacts as f64,
                s.iterations as f64,
            ]);
        }
        true
    }

    /// What the steps since `(spent, wrench_s)` cost, per step.
    fn cost(&self, before: (&Spent, f64), steps: u64, wall_s: f64) -> PhaseCost {
        let spent = self.run.spent.since(before.0);
        let n = steps.max(1) as f64;
        PhaseCost {
            steps,
            wall_s,
            ms_per_step: 1e3 * wall_s / n,
            time_split_ms_per_step: spent.split_ms_per_step(steps),
            mean_solver_iterations: spent.iterations as f64 / n,
            body_wrench_ms_per_step: 1e3 * (self.wrench_s - before.1) / n,
        }
    }
}

/// Phase 1: gravity off, the fabric's damping replaced by the sewing's
/// drag, the stitches stiffer (bounded by `max_force`), the skin's friction
/// the sewing's; all undone at its end. Returns its simulated length.
fn sewing(
    sim: &mut Simulation,
    sew: &SewingFile,
    r: &mut Recorder,
    observe: Observe,
    stopped: &mut bool,
) -> Result<f64> {
    let gravity = sim.params().gravity;
    let alphas: Vec<f64> = sim.fabrics().map(|f| f.damping.alpha).collect();
    let own: Vec<(f64, f64)> = sim.cloth.seams().iter().map(|s| (s.k, s.d)).collect();
    if !sew.gravity {
        sim.set_params(Params {
            gravity: Vector3::zeros(),
            ..sim.params().clone()
        })?;
    }
    for f in sim.fabrics_mut() {
        f.damping.alpha = f.damping.alpha.min(-sew.drag);
    }
    let f = sew.stiffness_factor;
    sim.cloth
        .set_seam_gains(&own.iter().map(|&(k, d)| (k * f, d * f)).collect::<Vec<_>>())?;
    let bound = sew
        .max_force
        .map(|w| w * sim.cloth.total_mass() * STANDARD_GRAVITY);
    // the panels close over the skin with the sewing's friction, then the
    // garment rests on it with the body's own
    let frictions: Vec<(Handle<Obstacle>, f64)> = sim
        .obstacles()
        .with_handles()
        .map(|(h, o)| (h, o.friction))
        .collect();
    for &(h, _) in &frictions {
        if let (Some(o), Some(f)) = (sim.obstacle_mut(h), sew.friction) {
            o.friction = f;
        }
    }
    let sew_steps = (sew.duration / sim.params().dt).round() as u64;
    for _ in 0..sew_steps {
        if let Some(bound) = bound {
            bound_sewing(sim, &own, sew.stiffness_factor, bound);
        }
        if !r.step(sim) {
            break;
        }
        if let Some(w) = sew.max_force {
            limit_sewing_speed(sim, w);
        }
        let step = Step {
            sim,
            phase: Phase::Sewing,
            done: sim.time,
            of: sew.duration,
        };
        if observe(&step)? == Control::Stop {
            *stopped = true;
            break;
        }
        if sew.closed.is_some_and(|c| largest_gap(sim) <= c) {
            break;
        }
    }
    let sewing_s = sim.time;
    for &(h, f) in &frictions {
        if let Some(o) = sim.obstacle_mut(h) {
            o.friction = f;
        }
    }
    sim.set_params(Params {
        gravity,
        ..sim.params().clone()
    })?;
    for (f, a) in sim.fabrics_mut().zip(alphas) {
        f.damping.alpha = a;
    }
    sim.cloth.set_seam_gains(&own)?;
    Ok(sewing_s)
}

/// Phase 2: the drape until the rms speed stays under `settle.speed` for
/// `settle.hold`; returns when it settled (s after sewing), if it did.
fn drape(
    sim: &mut Simulation,
    st: &SettleFile,
    sewing_s: f64,
    max_time: f64,
    r: &mut Recorder,
    observe: Observe,
    stopped: &mut bool,
) -> Result<Option<f64>> {
    let mut calm_since: Option<f64> = None;
    while sim.time - sewing_s < max_time - 1e-12 {
        if !r.step(sim) {
            return Ok(None);
        }
        let step = Step {
            sim,
            phase: Phase::Drape,
            done: sim.time - sewing_s,
            of: max_time,
        };
        let go_on = observe(&step)? == Control::Continue;
        if sim.rms_speed() < st.speed {
            let since = *calm_since.get_or_insert(sim.time);
            if sim.time - since >= st.hold - 1e-12 {
                return Ok(Some(since - sewing_s));
            }
        } else {
            calm_since = None;
        }
        if !go_on {
            *stopped = true;
            return Ok(None);
        }
    }
    Ok(None)
}

/// Phase 3: a body held in its first pose while the garment was sewn and
/// draped moves; the run lasts until its motion ends. Its length and cost,
/// if the body moves.
fn play_motion(
    sim: &mut Simulation,
    r: &mut Recorder,
    observe: Observe,
    stopped: &mut bool,
) -> Result<Option<(f64, PhaseCost)>> {
    let held: Vec<_> = sim
        .obstacles()
        .with_handles()
        .filter(|(_, o)| o.deforming().is_some_and(|b| b.held))
        .map(|(h, _)| h)
        .collect();
    if held.is_empty() {
        return Ok(None);
    }
    let mut play: f64 = 0.0;
    for h in held {
        if let Some(b) = sim.obstacle_mut(h).and_then(|o| o.deforming_mut()) {
            b.release();
            play = play.max(b.remaining());
        }
    }
    let t0 = sim.time;
    let (wall0, steps0, spent0, wrench0) = (Instant::now(), r.run.steps, r.run.spent, r.wrench_s);
    while sim.time - t0 < play - 1e-12 {
        if !r.step(sim) {
            break;
        }
        let step = Step {
            sim,
            phase: Phase::Motion,
            done: sim.time - t0,
            of: play,
        };
        if observe(&step)? == Control::Stop {
            *stopped = true;
            break;
        }
    }
    let wall = wall0.elapsed().as_secs_f64();
    let cost = r.cost((&spent0, wrench0), r.run.steps - steps0, wall);
    Ok(Some((sim.time - t0, cost)))
}

/// Sets the stitches' stiffness for the next sewing step: `factor` times
/// their own (`own`: stiffness and damping), scaled down together so that
/// their pull at the current gaps, `Σ k |g|`, is at most `bound` (N). The
/// pull keeps the linear law's shape (a wider gap pulls harder) and its
/// sum is bounded however wide the gaps.
fn bound_sewing(sim: &mut Simulation, own: &[(f64, f64)], factor: f64, bound: f64) {
    let pull: f64 = (sim.cloth.seams().iter().zip(own))
        .map(|(s, &(k, _))| factor * k * s.gap(sim.cloth.positions()).norm())
        .sum();
    let scale = factor * if pull > bound { bound / pull } else { 1.0 };
    let gains: Vec<(f64, f64)> = own.iter().map(|&(k, d)| (k * scale, d * scale)).collect();
    sim.cloth
        .set_seam_gains(&gains)
        .expect("scaled gains of checked seams");
}

/// While sewing with its pull bounded at `weights` garment weights, no
/// vertex keeps a speed it could not be stopped from in one step by that
/// many of its own weights, `weights · g · dt`: a vertex the body stops
/// hits it with at most that many of its own weights (cloth wedged in a
/// fold still presses both sides harder, docs/garments.md).
fn limit_sewing_speed(sim: &mut Simulation, weights: f64) {
    let top = weights * STANDARD_GRAVITY * sim.params().dt;
    let mut over = false;
    let capped: Vec<Vector3<f64>> = (sim.cloth.velocities().iter())
        .map(|v| {
            let s = v.norm();
            over |= s > top;
            if s > top {
                v * (top / s)
            } else {
                *v
            }
        })
        .collect();
    if over {
        sim.cloth
            .set_velocities(&capped)
            .expect("finite velocities scaled down");
    }
}

/// The widest gap of any stitch, m.
fn largest_gap(sim: &Simulation) -> f64 {
    (sim.cloth.seams().iter())
        .map(|s| s.gap(sim.cloth.positions()).norm())
        .fold(0.0, f64::max)
}

/// The garment as it moved: at most this many frames, evenly spaced in
/// simulated time (for `trial.glb`).
pub const MAX_FRAMES: usize = 60;

/// Keeps the garment's positions every `interval` simulated seconds,
/// doubling the interval (and dropping every other frame) whenever more
/// than [`MAX_FRAMES`] would be kept.
#[derive(Debug, Clone)]
pub struct Frames {
    interval: f64,
    next: f64,
    /// (time, positions), in time order.
    pub frames: Vec<(f64, Vec<[f32; 3]>)>,
}

impl Frames {
    fn new() -> Frames {
        Frames {
            interval: 0.05,
            next: 0.0,
            frames: Vec::new(),
        }
    }

    fn shot(sim: &Simulation) -> (f64, Vec<[f32; 3]>) {
        let x = sim.cloth.positions().iter();
        (
            sim.time,
            x.map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect(),
        )
    }

    fn observe(&mut self, sim: &Simulation) {
        // a state with a non-finite position (the step after it fails) is
        // no frame of the garment's motion
        if sim.time + 1e-9 < self.next || !finite(sim) {
            return;
        }
        self.frames.push(Frames::shot(sim));
        if self.frames.len() > MAX_FRAMES {
            let kept = std::mem::take(&mut self.frames);
            self.frames = kept.into_iter().step_by(2).collect();
            self.interval *= 2.0;
        }
        self.next = self.frames.last().map_or(0.0, |f| f.0) + self.interval;
    }

    /// The last state, if it is not the last frame already.
    fn finish(&mut self, sim: &Simulation) {
        if finite(sim) && self.frames.last().is_none_or(|f| f.0 < sim.time) {
            if self.frames.len() == MAX_FRAMES {
                self.frames.pop();
            }
            self.frames.push(Frames::shot(sim));
        }
    }
}

/// Every position of the garment is finite.
fn finite(sim: &Simulation) -> bool {
    sim.cloth
        .positions()
        .iter()
        .all(|p| p.iter().all(|c| c.is_finite()))
}

/// What a trial with a `dressing` adds to its outcome.
pub struct DressingOutcome {
    pub dressing: Dressing,
    pub rows: Vec<DressingRow>,
    /// Pictures at the first step and as the gripper passes each quarter of
    /// its path (`dressing_0.png` … `dressing_4.png`).
    pub pictures: Vec<Picture>,
}

/// A trial's run and fit: the simulation as it ended, the fit report, what
/// each vertex measured, the pressure on the body, the dressing's record.
pub struct TrialOutcome {
    pub fit: Fit,
    pub sim: Simulation,
    pub garment: Garment,
    pub vertex_fit: VertexFit,
    pub body_pressure: Option<BodyPressure>,
    pub dressing: Option<DressingOutcome>,
    /// The garment's positions over the run.
    pub frames: Frames,
}

/// Builds a trial, runs it and measures its fit. A step that fails ends the
/// run with what was done before it ([`TrialOutcome::error`]); a bad file or
/// setting is an error at once.
pub fn run_trial(t: &Trial, ov: &Overrides, observe: Observe) -> Result<TrialOutcome> {
    let (sim, g) = t.build(ov)?;
    run_built(t, ov, sim, g, observe)
}

/// [`run_trial`] on a trial already built (`Trial::build`), for a caller that
/// sets the simulation up further (e.g. the steps whose linear system it
/// captures).
pub fn run_built(
    t: &Trial,
    ov: &Overrides,
    mut sim: Simulation,
    g: Garment,
    observe: Observe,
) -> Result<TrialOutcome> {
    let body = body_handle(&sim);
    let mut frames = Frames::new();
    // the garment placed, before the first step
    frames.observe(&sim);
    let mut seen = |s: &Step| {
        frames.observe(s.sim);
        observe(s)
    };
    let (stats, dressing) = match &t.file.dressing {
        Some(d) => {
            let body = body.context("the trial has no body")?;
            d.check()?;
            let (stats, dressed) = dress(t, ov, &mut sim, &g, body, d, &mut seen)?;
            (stats, Some(dressed))
        }
        None => {
            let (sew, st) = (&t.file.sewing, &t.file.settle);
            let stats = sew_and_drape(&mut sim, body, sew, st, ov.max_time, &mut seen)?;
            (stats, None)
        }
    };
    frames.finish(&sim);
    let (mut fit, vertex_fit, body_pressure) = fit(&sim, &g, t, stats);
    fit.dressing = dressing.as_ref().map(|d| d.report.clone());
    fit.outcome = Some(super::outcome::outcome(t, &sim, &g, &vertex_fit, &fit));
    Ok(TrialOutcome {
        fit,
        sim,
        garment: g,
        vertex_fit,
        body_pressure,
        dressing: dressing.map(|d| d.outcome),
        frames,
    })
}

struct Dressed {
    report: DressingReport,
    outcome: DressingOutcome,
}

/// Sews the garment on the body, then the gripper pulls the sleeve over the
/// arm for at most `max_time` after sewing (`ov.max_time`, else the whole
/// path). The run's figures, the dressing's report and record.
fn dress(
    t: &Trial,
    ov: &Overrides,
    sim: &mut Simulation,
    g: &Garment,
    body: Handle<Obstacle>,
    d: &dressing::DressingFile,
    observe: Observe,
) -> Result<(RunStats, Dressed)> {
    if let Some(m) = ov.max_time {
        let why = "a dressing of at most 10 minutes";
        crate::limits::check_range("--max-time", m, 0.0, 600.0, "s", why)?;
    }
    let wall = Instant::now();
    // a vertex in a crease is held by the nearest surface alone: held by
    // both, the sleeve drawn over the hand's mesh catches in the folds
    // between its fingers (275 N on the arm past the wrist in the first half
    // of the cuff's path, against under 1 N; docs/garments.md, "Creases")
    let mut p = sim.params().clone();
    p.creases = false;
    sim.set_params(p)?;
    let (sew, st) = (&t.file.sewing, &t.file.settle);
    let mut stats = sew_and_drape(sim, Some(body), sew, st, Some(0.0), observe)?.into_result()?;
    let dressing = Dressing::set_up(sim, g, body, d)?;
    if d.edge_contacts {
        let mut p = sim.params().clone();
        p.obstacle_edges = true;
        sim.set_params(p)?;
    }
    let t0 = sim.time;
    let limit = ov.max_time.map(|m| stats.sewing_s + m);
    let (mut stopped, mut timed_out) = (stats.stopped, false);
    let mut pictures = Vec::new();
    let mut so_far: Vec<DressingRow> = Vec::new();
    let walk = Instant::now();
    let mut run = Run::new();
    let ran = {
        let mut on_step = |sim: &Simulation, dr: &Dressing, row: &DressingRow| -> Result<Control> {
            so_far.push(*row);
            // pictures at the first step and as the gripper passes each
            // quarter of its path
            let shot = pictures.len();
            let due = if shot == 0 {
                t0
            } else {
                dr.t_move + (dr.t_arrive - dr.t_move) * (shot as f64 / 4.0)
            };
            if shot <= 4 && sim.time >= due - 1e-9 {
                let title = format!(
                    "{}: t = {:.2} s, progress {:.0} %, force on the arm {:.1} N",
                    t.garment.name,
                    sim.time,
                    100.0 * row.progress,
                    row.arm_force_n
                );
                pictures.push(Picture::from_simulation(sim, &title));
            }
            let step = Step {
                sim,
                phase: Phase::Dressing,
                done: sim.time - t0,
                of: dr.t_end - t0,
            };
            if observe(&step)? == Control::Stop {
                stopped = true;
            }
            if limit.is_some_and(|l| sim.time >= l - 1e-9) {
                timed_out = true;
            }
            Ok(if stopped || timed_out {
                Control::Stop
            } else {
                Control::Continue
            })
        };
        match stats.stopped {
            true => Ok(Vec::new()),
            false => dressing.run(sim, d, &mut run, &mut on_step),
        }
    };
    // a failed step ends the dressing with the rows recorded before it
    let rows = match ran {
        Ok(rows) => rows,
        Err(e) if !so_far.is_empty() => {
            stats.failure = Some(format!("{e:#}"));
            so_far
        }
        Err(e) => return Err(e),
    };
    let mut report = dressing.report(d, &rows, walk.elapsed().as_secs_f64());
    report.final_distance_to_shoulder_m =
        (dressing.cuff_centroid(sim) - dressing.arm.shoulder()).norm();
    report.stopped_early = stopped;
    report.time_limit_s = ov.max_time.filter(|_| timed_out);
    let wall_s = wall.elapsed().as_secs_f64();
    let n = stats.steps + run.steps;
    stats.dressing_s = Some(sim.time - stats.sewing_s);
    stats.simulated_s = sim.time;
    stats.steps = n;
    stats.wall_s = wall_s;
    stats.ms_per_step = 1e3 * wall_s / n.max(1) as f64;
    stats.final_rms_speed_m_s = sim.rms_speed();
    stats.stopped = stopped;
    let outcome = DressingOutcome {
        dressing,
        rows,
        pictures,
    };
    Ok((stats, Dressed { report, outcome }))
}

impl TrialOutcome {
    /// The garment's vertices as the run ended, m.
    pub fn positions(&self) -> Vec<[f64; 3]> {
        self.sim
            .cloth
            .positions()
            .iter()
            .map(|p| [p.x, p.y, p.z])
            .collect()
    }

    /// The garment's triangles (indices into [`TrialOutcome::positions`]).
    pub fn triangles(&self) -> Vec<[usize; 3]> {
        self.sim.cloth.triangles.clone()
    }

    /// Writes the outputs into `dir` (made if need be): `garment.obj`,
    /// `garment.ply` (per-vertex stretch and pressure), `fit.json`,
    /// `trial.glb` (the run as a glTF scene),
    /// `body_pressure.ply`; a trial that drapes `trial.csv`,
    /// `body_wrench.csv`, `fit_strain.png` and `fit_pressure.png`; a dressing
    /// `dressing.csv`, `dressing.png` and `dressing_0.png` … `dressing_4.png`.
    pub fn write(&self, t: &Trial, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("making {}", dir.display()))?;
        let (sim, g, fit) = (&self.sim, &self.garment, &self.fit);
        match &self.dressing {
            None => {
                write_trace(&fit.run, &dir.join("trial.csv"))?;
                write_wrench(&fit.run, &dir.join("body_wrench.csv"))?;
            }
            Some(d) => {
                dressing::write_csv(&d.rows, &dir.join("dressing.csv"))?;
                dressing::write_png(&d.rows, &t.garment.name, &dir.join("dressing.png"))?;
            }
        }
        if let Some(p) = &self.body_pressure {
            write_body_ply(p, &dir.join("body_pressure.ply"))?;
        }
        write_obj(sim, g, &dir.join("garment.obj"))?;
        write_ply(sim, &self.vertex_fit, &dir.join("garment.ply"))?;
        let json = serde_json::to_string_pretty(fit)?;
        crate::io::write_atomic(&dir.join("fit.json"), |w| w.write_all(json.as_bytes()))?;
        self.write_glb(t, dir)?;
        match &self.dressing {
            None => self.write_pictures(t, dir),
            Some(d) => {
                for (k, p) in d.pictures.iter().enumerate() {
                    p.save_png(&dir.join(format!("dressing_{k}.png")))
                        .context("writing the dressing's pictures")?;
                }
                Ok(())
            }
        }
    }

    /// `trial.glb`: the body as it ended and the garment over the run,
    /// coloured by its stretch on `fit_strain.png`'s scale.
    fn write_glb(&self, t: &Trial, dir: &Path) -> Result<()> {
        let body = Surface::from_obstacle(body_now(&self.sim, t));
        let body_triangles: Vec<[u32; 3]> = (body.triangles.iter())
            .map(|f| f.map(|k| k as u32))
            .collect();
        // a vertex whose stretch is not finite (a failed run) is coloured
        // as unstretched
        let stretch: Vec<f64> = (self.vertex_fit.stretch.iter())
            .map(|&e| if e.is_finite() { e } else { 0.0 })
            .collect();
        let stretch = &stretch;
        let scene = GlbScene {
            body_vertices: &body.vertices,
            body_triangles: &body_triangles,
            garment_triangles: &self.sim.cloth.triangles,
            frames: &self.frames.frames,
            stretch,
            stretch_full: full_scale(stretch, 0.001),
            name: &t.garment.name,
        };
        write_glb(&scene, &dir.join("trial.glb"))
    }

    /// `fit_strain.png` and `fit_pressure.png`: the garment on the body,
    /// coloured by its stretch and by its pressure on the body.
    fn write_pictures(&self, t: &Trial, dir: &Path) -> Result<()> {
        let (sim, vf) = (&self.sim, &self.vertex_fit);
        let cloth = Surface {
            vertices: sim
                .cloth
                .positions()
                .iter()
                .map(|p| [p.x, p.y, p.z])
                .collect(),
            triangles: sim.cloth.triangles.clone(),
        };
        let body = vec![Surface::from_obstacle(body_now(sim, t))];
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
        strain_pic.save_png(&dir.join("fit_strain.png"))?;
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
        pressure_pic.save_png(&dir.join("fit_pressure.png"))
    }

    /// The error of the step that ended the run early, if one failed.
    pub fn error(&self) -> Option<anyhow::Error> {
        self.fit
            .run
            .failure
            .as_ref()
            .map(|f| anyhow::anyhow!("{f}"))
    }
}
