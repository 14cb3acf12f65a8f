//! Damping identification (thesis ch. 5) on a synthetic capture of
//! `free_fall.yaml` (known α, β), sampled at 120 Hz on the 11 × 11 grid.

mod support;
use garment_sim::lab::identify::{identify, sample_capture, IdentifyOptions};
use garment_sim::scene::{Overrides, Scene};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use std::path::Path;

fn capture() -> (Vec<Vec<Vector3<f64>>>, garment_sim::fabric::Fabric) {
    let sc = Scene::load(Path::new("config/scenes/free_fall.yaml")).unwrap();
    // one implicit Euler step per frame of the 120 Hz capture
    let mut sim = sc
        .build(&Overrides {
            dt: Some(1.0 / 120.0),
            ..Default::default()
        })
        .unwrap();
    let frames = sample_capture(&mut sim, 120.0, 1.5).unwrap();
    (frames, sim.fabric.clone())
}

#[test]
fn noise_free_capture_gives_back_alpha() {
    let (frames, fabric) = capture();
    let truth = fabric.damping;
    let id = identify(&frames, 120.0, &fabric, &IdentifyOptions::default()).unwrap();
    println!(
        "window {:?}; alpha {:.4} (true {}); beta_f {:.2e} ({:.1e}), beta_c {:.2e} ({:.1e}), beta_t {:.2e} ({:.1e}); global {:?}, condition number {:.2e}",
        id.window, id.alpha.mean, truth.alpha, id.beta_bend.mean, truth.beta_bend, id.beta_shear.mean,
        truth.beta_shear, id.beta_tension.mean, truth.beta_tension, id.global, id.global_condition_number
    );
    assert!(id.window_chosen_automatically && id.window.1 - id.window.0 > 60);
    // the thesis' ordered α alone, and the measured (joint) values
    assert!(
        (id.alpha.mean / truth.alpha - 1.0).abs() < 0.02,
        "alpha {}",
        id.alpha.mean
    );
    assert!(id.alpha.error_decrease > 0.5);
    let m = id.measured;
    assert_eq!(id.resolved, [true; 4]);
    assert!((m[0] / truth.alpha - 1.0).abs() < 0.02, "alpha {}", m[0]);
    for (k, (got, want)) in [
        (m[1], truth.beta_bend),
        (m[2], truth.beta_shear),
        (m[3], truth.beta_tension),
    ]
    .iter()
    .enumerate()
    {
        assert!(
            (got / want - 1.0).abs() < 0.15,
            "beta {k}: {got:e} vs {want:e}"
        );
    }
}

#[test]
fn noisy_capture_gives_back_alpha_within_5_percent() {
    let (mut frames, fabric) = capture();
    let mut rng = rand::rngs::StdRng::seed_from_u64(42);
    let mut gauss = || {
        // Box–Muller
        let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    };
    for f in frames.iter_mut() {
        for p in f.iter_mut() {
            *p += Vector3::new(gauss(), gauss(), gauss()) * 0.0005;
        }
    }
    let id = identify(&frames, 120.0, &fabric, &IdentifyOptions::default()).unwrap();
    println!(
        "0.5 mm noise: alpha {:.4} (ordered {:.4} ± {:.3}); betas {:.2e} {:.2e} {:.2e}",
        id.measured[0], id.alpha.mean, id.alpha.std, id.measured[1], id.measured[2], id.measured[3]
    );
    assert!(id.resolved[0]);
    for a in [id.measured[0], id.alpha.mean] {
        assert!((a / fabric.damping.alpha - 1.0).abs() < 0.05, "alpha {a}");
    }
}

#[test]
fn bad_captures_are_clear_errors() {
    let (frames, fabric) = capture();
    let short = &frames[..3];
    let e = identify(short, 120.0, &fabric, &IdentifyOptions::default()).unwrap_err();
    assert!(format!("{e}").contains("too short"));
    let mut bad = frames.clone();
    bad[5][7].x = f64::NAN;
    let e = identify(&bad, 120.0, &fabric, &IdentifyOptions::default()).unwrap_err();
    assert!(format!("{e}").contains("frame 5, marker 7"), "{e}");
    let mut bad = frames;
    bad[2].pop();
    let e = identify(&bad, 120.0, &fabric, &IdentifyOptions::default()).unwrap_err();
    assert!(format!("{e}").contains("frame 2 has 120 markers"), "{e}");
}

/// A capture where nothing moves (a cloth lying still, or a file of copies
/// of one frame) holds no damping to measure: refused, saying why, instead
/// of α = 0 written into a fabric file.
#[test]
fn a_capture_with_no_motion_is_refused() {
    let (frames, fabric) = capture();
    let still = vec![frames[0].clone(); 60];
    let e = identify(&still, 120.0, &fabric, &IdentifyOptions::default()).unwrap_err();
    let e = format!("{e}");
    assert!(e.contains("no motion") && e.contains("m/s"), "{e}");
    // markers jittering by 10 µm: still no motion to speak of
    let mut jitter = still;
    for (k, f) in jitter.iter_mut().enumerate() {
        for (m, p) in f.iter_mut().enumerate() {
            p.x += 1e-5 * (((k * 31 + m * 17) % 7) as f64 - 3.0) / 3.0;
        }
    }
    let e = identify(&jitter, 120.0, &fabric, &IdentifyOptions::default()).unwrap_err();
    assert!(format!("{e}").contains("no motion"), "{e}");
}

/// The whole tool on a C3D file: 0.5 mm noise, 5 % of markers missing at
/// random, the capture tilted by a known rotation and a ball drop captured in
/// the same tilted frame; `garment_sim identify` fills the gaps (Algorithm 1),
/// finds the vertical, and gives back α within 5 %.
#[test]
fn identify_command_on_a_tilted_noisy_c3d_with_missing_markers() {
    use garment_sim::capture::{write_c3d, Capture};
    use nalgebra::{Rotation3, Unit};
    let (frames, fabric) = capture();
    let tilt = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(1.0, 0.3, 0.0)), 0.35);
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let mut gauss = || {
        let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    };
    let n = frames[0].len();
    let mut missing = 0;
    let mut cap_frames = Vec::new();
    let mut rng2 = rand::rngs::StdRng::seed_from_u64(8);
    for f in &frames {
        let mut row = Vec::with_capacity(n);
        for p in f {
            let q = tilt * p + Vector3::new(gauss(), gauss(), gauss()) * 0.0005;
            if rng2.random_bool(0.05) {
                missing += 1;
                row.push(None);
            } else {
                row.push(Some(q));
            }
        }
        cap_frames.push(row);
    }
    let cap = Capture {
        labels: (0..n)
            .map(|k| format!("M{:02}_{:02}", k % 11, k / 11))
            .collect(),
        rate_hz: 120.0,
        units: "mm".into(),
        first_frame: 1,
        frames: cap_frames,
    };
    // a ball dropped from rest, in the same tilted frame
    let ball = Capture {
        labels: vec!["ball".into()],
        rate_hz: 120.0,
        units: "mm".into(),
        first_frame: 1,
        frames: (0..60)
            .map(|k| {
                let t = k as f64 / 120.0;
                Some(tilt * Vector3::new(0.1, 0.2, 2.5 - 0.5 * 9.81 * t * t))
            })
            .map(|p| vec![p])
            .collect(),
    };
    let dir = support::Scratch::new("identify");
    write_c3d(&dir.join("fall.c3d"), &cap).unwrap();
    write_c3d(&dir.join("ball.c3d"), &ball).unwrap();
    let out = support::garment_sim()
        .args(["identify"])
        .arg(dir.join("fall.c3d"))
        .args(["--fabric", "config/fabrics/acrylic.yaml", "--vertical"])
        .arg(dir.join("ball.c3d"))
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    println!("{text}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success());
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/report.json")).unwrap())
            .unwrap();
    let alpha = rep["result"]["measured"][0].as_f64().unwrap();
    assert!(rep["missing_markers_filled"].as_u64().unwrap() as usize == missing && missing > 500);
    let up = rep["vertical_from_ball"].as_array().unwrap();
    let up = Vector3::new(
        up[0].as_f64().unwrap(),
        up[1].as_f64().unwrap(),
        up[2].as_f64().unwrap(),
    );
    let angle = up.angle(&(tilt * Vector3::z())).to_degrees();
    println!(
        "alpha {alpha:.4} (true {}), vertical off by {angle:.4}°, {missing} markers filled",
        fabric.damping.alpha
    );
    assert!(angle < 0.1, "vertical off by {angle}°");
    assert!(
        (alpha / fabric.damping.alpha - 1.0).abs() < 0.05,
        "alpha {alpha}"
    );
    // the measured fabric loads and carries the measured α
    let f = garment_sim::io::load_fabric(&dir.join("out/fabric_measured.yaml")).unwrap();
    assert!((f.damping.alpha - alpha).abs() < 1e-12);
    // the vertical given as a direction instead of a ball drop
    let up = tilt * Vector3::z();
    let out = support::garment_sim()
        .args(["identify"])
        .arg(dir.join("fall.c3d"))
        .args(["--fabric", "config/fabrics/acrylic.yaml", "--up"])
        .arg(format!("{},{},{}", up.x, up.y, up.z))
        .arg("--out")
        .arg(dir.join("out_up"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out_up/report.json")).unwrap())
            .unwrap();
    let alpha_up = rep["result"]["measured"][0].as_f64().unwrap();
    assert!(
        (alpha_up - alpha).abs() < 1e-9,
        "--up {alpha_up} vs ball {alpha}"
    );
    // the thesis' figures: PNG files with something drawn on them
    for name in [
        "mean_speed.png",
        "alpha.png",
        "beta_bend.png",
        "beta_shear.png",
        "beta_tension.png",
    ] {
        let bytes = std::fs::read(dir.join("out").join(name)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name} is not a PNG");
        assert!(
            bytes.len() > 5_000,
            "{name}: {} bytes, nearly empty",
            bytes.len()
        );
    }
}

/// The ground truth through the file path: the noise-free capture written as
/// a CSV file (metres, shortest round-trip decimals: exact) and as a C3D file
/// (float32, the format's best: 3 m stored to about 0.2 µm), read back by
/// `identify_file`. From the CSV (float64): α within 2 % and every β within
/// 15 % (the joint equation-error fit). From the C3D (float32: 0.2 µm steps
/// at 3 m, too coarse for the spring forces on captured shapes): α within
/// 2 % from the ordered fit, β_f and β_c within 15 % from the trajectory fit;
/// β_t reported unresolved, not wrong: a 15 % change of it moves the markers
/// by about 1 nm, far below what float32 positions (or any capture) resolve.
#[test]
fn noise_free_files_give_back_alpha_and_betas() {
    use garment_sim::capture::{write_c3d, write_capture_csv, Capture};
    use garment_sim::lab::identify::identify_file;
    let (frames, fabric) = capture();
    let n = frames[0].len();
    let cap = |units: &str, scale: f64| Capture {
        labels: (0..n)
            .map(|k| format!("M{:02}_{:02}", k % 11, k / 11))
            .collect(),
        rate_hz: 120.0,
        units: units.into(),
        first_frame: 1,
        frames: frames
            .iter()
            .map(|f| f.iter().map(|p| Some(*p * scale)).collect())
            .collect(),
    };
    let dir = support::Scratch::new("identify_truth");
    let csv = dir.join("free_fall.csv");
    write_capture_csv(&csv, &cap("m", 1.0)).unwrap();
    let c3d = dir.join("free_fall.c3d");
    write_c3d(&c3d, &cap("mm", 1.0)).unwrap();
    let d = fabric.damping;
    let opts = IdentifyOptions::default();
    let from_csv = identify_file(&csv, None, &fabric, &opts, false)
        .unwrap()
        .result;
    let from_c3d = identify_file(&c3d, None, &fabric, &opts, false)
        .unwrap()
        .result;
    for (what, r) in [("CSV", &from_csv), ("C3D", &from_c3d)] {
        let m = r.measured;
        println!(
            "{what}, no noise: alpha {:.4} (true {}), beta_f {:.3e} ({:.1e}), beta_c {:.3e} ({:.1e}), beta_t {:.3e} ({:.1e}); resolved {:?}",
            m[0], d.alpha, m[1], d.beta_bend, m[2], d.beta_shear, m[3], d.beta_tension, r.resolved
        );
        assert!(
            (m[0] / d.alpha - 1.0).abs() < 0.02,
            "{what}: alpha {}",
            m[0]
        );
    }
    let m = from_csv.measured;
    assert_eq!(from_csv.resolved, [true; 4]);
    for (got, want) in [
        (m[1], d.beta_bend),
        (m[2], d.beta_shear),
        (m[3], d.beta_tension),
    ] {
        assert!((got / want - 1.0).abs() < 0.15, "{got:e} vs {want:e}");
    }
    let t = from_c3d
        .trajectory
        .as_ref()
        .expect("the C3D needs the trajectory fit");
    println!(
        "C3D trajectory fit: frames {:?}, rms {:.2e} m, 15 % moves the markers by {:?} m",
        t.frames, t.rms_m, t.effect_15pc_m
    );
    assert_eq!(from_c3d.resolved, [true, true, true, false]);
    let m = from_c3d.measured;
    for (got, want) in [(m[1], d.beta_bend), (m[2], d.beta_shear)] {
        assert!((got / want - 1.0).abs() < 0.15, "C3D: {got:e} vs {want:e}");
    }
    assert!(m[3].is_nan());
    // β_t is below resolution, not missed: its 15 % moves the markers by less
    // than a hundredth of what β_c's does, and less than the fit's residual
    let (dt, dc) = (t.effect_15pc_m[3], t.effect_15pc_m[2]);
    assert!(
        dt < 0.01 * dc && dt < t.rms_m,
        "{dt:e} vs {dc:e}, rms {:e}",
        t.rms_m
    );
}

/// A capture whose marker jumps to 1e30 m (a corrupt sample), or whose
/// coordinates are millimetres written as metres, is refused when it is
/// read, naming the file, the marker (label), the frame (its number in the
/// file) and the bound, MAX_CAPTURE_DISTANCE, instead of an error about
/// the viscous window (one frame at 1e32 m/s) or a fit that never ends;
/// `identify` on frames in memory names the frame and marker index.
#[test]
fn a_capture_beyond_the_capture_volume_is_refused_naming_file_marker_and_bound() {
    use garment_sim::capture::{write_capture_csv, Capture};
    use garment_sim::limits::MAX_CAPTURE_DISTANCE;
    let (frames, fabric) = capture();
    let n = frames[0].len();
    let cap = |f: &dyn Fn(usize, usize, Vector3<f64>) -> Vector3<f64>| Capture {
        labels: (0..n)
            .map(|k| format!("M{:02}_{:02}", k % 11, k / 11))
            .collect(),
        rate_hz: 120.0,
        units: "m".into(),
        first_frame: 1,
        frames: frames
            .iter()
            .enumerate()
            .map(|(k, fr)| {
                fr.iter()
                    .enumerate()
                    .map(|(m, p)| Some(f(k, m, *p)))
                    .collect()
            })
            .collect(),
    };
    let dir = support::Scratch::new("identify_far");
    let bound = format!("{MAX_CAPTURE_DISTANCE} m");
    // marker 47 (M03_04) at x = 1e30 m from index 60 on (file frame 61)
    let jump = dir.join("jump.csv");
    write_capture_csv(
        &jump,
        &cap(&|k, m, p| {
            if m == 47 && k >= 60 {
                Vector3::new(1e30, p.y, p.z)
            } else {
                p
            }
        }),
    )
    .unwrap();
    // every coordinate in millimetres, the file saying metres
    let mm = dir.join("mm.csv");
    write_capture_csv(&mm, &cap(&|_, _, p| p * 1000.0)).unwrap();
    for (file, needles) in [
        (
            &jump,
            vec![
                "jump.csv",
                "marker 47 (\"M03_04\")",
                "frame 61",
                "1e30",
                &bound,
                "MAX_CAPTURE_DISTANCE",
            ],
        ),
        (
            &mm,
            vec![
                "mm.csv",
                "marker 0 (\"M00_00\")",
                "frame 1 ",
                &bound,
                "MAX_CAPTURE_DISTANCE",
            ],
        ),
    ] {
        let out = support::garment_sim()
            .arg("identify")
            .arg(file)
            .args(["--fabric", "config/fabrics/acrylic.yaml", "--out"])
            .arg(dir.join("out"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        for n in needles {
            assert!(err.contains(n), "{} lacks {n:?}: {err}", file.display());
        }
        assert!(!err.contains("viscous window"), "{err}");
    }
    // the same bound on frames given in memory
    let mut far = frames;
    far[60][47].x = 1e30;
    let e = identify(&far, 120.0, &fabric, &IdentifyOptions::default()).unwrap_err();
    let e = format!("{e}");
    assert!(
        e.contains("frame 60, marker 47") && e.contains(&bound),
        "{e}"
    );
}
