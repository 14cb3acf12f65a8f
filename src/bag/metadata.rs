//! `metadata.yaml` of a rosbag2 bag directory (format version 9, as
//! `ros2 bag record` writes it since Jazzy) and the offered QoS profiles,
//! which are written identically on each MCAP channel (`offered_qos_profiles`)
//! and in `metadata.yaml`: readers such as `rosbags` match the two.

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// rosbag2 metadata format version written.
pub const VERSION: u32 = 9;

/// `sec`/`nsec` of a QoS duration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct QosTime {
    pub sec: u64,
    pub nsec: u64,
}

impl QosTime {
    /// `RMW_DURATION_INFINITE`, as rmw reports an unset deadline, lifespan or lease.
    pub const INFINITE: QosTime = QosTime {
        sec: 9_223_372_036,
        nsec: 854_775_807,
    };
}

/// One offered QoS profile in the rosbag2 v9 layout (policies as lower-case names).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Qos {
    /// `keep_last` or `keep_all`.
    pub history: String,
    pub depth: u32,
    /// `reliable` or `best_effort`.
    pub reliability: String,
    /// `volatile` or `transient_local`.
    pub durability: String,
    pub deadline: QosTime,
    pub lifespan: QosTime,
    /// `automatic` or `manual_by_topic`.
    pub liveliness: String,
    pub liveliness_lease_duration: QosTime,
    pub avoid_ros_namespace_conventions: bool,
}

impl Qos {
    fn base(depth: u32, reliability: &str, durability: &str) -> Qos {
        Qos {
            history: "keep_last".into(),
            depth,
            reliability: reliability.into(),
            durability: durability.into(),
            deadline: QosTime::INFINITE,
            lifespan: QosTime::INFINITE,
            liveliness: "automatic".into(),
            liveliness_lease_duration: QosTime::INFINITE,
            avoid_ros_namespace_conventions: false,
        }
    }
    /// rclcpp's default publisher QoS: keep last 10, reliable, volatile.
    pub fn default_publisher() -> Qos {
        Qos::base(10, "reliable", "volatile")
    }
    /// A latched topic: keep last 1, reliable, transient local.
    pub fn latched() -> Qos {
        Qos::base(1, "reliable", "transient_local")
    }
    /// What the node offers on `/clock`: keep last 1, reliable, volatile.
    pub fn clock() -> Qos {
        Qos::base(1, "reliable", "volatile")
    }
}

/// The channel metadata value: the profiles as a YAML sequence in a string.
pub fn qos_string(profiles: &[Qos]) -> String {
    serde_yaml::to_string(profiles).expect("QoS profiles serialise")
}

/// Parses a channel's `offered_qos_profiles` string.
pub fn parse_qos_string(s: &str) -> Result<Vec<Qos>> {
    if s.trim().is_empty() {
        return Ok(Vec::new());
    }
    serde_yaml::from_str(s).with_context(|| format!("offered_qos_profiles {s:?}"))
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Nanoseconds {
    pub nanoseconds: u64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartingTime {
    pub nanoseconds_since_epoch: u64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopicMetadata {
    pub name: String,
    #[serde(rename = "type")]
    pub type_name: String,
    pub serialization_format: String,
    pub offered_qos_profiles: Vec<Qos>,
    /// RIHS01 type hash; empty (not computed), which rosbag2 accepts.
    #[serde(default)]
    pub type_description_hash: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopicWithCount {
    pub topic_metadata: TopicMetadata,
    pub message_count: u64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileInformation {
    pub path: String,
    pub starting_time: StartingTime,
    pub duration: Nanoseconds,
    pub message_count: u64,
}

/// `rosbag2_bagfile_information`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BagInformation {
    pub version: u32,
    pub storage_identifier: String,
    pub duration: Nanoseconds,
    pub starting_time: StartingTime,
    pub message_count: u64,
    pub topics_with_message_count: Vec<TopicWithCount>,
    pub compression_format: String,
    pub compression_mode: String,
    pub relative_file_paths: Vec<String>,
    pub files: Vec<FileInformation>,
    #[serde(default)]
    pub custom_data: Option<std::collections::BTreeMap<String, String>>,
    #[serde(default)]
    pub ros_distro: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetadataFile {
    pub rosbag2_bagfile_information: BagInformation,
}

/// A topic and its message count, as [`BagInformation::new`] takes them.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicCount {
    pub name: String,
    pub type_name: String,
    pub qos: Vec<Qos>,
    pub count: u64,
}

impl BagInformation {
    /// The metadata of a one-file MCAP bag. `start`/`end`: first and last log
    /// times (ns), `None` when the bag holds no message yet.
    pub fn new(file_name: &str, topics: &[TopicCount], bounds: Option<(u64, u64)>) -> Self {
        let (start, end) = bounds.unwrap_or((0, 0));
        let count: u64 = topics.iter().map(|t| t.count).sum();
        BagInformation {
            version: VERSION,
            storage_identifier: "mcap".into(),
            duration: Nanoseconds {
                nanoseconds: end - start,
            },
            starting_time: StartingTime {
                nanoseconds_since_epoch: start,
            },
            message_count: count,
            topics_with_message_count: topics
                .iter()
                .map(|t| TopicWithCount {
                    topic_metadata: TopicMetadata {
                        name: t.name.clone(),
                        type_name: t.type_name.clone(),
                        serialization_format: "cdr".into(),
                        offered_qos_profiles: t.qos.clone(),
                        type_description_hash: String::new(),
                    },
                    message_count: t.count,
                })
                .collect(),
            compression_format: String::new(),
            compression_mode: String::new(),
            relative_file_paths: vec![file_name.to_string()],
            files: vec![FileInformation {
                path: file_name.to_string(),
                starting_time: StartingTime {
                    nanoseconds_since_epoch: start,
                },
                duration: Nanoseconds {
                    nanoseconds: end - start,
                },
                message_count: count,
            }],
            custom_data: None,
            ros_distro: "jazzy".into(),
        }
    }

    /// The YAML of `metadata.yaml`.
    pub fn to_yaml(&self) -> String {
        serde_yaml::to_string(&MetadataFile {
            rosbag2_bagfile_information: self.clone(),
        })
        .expect("metadata serialises")
    }

    /// The inner map alone, as rosbag2 stores it in the MCAP `rosbag2`
    /// metadata record (`serialized_metadata`).
    pub fn to_serialized_metadata(&self) -> String {
        serde_yaml::to_string(self).expect("metadata serialises")
    }

    /// Writes `dir/metadata.yaml` atomically (temporary file, fsync, rename;
    /// a failure, e.g. a full disk, leaves the old file and no temporary one).
    pub fn write(&self, dir: &Path) -> Result<()> {
        let yaml = self.to_yaml();
        crate::io::write_atomic(&dir.join("metadata.yaml"), |w| w.write_all(yaml.as_bytes()))
    }

    /// Reads `dir/metadata.yaml`.
    pub fn read(dir: &Path) -> Result<BagInformation> {
        let path = dir.join("metadata.yaml");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let m: MetadataFile = serde_yaml::from_str(&text)
            .with_context(|| format!("{}: not a rosbag2 metadata file", path.display()))?;
        Ok(m.rosbag2_bagfile_information)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qos_string_round_trips_and_names_policies() {
        let q = vec![Qos::latched()];
        let s = qos_string(&q);
        assert!(s.contains("durability: transient_local"), "{s}");
        assert!(s.contains("sec: 9223372036"), "{s}");
        assert_eq!(parse_qos_string(&s).unwrap(), q);
        assert!(parse_qos_string("").unwrap().is_empty());
        assert!(parse_qos_string("- history: [").is_err());
    }

    #[test]
    fn metadata_yaml_has_what_rosbag2_reads() {
        let m = BagInformation::new(
            "b_0.mcap",
            &[TopicCount {
                name: "/clock".into(),
                type_name: "rosgraph_msgs/msg/Clock".into(),
                qos: vec![Qos::clock()],
                count: 3,
            }],
            Some((10, 25)),
        );
        let y = m.to_yaml();
        for key in [
            "rosbag2_bagfile_information:",
            "version: 9",
            "storage_identifier: mcap",
            "nanoseconds: 15",
            "nanoseconds_since_epoch: 10",
            "message_count: 3",
            "relative_file_paths:",
            "- b_0.mcap",
            "serialization_format: cdr",
            "reliability: reliable",
        ] {
            assert!(y.contains(key), "{key} missing in\n{y}");
        }
        let back: MetadataFile = serde_yaml::from_str(&y).unwrap();
        assert_eq!(back.rosbag2_bagfile_information, m);
    }
}
