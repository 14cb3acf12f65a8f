//! C3D files: the block size, the key byte, the processor types (byte order and float
//! format) and the length units shared by the reader ([`read`]) and the writer
//! ([`write`]). What is supported is documented on [`crate::capture`].

mod read;
mod vax;
mod write;

pub use read::{parse_c3d, read_c3d};
pub use write::write_c3d;

use vax::{dec_to_f32, f32_to_dec};

const BLOCK: usize = 512;
const KEY: u8 = 0x50;

/// Processor type of a C3D file (byte 4 of the parameter section).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Processor {
    /// 84: little-endian integers, IEEE floats.
    Intel,
    /// 85: little-endian integers, VAX F_floating floats.
    Dec,
    /// 86: big-endian integers and IEEE floats.
    Mips,
}

impl Processor {
    fn from_code(b: u8) -> Option<Self> {
        match b {
            84 => Some(Processor::Intel),
            85 => Some(Processor::Dec),
            86 => Some(Processor::Mips),
            _ => None,
        }
    }

    fn code(self) -> u8 {
        match self {
            Processor::Intel => 84,
            Processor::Dec => 85,
            Processor::Mips => 86,
        }
    }

    fn i16(self, b: [u8; 2]) -> i16 {
        match self {
            Processor::Mips => i16::from_be_bytes(b),
            _ => i16::from_le_bytes(b),
        }
    }

    fn f32(self, b: [u8; 4]) -> f32 {
        match self {
            Processor::Intel => f32::from_le_bytes(b),
            Processor::Mips => f32::from_be_bytes(b),
            Processor::Dec => dec_to_f32(b),
        }
    }

    fn put_i16(self, v: i16, out: &mut Vec<u8>) {
        match self {
            Processor::Mips => out.extend_from_slice(&v.to_be_bytes()),
            _ => out.extend_from_slice(&v.to_le_bytes()),
        }
    }

    fn put_f32(self, v: f32, out: &mut Vec<u8>) {
        match self {
            Processor::Intel => out.extend_from_slice(&v.to_le_bytes()),
            Processor::Mips => out.extend_from_slice(&v.to_be_bytes()),
            Processor::Dec => out.extend_from_slice(&f32_to_dec(v)),
        }
    }
}

/// Divisor taking a length in `units` to metres.
fn units_divisor(units: &str) -> Option<f64> {
    match units.trim().to_ascii_lowercase().as_str() {
        "mm" => Some(1000.0),
        "cm" => Some(100.0),
        "dm" => Some(10.0),
        "m" => Some(1.0),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::write::{encode_c3d, Encoding};
    use super::*;
    use crate::capture::test_support::{assert_close, sample_capture};
    use crate::capture::Capture;
    use nalgebra::Vector3;

    /// `cap` encoded with `proc`, float data (`int_scale` `None`) or integer data with
    /// that `POINT:SCALE`, in `units`, with 3 analog channels × 2 samples per frame.
    pub(super) fn encode(
        cap: &Capture,
        proc: Processor,
        int_scale: Option<f32>,
        units: &'static str,
    ) -> Vec<u8> {
        encode_c3d(
            cap,
            &Encoding {
                proc,
                int_scale,
                analog_channels: 3,
                analog_samples: 2,
                units,
            },
        )
        .unwrap()
    }

    /// write_c3d → read_c3d: labels, rate, first frame and the missing pattern exact;
    /// coordinates equal to the f32 rounding of the millimetre values (relative 2^-24).
    #[test]
    fn c3d_round_trip_file() {
        let cap = sample_capture();
        let dir = std::env::temp_dir().join(format!("capture_rt_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("rt.c3d");
        write_c3d(&path, &cap).unwrap();
        let back = read_c3d(&path).unwrap();
        assert_eq!(back.rate_hz, 120.0);
        assert_eq!(back.units, "mm");
        assert_eq!(back.n_missing(), cap.n_missing());
        assert!(cap.n_missing() > 0);
        assert_close(&back, &cap, 6e-8, 1e-12);
        // Exactly what f32 millimetres give back.
        for (fa, fb) in back.frames.iter().zip(&cap.frames) {
            for (pa, pb) in fa.iter().zip(fb) {
                if let (Some(x), Some(y)) = (pa, pb) {
                    for k in 0..3 {
                        assert_eq!(x[k], f64::from((y[k] * 1000.0) as f32) / 1000.0);
                    }
                }
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Every processor type, integer and float data, analog samples interleaved.
    #[test]
    fn c3d_processors_and_formats() {
        let cap = sample_capture();
        for proc in [Processor::Intel, Processor::Dec, Processor::Mips] {
            let b = encode(&cap, proc, None, "mm");
            assert_eq!(b[512 + 3], proc.code());
            let back = parse_c3d(&b).unwrap();
            assert_close(&back, &cap, 6e-8, 1e-12);
            // Integer format, SCALE 0.1 mm: error ≤ 0.05 mm.
            let b = encode(&cap, proc, Some(0.1), "mm");
            let back = parse_c3d(&b).unwrap();
            assert_close(&back, &cap, 0.0, 0.05e-3 + 1e-12);
            // Centimetre units.
            let back = parse_c3d(&encode(&cap, proc, None, "cm")).unwrap();
            assert_eq!(back.units, "cm");
            assert_close(&back, &cap, 6e-8, 1e-12);
        }
    }

    /// Many markers with long labels: LABELS is split into LABELS2, LABELS3, ...
    #[test]
    fn c3d_many_long_labels() {
        let n = 500;
        let labels: Vec<String> = (0..n).map(|m| format!("{m:0>200}")).collect();
        let frames = vec![(0..n)
            .map(|m| (m % 3 != 0).then(|| Vector3::new(m as f64 * 1e-3, 0.5, -0.25)))
            .collect()];
        let cap = Capture {
            labels,
            rate_hz: 60.0,
            units: "m".into(),
            first_frame: 1,
            frames,
        };
        let back = parse_c3d(&encode(&cap, Processor::Intel, None, "mm")).unwrap();
        assert_close(&back, &cap, 6e-8, 1e-12);
        // 700 such labels do not fit in 255 parameter blocks: an error, not a bad file.
        let mut big = cap.clone();
        big.labels.extend((n..700).map(|m| format!("{m:0>200}")));
        big.frames[0].resize(700, None);
        let e = encode_c3d(
            &big,
            &Encoding {
                proc: Processor::Intel,
                int_scale: None,
                analog_channels: 0,
                analog_samples: 0,
                units: "mm",
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("255"), "{e}");
    }

    /// More than 65535 frames (and a first frame above 65535) go through
    /// TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD.
    #[test]
    fn c3d_long_capture() {
        let n = 70_000;
        let cap = Capture {
            labels: vec!["ball".into()],
            rate_hz: 1000.0,
            units: "m".into(),
            first_frame: 66_000,
            frames: (0..n)
                .map(|f| vec![(f % 1000 != 7).then(|| Vector3::new(0.0, 0.0, f as f64 * 1e-5))])
                .collect(),
        };
        let back = parse_c3d(&encode(&cap, Processor::Mips, None, "mm")).unwrap();
        assert_eq!(back.frames.len(), n);
        assert_eq!(back.first_frame, 66_000);
        assert_close(&back, &cap, 6e-8, 1e-12);
    }
}
