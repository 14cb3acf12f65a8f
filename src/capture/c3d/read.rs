//! Reading C3D files: header, parameter section and 3D data, every access bounds-checked.

use super::{units_divisor, Processor, BLOCK, KEY};
use crate::capture::{io_err, Capture, CaptureError};
use nalgebra::Vector3;
use std::path::Path;

fn c3d_err(offset: usize, message: impl Into<String>) -> CaptureError {
    CaptureError::C3d {
        path: None,
        offset,
        message: message.into(),
    }
}

/// Bounds-checked view of the file bytes.
struct Bytes<'a> {
    b: &'a [u8],
    proc: Processor,
}

impl<'a> Bytes<'a> {
    fn slice(&self, off: usize, n: usize, what: &str) -> Result<&'a [u8], CaptureError> {
        off.checked_add(n)
            .and_then(|end| self.b.get(off..end))
            .ok_or_else(|| {
                c3d_err(
                    off,
                    format!(
                        "{what}: needs {n} byte(s) but the file ends at byte {}",
                        self.b.len()
                    ),
                )
            })
    }

    fn u8(&self, off: usize, what: &str) -> Result<u8, CaptureError> {
        Ok(self.slice(off, 1, what)?[0])
    }

    fn i8(&self, off: usize, what: &str) -> Result<i8, CaptureError> {
        Ok(self.u8(off, what)? as i8)
    }

    fn i16(&self, off: usize, what: &str) -> Result<i16, CaptureError> {
        let s = self.slice(off, 2, what)?;
        Ok(self.proc.i16([s[0], s[1]]))
    }

    fn u16(&self, off: usize, what: &str) -> Result<u16, CaptureError> {
        Ok(self.i16(off, what)? as u16)
    }

    fn f32(&self, off: usize, what: &str) -> Result<f32, CaptureError> {
        let s = self.slice(off, 4, what)?;
        Ok(self.proc.f32([s[0], s[1], s[2], s[3]]))
    }
}

// ---------------------------------------------------------------------------------------
// Header and parameters
// ---------------------------------------------------------------------------------------

struct Header {
    points: u16,
    analog_per_frame_total: u16,
    first_frame: u16,
    last_frame: u16,
    scale: f32,
    data_start: u16,
    rate: f32,
}

fn parse_header(r: &Bytes) -> Result<Header, CaptureError> {
    Ok(Header {
        points: r.u16(2, "header word 2 (number of 3D points)")?,
        analog_per_frame_total: r.u16(4, "header word 3 (analog samples per frame)")?,
        first_frame: r.u16(6, "header word 4 (first frame)")?,
        last_frame: r.u16(8, "header word 5 (last frame)")?,
        scale: r.f32(12, "header words 7-8 (scale factor)")?,
        data_start: r.u16(16, "header word 9 (data start block)")?,
        rate: r.f32(20, "header words 11-12 (frame rate)")?,
    })
}

/// A parameter record; `dims` and `data` borrow the file bytes, so a malformed section
/// whose records overlap cannot multiply memory use.
struct Param<'a> {
    group_id: u8,
    name: String,
    /// -1 char, 1 byte, 2 int16, 4 float.
    kind: i8,
    dims: &'a [u8],
    data: &'a [u8],
    /// Byte offset of the record in the file.
    offset: usize,
}

struct Params<'a> {
    proc: Processor,
    groups: Vec<(u8, String)>,
    params: Vec<Param<'a>>,
}

fn ascii(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Largest parameter section the format can describe (its block count is one byte).
const MAX_PARAM_BYTES: usize = 255 * BLOCK;

fn parse_params<'a>(r: &Bytes<'a>, start: usize) -> Result<Params<'a>, CaptureError> {
    let mut groups = Vec::new();
    let mut params = Vec::new();
    // The first record follows the 4-byte parameter-section header.
    let mut p = start
        .checked_add(4)
        .ok_or_else(|| c3d_err(start, "parameter section offset overflows"))?;
    loop {
        if p >= r.b.len() {
            // Tolerate a section that simply runs to the end of the file.
            break;
        }
        if p - start >= MAX_PARAM_BYTES {
            return Err(c3d_err(
                p,
                format!(
                    "parameter section at byte {start}: record at byte {p} lies beyond the largest possible section (255 blocks)"
                ),
            ));
        }
        let where_ = |m: String| c3d_err(p, format!("parameter section at byte {p}: {m}"));
        let nlen_raw = r.i8(p, "parameter record name length")?;
        if nlen_raw == 0 {
            break; // zero padding after the last record
        }
        let nlen = usize::from(nlen_raw.unsigned_abs());
        let id = r.i8(p + 1, "parameter record group id").map_err(|_| {
            where_(format!(
                "record with name length {nlen} has no group id byte before the end of file"
            ))
        })?;
        let name_bytes = r.slice(p + 2, nlen, "name").map_err(|_| {
            where_(format!(
                "{} id {id} name length {nlen} runs past end of file ({} bytes)",
                if id < 0 { "group" } else { "parameter" },
                r.b.len()
            ))
        })?;
        let name = ascii(name_bytes).trim().to_string();
        let next_pos = p + 2 + nlen;
        let next = r.i16(next_pos, "next-record pointer").map_err(|_| {
            where_(format!(
                "record '{name}' (id {id}): next-record pointer at byte {next_pos} runs past end of file"
            ))
        })?;
        if id < 0 {
            groups.push((id.unsigned_abs(), name.clone()));
        } else if id > 0 {
            let q = next_pos + 2;
            let kind = r.i8(q, "data type").map_err(|_| {
                where_(format!(
                    "parameter '{name}': data type byte at {q} runs past end of file"
                ))
            })?;
            if !matches!(kind, -1 | 1 | 2 | 4) {
                return Err(where_(format!(
                    "parameter '{name}' (group id {id}): data type {kind} is not -1, 1, 2 or 4"
                )));
            }
            let ndims = usize::from(r.u8(q + 1, "dimension count").map_err(|_| {
                where_(format!(
                    "parameter '{name}': dimension count at byte {} runs past end of file",
                    q + 1
                ))
            })?);
            let dim_bytes = r.slice(q + 2, ndims, "dimensions").map_err(|_| {
                where_(format!(
                    "parameter '{name}': {ndims} dimensions at byte {} run past end of file",
                    q + 2
                ))
            })?;
            // Checked: 255 dimensions of up to 255 overflow any integer.
            let count = dim_bytes
                .iter()
                .try_fold(1usize, |a, &d| a.checked_mul(usize::from(d)));
            let size = count.and_then(|c| c.checked_mul(usize::from(kind.unsigned_abs())));
            let data_pos = q + 2 + ndims;
            let data = size
                .and_then(|n| r.slice(data_pos, n, "data").ok())
                .ok_or_else(|| {
                    where_(format!(
                        "parameter '{name}': {} data of dimensions {dim_bytes:?} at byte {data_pos} runs past end of file ({} bytes)",
                        kind_name(kind),
                        r.b.len()
                    ))
                })?;
            params.push(Param {
                group_id: id.unsigned_abs(),
                name: name.clone(),
                kind,
                dims: dim_bytes,
                data,
                offset: p,
            });
        }
        // id == 0 is not valid C3D; such a record is skipped by following its pointer.
        if next == 0 {
            break;
        }
        if next < 0 {
            return Err(where_(format!(
                "record '{name}' (id {id}): next-record pointer {next} points backwards"
            )));
        }
        // next > 0: strictly forward, so the loop terminates.
        p = next_pos + next as usize;
    }
    Ok(Params {
        proc: r.proc,
        groups,
        params,
    })
}

fn kind_name(kind: i8) -> &'static str {
    match kind {
        -1 => "char",
        1 => "byte",
        2 => "int16",
        _ => "float",
    }
}

impl<'a> Params<'a> {
    fn get(&self, group: &str, name: &str) -> Option<&Param<'a>> {
        let gid = self
            .groups
            .iter()
            .find(|(_, g)| g.eq_ignore_ascii_case(group))?
            .0;
        self.params
            .iter()
            .find(|p| p.group_id == gid && p.name.eq_ignore_ascii_case(name))
    }

    /// First value of a numeric parameter, as f64.
    fn float(&self, group: &str, name: &str) -> Option<(f64, usize)> {
        let p = self.get(group, name)?;
        Some((p.float(self.proc, 0)?, p.offset))
    }

    /// First value of an integer parameter read as unsigned 16-bit (the C3D convention
    /// for counts stored in int16), or a float parameter rounded.
    fn count(&self, group: &str, name: &str) -> Option<(u32, usize)> {
        let p = self.get(group, name)?;
        Some((p.unsigned(self.proc, 0)?, p.offset))
    }

    /// A 32-bit value stored as two int16 words (low word first), as in
    /// `TRIAL:ACTUAL_START_FIELD`.
    fn long_field(&self, group: &str, name: &str) -> Option<u32> {
        let p = self.get(group, name)?;
        if p.kind != 2 {
            return p.unsigned(self.proc, 0);
        }
        let lo = p.unsigned(self.proc, 0)?;
        let hi = p.unsigned(self.proc, 1).unwrap_or(0);
        Some(lo | (hi << 16))
    }
}

impl Param<'_> {
    fn float(&self, proc: Processor, i: usize) -> Option<f64> {
        match self.kind {
            4 => {
                let s = self.data.get(4 * i..4 * i + 4)?;
                Some(f64::from(proc.f32([s[0], s[1], s[2], s[3]])))
            }
            2 => {
                let s = self.data.get(2 * i..2 * i + 2)?;
                Some(f64::from(proc.i16([s[0], s[1]])))
            }
            1 => self.data.get(i).map(|&b| f64::from(b)),
            _ => None,
        }
    }

    fn unsigned(&self, proc: Processor, i: usize) -> Option<u32> {
        match self.kind {
            2 => {
                let s = self.data.get(2 * i..2 * i + 2)?;
                Some(u32::from(proc.i16([s[0], s[1]]) as u16))
            }
            1 => self.data.get(i).map(|&b| u32::from(b)),
            4 => {
                let v = self.float(proc, i)?;
                (v.is_finite() && v >= 0.0 && v <= f64::from(u32::MAX)).then(|| v.round() as u32)
            }
            _ => None,
        }
    }

    /// Strings of a char parameter: the first dimension is the string length, the
    /// remaining dimensions (column-major) count the strings.
    fn strings(&self) -> Vec<String> {
        if self.kind != -1 {
            return Vec::new();
        }
        let clean = |b: &[u8]| {
            ascii(b)
                .trim_matches(|c: char| c == ' ' || c == '\0')
                .to_string()
        };
        match self.dims.first() {
            None => vec![clean(self.data)],
            Some(&0) => Vec::new(),
            Some(&len) => self.data.chunks(usize::from(len)).map(clean).collect(),
        }
    }
}

// ---------------------------------------------------------------------------------------
// Points
// ---------------------------------------------------------------------------------------

/// Reads a C3D file; see the [`crate::capture`] documentation for what is supported.
pub fn read_c3d(path: &Path) -> Result<Capture, CaptureError> {
    let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
    parse_c3d(&bytes).map_err(|e| e.with_path(path))
}

/// The parameter section's start (byte) and the processor type it names,
/// from the header's first bytes.
fn parameter_start(bytes: &[u8]) -> Result<(usize, Processor), CaptureError> {
    if bytes.len() < BLOCK {
        return Err(c3d_err(
            0,
            format!(
                "header: file is {} bytes, a C3D file needs at least the 512-byte header",
                bytes.len()
            ),
        ));
    }
    let param_block = bytes[0];
    if bytes[1] != KEY {
        return Err(c3d_err(
            1,
            format!(
                "header: byte 2 is 0x{:02X}, expected 0x50 (not a C3D file, or an unsupported data format)",
                bytes[1]
            ),
        ));
    }
    if param_block == 0 {
        return Err(c3d_err(
            0,
            "header: parameter block number is 0 (blocks count from 1)",
        ));
    }
    let param_start = (usize::from(param_block) - 1) * BLOCK;
    let proc_pos = param_start + 3;
    let proc_code = *bytes.get(proc_pos).ok_or_else(|| {
        c3d_err(
            param_start,
            format!(
                "header: parameter section starts at block {param_block} (byte {param_start}) but the file has only {} bytes",
                bytes.len()
            ),
        )
    })?;
    let proc = Processor::from_code(proc_code).ok_or_else(|| {
        c3d_err(
            proc_pos,
            format!(
                "parameter section at byte {param_start}: processor type {proc_code} is not 84 (Intel), 85 (DEC) or 86 (SGI/MIPS)"
            ),
        )
    })?;
    Ok((param_start, proc))
}

/// POINT:SCALE (else the header's): non-zero and finite, negative for
/// float data.
fn point_scale(prm: &Params, h: &Header) -> Result<f64, CaptureError> {
    let (scale, scale_at) = match prm.float("POINT", "SCALE") {
        Some((s, at)) => (s, at),
        None => (f64::from(h.scale), 12),
    };
    if !scale.is_finite() || scale == 0.0 {
        return Err(c3d_err(
            scale_at,
            format!(
                "POINT:SCALE is {scale}; it must be non-zero and finite (its sign selects integer or float data)"
            ),
        ));
    }
    Ok(scale)
}

/// The frame rate, Hz: POINT:RATE if usable, else the header's.
fn frame_rate(prm: &Params, h: &Header) -> Result<f64, CaptureError> {
    let rate = match prm.float("POINT", "RATE") {
        Some((v, _)) if v.is_finite() && v > 0.0 => v,
        Some((v, at)) if !(f64::from(h.rate).is_finite() && h.rate > 0.0) => {
            return Err(c3d_err(
                at,
                format!(
                    "POINT:RATE is {v} and header frame rate is {}; no usable frame rate",
                    h.rate
                ),
            ))
        }
        _ => f64::from(h.rate),
    };
    if !(rate.is_finite() && rate > 0.0) {
        return Err(c3d_err(
            20,
            format!("header frame rate is {rate}; no POINT:RATE parameter gives a usable one"),
        ));
    }
    Ok(rate)
}

/// The data section's first block (POINT:DATA_START, else the header's)
/// and its byte offset.
fn data_start(prm: &Params, h: &Header) -> Result<(u32, usize), CaptureError> {
    let data_start = match prm.count("POINT", "DATA_START") {
        Some((v, _)) if v > 0 => v,
        _ => u32::from(h.data_start),
    };
    if data_start == 0 {
        return Err(c3d_err(
            16,
            "data start block is 0 in both the header and POINT:DATA_START",
        ));
    }
    let data_pos = (data_start as usize - 1)
        .checked_mul(BLOCK)
        .ok_or_else(|| c3d_err(16, format!("data start block {data_start} overflows")))?;
    Ok((data_start, data_pos))
}

/// The first frame's number and the frame count: TRIAL's fields, else
/// POINT:LONG_FRAMES, POINT:FRAMES or the header's.
fn frame_numbering(prm: &Params, h: &Header) -> (u32, u32) {
    let header_frames = if h.last_frame >= h.first_frame {
        u32::from(h.last_frame) - u32::from(h.first_frame) + 1
    } else {
        0
    };
    let trial_start = prm.long_field("TRIAL", "ACTUAL_START_FIELD");
    let trial_end = prm.long_field("TRIAL", "ACTUAL_END_FIELD");
    let first_frame = trial_start.unwrap_or(u32::from(h.first_frame));
    let n_frames: u32 = match (trial_start, trial_end) {
        (Some(s), Some(e)) if e.checked_sub(s).and_then(|d| d.checked_add(1)).is_some() => {
            e - s + 1
        }
        _ => match prm.float("POINT", "LONG_FRAMES") {
            Some((v, _)) if v.is_finite() && v >= 1.0 && v <= f64::from(u32::MAX) => {
                v.round() as u32
            }
            _ => prm.count("POINT", "FRAMES").map_or(header_frames, |v| v.0),
        },
    };
    (first_frame, n_frames)
}

/// POINT:UNITS (default mm) and the divisor that turns them into metres.
fn point_units(prm: &Params) -> Result<(String, f64), CaptureError> {
    let units = prm
        .get("POINT", "UNITS")
        .and_then(|p| p.strings().into_iter().next())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "mm".to_string());
    let divisor = units_divisor(&units).ok_or_else(|| {
        c3d_err(
            prm.get("POINT", "UNITS").map_or(0, |p| p.offset),
            format!("POINT:UNITS '{units}' is not one of mm, cm, dm, m"),
        )
    })?;
    Ok((units, divisor))
}

/// The points' labels: LABELS, LABELS2, LABELS3, ..., at most `used`.
fn point_labels(prm: &Params, used: usize) -> Vec<String> {
    let mut labels: Vec<String> = Vec::new();
    let mut k = 1usize;
    while labels.len() < used {
        let name = if k == 1 {
            "LABELS".to_string()
        } else {
            format!("LABELS{k}")
        };
        match prm.get("POINT", &name) {
            Some(p) => labels.extend(p.strings()),
            None => break,
        }
        k += 1;
    }
    labels.truncate(used);
    labels
}

/// The analog samples per frame to skip: from ANALOG:USED and ANALOG:RATE
/// when they give a whole number per frame, else the header's.
fn analog_samples(prm: &Params, h: &Header, rate: f64) -> usize {
    let from_params = match (prm.count("ANALOG", "USED"), prm.float("ANALOG", "RATE")) {
        (Some((0, _)), _) => Some(0usize),
        (Some((ch, _)), Some((arate, _))) if arate.is_finite() && arate > 0.0 => {
            let per = arate / rate;
            let n = per.round();
            ((per - n).abs() < 1e-3 && (1.0..=65535.0).contains(&n))
                .then(|| (ch as usize).saturating_mul(n as usize))
        }
        _ => None,
    };
    from_params.unwrap_or(usize::from(h.analog_per_frame_total))
}

/// Where the 3D points are in the data section and how to read them.
struct PointData {
    data_start: u32,
    data_pos: usize,
    used: usize,
    analog_total: usize,
    n_frames: u32,
    float_data: bool,
    scale: f64,
    divisor: f64,
}

impl PointData {
    /// Bytes per value (4 for float data, 2 for integer).
    fn word(&self) -> usize {
        if self.float_data {
            4
        } else {
            2
        }
    }

    /// Bytes per frame, checked against what the file holds after the
    /// data section's start.
    fn frame_bytes(&self, file_len: usize) -> Result<usize, CaptureError> {
        let (data_pos, data_start, used, analog_total, n_frames) = (
            self.data_pos,
            self.data_start,
            self.used,
            self.analog_total,
            self.n_frames,
        );
        let word = self.word();
        let values_per_frame = used
            .checked_mul(4)
            .and_then(|v| v.checked_add(analog_total));
        let frame_bytes = values_per_frame.and_then(|v| v.checked_mul(word)).ok_or_else(|| {
            c3d_err(
                data_pos,
                format!("data section: {used} points and {analog_total} analog samples per frame overflow"),
            )
        })?;
        let available = file_len.saturating_sub(data_pos);
        let n_frames_us = n_frames as usize;
        if frame_bytes == 0 {
            if n_frames > 65535 {
                return Err(c3d_err(
                    data_pos,
                    format!("data section: {n_frames} frames announced but frames hold no data"),
                ));
            }
        } else {
            let need = frame_bytes.checked_mul(n_frames_us);
            if need.is_none_or(|n| n > available) {
                return Err(c3d_err(
                    data_pos,
                    format!(
                        "data section at byte {data_pos} (block {data_start}): {n_frames} frames of {used} points + {analog_total} analog samples ({frame_bytes} bytes each) need {} bytes but only {available} remain in the file",
                        need.map_or_else(|| "more than usize::MAX".to_string(), |n| n.to_string())
                    ),
                ));
            }
        }
        Ok(frame_bytes)
    }

    /// The points of every frame, in metres (`None`: missing, by negative
    /// residual or a non-finite value).
    fn read(
        &self,
        r: &Bytes,
        frame_bytes: usize,
    ) -> Result<Vec<Vec<Option<Vector3<f64>>>>, CaptureError> {
        let (word, used, scale, divisor) = (self.word(), self.used, self.scale, self.divisor);
        let n_frames_us = self.n_frames as usize;
        let mut frames = Vec::with_capacity(n_frames_us);
        for f in 0..n_frames_us {
            let base = self.data_pos + f * frame_bytes; // bounded by the check in `frame_bytes`
            let mut row = Vec::with_capacity(used);
            for m in 0..used {
                let at = base + m * 4 * word;
                let what = "3D point";
                let (xyz, valid) = if self.float_data {
                    let x = r.f32(at, what)?;
                    let y = r.f32(at + 4, what)?;
                    let z = r.f32(at + 8, what)?;
                    let res = r.f32(at + 12, what)?;
                    // The residual word is a float to be read as a signed integer.
                    let valid = !res.is_nan() && res.trunc() >= 0.0;
                    (
                        Vector3::new(f64::from(x), f64::from(y), f64::from(z)),
                        valid,
                    )
                } else {
                    let x = r.i16(at, what)?;
                    let y = r.i16(at + 2, what)?;
                    let z = r.i16(at + 4, what)?;
                    let res = r.i16(at + 6, what)?;
                    (
                        Vector3::new(f64::from(x), f64::from(y), f64::from(z)) * scale,
                        res >= 0,
                    )
                };
                row.push((valid && xyz.iter().all(|c| c.is_finite())).then(|| xyz / divisor));
            }
            frames.push(row);
        }
        Ok(frames)
    }
}

/// Parses the bytes of a C3D file; see the [`crate::capture`] documentation for what is
/// supported.
pub fn parse_c3d(bytes: &[u8]) -> Result<Capture, CaptureError> {
    let (param_start, proc) = parameter_start(bytes)?;
    let r = Bytes { b: bytes, proc };
    let h = parse_header(&r)?;
    let prm = parse_params(&r, param_start)?;

    // --- POINT group -------------------------------------------------------------------
    let used = prm
        .count("POINT", "USED")
        .map_or(u32::from(h.points), |v| v.0);
    let used = usize::try_from(used).unwrap_or(usize::MAX);
    let scale = point_scale(&prm, &h)?;
    let rate = frame_rate(&prm, &h)?;
    let (data_start, data_pos) = data_start(&prm, &h)?;
    let (first_frame, n_frames) = frame_numbering(&prm, &h);
    let (units, divisor) = point_units(&prm)?;
    let mut labels = point_labels(&prm, used);
    let analog_total = analog_samples(&prm, &h, rate);

    // --- Data section ---------------------------------------------------------------
    let data = PointData {
        data_start,
        data_pos,
        used,
        analog_total,
        n_frames,
        float_data: scale < 0.0,
        scale,
        divisor,
    };
    let frame_bytes = data.frame_bytes(bytes.len())?;
    for i in labels.len()..used {
        labels.push(format!("POINT{}", i + 1));
    }
    let frames = data.read(&r, frame_bytes)?;

    Ok(Capture {
        labels,
        rate_hz: rate,
        units,
        first_frame,
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::c3d::tests::encode;
    use crate::capture::test_support::{sample_capture, Lcg};

    /// Little-endian Intel writer for the hand-built file below (independent of
    /// `encode_c3d`).
    fn le16(v: &mut Vec<u8>, x: i16) {
        v.extend_from_slice(&x.to_le_bytes());
    }

    /// A C3D file built byte by byte: integer data with POINT:SCALE = 0.5 (mm), 2 points,
    /// 3 frames, 2 analog channels × 2 samples per frame, parameters in an unusual
    /// order (a parameter before its group, a locked parameter, a two-block section).
    #[test]
    fn c3d_integer_file_by_hand() {
        let mut f = vec![0u8; 512];
        f[0] = 2;
        f[1] = 0x50;
        f[2..4].copy_from_slice(&2i16.to_le_bytes()); // points
        f[4..6].copy_from_slice(&4i16.to_le_bytes()); // analog per frame (total)
        f[6..8].copy_from_slice(&10i16.to_le_bytes()); // first frame
        f[8..10].copy_from_slice(&12i16.to_le_bytes()); // last frame
        f[12..16].copy_from_slice(&0.5f32.to_le_bytes()); // scale
        f[16..18].copy_from_slice(&4i16.to_le_bytes()); // data start block
        f[18..20].copy_from_slice(&2i16.to_le_bytes()); // analog samples per frame
        f[20..24].copy_from_slice(&50f32.to_le_bytes()); // rate
                                                         // Parameter section: blocks 2-3.
        let mut p = vec![1u8, 0x50, 2, 84];
        // (name, group id, payload after the next-pointer)
        let mut recs: Vec<(Vec<u8>, i8, Vec<u8>)> = Vec::new();
        // POINT:SCALE before the POINT group, locked.
        let mut d = vec![4u8, 0];
        d.extend_from_slice(&0.5f32.to_le_bytes());
        d.push(0);
        recs.push((b"SCALE".to_vec(), 1, d));
        recs.push((b"POINT".to_vec(), -1, {
            let mut d = vec![5u8];
            d.extend_from_slice(b"point");
            d
        }));
        let mut d = vec![2u8, 0];
        le16(&mut d, 2);
        d.push(0);
        recs.push((b"USED".to_vec(), 1, d));
        let mut d = vec![4u8, 0];
        d.extend_from_slice(&50f32.to_le_bytes());
        d.push(0);
        recs.push((b"RATE".to_vec(), 1, d));
        let mut d = vec![2u8, 0];
        le16(&mut d, 3);
        d.push(0);
        recs.push((b"FRAMES".to_vec(), 1, d));
        let mut d = vec![2u8, 0];
        le16(&mut d, 4);
        d.push(0);
        recs.push((b"DATA_START".to_vec(), 1, d));
        let mut d = vec![0xFFu8, 2, 4, 2];
        d.extend_from_slice(b"LEFTRGHT");
        d.push(0);
        recs.push((b"LABELS".to_vec(), 1, d));
        let mut d = vec![0xFFu8, 1, 2];
        d.extend_from_slice(b"mm");
        d.push(0);
        recs.push((b"UNITS".to_vec(), 1, d));
        recs.push((b"ANALOG".to_vec(), -2, vec![0]));
        let mut d = vec![2u8, 0];
        le16(&mut d, 2);
        d.push(0);
        recs.push((b"USED".to_vec(), 2, d));
        let mut d = vec![4u8, 0];
        d.extend_from_slice(&100f32.to_le_bytes());
        d.push(0);
        recs.push((b"RATE".to_vec(), 2, d));
        let nrec = recs.len();
        for (k, (name, id, payload)) in recs.into_iter().enumerate() {
            let locked = k == 0;
            let nl = name.len() as i8;
            p.push(if locked { (-nl) as u8 } else { nl as u8 });
            p.push(id as u8);
            p.extend_from_slice(&name);
            let next: i16 = if k + 1 == nrec {
                0
            } else {
                2 + payload.len() as i16
            };
            le16(&mut p, next);
            p.extend_from_slice(&payload);
        }
        p.resize(1024, 0);
        f.extend_from_slice(&p);
        // Data: 3 frames × (2 points × 4 words + 4 analog words).
        let pts: [[[i16; 4]; 2]; 3] = [
            [[100, -200, 3000, 0x0305], [1, 2, 3, 0]],
            [[101, -202, 3004, 0], [-1, -1, -1, -1]],
            [[102, -204, 3008, 0x7F7F], [32767, -32767, 0, 12]],
        ];
        for fr in pts {
            for pt in fr {
                for w in pt {
                    le16(&mut f, w);
                }
            }
            for a in 0..4 {
                le16(&mut f, 1000 + a);
            }
        }
        let cap = parse_c3d(&f).unwrap();
        assert_eq!(cap.labels, vec!["LEFT", "RGHT"]);
        assert_eq!(cap.rate_hz, 50.0);
        assert_eq!(cap.first_frame, 10);
        assert_eq!(cap.frames.len(), 3);
        let mm = |x: f64, y: f64, z: f64| Some(Vector3::new(x, y, z) * 0.5 / 1000.0);
        assert_eq!(cap.frames[0][0], mm(100.0, -200.0, 3000.0));
        assert_eq!(cap.frames[0][1], mm(1.0, 2.0, 3.0));
        assert_eq!(cap.frames[1][0], mm(101.0, -202.0, 3004.0));
        assert_eq!(cap.frames[1][1], None);
        assert_eq!(cap.frames[2][0], mm(102.0, -204.0, 3008.0));
        assert_eq!(cap.frames[2][1], mm(32767.0, -32767.0, 0.0));
        assert_eq!(cap.frames[2][0].unwrap().z, 1.504);

        // Truncating the last analog word is reported with its place.
        let err = parse_c3d(&f[..f.len() - 2]).unwrap_err().to_string();
        assert!(err.contains("data section at byte 1536"), "{err}");
        // A name length running past the end of the file is named.
        let mut g = f[..512 + 4 + 2].to_vec();
        g[512 + 4] = 100;
        let err = parse_c3d(&g).unwrap_err().to_string();
        assert!(
            err.contains("parameter section at byte 516: parameter id 1 name length 100 runs past end of file"),
            "{err}"
        );
    }

    #[test]
    fn c3d_rejects_garbage_with_location() {
        let e = parse_c3d(&[0u8; 100]).unwrap_err().to_string();
        assert!(e.contains("512-byte header"), "{e}");
        let mut b = encode(&sample_capture(), Processor::Intel, None, "mm");
        b[512 + 3] = 99;
        let e = parse_c3d(&b).unwrap_err().to_string();
        assert!(e.contains("processor type 99"), "{e}");
    }

    /// Random mutations and truncations of valid files must never panic.
    #[test]
    fn c3d_fuzz_no_panic() {
        let cap = sample_capture();
        let seeds = [
            encode(&cap, Processor::Intel, None, "mm"),
            encode(&cap, Processor::Dec, Some(0.1), "cm"),
            encode(&cap, Processor::Mips, None, "m"),
        ];
        let mut rng = Lcg(12345);
        let mut parsed_ok = 0;
        // CAPTURE_FUZZ_ITERS=1000000 cargo test --release fuzz  for a longer run.
        let iters: usize = std::env::var("CAPTURE_FUZZ_ITERS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(3000);
        for it in 0..iters {
            let mut b = seeds[it % seeds.len()].clone();
            match rng.below(4) {
                0 => {
                    let n = rng.below(b.len() + 1);
                    b.truncate(n);
                }
                1 => {
                    for _ in 0..1 + rng.below(8) {
                        let k = rng.below(b.len());
                        b[k] = rng.next() as u8;
                    }
                }
                2 => {
                    // Hit the header and the parameter section, where counts live.
                    for _ in 0..1 + rng.below(4) {
                        let k = rng.below(b.len().min(1024));
                        b[k] = [0x00, 0xFF, 0x7F, 0x80, 0x01][rng.below(5)];
                    }
                }
                _ => {
                    let k = rng.below(b.len());
                    let n = rng.below(64);
                    let v = rng.next() as u8;
                    b.splice(k..k, std::iter::repeat_n(v, n));
                }
            }
            let r = std::panic::catch_unwind(|| parse_c3d(&b).map(|c| c.frames.len()));
            match r {
                Ok(Ok(_)) => parsed_ok += 1,
                Ok(Err(e)) => assert!(!e.to_string().is_empty()),
                Err(_) => panic!("parse_c3d panicked on mutation {it}"),
            }
        }
        assert!(
            parsed_ok > iters / 30,
            "too few mutated files still parse: {parsed_ok}"
        );
    }
}
