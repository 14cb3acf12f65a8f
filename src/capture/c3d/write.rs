//! Writing C3D files.

use super::{units_divisor, Processor, BLOCK, KEY};
use crate::capture::{io_err, Capture, CaptureError};
use std::path::Path;

/// Builds a parameter section.
struct ParamWriter {
    proc: Processor,
    out: Vec<u8>,
    /// Position of the last record's next-pointer, patched when the next record starts.
    last_next: Option<usize>,
}

enum PValue<'a> {
    Int(&'a [i16]),
    Float(&'a [f32]),
    /// Strings padded to a common length: dims [len, count].
    Strings(&'a [String]),
}

impl ParamWriter {
    fn new(proc: Processor) -> Self {
        ParamWriter {
            proc,
            out: Vec::new(),
            last_next: None,
        }
    }

    fn start_record(&mut self, name: &str, id: i8) {
        let here = self.out.len();
        if let Some(pos) = self.last_next {
            let off = (here - pos) as i16;
            let mut b = Vec::new();
            self.proc.put_i16(off, &mut b);
            self.out[pos..pos + 2].copy_from_slice(&b);
        }
        self.out.push(name.len() as u8);
        self.out.push(id as u8);
        self.out.extend_from_slice(name.as_bytes());
        self.last_next = Some(self.out.len());
        self.out.extend_from_slice(&[0, 0]);
    }

    fn group(&mut self, id: i8, name: &str, desc: &str) {
        self.start_record(name, -id);
        self.out.push(desc.len() as u8);
        self.out.extend_from_slice(desc.as_bytes());
    }

    fn param(&mut self, group: i8, name: &str, value: PValue) {
        self.start_record(name, group);
        match value {
            PValue::Int(v) => {
                self.out.push(2);
                self.dims(v.len());
                for &x in v {
                    self.proc.put_i16(x, &mut self.out);
                }
            }
            PValue::Float(v) => {
                self.out.push(4);
                self.dims(v.len());
                for &x in v {
                    self.proc.put_f32(x, &mut self.out);
                }
            }
            PValue::Strings(v) => {
                let len = v.iter().map(|s| s.len()).max().unwrap_or(0).max(1);
                self.out.push((-1i8) as u8);
                self.out.push(2);
                self.out.push(len as u8);
                self.out.push(v.len() as u8);
                for s in v {
                    self.out.extend_from_slice(s.as_bytes());
                    self.out.extend(std::iter::repeat_n(b' ', len - s.len()));
                }
            }
        }
        self.out.push(0); // empty description
    }

    fn dims(&mut self, n: usize) {
        if n == 1 {
            self.out.push(0); // scalar
        } else {
            self.out.push(1);
            self.out.push(n as u8);
        }
    }
}

/// How [`encode_c3d`] stores the data (only Intel/float is public through [`write_c3d`];
/// the others exist to test the reader).
pub(super) struct Encoding {
    pub(super) proc: Processor,
    /// `None`: float format; `Some(s)`: integer format with POINT:SCALE = s (> 0).
    pub(super) int_scale: Option<f32>,
    /// Analog channels and samples per frame, filled with a ramp (to test skipping).
    pub(super) analog_channels: usize,
    pub(super) analog_samples: usize,
    pub(super) units: &'static str,
}

/// Writes a capture as a C3D file: Intel processor, floating-point 3D data, `mm`
/// units, residual 0 for present points ("processed") and -1 with zero coordinates for
/// missing ones, no analog data; `POINT:SCALE` = −(largest coordinate in mm)/32000 as
/// the specification recommends. Up to 65535 markers (`LABELS`, `LABELS2`, …); labels
/// longer than 255 characters or non-ASCII are rejected, as is a parameter section
/// above 255 blocks. Frame numbers above 65535 are written with
/// `TRIAL:ACTUAL_START_FIELD` / `ACTUAL_END_FIELD` and `POINT:LONG_FRAMES`; a
/// `first_frame` of 0 is written as 1 (C3D frames count from 1).
pub fn write_c3d(path: &Path, cap: &Capture) -> Result<(), CaptureError> {
    let bytes = encode_c3d(
        cap,
        &Encoding {
            proc: Processor::Intel,
            int_scale: None,
            analog_channels: 0,
            analog_samples: 0,
            units: "mm",
        },
    )?;
    std::fs::write(path, bytes).map_err(|e| io_err(path, e))
}

/// What [`encode_c3d`] derives from a capture before writing it.
struct Layout {
    /// Markers.
    n: usize,
    /// Frames.
    nf: usize,
    /// First and last frame numbers (from 1).
    first: u32,
    last: u32,
    /// Frame numbers beyond 16 bits: TRIAL fields and POINT:LONG_FRAMES.
    long: bool,
    /// Metres to the file's units.
    to_unit: f64,
    /// POINT:SCALE.
    scale: f32,
    /// Analog samples per frame.
    analog_total: usize,
}

impl Layout {
    /// Checks the capture against what C3D can hold (markers, labels,
    /// frames) and derives the layout.
    fn of(cap: &Capture, enc: &Encoding) -> Result<Layout, CaptureError> {
        cap.check()?;
        let n = cap.labels.len();
        if n > 65535 {
            return Err(CaptureError::Invalid(format!(
                "{n} markers; C3D holds at most 65535"
            )));
        }
        if let Some(l) = cap.labels.iter().find(|l| l.len() > 255 || !l.is_ascii()) {
            return Err(CaptureError::Invalid(format!(
                "label '{l}' is not ASCII or longer than 255 characters"
            )));
        }
        let nf = cap.frames.len();
        let nf32 = u32::try_from(nf)
            .map_err(|_| CaptureError::Invalid(format!("{nf} frames; C3D holds at most 2^32-1")))?;
        let first = cap.first_frame.max(1);
        let last = first.checked_add(nf32.saturating_sub(1)).ok_or_else(|| {
            CaptureError::Invalid(format!(
                "first frame {first} + {nf} frames exceeds the 32-bit frame range"
            ))
        })?;
        let long = last > 65535;
        let to_unit = units_divisor(enc.units).unwrap_or(1000.0);
        let max_abs = cap
            .frames
            .iter()
            .flatten()
            .flatten()
            .flat_map(|p| p.iter().map(|c| (c * to_unit).abs()))
            .fold(0.0f64, f64::max);
        // Spec: SCALE = largest coordinate / 32000 (its magnitude scales residuals).
        let mag = if max_abs > 0.0 {
            (max_abs / 32000.0) as f32
        } else {
            0.1
        };
        let scale = match enc.int_scale {
            Some(s) => s,
            None => -mag.max(f32::MIN_POSITIVE),
        };
        Ok(Layout {
            n,
            nf,
            first,
            last,
            long,
            to_unit,
            scale,
            analog_total: enc.analog_channels * enc.analog_samples,
        })
    }
}

/// The parameter section's records (POINT, ANALOG, and TRIAL for long
/// frame numbers), with POINT:DATA_START 0; and where its value is, to be
/// patched.
fn write_parameters(cap: &Capture, enc: &Encoding, l: &Layout) -> (ParamWriter, usize) {
    let (n, nf) = (l.n, l.nf);
    let mut w = ParamWriter::new(enc.proc);
    w.group(1, "POINT", "3D point parameters");
    w.param(1, "USED", PValue::Int(&[n as u16 as i16]));
    w.param(1, "SCALE", PValue::Float(&[l.scale]));
    w.param(1, "RATE", PValue::Float(&[cap.rate_hz as f32]));
    w.param(1, "DATA_START", PValue::Int(&[0]));
    let ds_value_pos = w.out.len() - 3; // 2 data bytes + description length byte
    w.param(1, "FRAMES", PValue::Int(&[nf.min(65535) as u16 as i16]));
    if l.long {
        w.param(1, "LONG_FRAMES", PValue::Float(&[nf as f32]));
    }
    w.param(1, "UNITS", PValue::Strings(&[enc.units.to_string()]));
    // LABELS, LABELS2, ...: at most 255 strings each, and small enough for the 16-bit
    // next-record pointer.
    let label_len = cap.labels.iter().map(|l| l.len()).max().unwrap_or(1).max(1);
    let per_chunk = (30_000 / label_len).clamp(1, 255);
    for (k, chunk) in cap.labels.chunks(per_chunk).enumerate() {
        let name = if k == 0 {
            "LABELS".to_string()
        } else {
            format!("LABELS{}", k + 1)
        };
        w.param(1, &name, PValue::Strings(chunk));
        let dname = if k == 0 {
            "DESCRIPTIONS".to_string()
        } else {
            format!("DESCRIPTIONS{}", k + 1)
        };
        let blanks = vec![String::new(); chunk.len()];
        w.param(1, &dname, PValue::Strings(&blanks));
    }
    if n == 0 {
        w.param(1, "LABELS", PValue::Strings(&[]));
    }
    w.group(2, "ANALOG", "Analog data parameters");
    w.param(2, "USED", PValue::Int(&[enc.analog_channels as i16]));
    w.param(
        2,
        "RATE",
        PValue::Float(&[(cap.rate_hz * enc.analog_samples.max(1) as f64) as f32]),
    );
    if l.long || cap.first_frame > 65535 {
        let split = |v: u32| [(v & 0xffff) as u16 as i16, (v >> 16) as u16 as i16];
        w.group(3, "TRIAL", "Trial parameters");
        w.param(3, "ACTUAL_START_FIELD", PValue::Int(&split(l.first)));
        w.param(3, "ACTUAL_END_FIELD", PValue::Int(&split(l.last)));
    }
    (w, ds_value_pos)
}

/// The header (block 1).
fn write_header(out: &mut Vec<u8>, cap: &Capture, enc: &Encoding, l: &Layout, data_start: usize) {
    let p = enc.proc;
    out.push(2);
    out.push(KEY);
    p.put_i16(l.n as u16 as i16, out);
    p.put_i16(l.analog_total.min(65535) as u16 as i16, out);
    p.put_i16(l.first.min(65535) as u16 as i16, out);
    p.put_i16(l.last.min(65535) as u16 as i16, out);
    p.put_i16(0, out); // max interpolation gap
    p.put_f32(l.scale, out);
    p.put_i16(data_start as u16 as i16, out);
    p.put_i16(enc.analog_samples.min(65535) as u16 as i16, out);
    p.put_f32(cap.rate_hz as f32, out);
    out.resize(BLOCK, 0);
    // Word 150: key 12345 = 4-character event labels supported; word 151: 0 events.
    let mut key = Vec::new();
    p.put_i16(12345, &mut key);
    out[298..300].copy_from_slice(&key);
}

/// The data section: every frame's points (missing ones with residual −1)
/// and its analog samples (a ramp).
fn write_data(
    out: &mut Vec<u8>,
    cap: &Capture,
    enc: &Encoding,
    l: &Layout,
) -> Result<(), CaptureError> {
    let (p, to_unit) = (enc.proc, l.to_unit);
    let mut ramp: i16 = 0;
    for fr in &cap.frames {
        for pt in fr {
            match (pt, enc.int_scale) {
                (Some(v), None) => {
                    for c in v.iter() {
                        p.put_f32((c * to_unit) as f32, out);
                    }
                    p.put_f32(0.0, out);
                }
                (None, None) => {
                    for _ in 0..3 {
                        p.put_f32(0.0, out);
                    }
                    p.put_f32(-1.0, out);
                }
                (Some(v), Some(s)) => {
                    for c in v.iter() {
                        let q = (c * to_unit / f64::from(s)).round();
                        if q.abs() > 32767.0 {
                            return Err(CaptureError::Invalid(format!(
                                "coordinate {c} m does not fit int16 with SCALE {s}"
                            )));
                        }
                        p.put_i16(q as i16, out);
                    }
                    p.put_i16(0, out);
                }
                (None, Some(_)) => {
                    for _ in 0..3 {
                        p.put_i16(0, out);
                    }
                    p.put_i16(-1, out);
                }
            }
        }
        for _ in 0..l.analog_total {
            ramp = ramp.wrapping_add(1);
            if enc.int_scale.is_some() {
                p.put_i16(ramp, out);
            } else {
                p.put_f32(f32::from(ramp), out);
            }
        }
    }
    Ok(())
}

/// Encodes a capture as the bytes of a C3D file as `enc` says.
pub(super) fn encode_c3d(cap: &Capture, enc: &Encoding) -> Result<Vec<u8>, CaptureError> {
    let l = Layout::of(cap, enc)?;
    // Parameters (data start is patched in once the section size is known).
    let (mut w, ds_value_pos) = write_parameters(cap, enc, &l);
    let section_len = 4 + w.out.len();
    let nblocks = section_len.div_ceil(BLOCK);
    if nblocks > 255 {
        return Err(CaptureError::Invalid(format!(
            "parameter section needs {nblocks} blocks; C3D allows 255"
        )));
    }
    let data_start = 2 + nblocks; // header is block 1, parameters start at block 2
    if data_start > 65535 {
        return Err(CaptureError::Invalid("data start block overflows".into()));
    }
    let mut ds = Vec::new();
    enc.proc.put_i16(data_start as u16 as i16, &mut ds);
    w.out[ds_value_pos..ds_value_pos + 2].copy_from_slice(&ds);

    let word = if enc.int_scale.is_some() { 2 } else { 4 };
    let data_len =
        l.nf.checked_mul((4 * l.n + l.analog_total) * word)
            .ok_or_else(|| CaptureError::Invalid("data section size overflows".into()))?;
    let mut out = Vec::with_capacity(BLOCK * data_start + data_len);
    write_header(&mut out, cap, enc, &l, data_start);

    // Parameter section (blocks 2..).
    out.extend_from_slice(&[1, KEY, nblocks as u8, enc.proc.code()]);
    out.extend_from_slice(&w.out);
    out.resize(BLOCK * (data_start - 1), 0);

    write_data(&mut out, cap, enc, &l)?;
    Ok(out)
}
