//! Reads a bag's MCAP file record by record, tolerating a file cut short by
//! a crash: everything up to the last complete record is read, and the
//! reader says where and why the file ends early.

use super::metadata::{parse_qos_string, BagInformation, Qos};
use anyhow::{anyhow, bail, Context, Result};
use mcap::records::Record;
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// A schema record.
#[derive(Debug, Clone, PartialEq)]
pub struct SchemaInfo {
    pub id: u16,
    pub name: String,
    pub encoding: String,
    pub text: String,
}

/// A channel record, with what was counted of its messages.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub schema_id: u16,
    /// The schema's name (the ROS type, `pkg/msg/Type`).
    pub type_name: String,
    pub message_encoding: String,
    pub metadata: BTreeMap<String, String>,
    pub message_count: u64,
}

impl ChannelInfo {
    /// The offered QoS profiles stored on the channel.
    pub fn qos(&self) -> Result<Vec<Qos>> {
        parse_qos_string(
            self.metadata
                .get("offered_qos_profiles")
                .map(String::as_str)
                .unwrap_or(""),
        )
        .with_context(|| format!("channel {}", self.topic))
    }
}

/// One message, borrowed from the reader's buffer or a decompressed chunk.
#[derive(Debug)]
pub struct MessageRef<'a> {
    pub channel: &'a ChannelInfo,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: &'a [u8],
}

/// How the MCAP file ends.
#[derive(Debug, Clone, PartialEq)]
pub enum Ending {
    /// Data end, summary, footer and closing magic: a finished file.
    Complete,
    /// The file stops (or is damaged) at byte `offset`: everything before
    /// it is read; `reason` says what was found there.
    Truncated { offset: u64, reason: String },
}

/// A bag (MCAP file) opened for reading: schemas, channels and counts from
/// one pass over the file.
pub struct Reader {
    /// The MCAP file.
    pub path: PathBuf,
    /// The bag directory (the file's directory).
    pub dir: PathBuf,
    data: Vec<u8>,
    pub schemas: BTreeMap<u16, SchemaInfo>,
    pub channels: BTreeMap<u16, ChannelInfo>,
    /// Complete chunks, and loose message records, in file order: byte ranges.
    records: Vec<(usize, usize)>,
    pub chunk_count: usize,
    pub chunk_compression: Option<String>,
    pub message_count: u64,
    /// First and last log time, ns.
    pub bounds: Option<(u64, u64)>,
    pub ending: Ending,
    /// Chunks skipped because they cannot be read (CRC mismatch, bad
    /// compressed data): byte offset and why. The records after them are
    /// read as usual.
    pub damaged: Vec<(u64, String)>,
    /// Whether the data section holds the `rosbag2` metadata record.
    pub has_rosbag2_record: bool,
}

/// The MCAP file of a bag directory (from `metadata.yaml`, else the only
/// `*.mcap` in it), or `path` itself if it is a file.
pub fn mcap_file(path: &Path) -> Result<PathBuf> {
    if path.is_file() {
        return Ok(path.to_path_buf());
    }
    if !path.is_dir() {
        bail!("{}: no such bag directory or MCAP file", path.display());
    }
    if let Ok(info) = BagInformation::read(path) {
        if let Some(f) = info.relative_file_paths.first() {
            let p = path.join(f);
            if p.is_file() {
                return Ok(p);
            }
        }
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(path)
        .with_context(|| format!("cannot read {}", path.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    found.sort();
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => bail!("{}: no .mcap file in this bag directory", path.display()),
        _ => bail!(
            "{}: several .mcap files and no metadata.yaml naming one",
            path.display()
        ),
    }
}

impl Reader {
    /// Opens a bag directory or an MCAP file and scans it.
    pub fn open(path: &Path) -> Result<Reader> {
        let file = mcap_file(path)?;
        let data =
            std::fs::read(&file).with_context(|| format!("cannot read {}", file.display()))?;
        let dir = file
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let mut r = Reader {
            path: file,
            dir,
            data,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            records: Vec::new(),
            chunk_count: 0,
            chunk_compression: None,
            message_count: 0,
            bounds: None,
            ending: Ending::Complete,
            damaged: Vec::new(),
            has_rosbag2_record: false,
        };
        r.scan()?;
        Ok(r)
    }

    fn scan(&mut self) -> Result<()> {
        let data = std::mem::take(&mut self.data);
        let res = self.scan_in(&data);
        self.data = data;
        res
    }

    fn scan_in(&mut self, data: &[u8]) -> Result<()> {
        if data.len() < MAGIC.len() || &data[..MAGIC.len()] != MAGIC {
            bail!("{}: not an MCAP file (bad magic)", self.path.display());
        }
        let mut pos = MAGIC.len();
        let mut in_summary = false;
        loop {
            let at = pos as u64;
            let truncated = |reason: String| Ending::Truncated { offset: at, reason };
            if pos + 9 > data.len() {
                self.ending = truncated(if pos == data.len() {
                    "file ends after a complete record (no data end, summary or footer)".into()
                } else {
                    "file ends inside a record header".into()
                });
                break;
            }
            let op = data[pos];
            let len = u64::from_le_bytes(data[pos + 1..pos + 9].try_into().unwrap()) as usize;
            let start = pos + 9;
            let Some(end) = start.checked_add(len).filter(|&e| e <= data.len()) else {
                self.ending = truncated(format!(
                    "record (opcode 0x{op:02x}) of {len} bytes cut short: file ends after {} bytes",
                    data.len() - start
                ));
                break;
            };
            let rec = match mcap::read::parse_record(op, &data[start..end]) {
                Ok(r) => r,
                Err(e) => {
                    self.ending = truncated(format!("bad record (opcode 0x{op:02x}): {e}"));
                    break;
                }
            };
            match rec {
                Record::Footer(_) => {
                    if data.len() == end + MAGIC.len() && &data[end..] == MAGIC {
                        self.ending = Ending::Complete;
                    } else {
                        self.ending = Ending::Truncated {
                            offset: end as u64,
                            reason: "footer not followed by the closing magic".into(),
                        };
                    }
                    break;
                }
                Record::DataEnd(_) => in_summary = true,
                _ if in_summary => {}
                Record::Schema { header, data } => self.add_schema(header, &data),
                Record::Channel(c) => self.add_channel(c)?,
                Record::Metadata(m) if m.name == "rosbag2" => {
                    self.has_rosbag2_record = true;
                }
                Record::Message { header, .. } => {
                    self.count(header.channel_id, header.log_time)?;
                    self.records.push((pos, end));
                }
                Record::Chunk { header, data: body } => {
                    let comp = header.compression.clone();
                    let mut inner = Vec::new();
                    let ok = (|| -> Result<()> {
                        let rd = mcap::read::ChunkReader::new(header, &body)?;
                        for rec in rd {
                            inner.push(rec?.into_owned());
                        }
                        Ok(())
                    })();
                    if let Err(e) = ok {
                        // the record's own length is intact: skip it, read on
                        self.damaged.push((at, format!("damaged chunk: {e:#}")));
                        pos = end;
                        continue;
                    }
                    for rec in inner {
                        match rec {
                            Record::Schema { header, data } => self.add_schema(header, &data),
                            Record::Channel(c) => self.add_channel(c)?,
                            Record::Message { header, .. } => {
                                self.count(header.channel_id, header.log_time)?
                            }
                            _ => {}
                        }
                    }
                    self.chunk_count += 1;
                    self.chunk_compression.get_or_insert(comp);
                    self.records.push((pos, end));
                }
                _ => {}
            }
            pos = end;
        }
        Ok(())
    }

    fn add_schema(&mut self, h: mcap::records::SchemaHeader, data: &[u8]) {
        self.schemas.entry(h.id).or_insert_with(|| SchemaInfo {
            id: h.id,
            name: h.name,
            encoding: h.encoding,
            text: String::from_utf8_lossy(data).into_owned(),
        });
    }

    fn add_channel(&mut self, c: mcap::records::Channel) -> Result<()> {
        if self.channels.contains_key(&c.id) {
            return Ok(());
        }
        let type_name = self
            .schemas
            .get(&c.schema_id)
            .map(|s| s.name.clone())
            .ok_or_else(|| {
                anyhow!(
                    "{}: channel {} ({}) refers to schema {} before it is defined",
                    self.path.display(),
                    c.id,
                    c.topic,
                    c.schema_id
                )
            })?;
        self.channels.insert(
            c.id,
            ChannelInfo {
                id: c.id,
                topic: c.topic,
                schema_id: c.schema_id,
                type_name,
                message_encoding: c.message_encoding,
                metadata: c.metadata,
                message_count: 0,
            },
        );
        Ok(())
    }

    fn count(&mut self, channel: u16, t: u64) -> Result<()> {
        let c = self.channels.get_mut(&channel).ok_or_else(|| {
            anyhow!(
                "{}: message on channel {channel}, which is not defined",
                self.path.display()
            )
        })?;
        c.message_count += 1;
        self.message_count += 1;
        self.bounds = Some(match self.bounds {
            None => (t, t),
            Some((a, b)) => (a.min(t), b.max(t)),
        });
        Ok(())
    }

    /// Whether the file is finished (summary, footer, closing magic).
    pub fn is_complete(&self) -> bool {
        self.ending == Ending::Complete && self.damaged.is_empty()
    }

    /// The channel of a topic, or an error listing the bag's topics.
    pub fn channel(&self, topic: &str) -> Result<&ChannelInfo> {
        self.channels
            .values()
            .find(|c| c.topic == topic)
            .ok_or_else(|| {
                anyhow!(
                    "{}: no topic {topic} in this bag (topics: {})",
                    self.path.display(),
                    self.channels
                        .values()
                        .map(|c| c.topic.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })
    }

    /// Calls `f` on every readable message in file order; `f` may stop early.
    pub fn for_each_message<F>(&self, mut f: F) -> Result<()>
    where
        F: FnMut(MessageRef<'_>) -> Result<ControlFlow<()>>,
    {
        let mut emit = |header: mcap::records::MessageHeader, data: &[u8]| {
            f(MessageRef {
                channel: &self.channels[&header.channel_id],
                sequence: header.sequence,
                log_time: header.log_time,
                publish_time: header.publish_time,
                data,
            })
        };
        for &(a, b) in &self.records {
            let op = self.data[a];
            match mcap::read::parse_record(op, &self.data[a + 9..b])? {
                Record::Message { header, data } if emit(header, &data)?.is_break() => {
                    return Ok(());
                }
                Record::Chunk { header, data } => {
                    for rec in mcap::read::ChunkReader::new(header, &data)? {
                        if let Record::Message { header, data } = rec? {
                            if emit(header, &data)?.is_break() {
                                return Ok(());
                            }
                        }
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Log times (ns) of every message of one topic, in file order.
    pub fn log_times(&self, topic: &str) -> Result<Vec<u64>> {
        let id = self.channel(topic)?.id;
        let mut out = Vec::new();
        self.for_each_message(|m| {
            if m.channel.id == id {
                out.push(m.log_time);
            }
            Ok(ControlFlow::Continue(()))
        })?;
        Ok(out)
    }

    /// The CDR bytes of the first message of `topic` logged at `log_time`.
    pub fn message_at(&self, topic: &str, log_time: u64) -> Result<Option<Vec<u8>>> {
        let id = self.channel(topic)?.id;
        let mut out = None;
        self.for_each_message(|m| {
            if m.channel.id == id && m.log_time == log_time {
                out = Some(m.data.to_vec());
                return Ok(ControlFlow::Break(()));
            }
            Ok(ControlFlow::Continue(()))
        })?;
        Ok(out)
    }

    /// Size of the MCAP file, bytes.
    pub fn file_size(&self) -> u64 {
        self.data.len() as u64
    }
}
