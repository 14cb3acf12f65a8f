//! Records a [`Simulation`] as the node publishes it: the same messages
//! (built by [`crate::msgs::publish`]) on the same topics, plus `/clock` and a
//! latched description of the scene. Used by `garment_sim drape --bag` and by
//! the node (`record_bag`), so both write the same bag for the same scene.

use super::metadata::Qos;
use super::writer::{BagOptions, BagSummary, Writer};
use crate::msgs::publish::{self, DiagnosticFigures};
use crate::msgs::{Clock, DiagnosticArray, Marker, MarkerArray, PointCloud2, RosType, StringMsg};
use crate::scene::{Overrides, Scene};
use crate::solver::Simulation;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;

/// Fully qualified topic names the recorder writes (the node resolves its
/// namespace and remappings and passes the result). Defaults: the node in
/// namespace `/` with its relative names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicNames {
    /// sensor_msgs/msg/PointCloud2 (x, y, z, strain, speed).
    pub points: String,
    /// visualization_msgs/msg/Marker (the cloth as a triangle list).
    pub mesh: String,
    /// visualization_msgs/msg/MarkerArray.
    pub obstacles: String,
    /// diagnostic_msgs/msg/DiagnosticArray.
    pub diagnostics: String,
    /// rosgraph_msgs/msg/Clock.
    pub clock: String,
    /// std_msgs/msg/String, latched (transient local): the scene description.
    pub scene_description: String,
}

impl Default for TopicNames {
    fn default() -> Self {
        TopicNames {
            points: "/cloth/points".into(),
            mesh: "/cloth/mesh".into(),
            obstacles: "/obstacles/markers".into(),
            diagnostics: "/diagnostics".into(),
            clock: "/clock".into(),
            scene_description: "/scene_description".into(),
        }
    }
}

/// The recorder of a simulation's bag.
pub struct SimRecorder {
    writer: Writer,
    topics: TopicNames,
    scene_description: Option<String>,
    frames: u64,
    offset_ns: u64,
    last_ns: Option<u64>,
    /// Until the bag is finished (or dropped), a second SIGINT lets it be
    /// finished ([`crate::scene::run::stop_flag`]).
    _open: crate::scene::run::Recording,
}

/// The messages of one recorded frame.
pub struct Frame<'a> {
    pub cloud: &'a PointCloud2,
    pub mesh: &'a Marker,
    pub obstacles: &'a MarkerArray,
    pub diagnostics: &'a DiagnosticArray,
    pub clock: &'a Clock,
}

impl SimRecorder {
    /// Creates the bag directory `dir` (which must not exist) with the six
    /// topics. `scene_description` is written once on
    /// `topics.scene_description`, stamped with the first recorded frame's
    /// time (see [`scene_description`] for its layout).
    pub fn create(
        dir: &Path,
        opts: &BagOptions,
        topics: &TopicNames,
        scene_description: &str,
    ) -> Result<SimRecorder> {
        let open = crate::scene::run::Recording::start();
        let mut writer = Writer::create(dir, opts)?;
        // the QoS the node offers on each (node.rs), as `ros2 bag record` would record them
        let (reliable, clock, latched) = (Qos::default_publisher(), Qos::clock(), Qos::latched());
        for (name, type_name, qos) in [
            (&topics.points, PointCloud2::NAME, &reliable),
            (&topics.mesh, Marker::NAME, &reliable),
            (&topics.obstacles, MarkerArray::NAME, &reliable),
            (&topics.diagnostics, DiagnosticArray::NAME, &reliable),
            (&topics.clock, Clock::NAME, &clock),
            (&topics.scene_description, StringMsg::NAME, &latched),
        ] {
            writer.add_topic(name, type_name, std::slice::from_ref(qos))?;
        }
        Ok(SimRecorder {
            writer,
            topics: topics.clone(),
            scene_description: Some(scene_description.to_string()),
            frames: 0,
            offset_ns: 0,
            last_ns: None,
            _open: open,
        })
    }

    /// Records the current state: the point cloud, the cloth marker, the
    /// obstacle markers, the diagnostics and the clock, all stamped with the
    /// simulated time (header stamp = log time = publish time). The first call
    /// also writes the scene description.
    pub fn record(
        &mut self,
        sim: &Simulation,
        frame_id: &str,
        figures: &DiagnosticFigures,
    ) -> Result<()> {
        let h = publish::header(sim, frame_id);
        self.record_frame(&Frame {
            cloud: &publish::cloud(sim, h.clone()),
            mesh: &publish::cloth_marker(sim, h.clone()),
            obstacles: &publish::obstacle_markers(sim, h.clone()),
            diagnostics: &publish::diagnostics(sim, h.clone(), figures),
            clock: &Clock { clock: h.stamp },
        })
    }

    /// Records messages already built (the node records what it publishes).
    /// Log time = publish time = the cloud's header stamp plus the offset
    /// added by [`SimRecorder::restart`].
    pub fn record_frame(&mut self, f: &Frame) -> Result<()> {
        let t = (f.cloud.header.stamp.nanos().max(0) as u64).saturating_add(self.offset_ns);
        if let Some(d) = self.scene_description.take() {
            self.writer
                .write(&self.topics.scene_description, t, &StringMsg { data: d })?;
        }
        let w = &mut self.writer;
        w.write(&self.topics.points, t, f.cloud)?;
        w.write(&self.topics.mesh, t, f.mesh)?;
        w.write(&self.topics.obstacles, t, f.obstacles)?;
        w.write(&self.topics.diagnostics, t, f.diagnostics)?;
        w.write(&self.topics.clock, t, f.clock)?;
        self.last_ns = Some(t);
        self.frames += 1;
        Ok(())
    }

    /// The simulation restarted at t = 0 (the node's `~/reset`): later frames
    /// are logged after the last one (log times stay ordered; header stamps
    /// are the new run's simulated time) and the new scene description is
    /// written with the next frame.
    pub fn restart(&mut self, scene_description: &str, gap_ns: u64) {
        if let Some(last) = self.last_ns {
            self.offset_ns = last + gap_ns;
        }
        self.scene_description = Some(scene_description.to_string());
    }

    /// Frames recorded so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Finishes the bag: last chunk, summary, indexes, `metadata.yaml`.
    pub fn finish(self) -> Result<BagSummary> {
        self.writer.finish()
    }
}

/// The scene description a bag carries on `/scene_description`: a YAML
/// document (format `garment_sim/scene_description/1`) with the scene file's
/// path and text, the fabric file's path and text, the command-line
/// overrides, and the grid built from them, so that a bag explains itself.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct SceneDescription {
    pub format: String,
    pub scene_file: String,
    pub scene_yaml: String,
    pub fabric_file: String,
    pub fabric_yaml: String,
    /// The overrides given on the command line or as node parameters.
    pub overrides: Overrides,
    /// Vertices along warp and weft; vertex index `j * nx + i`.
    pub grid: [usize; 2],
    pub dt_s: f64,
}

/// Builds the scene description of `scene` with overrides `ov` for the
/// simulation `sim` built from them.
pub fn scene_description(scene: &Scene, ov: &Overrides, sim: &Simulation) -> Result<String> {
    let scene_yaml = std::fs::read_to_string(&scene.path)
        .with_context(|| format!("cannot read scene file {}", scene.path.display()))?;
    let fabric_path = scene.fabric_path();
    let fabric_yaml = std::fs::read_to_string(&fabric_path)
        .with_context(|| format!("cannot read fabric file {}", fabric_path.display()))?;
    let d = SceneDescription {
        format: "garment_sim/scene_description/1".into(),
        scene_file: scene.path.display().to_string(),
        scene_yaml,
        fabric_file: fabric_path.display().to_string(),
        fabric_yaml,
        overrides: ov.clone(),
        grid: [sim.cloth.nx, sim.cloth.ny],
        dt_s: sim.params().dt,
    };
    Ok(serde_yaml::to_string(&d)?)
}
