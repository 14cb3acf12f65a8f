//! Helpers shared by the unit tests of the capture modules.

use super::Capture;
use nalgebra::Vector3;

/// Small deterministic generator (64-bit LCG, Knuth's MMIX constants).
pub(super) struct Lcg(pub(super) u64);
impl Lcg {
    pub(super) fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    pub(super) fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    /// Uniform in [-1, 1).
    pub(super) fn sym(&mut self) -> f64 {
        (self.next() as f64 / (1u64 << 31) as f64) * 2.0 - 1.0
    }
}

/// Four markers over seven frames, a few of them missing.
pub(super) fn sample_capture() -> Capture {
    let labels: Vec<String> = ["A", "B_long_label", "C", "D"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let frames = (0..7)
        .map(|f| {
            (0..4)
                .map(|m| {
                    if (f + m) % 5 == 3 {
                        None
                    } else {
                        Some(Vector3::new(
                            0.123456789 * m as f64 - 0.5 + 0.01 * f as f64,
                            1.0 / 3.0 + 0.2 * f as f64,
                            2.5 - 0.001234 * (f * f) as f64,
                        ))
                    }
                })
                .collect()
        })
        .collect();
    Capture {
        labels,
        rate_hz: 120.0,
        units: "m".into(),
        first_frame: 5,
        frames,
    }
}

/// |a − b| within `rel` of |b| (plus `abs`) for every present point; same missing set.
pub(super) fn assert_close(a: &Capture, b: &Capture, rel: f64, abs: f64) {
    assert_eq!(a.labels, b.labels);
    assert_eq!(a.first_frame, b.first_frame);
    assert_eq!(a.frames.len(), b.frames.len());
    for (fa, fb) in a.frames.iter().zip(&b.frames) {
        assert_eq!(fa.len(), fb.len());
        for (pa, pb) in fa.iter().zip(fb) {
            match (pa, pb) {
                (Some(x), Some(y)) => {
                    for k in 0..3 {
                        assert!(
                            (x[k] - y[k]).abs() <= rel * y[k].abs() + abs,
                            "{} vs {}",
                            x[k],
                            y[k]
                        );
                    }
                }
                (None, None) => {}
                _ => panic!("missing-marker pattern differs: {pa:?} vs {pb:?}"),
            }
        }
    }
}
