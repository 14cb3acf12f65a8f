//! `garment_sim bag info | export | repair`: what a bag holds, the cloth
//! shape at a time, and rebuilding a bag cut short by a crash.

use super::metadata::{BagInformation, TopicCount};
use super::reader::{Ending, Reader};
use super::recorder::SceneDescription;
use super::writer::{BagOptions, BagSummary, Compression, Writer};
use crate::msgs::publish;
use crate::msgs::{from_cdr, Marker, MarkerArray, PointCloud2, PointField, RosType, StringMsg};
use crate::pictures::render::{Picture, Surface};
use anyhow::{bail, Context, Result};
use std::collections::HashMap;
use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// What `bag info` reports.
#[derive(Debug, Clone, PartialEq)]
pub struct BagInfo {
    pub file: PathBuf,
    pub bytes: u64,
    pub message_count: u64,
    pub bounds: Option<(u64, u64)>,
    pub chunks: usize,
    pub compression: Option<String>,
    /// Topic, type, count, in channel order.
    pub topics: Vec<(String, String, u64)>,
    pub ending: Ending,
    /// Chunks that do not read (CRC mismatch, bad compressed data): byte
    /// offset and why; their messages are not counted above.
    pub damaged: Vec<(u64, String)>,
    /// Differences between `metadata.yaml` and the MCAP file (empty if they agree).
    pub metadata_problems: Vec<String>,
}

impl BagInfo {
    pub fn duration_s(&self) -> f64 {
        self.bounds
            .map(|(a, b)| (b - a) as f64 * 1e-9)
            .unwrap_or(0.0)
    }
}

impl std::fmt::Display for BagInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "Files:             {}", self.file.display())?;
        writeln!(
            f,
            "Bag size:          {:.2} MiB",
            self.bytes as f64 / (1024.0 * 1024.0)
        )?;
        writeln!(f, "Storage id:        mcap")?;
        writeln!(f, "Duration:          {:.9} s", self.duration_s())?;
        if let Some((a, b)) = self.bounds {
            writeln!(
                f,
                "Start:             {:.9} s (simulated time)",
                a as f64 * 1e-9
            )?;
            writeln!(
                f,
                "End:               {:.9} s (simulated time)",
                b as f64 * 1e-9
            )?;
        }
        writeln!(f, "Messages:          {}", self.message_count)?;
        writeln!(
            f,
            "Chunks:            {} ({})",
            self.chunks,
            match self.compression.as_deref() {
                None => "none",
                Some("") => "uncompressed",
                Some(c) => c,
            }
        )?;
        for (at, why) in &self.damaged {
            writeln!(
                f,
                "State:             DAMAGED: the chunk at byte {at} does not read ({why}); its \
                 messages are lost, the others are counted above and readable; `garment_sim \
                 bag repair` rewrites the bag with every other chunk (the damaged file kept as \
                 {}.damaged)",
                self.file
                    .file_name()
                    .map(|n| n.to_string_lossy())
                    .unwrap_or_default()
            )?;
        }
        match &self.ending {
            Ending::Complete if !self.damaged.is_empty() => writeln!(
                f,
                "State:             finished (summary and footer) but damaged, see above"
            )?,
            Ending::Complete => writeln!(f, "State:             complete")?,
            Ending::Truncated { offset, reason } => writeln!(
                f,
                "State:             TRUNCATED at byte {offset} ({reason}); the messages above are readable; `garment_sim bag repair` rebuilds the summary and metadata.yaml"
            )?,
        }
        for p in &self.metadata_problems {
            writeln!(f, "metadata.yaml:     {p}")?;
        }
        for (k, (t, ty, n)) in self.topics.iter().enumerate() {
            writeln!(
                f,
                "{}Topic: {t} | Type: {ty} | Count: {n} | Serialization Format: cdr",
                if k == 0 {
                    "Topic information: "
                } else {
                    "                   "
                }
            )?;
        }
        Ok(())
    }
}

fn topic_counts(r: &Reader) -> Result<Vec<TopicCount>> {
    r.channels
        .values()
        .map(|c| {
            Ok(TopicCount {
                name: c.topic.clone(),
                type_name: c.type_name.clone(),
                qos: c.qos()?,
                count: c.message_count,
            })
        })
        .collect()
}

/// Reads a bag (directory or MCAP file) and compares it with its `metadata.yaml`.
pub fn info(path: &Path) -> Result<BagInfo> {
    let r = Reader::open(path)?;
    let mut problems = Vec::new();
    match BagInformation::read(&r.dir) {
        Err(e) => problems.push(format!("{e:#}")),
        Ok(m) => {
            let file_name = r
                .path
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let expect = BagInformation::new(&file_name, &topic_counts(&r)?, r.bounds);
            if m.message_count != expect.message_count {
                problems.push(format!(
                    "says {} messages, the MCAP file holds {}",
                    m.message_count, expect.message_count
                ));
            }
            if m.relative_file_paths != expect.relative_file_paths {
                problems.push(format!(
                    "names files {:?}, the bag's file is {file_name}",
                    m.relative_file_paths
                ));
            }
            for t in &expect.topics_with_message_count {
                match m
                    .topics_with_message_count
                    .iter()
                    .find(|x| x.topic_metadata.name == t.topic_metadata.name)
                {
                    None => problems.push(format!("lacks topic {}", t.topic_metadata.name)),
                    Some(x) if x != t => problems.push(format!(
                        "topic {}: {} messages, type {}; the MCAP file: {} messages, type {} (or the QoS differ)",
                        t.topic_metadata.name,
                        x.message_count,
                        x.topic_metadata.type_name,
                        t.message_count,
                        t.topic_metadata.type_name
                    )),
                    _ => {}
                }
            }
        }
    }
    Ok(BagInfo {
        file: r.path.clone(),
        bytes: r.file_size(),
        message_count: r.message_count,
        bounds: r.bounds,
        chunks: r.chunk_count,
        compression: r.chunk_compression.clone(),
        topics: r
            .channels
            .values()
            .map(|c| (c.topic.clone(), c.type_name.clone(), c.message_count))
            .collect(),
        ending: r.ending.clone(),
        damaged: r.damaged.clone(),
        metadata_problems: problems,
    })
}

/// Which frame `bag export` takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ExportTime {
    /// The last frame at or before this simulated time, s.
    At(f64),
    /// The last frame of the bag.
    Last,
}

/// Shape file formats (PNG: a picture of the frame, see [`crate::pictures::render`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShapeFormat {
    Ply,
    Obj,
    Png,
}

impl std::str::FromStr for ShapeFormat {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "ply" => Ok(ShapeFormat::Ply),
            "obj" => Ok(ShapeFormat::Obj),
            "png" => Ok(ShapeFormat::Png),
            _ => bail!("format {s:?}: expected ply, obj or png"),
        }
    }
}

/// The cloth shape of one frame of a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// Simulated time of the frame, s.
    pub time_s: f64,
    /// Vertices in the cloud's order (grid order `j * nx + i` for garment_sim bags), m.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles (vertex indices), from the mesh marker of the same stamp.
    pub faces: Vec<[usize; 3]>,
    /// Per-vertex strain, from the cloud's `strain` field if it has one.
    pub strain: Option<Vec<f64>>,
    /// The obstacles, from the last obstacle markers (TRIANGLE_LIST) at or
    /// before the frame, world coordinates.
    pub obstacles: Vec<Surface>,
    /// Scene name and grid, from the bag's scene description if it has one.
    pub scene: Option<(String, [usize; 2])>,
}

/// Reads the cloth shape at `when` from a bag: the point cloud on
/// `points_topic` gives the vertices (in its order) and their strains; the
/// TRIANGLE_LIST marker of the same stamp on `mesh_topic`, if there is one,
/// gives the triangles and the positions at full (float64) precision. The
/// obstacles come from `/obstacles/markers` and the scene's name from
/// `/scene_description` (or the bag's only topics ending in those names).
pub fn shape_at(
    path: &Path,
    when: ExportTime,
    points_topic: &str,
    mesh_topic: &str,
) -> Result<Shape> {
    let r = Reader::open(path)?;
    // a node in a namespace records e.g. /lab/cloth/points: if the default
    // names are absent, take the bag's only topics of those names' endings
    let resolve = |topic: &str, type_name: &str| -> String {
        if r.channels.values().any(|c| c.topic == topic) {
            return topic.to_string();
        }
        let tail = topic.trim_start_matches('/');
        let found: Vec<&str> = r
            .channels
            .values()
            .filter(|c| c.type_name == type_name && c.topic.ends_with(&format!("/{tail}")))
            .map(|c| c.topic.as_str())
            .collect();
        match found.as_slice() {
            [one] => one.to_string(),
            _ => topic.to_string(),
        }
    };
    let points_topic = resolve(points_topic, PointCloud2::NAME);
    let points_topic = points_topic.as_str();
    let mesh_topic = resolve(mesh_topic, Marker::NAME);
    let mesh_topic = mesh_topic.as_str();
    // frame times first; only the chosen frame's messages are copied
    let times = r.log_times(points_topic)?;
    let (first, last) = match (times.first(), times.last()) {
        (Some(&a), Some(&b)) => (a, b),
        _ => bail!("{}: no message on {points_topic}", r.path.display()),
    };
    const TOL_NS: i128 = 1000;
    let k = match when {
        ExportTime::Last => times.len() - 1,
        ExportTime::At(t) => {
            let tn = (t * 1e9).round() as i128;
            if !t.is_finite() || tn < first as i128 - TOL_NS || tn > last as i128 + TOL_NS {
                bail!(
                    "time {t} s is outside the bag {}: {points_topic} has frames from {:.6} s to {:.6} s",
                    r.path.display(),
                    first as f64 * 1e-9,
                    last as f64 * 1e-9
                );
            }
            times
                .iter()
                .rposition(|&s| (s as i128) <= tn + TOL_NS)
                .expect("t is within the bag")
        }
    };
    let stamp = &times[k];
    let bytes = r
        .message_at(points_topic, *stamp)?
        .expect("the frame was just listed");
    let cloud: PointCloud2 = from_cdr(&bytes)
        .with_context(|| format!("{points_topic} at {} ns: not a PointCloud2", stamp))?;
    let pts =
        publish::cloud_points(&cloud).with_context(|| format!("{points_topic} at {} ns", stamp))?;
    let mut vertices: Vec<[f64; 3]> = pts
        .iter()
        .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64])
        .collect();
    let mut faces = Vec::new();
    if r.channels.values().any(|c| c.topic == mesh_topic) {
        let marker: Option<Marker> = match r.message_at(mesh_topic, *stamp)? {
            None => None,
            Some(b) => Some(
                from_cdr(&b)
                    .with_context(|| format!("{mesh_topic} at {stamp} ns: not a Marker"))?,
            ),
        };
        if let Some(mk) = marker.filter(|m| m.type_ == Marker::TRIANGLE_LIST) {
            // each marker point is a vertex's float64 position; the cloud holds
            // the same values rounded to float32, which identifies the vertex
            let key = |p: [f32; 3]| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()];
            let mut index: HashMap<[u32; 3], usize> = HashMap::with_capacity(pts.len());
            let mut unique = true;
            for (i, p) in pts.iter().enumerate() {
                unique &= index.insert(key(*p), i).is_none();
            }
            let mut ids = Vec::with_capacity(mk.points.len());
            for p in &mk.points {
                match index.get(&key([p.x as f32, p.y as f32, p.z as f32])) {
                    Some(&i) if unique => {
                        vertices[i] = [p.x, p.y, p.z];
                        ids.push(i);
                    }
                    _ => {
                        ids.clear();
                        break;
                    }
                }
            }
            if ids.len() == mk.points.len() && ids.len() % 3 == 0 {
                faces = ids.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
            }
        }
    }
    let strain = cloud_strain(&cloud);
    // obstacles and scene name only label and decorate a picture: a topic
    // of another type or a message that does not decode leaves them out
    // rather than failing the export of the cloth
    let obstacles_topic = resolve("/obstacles/markers", MarkerArray::NAME);
    let mut obstacles = Vec::new();
    if r.channels
        .values()
        .any(|c| c.topic == obstacles_topic && c.type_name == MarkerArray::NAME)
    {
        let times = r.log_times(&obstacles_topic)?;
        if let Some(k) = times.iter().rposition(|&s| s <= *stamp) {
            let b = r
                .message_at(&obstacles_topic, times[k])?
                .expect("the message was just listed");
            if let Ok(m) = from_cdr::<MarkerArray>(&b) {
                obstacles = obstacle_surfaces(&m);
            }
        }
    }
    let description_topic = resolve("/scene_description", StringMsg::NAME);
    let mut scene = None;
    if r.channels
        .values()
        .any(|c| c.topic == description_topic && c.type_name == StringMsg::NAME)
    {
        let times = r.log_times(&description_topic)?;
        if let Some(k) = times.iter().rposition(|&s| s <= *stamp) {
            let b = r
                .message_at(&description_topic, times[k])?
                .expect("the message was just listed");
            let d: Option<SceneDescription> = from_cdr::<StringMsg>(&b)
                .ok()
                .and_then(|m| serde_yaml::from_str(&m.data).ok());
            scene = d.map(|d| {
                let name = serde_yaml::from_str::<serde_yaml::Value>(&d.scene_yaml)
                    .ok()
                    .and_then(|v| v.get("name").and_then(|n| n.as_str()).map(String::from))
                    .filter(|n| !n.is_empty())
                    .unwrap_or(d.scene_file);
                (name, d.grid)
            });
        }
    }
    Ok(Shape {
        time_s: *stamp as f64 * 1e-9,
        vertices,
        faces,
        strain,
        obstacles,
        scene,
    })
}

/// The `strain` field of a little-endian cloud, if it has a float32 one.
fn cloud_strain(c: &PointCloud2) -> Option<Vec<f64>> {
    let f = c
        .fields
        .iter()
        .find(|f| f.name == "strain" && f.datatype == PointField::FLOAT32)?;
    let (n, step, off) = (
        (c.width * c.height) as usize,
        c.point_step as usize,
        f.offset as usize,
    );
    if c.is_bigendian || off + 4 > step || c.data.len() < n * step {
        return None;
    }
    Some(
        (0..n)
            .map(|i| {
                let k = i * step + off;
                f32::from_le_bytes(c.data[k..k + 4].try_into().unwrap()) as f64
            })
            .collect(),
    )
}

/// The TRIANGLE_LIST markers added by a marker array, moved to their poses.
fn obstacle_surfaces(m: &MarkerArray) -> Vec<Surface> {
    m.markers
        .iter()
        .filter(|k| k.action == Marker::ADD && k.type_ == Marker::TRIANGLE_LIST)
        .filter_map(|k| {
            let pose = k.pose.to_isometry().ok()?;
            let pts: Vec<[f64; 3]> = k
                .points
                .iter()
                .map(|p| {
                    let q = pose * nalgebra::Point3::new(p.x, p.y, p.z);
                    [q.x, q.y, q.z]
                })
                .collect();
            Some(Surface::from_triangle_list(&pts))
        })
        .collect()
}

/// A picture of a shape read from a bag, labelled with the scene and the time.
pub fn shape_picture(shape: &Shape) -> Picture {
    let (title, grid) = match &shape.scene {
        Some((name, g)) => (name.clone(), Some(*g)),
        None => ("bag frame".to_string(), None),
    };
    let mut p = Picture::new(
        &title,
        Surface {
            vertices: shape.vertices.clone(),
            triangles: shape.faces.clone(),
        },
    );
    p.strain = shape.strain.clone();
    p.obstacles = shape.obstacles.clone();
    p.info = vec![
        match grid {
            Some(g) => format!("grid {} x {}", g[0], g[1]),
            None => format!("{} vertices", shape.vertices.len()),
        },
        format!("t = {:.2} s", shape.time_s),
    ];
    p
}

/// Writes a shape as ASCII PLY (double x y z, triangle faces) or OBJ.
pub fn write_shape(shape: &Shape, format: ShapeFormat, out: &Path) -> Result<()> {
    if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    if format == ShapeFormat::Png {
        return shape_picture(shape).save_png(out);
    }
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(out).with_context(|| format!("cannot create {}", out.display()))?,
    );
    match format {
        ShapeFormat::Png => unreachable!("drawn above"),
        ShapeFormat::Ply => {
            writeln!(
                w,
                "ply\nformat ascii 1.0\ncomment garment_sim cloth from a bag at t = {} s, metres",
                shape.time_s
            )?;
            writeln!(
                w,
                "element vertex {}\nproperty double x\nproperty double y\nproperty double z",
                shape.vertices.len()
            )?;
            writeln!(
                w,
                "element face {}\nproperty list uchar int vertex_indices\nend_header",
                shape.faces.len()
            )?;
            for v in &shape.vertices {
                writeln!(w, "{} {} {}", v[0], v[1], v[2])?;
            }
            for f in &shape.faces {
                writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
            }
        }
        ShapeFormat::Obj => {
            writeln!(
                w,
                "# garment_sim cloth from a bag at t = {} s, metres",
                shape.time_s
            )?;
            for v in &shape.vertices {
                writeln!(w, "v {} {} {}", v[0], v[1], v[2])?;
            }
            for f in &shape.faces {
                writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
            }
        }
    }
    w.flush()
        .with_context(|| format!("cannot write {}", out.display()))?;
    Ok(())
}

/// What `bag repair` did.
#[derive(Debug, Clone, PartialEq)]
pub struct RepairReport {
    /// The file was already complete: only `metadata.yaml` was rewritten.
    pub was_complete: bool,
    /// Where the damaged file ended, and why.
    pub ending: Ending,
    /// Bytes of the damaged file after the last complete record (dropped).
    pub bytes_dropped: u64,
    /// Unreadable chunks dropped (byte offset in the damaged file, why);
    /// every chunk before and after them that reads is kept.
    pub dropped_chunks: Vec<(u64, String)>,
    /// Where the damaged file was kept (beside it, `NAME.damaged`).
    pub backup: Option<std::path::PathBuf>,
    pub bag: BagSummary,
}

/// Rebuilds a bag cut short by a crash or with damaged chunks: every message
/// of every chunk that reads (its CRC holds), before and after the damage,
/// is rewritten into a new, finished MCAP file (same topics, schemas, QoS
/// and compression); the damaged file is kept beside it as `NAME.damaged`
/// and the new one takes its name; `metadata.yaml` is rewritten from it. A
/// failure leaves the bag as it was and no temporary file. A complete bag
/// only gets its `metadata.yaml` rewritten.
pub fn repair(path: &Path) -> Result<RepairReport> {
    let r = Reader::open(path)?;
    let file_name = r
        .path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .context("bag file has no name")?;
    if r.is_complete() {
        let info = BagInformation::new(&file_name, &topic_counts(&r)?, r.bounds);
        info.write(&r.dir)?;
        return Ok(RepairReport {
            was_complete: true,
            ending: Ending::Complete,
            bytes_dropped: 0,
            dropped_chunks: Vec::new(),
            backup: None,
            bag: BagSummary {
                dir: r.dir.clone(),
                file: r.path.clone(),
                message_count: r.message_count,
                topics: r
                    .channels
                    .values()
                    .map(|c| (c.topic.clone(), c.type_name.clone(), c.message_count))
                    .collect(),
                bounds: r.bounds,
                bytes: r.file_size(),
                chunks: r.chunk_count,
            },
        });
    }
    let compression = match r.chunk_compression.as_deref() {
        Some("lz4") => Compression::Lz4,
        Some("") => Compression::None,
        _ => Compression::Zstd,
    };
    let opts = BagOptions {
        compression,
        ..BagOptions::default()
    };
    let tmp = r.dir.join(format!(".{file_name}.repair"));
    let written = (|| -> Result<BagSummary> {
        let mut w = Writer::create_file(&r.dir, &tmp, &file_name, &opts)?;
        for c in r.channels.values() {
            let schema = &r.schemas[&c.schema_id];
            w.add_topic_with_schema(&c.topic, &c.type_name, &schema.text, &c.qos()?)?;
        }
        r.for_each_message(|m| {
            w.write_raw(&m.channel.topic, m.log_time, m.data)?;
            Ok(ControlFlow::Continue(()))
        })?;
        w.finish()
    })();
    let mut bag = match written {
        Ok(b) => b,
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            return Err(e.context(format!(
                "repair of {} failed: the bag is left as it was",
                r.path.display()
            )));
        }
    };
    // keep the damaged file beside the repaired one
    let mut backup = r.dir.join(format!("{file_name}.damaged"));
    let mut k = 1;
    while backup.exists() {
        backup = r.dir.join(format!("{file_name}.damaged.{k}"));
        k += 1;
    }
    if let Err(e) = std::fs::rename(&r.path, &backup) {
        let _ = std::fs::remove_file(&tmp);
        return Err(anyhow::Error::new(e).context(format!(
            "cannot keep the damaged {} as {}: the bag is left as it was",
            r.path.display(),
            backup.display()
        )));
    }
    if let Err(e) = std::fs::rename(&tmp, &r.path) {
        let _ = std::fs::rename(&backup, &r.path);
        let _ = std::fs::remove_file(&tmp);
        return Err(anyhow::Error::new(e).context(format!(
            "cannot replace {} with the repaired file: the bag is left as it was",
            r.path.display()
        )));
    }
    bag.file = r.path.clone();
    let valid = match &r.ending {
        Ending::Truncated { offset, .. } => *offset,
        Ending::Complete => r.file_size(),
    };
    Ok(RepairReport {
        was_complete: false,
        ending: r.ending.clone(),
        bytes_dropped: r.file_size() - valid,
        dropped_chunks: r.damaged.clone(),
        backup: Some(backup),
        bag,
    })
}
