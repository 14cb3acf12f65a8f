//! Damping identification (thesis ch. 5) on a synthetic capture of
//! `free_fall.yaml` (known α, β), sampled at 120 Hz on the 11 × 11 grid.

use garment_sim::lab::identify::{identify, sample_capture, IdentifyOptions};
use garment_sim::scene::{Overrides, Scene};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use std::path::Path;

fn capture() -> (Vec<Vec<Vector3<f64>>>, garment_sim::fabric::Fabric) {
    let sc = Scene::load(Path::new("config/scenes/free_fall.yaml")).unwrap();
    let mut sim = sc.build(&Overrides::default()).unwrap();
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
    assert!(
        (id.alpha.mean / truth.alpha - 1.0).abs() < 0.02,
        "alpha {}",
        id.alpha.mean
    );
    assert!(id.alpha.error_decrease > 0.5);
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
        "0.5 mm noise: alpha {:.4} ± {:.3}",
        id.alpha.mean, id.alpha.std
    );
    assert!(
        (id.alpha.mean / fabric.damping.alpha - 1.0).abs() < 0.05,
        "alpha {}",
        id.alpha.mean
    );
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
