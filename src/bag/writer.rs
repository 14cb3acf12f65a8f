//! The low-level bag writer: one MCAP file in a rosbag2 bag directory, with
//! `ros2msg` schemas, `cdr` channels carrying their offered QoS, chunks
//! flushed to the operating system as soon as they are complete, and
//! `metadata.yaml` rewritten after every chunk so that the directory stays a
//! readable bag whatever happens to the process.

use super::metadata::{qos_string, BagInformation, Qos, TopicCount};
use crate::msgs::definitions;
use crate::msgs::{to_cdr, RosType};
use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    None,
    #[default]
    Zstd,
    Lz4,
}

impl std::str::FromStr for Compression {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "none" => Ok(Compression::None),
            "zstd" => Ok(Compression::Zstd),
            "lz4" => Ok(Compression::Lz4),
            _ => bail!("compression {s:?}: expected none, zstd or lz4"),
        }
    }
}

impl std::fmt::Display for Compression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Compression::None => "none",
            Compression::Zstd => "zstd",
            Compression::Lz4 => "lz4",
        })
    }
}

/// How a bag is written.
#[derive(Debug, Clone, PartialEq)]
pub struct BagOptions {
    /// Chunk compression (default zstd).
    pub compression: Compression,
    /// A chunk is closed, compressed and flushed to the file once it holds at
    /// least this many bytes of (uncompressed) records (default 1 MiB). A
    /// crash loses at most the chunk being filled.
    pub chunk_size: u64,
    /// zstd level (1–19; default 3) or lz4 level; 0 = the library default.
    pub compression_level: u32,
}

impl Default for BagOptions {
    fn default() -> Self {
        BagOptions {
            compression: Compression::Zstd,
            chunk_size: 1 << 20,
            compression_level: 0,
        }
    }
}

/// What a finished bag holds.
#[derive(Debug, Clone, PartialEq)]
pub struct BagSummary {
    pub dir: PathBuf,
    /// The MCAP file (inside `dir`).
    pub file: PathBuf,
    pub message_count: u64,
    /// Topics in the order they were added: name, type, message count.
    pub topics: Vec<(String, String, u64)>,
    /// First and last log time, ns (`None` if the bag is empty).
    pub bounds: Option<(u64, u64)>,
    /// Size of the MCAP file, bytes.
    pub bytes: u64,
    pub chunks: usize,
}

impl BagSummary {
    /// Duration between the first and the last message, s.
    pub fn duration_s(&self) -> f64 {
        self.bounds
            .map(|(a, b)| (b - a) as f64 * 1e-9)
            .unwrap_or(0.0)
    }
}

struct Topic {
    name: String,
    type_name: String,
    qos: Vec<Qos>,
    channel: u16,
    count: u64,
}

/// A rosbag2 MCAP bag being written. Messages are written with
/// [`Writer::write`]; [`Writer::finish`] writes the summary, indexes and
/// `metadata.yaml`. Dropping an unfinished writer finishes it (errors ignored).
pub struct Writer {
    dir: PathBuf,
    file_name: String,
    mcap: Option<mcap::Writer<BufWriter<File>>>,
    topics: Vec<Topic>,
    by_name: HashMap<String, usize>,
    opts: BagOptions,
    chunk_bytes: u64,
    chunks: usize,
    bounds: Option<(u64, u64)>,
    rosbag2_record_written: bool,
}

/// Bytes a message record takes in a chunk besides its data (opcode, length, header).
const MESSAGE_RECORD_OVERHEAD: u64 = 1 + 8 + 2 + 4 + 8 + 8;

impl Writer {
    /// Creates the bag directory `dir` (which must not exist, or be empty, as
    /// with `ros2 bag record -o`) with `<name>_0.mcap` and `metadata.yaml`.
    pub fn create(dir: &Path, opts: &BagOptions) -> Result<Writer> {
        if dir.exists() {
            let empty = dir.is_dir()
                && std::fs::read_dir(dir)
                    .with_context(|| format!("cannot read {}", dir.display()))?
                    .next()
                    .is_none();
            if !empty {
                bail!(
                    "bag directory {} already exists; choose a new one (a bag is never overwritten)",
                    dir.display()
                );
            }
        }
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create bag directory {}", dir.display()))?;
        let stem = dir
            .canonicalize()
            .ok()
            .and_then(|d| d.file_name().map(|s| s.to_string_lossy().into_owned()))
            .unwrap_or_else(|| "bag".into());
        let file_name = format!("{stem}_0.mcap");
        let w = Writer::create_file(dir, &dir.join(&file_name), &file_name, opts)?;
        w.information().write(dir)?;
        Ok(w)
    }

    /// Writes to `path` while `metadata.yaml` (in `dir`) names the file
    /// `file_name` (used by repair, which writes a temporary file first).
    pub(crate) fn create_file(
        dir: &Path,
        path: &Path,
        file_name: &str,
        opts: &BagOptions,
    ) -> Result<Writer> {
        anyhow::ensure!(opts.chunk_size > 0, "bag chunk size must be > 0 bytes");
        let f = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let compression = match opts.compression {
            Compression::None => None,
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
        };
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(format!("garment_sim {}", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .compression_level(opts.compression_level)
            .compression_threads(0)
            // chunks are closed by this writer (see `write_raw`), so that each
            // is flushed to the file as soon as it is complete
            .chunk_size(None)
            .create(BufWriter::with_capacity(1 << 20, f))
            .with_context(|| format!("cannot start MCAP file {}", path.display()))?;
        let w = Writer {
            dir: dir.to_path_buf(),
            file_name: file_name.to_string(),
            mcap: Some(mcap),
            topics: Vec::new(),
            by_name: HashMap::new(),
            opts: opts.clone(),
            chunk_bytes: 0,
            chunks: 0,
            bounds: None,
            rosbag2_record_written: false,
        };
        Ok(w)
    }

    /// The bag directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The MCAP file.
    pub fn file(&self) -> PathBuf {
        self.dir.join(&self.file_name)
    }

    /// Adds a topic of a type whose definition [`definitions`] knows.
    pub fn add_topic(&mut self, name: &str, type_name: &str, qos: &[Qos]) -> Result<()> {
        let schema = definitions::schema_text(type_name)
            .ok_or_else(|| anyhow!("topic {name}: no message definition for type {type_name}"))?;
        self.add_topic_with_schema(name, type_name, &schema, qos)
    }

    /// Adds a topic with an explicit `ros2msg` schema text.
    pub fn add_topic_with_schema(
        &mut self,
        name: &str,
        type_name: &str,
        schema: &str,
        qos: &[Qos],
    ) -> Result<()> {
        anyhow::ensure!(
            name.starts_with('/'),
            "topic {name:?}: a bag stores fully qualified topic names (starting with /)"
        );
        if self.by_name.contains_key(name) {
            bail!("topic {name} is already in the bag");
        }
        let mcap = self.mcap.as_mut().context("bag already finished")?;
        let schema_id = mcap
            .add_schema(type_name, "ros2msg", schema.as_bytes())
            .with_context(|| format!("topic {name}: schema {type_name}"))?;
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), qos_string(qos));
        let channel = mcap
            .add_channel(schema_id, name, "cdr", &meta)
            .with_context(|| format!("topic {name}: channel"))?;
        self.chunk_bytes += schema.len() as u64 + 64 + meta["offered_qos_profiles"].len() as u64;
        self.by_name.insert(name.to_string(), self.topics.len());
        self.topics.push(Topic {
            name: name.to_string(),
            type_name: type_name.to_string(),
            qos: qos.to_vec(),
            channel,
            count: 0,
        });
        Ok(())
    }

    /// Writes a message, CDR-serialised with its encapsulation header, on
    /// `topic` (added before, with type `T::NAME`) at log time = publish time
    /// = `stamp_ns`.
    pub fn write<T: Serialize + RosType>(
        &mut self,
        topic: &str,
        stamp_ns: u64,
        msg: &T,
    ) -> Result<()> {
        let k = self.topic_index(topic)?;
        if self.topics[k].type_name != T::NAME {
            bail!(
                "topic {topic} holds {}, not {}",
                self.topics[k].type_name,
                T::NAME
            );
        }
        self.write_raw(topic, stamp_ns, &to_cdr(msg))
    }

    fn topic_index(&self, topic: &str) -> Result<usize> {
        self.by_name.get(topic).copied().ok_or_else(|| {
            anyhow!(
                "topic {topic} is not in the bag (topics: {})",
                self.topics
                    .iter()
                    .map(|t| t.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
    }

    /// Writes already serialised CDR (with its 4-byte encapsulation header).
    pub fn write_raw(&mut self, topic: &str, stamp_ns: u64, cdr: &[u8]) -> Result<()> {
        let k = self.topic_index(topic)?;
        if !self.rosbag2_record_written {
            // rosbag2's own MCAP reader takes the metadata version (and so the
            // QoS layout) from this record: write it before any message, so
            // that even a bag cut short by a crash carries it.
            self.write_rosbag2_record()?;
            self.rosbag2_record_written = true;
            self.flush()?;
        }
        let t = &mut self.topics[k];
        let header = mcap::records::MessageHeader {
            channel_id: t.channel,
            sequence: t.count as u32,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        let mcap = self.mcap.as_mut().context("bag already finished")?;
        mcap.write_to_known_channel(&header, cdr)
            .with_context(|| format!("cannot write a message on {topic} to {}", self.file_name))?;
        t.count += 1;
        self.bounds = Some(match self.bounds {
            None => (stamp_ns, stamp_ns),
            Some((a, b)) => (a.min(stamp_ns), b.max(stamp_ns)),
        });
        self.chunk_bytes += cdr.len() as u64 + MESSAGE_RECORD_OVERHEAD;
        if self.chunk_bytes >= self.opts.chunk_size {
            self.flush()?;
        }
        Ok(())
    }

    fn write_rosbag2_record(&mut self) -> Result<()> {
        let info = self.information();
        let mcap = self.mcap.as_mut().context("bag already finished")?;
        let mut m = BTreeMap::new();
        m.insert(
            "serialized_metadata".to_string(),
            info.to_serialized_metadata(),
        );
        m.insert("ROS_DISTRO".to_string(), info.ros_distro.clone());
        mcap.write_metadata(&mcap::records::Metadata {
            name: "rosbag2".into(),
            metadata: m,
        })
        .with_context(|| format!("cannot write to {}", self.file_name))?;
        Ok(())
    }

    /// Closes the current chunk (if any), hands it to the operating system
    /// and rewrites `metadata.yaml` to describe every message written so far.
    pub fn flush(&mut self) -> Result<()> {
        let mcap = self.mcap.as_mut().context("bag already finished")?;
        mcap.flush()
            .with_context(|| format!("cannot write a chunk to {}", self.file_name))?;
        if self.chunk_bytes > 0 {
            self.chunks += 1;
        }
        self.chunk_bytes = 0;
        self.information().write(&self.dir)
    }

    /// The metadata of what was written so far.
    pub fn information(&self) -> BagInformation {
        let topics: Vec<TopicCount> = self
            .topics
            .iter()
            .map(|t| TopicCount {
                name: t.name.clone(),
                type_name: t.type_name.clone(),
                qos: t.qos.clone(),
                count: t.count,
            })
            .collect();
        BagInformation::new(&self.file_name, &topics, self.bounds)
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.topics.iter().map(|t| t.count).sum()
    }

    /// Writes the last chunk, the `rosbag2` metadata record, the summary
    /// (schemas, channels, statistics, chunk and message indexes), the footer,
    /// and `metadata.yaml`; syncs the file to disk.
    pub fn finish(mut self) -> Result<BagSummary> {
        self.finish_inner()
    }

    fn finish_inner(&mut self) -> Result<BagSummary> {
        if self.chunk_bytes > 0 {
            self.chunks += 1;
        }
        self.write_rosbag2_record()?;
        let mut mcap = self.mcap.take().context("bag already finished")?;
        mcap.finish()
            .with_context(|| format!("cannot write the summary of {}", self.file_name))?;
        let buf = mcap.into_inner();
        let f = buf
            .into_inner()
            .map_err(|e| anyhow!("cannot write {}: {}", self.file_name, e.error()))?;
        f.sync_all()
            .with_context(|| format!("cannot sync {}", self.file_name))?;
        let info = self.information();
        info.write(&self.dir)?;
        let bytes = f.metadata().map(|m| m.len()).unwrap_or(0);
        Ok(BagSummary {
            dir: self.dir.clone(),
            file: self.file(),
            message_count: self.message_count(),
            topics: self
                .topics
                .iter()
                .map(|t| (t.name.clone(), t.type_name.clone(), t.count))
                .collect(),
            bounds: self.bounds,
            bytes,
            chunks: self.chunks,
        })
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        if self.mcap.is_some() {
            let _ = self.finish_inner();
        }
    }
}
