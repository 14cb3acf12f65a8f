//! Motion-capture data layer: C3D and CSV input/output, gap filling and the vertical.
//!
//! This module feeds the damping identification of Charfi (2006), chapter 5
//! ([`crate::lab::identify`]): a fabric square carrying an nx × ny grid of reflective
//! markers is dropped and tracked; the capture is brought into a frame whose +z axis is
//! the vertical (thesis §5.2.2.3, found from a falling ball) and the markers the cameras
//! lost are filled in (thesis §5.3, Algorithm 1).
//!
//! # C3D support
//!
//! [`read_c3d`] / [`parse_c3d`] follow "The C3D File Format User Guide" (c3d.org):
//!
//! * 512-byte header; parameter section with groups and parameters in any order, locked
//!   flags (negative name length), data types -1 (char), 1 (byte), 2 (int16), 4 (float),
//!   0–7 dimensions, and the next-record pointer (0 ends the section);
//! * the POINT group: `USED`, `LABELS`, `LABELS2`, `LABELS3`…, `SCALE`, `RATE`,
//!   `DATA_START`, `FRAMES`, `UNITS` (the header values are the fallback when a parameter
//!   is absent); frame counts above 65535 through `TRIAL:ACTUAL_START_FIELD` /
//!   `TRIAL:ACTUAL_END_FIELD` or `POINT:LONG_FRAMES`;
//! * integer 3D data (`SCALE` > 0: int16 × SCALE) and floating-point 3D data
//!   (`SCALE` < 0: f32, already scaled);
//! * processor types 84 (Intel: little-endian, IEEE floats), 85 (DEC: little-endian
//!   integers, VAX F_floating floats, converted exactly) and 86 (SGI/MIPS: big-endian,
//!   IEEE floats) — all three are read; [`write_c3d`] writes Intel only;
//! * analog samples interleaved with the frames are skipped (their count per frame is
//!   `ANALOG:USED` × `ANALOG:RATE` / `POINT:RATE`, or header word 3 when those
//!   parameters are absent); header events and the optional label/range section are
//!   ignored.
//!
//! The 4th word of each point is the residual/camera word; a negative value marks an
//! invalid point, read as `None`. Non-finite coordinates are also read as `None`.
//! Coordinates are converted to metres from `POINT:UNITS` (`mm`, `cm`, `dm`, `m`; default
//! `mm` when the parameter is absent).
//!
//! A malformed file is reported as [`CaptureError::C3d`] with the byte offset and what was
//! being read; the parser never indexes out of bounds, never overflows, and sizes every
//! allocation by what the file can actually hold.
//!
//! # CSV format
//!
//! [`write_capture_csv`] / [`read_capture_csv`] use a plain text table:
//!
//! ```text
//! # rate_hz=120
//! frame,time,M1_x,M1_y,M1_z,M2_x,M2_y,M2_z
//! 1,0,0.1,0.2,1.5,,,
//! 2,0.008333333333333333,0.1,0.2,1.49,0.3,0.2,1.5
//! ```
//!
//! * optional leading comment lines start with `#`; `# rate_hz=<Hz>` sets the frame
//!   rate (otherwise it is inferred from the `time` column, which needs two frames);
//! * header `frame,time` then three columns `<label>_x,<label>_y,<label>_z` per marker;
//! * `frame` is the C3D-style frame number (consecutive integers), `time` is
//!   `(frame - first frame) / rate_hz` in seconds;
//! * coordinates in metres; three empty cells mean the marker is missing in that frame.
//!   Labels must not contain commas, quotes or line breaks.
//!   Numbers are written with Rust's shortest round-trip formatting, so a write/read
//!   round trip is exact.

use nalgebra::Vector3;
use std::fmt;
use std::path::{Path, PathBuf};

// C3D reading and writing.
mod c3d;
// The CSV table.
mod csv;
// Gap filling of the marker grid.
mod gaps;
// The vertical from a dropped ball, and the rotation to it.
mod vertical;

#[cfg(test)]
mod test_support;

pub use c3d::{parse_c3d, read_c3d, write_c3d};
pub use csv::{capture_to_csv, parse_capture_csv, read_capture_csv, write_capture_csv};
pub use gaps::{fill_gaps, FillReport, GridMap};
pub use vertical::{rotate_capture, rotation_to_z, vertical_from_ball};

/// A marker capture: `frames[f][m]` is the position of marker `m` (label `labels[m]`) in
/// frame `first_frame + f`, in metres, or `None` when the marker was not reconstructed.
#[derive(Clone, Debug, PartialEq)]
pub struct Capture {
    /// Marker labels, one per marker column.
    pub labels: Vec<String>,
    /// Frame rate in Hz.
    pub rate_hz: f64,
    /// Length unit of the source file (`"mm"`, `"cm"`, `"m"`…), for information only:
    /// the coordinates in `frames` are always in metres.
    pub units: String,
    /// Number of the first frame (C3D frames count from 1).
    pub first_frame: u32,
    /// `frames[f][m]`: marker `m` in frame `f` (metres), `None` if missing.
    pub frames: Vec<Vec<Option<Vector3<f64>>>>,
}

impl Capture {
    /// Number of markers (labels).
    pub fn n_markers(&self) -> usize {
        self.labels.len()
    }

    /// Number of missing (`None`) marker positions over all frames.
    pub fn n_missing(&self) -> usize {
        self.frames.iter().flatten().filter(|p| p.is_none()).count()
    }

    /// Positions of marker `m` in the frames where it is present, in frame order
    /// (e.g. a ball track for [`vertical_from_ball`]).
    pub fn track(&self, m: usize) -> Vec<Vector3<f64>> {
        self.frames
            .iter()
            .filter_map(|fr| fr.get(m).copied().flatten())
            .collect()
    }

    /// Checks that every frame has one entry per label and that the rate is usable.
    pub fn check(&self) -> Result<(), CaptureError> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return Err(CaptureError::Invalid(format!(
                "capture frame rate {} Hz is not a positive finite number",
                self.rate_hz
            )));
        }
        let n = self.labels.len();
        if let Some((f, fr)) = self.frames.iter().enumerate().find(|(_, fr)| fr.len() != n) {
            return Err(CaptureError::Invalid(format!(
                "capture frame index {f} has {} markers but there are {n} labels",
                fr.len()
            )));
        }
        Ok(())
    }

    /// Refuses a marker position farther than
    /// [`crate::limits::MAX_CAPTURE_DISTANCE`] from the origin (a unit slip or
    /// a corrupt sample), naming the marker (label and index), the frame (its
    /// number in the file and its index from 0) and the bound.
    pub fn check_positions(&self) -> Result<(), CaptureError> {
        use crate::limits::{check_capture_position, MAX_CAPTURE_DISTANCE};
        for (f, fr) in self.frames.iter().enumerate() {
            for (m, p) in fr.iter().enumerate() {
                let Some(p) = p else { continue };
                if p.norm() <= MAX_CAPTURE_DISTANCE {
                    continue;
                }
                let label = self.labels.get(m).map_or("", String::as_str);
                let what = format!(
                    "marker {m} ({label:?}), frame {} (index {f})",
                    u64::from(self.first_frame) + f as u64
                );
                check_capture_position(&what, p)
                    .map_err(|e| CaptureError::Invalid(e.to_string()))?;
            }
        }
        Ok(())
    }
}

/// Everything that can go wrong in this module; each variant says what and where.
#[derive(Debug)]
pub enum CaptureError {
    /// Reading or writing a file failed.
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A C3D file is malformed or unsupported; `offset` is the byte where the problem is.
    C3d {
        path: Option<PathBuf>,
        offset: usize,
        message: String,
    },
    /// A CSV capture file is malformed; `line` is 1-based.
    Csv {
        path: Option<PathBuf>,
        line: usize,
        message: String,
    },
    /// The capture (or an argument) cannot be used for the requested operation.
    Invalid(String),
    /// Gap filling stalled: missing markers without any applicable estimate.
    GapFill(String),
    /// A least-squares fit is impossible (degenerate data).
    Fit(String),
}

impl fmt::Display for CaptureError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CaptureError::Io { path, source } => write!(f, "{}: {source}", path.display()),
            CaptureError::C3d {
                path,
                offset,
                message,
            } => {
                if let Some(p) = path {
                    write!(f, "{}: ", p.display())?;
                }
                write!(f, "C3D byte {offset}: {message}")
            }
            CaptureError::Csv {
                path,
                line,
                message,
            } => {
                if let Some(p) = path {
                    write!(f, "{}: ", p.display())?;
                }
                write!(f, "CSV line {line}: {message}")
            }
            CaptureError::Invalid(m) => write!(f, "invalid capture: {m}"),
            CaptureError::GapFill(m) => write!(f, "gap filling: {m}"),
            CaptureError::Fit(m) => write!(f, "fit: {m}"),
        }
    }
}

impl std::error::Error for CaptureError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            CaptureError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl CaptureError {
    fn with_path(self, p: &Path) -> Self {
        match self {
            CaptureError::C3d {
                offset, message, ..
            } => CaptureError::C3d {
                path: Some(p.to_path_buf()),
                offset,
                message,
            },
            CaptureError::Csv { line, message, .. } => CaptureError::Csv {
                path: Some(p.to_path_buf()),
                line,
                message,
            },
            e => e,
        }
    }
}

fn io_err(path: &Path, source: std::io::Error) -> CaptureError {
    CaptureError::Io {
        path: path.to_path_buf(),
        source,
    }
}
