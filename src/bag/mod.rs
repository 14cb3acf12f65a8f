//! rosbag2 bags (MCAP storage, as `ros2 bag record` writes by default since
//! Iron) of simulations: written headless by `garment_sim drape --bag` and by
//! the node (`record_bag`), read by `garment_sim bag info | export | repair`,
//! `ros2 bag`, `rosbags`, the `mcap` tools and Foxglove.
//!
//! A bag is a directory holding `<dir name>_0.mcap` and `metadata.yaml`
//! (format version 9). In the MCAP file: profile `ros2`; one schema per type,
//! encoding `ros2msg`, holding the full definition with its dependencies
//! ([`crate::msgs::definitions`]); one channel per topic, message encoding `cdr`, with the
//! offered QoS profiles in its `offered_qos_profiles` metadata (the same
//! profiles as in `metadata.yaml`); messages as CDR with the 4-byte
//! encapsulation header, **log time = publish time = the header stamp, i.e.
//! the simulated time in nanoseconds** (a drape starts at 0); a `rosbag2`
//! metadata record before the first message and at the end.
//!
//! Crash safety: chunks are closed by the writer once they hold
//! [`BagOptions::chunk_size`] bytes and handed to the operating system at
//! once, and `metadata.yaml` is rewritten (atomically) after each chunk, so a
//! killed process leaves a bag readable up to its last complete chunk, with a
//! `metadata.yaml` describing exactly those messages; [`repair`] then rebuilds
//! the summary and indexes. SIGINT and SIGTERM set [`stop_flag`], on which
//! `drape --bag` stops stepping and finishes the bag.
//!
//! The physics modules never depend on this one.

pub mod metadata;
pub mod reader;
pub mod recorder;
pub mod tools;
pub mod writer;

pub use metadata::{BagInformation, Qos};
pub use reader::{Ending, Reader};
pub use recorder::{scene_description, Frame, SimRecorder, TopicNames};
pub use tools::{
    info, repair, shape_at, shape_picture, write_shape, BagInfo, ExportTime, RepairReport, Shape,
    ShapeFormat,
};
pub use writer::{BagOptions, BagSummary, Compression, Writer};

use crate::msgs::publish::{DiagnosticFigures, FrameClock};
use crate::run::{Control, Observe, Step};
use crate::scene::run;
use crate::scene::{Overrides, Scene};
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// How `drape --bag` records.
#[derive(Debug, Clone)]
pub struct DrapeBag {
    pub dir: PathBuf,
    pub options: BagOptions,
    /// Frames per simulated second (a frame at the first step at or after
    /// each multiple of 1/rate; ≥ 1/dt records every step).
    pub rate_hz: f64,
    pub topics: TopicNames,
    pub frame_id: String,
}

impl DrapeBag {
    pub fn new(dir: &Path) -> DrapeBag {
        DrapeBag {
            dir: dir.to_path_buf(),
            options: BagOptions::default(),
            rate_hz: 30.0,
            topics: TopicNames::default(),
            frame_id: "world".into(),
        }
    }
}

/// What a recorded drape did.
#[derive(Debug, Clone)]
pub struct DrapeRecorded {
    /// The finished bag; `None` if writing it failed (see `bag_error`).
    pub bag: Option<BagSummary>,
    /// Why the recording stopped before the end (a full disk), naming the
    /// bag's file: the run went on without it and wrote its outputs.
    pub bag_error: Option<String>,
    pub frames: u64,
    /// The run was stopped by `stop` before its duration.
    pub stopped: bool,
    /// Wall time spent building, serialising, compressing and writing the
    /// bag's messages, s (included in the summary's wall time).
    pub record_s: f64,
}

/// Runs a scene headless as [`run::drape`] does while recording it into
/// a bag: a frame before the first step and at `bag.rate_hz` in simulated
/// time. `also` (e.g. a live view, a progress line) sees each step after
/// the recorder; the run stops when it says so or when `stop` is set, then
/// the bag is finished. `sim` is the scene built with `ov`. The caller
/// writes the drape's outputs ([`run::DrapeOutcome::write`]).
pub fn drape_recorded(
    scene: &Scene,
    ov: &Overrides,
    sim: crate::solver::Simulation,
    bag: &DrapeBag,
    stop: &AtomicBool,
    also: Observe,
) -> Result<(run::DrapeOutcome, DrapeRecorded)> {
    if !(bag.rate_hz.is_finite() && bag.rate_hz > 0.0) {
        bail!("bag rate {} Hz: must be a finite number > 0", bag.rate_hz);
    }
    let mut clock = FrameClock::new(sim.time);
    let description = scene_description(scene, ov, &sim)?;
    let mut rec = Some(SimRecorder::create(
        &bag.dir,
        &bag.options,
        &bag.topics,
        &description,
    )?);
    let mut bag_error: Option<String> = None;
    let mut frames_before_failure = 0;
    let mut last = (Instant::now(), sim.steps, sim.time);
    let mut last_recorded = None;
    let mut stopped = false;
    let mut record_s = 0.0;
    let mut observer = |step: &Step| -> Result<Control> {
        let s = step.sim;
        if clock.due(s.time, bag.rate_hz) {
            let now = Instant::now();
            let (n, t) = (s.steps - last.1, s.time - last.2);
            let wall = now.duration_since(last.0).as_secs_f64();
            let fig = DiagnosticFigures {
                step_time_ms: if n > 0 { 1e3 * wall / n as f64 } else { 0.0 },
                real_time_factor: if wall > 0.0 { t / wall } else { 0.0 },
                ..Default::default()
            };
            let t_rec = Instant::now();
            if let Some(r) = rec.as_mut() {
                if let Err(e) = r.record(s, &bag.frame_id, &fig) {
                    // the bag cannot be written (a full disk): stop recording,
                    // close what was written, and go on with the run
                    bag_error = Some(stopped_recording(&bag.dir, s.time, e, rec.take()));
                } else {
                    frames_before_failure = r.frames();
                }
            }
            record_s += t_rec.elapsed().as_secs_f64();
            last = (Instant::now(), s.steps, s.time);
            last_recorded = Some(s.time);
        }
        let next = also(step)?;
        if stop.load(Ordering::Relaxed) {
            stopped = true;
            return Ok(Control::Stop);
        }
        Ok(next)
    };
    let outcome = run::drape_built(scene, ov, sim, &mut observer)?;
    let sim = &outcome.sim;
    let t_rec = Instant::now();
    let mut frames = frames_before_failure;
    let mut finished = None;
    if let Some(mut r) = rec.take() {
        // the final state, as the node records it when it stops
        let last = match last_recorded != Some(sim.time) {
            true => r.record(sim, &bag.frame_id, &DiagnosticFigures::default()),
            false => Ok(()),
        };
        frames = r.frames();
        match last {
            Err(e) => bag_error = Some(stopped_recording(&bag.dir, sim.time, e, Some(r))),
            Ok(()) => match r.finish() {
                Ok(b) => finished = Some(b),
                Err(e) => {
                    bag_error = Some(format!(
                        "bag {}: {e:#}; `garment_sim bag repair {}` rebuilds it from its \
                         complete chunks",
                        bag.dir.display(),
                        bag.dir.display()
                    ))
                }
            },
        }
    }
    record_s += t_rec.elapsed().as_secs_f64();
    let recorded = DrapeRecorded {
        bag: finished,
        bag_error,
        frames,
        stopped,
        record_s,
    };
    Ok((outcome, recorded))
}

/// The recording of `dir` failed at simulated time `t` with `e`: closes
/// what was written (which may fail too on a full disk) and says what is
/// left.
fn stopped_recording(dir: &Path, t: f64, e: anyhow::Error, rec: Option<SimRecorder>) -> String {
    let frames = rec.as_ref().map(|r| r.frames()).unwrap_or(0);
    let closed = rec.map(|r| r.finish());
    let left = match closed {
        Some(Ok(b)) => format!(
            "the bag was closed with the {} messages written before ({frames} frames)",
            b.message_count
        ),
        _ => format!(
            "the bag could not be closed: it is readable up to its last complete chunk, and \
             `garment_sim bag repair {}` rebuilds it (with space to write)",
            dir.display()
        ),
    };
    format!(
        "bag {}: {e:#}; recording stopped at t = {t:.4} s and the run went on without it; {left}",
        dir.display()
    )
}
