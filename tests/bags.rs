//! Bags against independent readers (tests/bag_interop.py): the Python
//! `rosbags` package (its rosbag2 reader and its own CDR deserialiser, with
//! types built from the bag's own schemas) and the `mcap` package with
//! `mcap-ros2-support`. The expected cloth trajectory comes from this file:
//! the simulation stepped in-process, with no bag code on its path, sampled
//! at the bag's frame times. Signals (SIGINT, SIGTERM, SIGKILL + `bag
//! repair`) and the node's `record_bag` are exercised there too; everything
//! runs in a network namespace made for the test (`unshare -rn`, loopback
//! only) because the node starts DDS.

mod support;

use garment_sim::msgs::publish::FrameClock;
use garment_sim::scene::{Overrides, Scene};
use std::path::Path;

/// The reference run the Python tests record: table drape, 2 cm grid,
/// dt = 4 ms, 0.3 s, frames at 30 Hz (first step at or after each 1/30 s),
/// default solver (`auto`, whose choice depends on iteration counts only).
const SPACING: f64 = 0.02;
const DT: f64 = 0.004;
const DURATION: f64 = 0.3;
const RATE: f64 = 30.0;

/// Writes `{"times": [...], "positions": [[x, y, z, ...], ...], "nx", "ny"}`.
fn write_expected(path: &Path) {
    let sc = Scene::load(Path::new("config/scenes/table_drape.yaml")).unwrap();
    let ov = Overrides {
        spacing: Some(SPACING),
        dt: Some(DT),
        duration: Some(DURATION),
        ..Default::default()
    };
    let mut sim = sc.build(&ov).unwrap();
    let mut clock = FrameClock::new(sim.time);
    let mut times = Vec::new();
    let mut frames: Vec<Vec<f64>> = Vec::new();
    let mut sample = |sim: &garment_sim::solver::Simulation, times: &mut Vec<f64>| {
        times.push(sim.time);
        frames.push(
            sim.cloth
                .positions()
                .iter()
                .flat_map(|p| [p.x, p.y, p.z])
                .collect(),
        );
    };
    let steps = (DURATION / DT).round() as usize;
    if clock.due(sim.time, RATE) {
        sample(&sim, &mut times);
    }
    for k in 1..=steps {
        sim.step().unwrap();
        if clock.due(sim.time, RATE) || k == steps && times.last() != Some(&sim.time) {
            sample(&sim, &mut times);
        }
    }
    let json = serde_json::json!({
        "times": times,
        "positions": frames,
        "nx": sim.cloth.nx,
        "ny": sim.cloth.ny,
        "spacing": SPACING,
        "dt": DT,
        "duration": DURATION,
        "rate": RATE,
    });
    std::fs::write(path, serde_json::to_string(&json).unwrap()).unwrap();
}

#[test]
fn bags_open_in_rosbags_and_mcap_and_survive_signals() {
    let dir = support::Scratch::new("bags");
    let expected = dir.join("expected.json");
    write_expected(&expected);
    let bin = std::ffi::OsString::from(support::garment_sim_path());
    support::pytest(
        "tests/bag_interop.py",
        "rosbags, mcap, mcap_ros2, numpy, yaml, pytest",
        true,
        &[
            ("GARMENT_SIM_BIN", &bin),
            ("GARMENT_SIM_EXPECTED", expected.as_os_str()),
            ("GARMENT_SIM_TMP", dir.as_os_str()),
        ],
        "10 passed",
    );
}
