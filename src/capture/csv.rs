//! The capture CSV table (its format is documented on [`crate::capture`]).

use super::{io_err, Capture, CaptureError};
use nalgebra::Vector3;
use std::path::Path;

fn csv_err(line: usize, message: impl Into<String>) -> CaptureError {
    CaptureError::Csv {
        path: None,
        line,
        message: message.into(),
    }
}

/// Writes a capture in the CSV format described in the [`crate::capture`]
/// documentation.
pub fn write_capture_csv(path: &Path, cap: &Capture) -> Result<(), CaptureError> {
    let text = capture_to_csv(cap)?;
    std::fs::write(path, text).map_err(|e| io_err(path, e))
}

/// The CSV text of a capture (see [`write_capture_csv`]).
pub fn capture_to_csv(cap: &Capture) -> Result<String, CaptureError> {
    use std::fmt::Write as _;
    cap.check()?;
    if let Some(l) = cap
        .labels
        .iter()
        .find(|l| l.contains([',', '"', '\n', '\r']))
    {
        return Err(CaptureError::Invalid(format!(
            "label '{l}' contains a comma, quote or line break; it cannot be written to CSV"
        )));
    }
    let mut s = String::new();
    let _ = writeln!(s, "# rate_hz={}", cap.rate_hz);
    s.push_str("frame,time");
    for l in &cap.labels {
        let _ = write!(s, ",{l}_x,{l}_y,{l}_z");
    }
    s.push('\n');
    for (f, fr) in cap.frames.iter().enumerate() {
        let frame = u64::from(cap.first_frame) + f as u64;
        let _ = write!(s, "{frame},{}", f as f64 / cap.rate_hz);
        for p in fr {
            match p {
                Some(v) => {
                    let _ = write!(s, ",{},{},{}", v.x, v.y, v.z);
                }
                None => s.push_str(",,,"),
            }
        }
        s.push('\n');
    }
    Ok(s)
}

/// Reads a capture from the CSV format described in the [`crate::capture`]
/// documentation.
pub fn read_capture_csv(path: &Path) -> Result<Capture, CaptureError> {
    let text = std::fs::read_to_string(path).map_err(|e| io_err(path, e))?;
    parse_capture_csv(&text).map_err(|e| e.with_path(path))
}

type CsvRow = (u32, f64, Vec<Option<Vector3<f64>>>);

/// Parses CSV text (see [`read_capture_csv`]).
pub fn parse_capture_csv(text: &str) -> Result<Capture, CaptureError> {
    let mut rate: Option<f64> = None;
    let mut header: Option<(usize, Vec<String>)> = None;
    // (frame number, time, points)
    let mut rows: Vec<CsvRow> = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let ln = k + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(c) = line.strip_prefix('#') {
            if let Some(v) = c.trim().strip_prefix("rate_hz=") {
                let r: f64 = v
                    .trim()
                    .parse()
                    .map_err(|_| csv_err(ln, format!("rate_hz '{}' is not a number", v.trim())))?;
                rate = Some(r);
            }
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let Some((_, labels)) = &header else {
            if cells.len() < 2
                || !cells[0].eq_ignore_ascii_case("frame")
                || !cells[1].eq_ignore_ascii_case("time")
            {
                return Err(csv_err(ln, "header must start with 'frame,time'"));
            }
            if !(cells.len() - 2).is_multiple_of(3) {
                return Err(csv_err(
                    ln,
                    format!(
                        "header has {} coordinate columns, not a multiple of 3",
                        cells.len() - 2
                    ),
                ));
            }
            let mut labels = Vec::new();
            for (t, c) in cells[2..].chunks(3).enumerate() {
                let col = 3 + 3 * t;
                let lab = c[0].strip_suffix("_x").ok_or_else(|| {
                    csv_err(ln, format!("column {col} '{}' does not end in _x", c[0]))
                })?;
                for (a, sfx) in [(1, "_y"), (2, "_z")] {
                    if c[a].strip_suffix(sfx) != Some(lab) {
                        return Err(csv_err(
                            ln,
                            format!("column {} '{}' should be '{lab}{sfx}'", col + a, c[a]),
                        ));
                    }
                }
                labels.push(lab.to_string());
            }
            header = Some((ln, labels));
            continue;
        };
        let n = labels.len();
        if cells.len() != 2 + 3 * n {
            return Err(csv_err(
                ln,
                format!(
                    "{} cells, expected {} (frame, time, 3 per marker)",
                    cells.len(),
                    2 + 3 * n
                ),
            ));
        }
        let frame: u32 = cells[0].parse().map_err(|_| {
            csv_err(
                ln,
                format!("frame '{}' is not a non-negative integer", cells[0]),
            )
        })?;
        let time: f64 = cells[1]
            .parse()
            .map_err(|_| csv_err(ln, format!("time '{}' is not a number", cells[1])))?;
        let mut pts = Vec::with_capacity(n);
        for (m, c) in cells[2..].chunks(3).enumerate() {
            let empty = c.iter().filter(|s| s.is_empty()).count();
            match empty {
                3 => pts.push(None),
                0 => {
                    let mut v = [0.0; 3];
                    for a in 0..3 {
                        v[a] = c[a].parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                            csv_err(
                                ln,
                                format!("column {} ('{}' coordinate): '{}' is not a finite number", 3 + 3 * m + a, labels[m], c[a]),
                            )
                        })?;
                    }
                    pts.push(Some(Vector3::from(v)));
                }
                _ => {
                    return Err(csv_err(
                        ln,
                        format!("marker '{}' has {empty} empty coordinate(s) of 3; use 3 empty cells for a missing marker", labels[m]),
                    ))
                }
            }
        }
        if let Some(&(prev, _, _)) = rows.last() {
            if Some(frame) != prev.checked_add(1) {
                return Err(csv_err(
                    ln,
                    format!("frame {frame} follows frame {prev}; frames must be consecutive"),
                ));
            }
        }
        rows.push((frame, time, pts));
    }
    let (hl, labels) = header.ok_or_else(|| csv_err(1, "no 'frame,time,...' header line"))?;
    let rate =
        match rate {
            Some(r) => r,
            None => match (rows.first(), rows.last()) {
                (Some(a), Some(b)) if b.0 > a.0 => f64::from(b.0 - a.0) / (b.1 - a.1),
                _ => return Err(csv_err(
                    hl,
                    "cannot infer the frame rate from fewer than two frames; add '# rate_hz=<Hz>'",
                )),
            },
        };
    if !(rate.is_finite() && rate > 0.0) {
        return Err(csv_err(
            hl,
            format!("frame rate {rate} Hz is not a positive finite number"),
        ));
    }
    Ok(Capture {
        labels,
        rate_hz: rate,
        units: "m".to_string(),
        first_frame: rows.first().map_or(1, |r| r.0),
        frames: rows.into_iter().map(|r| r.2).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::test_support::sample_capture;

    #[test]
    fn csv_round_trip_exact() {
        let cap = sample_capture();
        let text = capture_to_csv(&cap).unwrap();
        let back = parse_capture_csv(&text).unwrap();
        assert_eq!(back.frames, cap.frames);
        assert_eq!(back.labels, cap.labels);
        assert_eq!(back.first_frame, 5);
        assert_eq!(back.rate_hz, 120.0);
        // Without the rate comment, the rate comes from the time column.
        let no_rate: String = text.lines().skip(1).map(|l| format!("{l}\n")).collect();
        let back = parse_capture_csv(&no_rate).unwrap();
        assert!((back.rate_hz - 120.0).abs() < 1e-9);
        // Errors name the line.
        let bad = "frame,time,a_x,a_y,a_z\n1,0,1,2,3\n2,0.1,1,,3\n";
        let e = parse_capture_csv(bad).unwrap_err().to_string();
        assert!(e.contains("CSV line 3") && e.contains("'a'"), "{e}");
        // Through a file.
        let path = std::env::temp_dir().join(format!("capture_{}.csv", std::process::id()));
        write_capture_csv(&path, &cap).unwrap();
        assert_eq!(read_capture_csv(&path).unwrap().frames, cap.frames);
        std::fs::remove_file(&path).ok();
    }
}
