//! Dumps a C3D capture as JSON (used by `tests/c3d_interop.py`).
//!
//! ```text
//! cargo run --release --example c3d_dump -- FILE.c3d
//!     prints the capture read from FILE.c3d
//! cargo run --release --example c3d_dump -- --write OUT.c3d
//!     writes a fixed synthetic capture to OUT.c3d, then prints it as read back
//! ```
//!
//! JSON: `{"labels": [..], "rate_hz": f, "units": s, "first_frame": n,
//! "frames": [[[x, y, z] | null, ..], ..]}`, coordinates in metres, numbers printed with
//! Rust's shortest round-trip formatting (exact when parsed as f64).

use garment_sim::capture::{read_c3d, write_c3d, Capture};
use nalgebra::Vector3;
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;

fn json_string(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            c if (c as u32) < 0x20 => o.push_str(&format!("\\u{:04x}", c as u32)),
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

fn json(cap: &Capture) -> String {
    let labels: Vec<String> = cap.labels.iter().map(|l| json_string(l)).collect();
    let frames: Vec<String> = cap
        .frames
        .iter()
        .map(|fr| {
            let pts: Vec<String> = fr
                .iter()
                .map(|p| match p {
                    Some(v) => format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z),
                    None => "null".to_string(),
                })
                .collect();
            format!("[{}]", pts.join(", "))
        })
        .collect();
    format!(
        "{{\"labels\": [{}], \"rate_hz\": {:?}, \"units\": {}, \"first_frame\": {}, \"frames\": [\n{}\n]}}",
        labels.join(", "),
        cap.rate_hz,
        json_string(&cap.units),
        cap.first_frame,
        frames.join(",\n")
    )
}

/// 4 markers × 6 frames at 120 Hz from frame 3, with a few missing markers.
fn synthetic() -> Capture {
    let frames = (0..6)
        .map(|f| {
            (0..4)
                .map(|m| {
                    if (f * 4 + m) % 7 == 2 {
                        None
                    } else {
                        let (f, m) = (f as f64, m as f64);
                        Some(Vector3::new(
                            0.1234567 * m - 0.25 + 0.003 * f,
                            -0.5 + 0.05 * m * m + 0.0101 * f,
                            1.75 - 0.00681 * f * f + 0.001 * m,
                        ))
                    }
                })
                .collect()
        })
        .collect();
    Capture {
        labels: vec![
            "LFT1".into(),
            "RGT1".into(),
            "marker three".into(),
            "M4".into(),
        ],
        rate_hz: 120.0,
        units: "m".into(),
        first_frame: 3,
        frames,
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = match args.as_slice() {
        [flag, out] if flag == "--write" => {
            if let Err(e) = write_c3d(Path::new(out), &synthetic()) {
                eprintln!("c3d_dump: {e}");
                return ExitCode::FAILURE;
            }
            out.clone()
        }
        [file] => file.clone(),
        _ => {
            eprintln!("usage: c3d_dump FILE.c3d | c3d_dump --write OUT.c3d");
            return ExitCode::from(2);
        }
    };
    match read_c3d(Path::new(&path)) {
        Ok(cap) => {
            let mut out = std::io::stdout().lock();
            match writeln!(out, "{}", json(&cap)) {
                Ok(()) => ExitCode::SUCCESS,
                Err(_) => ExitCode::FAILURE, // e.g. closed pipe: no panic
            }
        }
        Err(e) => {
            eprintln!("c3d_dump: {e}");
            ExitCode::FAILURE
        }
    }
}
