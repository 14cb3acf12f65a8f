//! Cantilever bending test (issue 24): Peirce's cantilever on every shipped
//! fabric, and a clamped strip at rest against the elastica of a linearly
//! elastic strip under its own weight, solved here independently.

mod support;
use garment_sim::fabric::kes::GF_CM2_PER_CM;
use garment_sim::lab::cantilever::*;
use garment_sim::lab::kes_lab::Direction;

/// The elastica of a clamped, inextensible, linearly elastic strip of length
/// `l` under its own weight: `θ'' = −(w/B)(l − s) cos θ`, `θ(0) = 0`,
/// `θ'(l) = 0` (θ the angle below the horizontal, `w/B` weight per area over
/// flexural rigidity per width). RK4 on (θ, θ', x, z) over `n` steps; the
/// clamp curvature θ'(0) found by bisection so that θ'(l) = 0. Returns the
/// centreline (x, z) at the `n + 1` nodes, z downward negative.
fn elastica(l: f64, w_over_b: f64, n: usize) -> Vec<(f64, f64)> {
    let shoot = |m0: f64, keep: bool| -> (f64, Vec<(f64, f64)>) {
        let ds = l / n as f64;
        let f = |s: f64, y: [f64; 4]| -> [f64; 4] {
            [
                y[1],
                -w_over_b * (l - s) * y[0].cos(),
                y[0].cos(),
                -y[0].sin(),
            ]
        };
        let mut y = [0.0, m0, 0.0, 0.0];
        let mut path = vec![(0.0, 0.0)];
        for k in 0..n {
            let s = k as f64 * ds;
            let k1 = f(s, y);
            let add = |a: [f64; 4], b: [f64; 4], h: f64| {
                [
                    a[0] + h * b[0],
                    a[1] + h * b[1],
                    a[2] + h * b[2],
                    a[3] + h * b[3],
                ]
            };
            let k2 = f(s + ds / 2.0, add(y, k1, ds / 2.0));
            let k3 = f(s + ds / 2.0, add(y, k2, ds / 2.0));
            let k4 = f(s + ds, add(y, k3, ds));
            for c in 0..4 {
                y[c] += ds / 6.0 * (k1[c] + 2.0 * k2[c] + 2.0 * k3[c] + k4[c]);
            }
            if keep {
                path.push((y[2], y[3]));
            }
        }
        (y[1], path)
    };
    // θ'(l) grows with θ'(0): bracket [0, w l²/(2B)] (the small-deflection
    // clamp curvature, an upper bound since cos θ ≤ 1 shortens the lever)
    let (mut lo, mut hi) = (0.0, w_over_b * l * l / 2.0);
    assert!(shoot(lo, false).0 < 0.0 && shoot(hi, false).0 >= -1e-12);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if shoot(mid, false).0 < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    shoot(0.5 * (lo + hi), true).1
}

#[test]
fn elastica_of_the_test_matches_the_small_deflection_closed_form() {
    // tip deflection of a uniformly loaded cantilever: w l⁴ / (8 B)
    let (l, wb) = (0.1, 0.5);
    let p = elastica(l, wb, 2000);
    let tip = -p.last().unwrap().1;
    let want = wb * l.powi(4) / 8.0;
    assert!((tip - want).abs() < 1e-3 * want, "{tip} vs {want}");
    // and Peirce's relation at 41.5°: the overhang 2c puts the tip line there
    // (Peirce's formula is an approximation of the elastica: within 1 %)
    let c: f64 = 0.02;
    let p = elastica(2.0 * c, 1.0 / c.powi(3), 4000);
    let (x, z) = *p.last().unwrap();
    let theta = (-z).atan2(x).to_degrees();
    assert!(
        (theta - PEIRCE_ANGLE_DEG).abs() < 0.01 * PEIRCE_ANGLE_DEG,
        "{theta}°"
    );
}

/// Tip deflection of the simulated clamped strip against the elastica.
fn elastica_gap(
    path: &std::path::Path,
    dir: Direction,
    spacing: f64,
    overhang_in_c: f64,
    symmetric_hinges: bool,
) -> (f64, f64, f64) {
    let f = garment_sim::io::load_fabric(path).unwrap();
    let (b, _) = fabric_bending(&f, dir).unwrap();
    let opt = CantileverOptions {
        spacing,
        hysteresis: false,
        rest_speed: 1e-6,
        symmetric_hinges,
        ..Default::default()
    };
    let w = f.areal_mass * 9.81;
    let b_si = b * GF_CM2_PER_CM;
    let c = (b_si / w).cbrt();
    let (profile, l) = clamped_strip(&f, dir, overhang_in_c * c, &opt).unwrap();
    let sim_tip = -profile.last().unwrap()[1];
    let want = -elastica(l, w / b_si, 4000).last().unwrap().1;
    (sim_tip, want, l)
}

/// Without hysteresis the bending law is elastic, and its slope is the
/// fabric's B (its elastic part is the middle of the KES loop, ±2HB/2 about
/// it); with hysteresis a strip loaded from flat follows the loading branch,
/// B κ + 2HB/2 once its curvature has run a few memory lengths, which is not
/// the linearly elastic strip of the elastica.
#[test]
fn clamped_strip_at_rest_matches_the_elastica() {
    let mut report = String::new();
    for path in support::shipped_fabrics() {
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        for dir in Direction::ALL {
            // the overhang of the 41.5° reading, and a shorter one
            for k in [1.0, 2.0] {
                let (sim, want, l) = elastica_gap(&path, dir, 0.002, k, true);
                let err = (sim - want) / want;
                report.push_str(&format!(
                    "{stem} {} overhang {:.2} cm: tip deflection {:.3} mm, elastica {:.3} mm ({:+.2} %)\n",
                    dir.name(),
                    100.0 * l,
                    1e3 * sim,
                    1e3 * want,
                    100.0 * err
                ));
                assert!(err.abs() < 0.02, "{report}");
            }
        }
    }
    println!("{report}");
}

/// The grid's single skewed hinge per edge lets the strip twist into the
/// diagonal fold that costs no bending: the same strip deflects far more
/// than the elastica (which is why the cantilever uses hinge pairs).
#[test]
fn single_skewed_hinges_make_the_strip_droop() {
    let path = std::path::Path::new("config/fabrics/wool_tropical.yaml");
    let (sim, want, _) = elastica_gap(path, Direction::Warp, 0.0025, 1.0, false);
    assert!(sim > 1.5 * want, "{sim} vs elastica {want}");
    let (sim, want, _) = elastica_gap(path, Direction::Warp, 0.0025, 1.0, true);
    assert!((sim - want).abs() < 0.02 * want, "{sim} vs elastica {want}");
}

/// Where the discrete clamp sits, against a closed form. A strip of hinges
/// (curvature lumped at each vertex over its spacing) pinned up to a row
/// with `n` free rows beyond, under a uniform load lumped on its vertices,
/// has at small deflections the tip deflection
/// `Σ_{m=1..n} (w h² m²/2)(h/B)(m h) = w h⁴ n²(n+1)²/(8B)`: the moment at
/// each hinge is exact, the sum is the midpoint rule of the continuum's
/// `∫ M (L − x) / B dx`. Against the continuum clamped half a spacing inside
/// the last pinned row (overhang `L = (n + ½) h`, `w L⁴ / (8B)`) that is the
/// factor `[n(n+1)/(n+½)²]²`, 0.79 … 0.98 for n = 1 … 4: the error is second
/// order, and it is why the slide at 1 cm, whose 41.5° overhang spans 2–4
/// rows, reads B high without hysteresis. (Clamped at the last pinned row
/// instead, the factor would be `[(n+1)/n]²`, first order.) A fabric 700
/// times stiffer in bending (47 gf·cm²/cm) keeps the tip within 0.5 % of the
/// overhang below the clamp.
#[test]
fn the_discrete_clamp_is_half_a_spacing_inside_the_last_pinned_row() {
    let path = std::path::Path::new("config/fabrics/wool_tropical.yaml");
    let f = support::with_bending_scaled(&garment_sim::io::load_fabric(path).unwrap(), 700.0);
    let (b, _) = fabric_bending(&f, Direction::Warp).unwrap();
    let (w, b_si) = (f.areal_mass * 9.81, b * GF_CM2_PER_CM);
    let h = 0.01;
    let opt = CantileverOptions {
        spacing: h,
        hysteresis: false,
        rest_speed: 1e-9,
        symmetric_hinges: true,
        ..Default::default()
    };
    let mut report = String::new();
    for n in 1..=4u32 {
        let nf = n as f64;
        let (profile, l) = clamped_strip(&f, Direction::Warp, (nf + 0.5) * h, &opt).unwrap();
        assert!((l - (nf + 0.5) * h).abs() < 1e-12);
        let tip = -profile.last().unwrap()[1];
        let continuum = w * l.powi(4) / (8.0 * b_si);
        let want = (nf * (nf + 1.0) / (nf + 0.5).powi(2)).powi(2);
        report.push_str(&format!(
            "n = {n}: tip {tip:.4e} m, continuum {continuum:.4e} m, ratio {:.4} (closed form {want:.4})\n",
            tip / continuum
        ));
        assert!(tip < 5e-3 * l, "{report}");
        assert!((tip / continuum - want).abs() < 0.003 * want, "{report}");
    }
    println!("{report}");
}

/// Without hysteresis (a linearly elastic law of slope B) the slide reads
/// back the fabric's B as the grid is refined: within 1 % at 0.25 cm, for
/// every shipped fabric and both directions.
#[test]
fn cantilever_converges_to_the_fabric_b_without_hysteresis() {
    let mut report = String::new();
    let mut worst = 0.0f64;
    for path in support::shipped_fabrics() {
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let f = garment_sim::io::load_fabric(&path).unwrap();
        for dir in Direction::ALL {
            let opt = CantileverOptions {
                spacing: 0.0025,
                hysteresis: false,
                ..Default::default()
            };
            let rep = run(&f, dir, &opt, &mut |_, _| {}).unwrap();
            report.push_str(&format!(
                "{stem} {}: c {:.3} cm, B {:.4} vs fabric {:.4} gf·cm²/cm ({:+.2} %)\n",
                dir.name(),
                100.0 * rep.bending_length_m,
                rep.flexural_rigidity_gf_cm2_cm,
                rep.fabric_b_gf_cm2_cm,
                100.0 * rep.relative_error
            ));
            worst = worst.max(rep.relative_error.abs());
            // the readings bracket 41.5° and the reading is at rest
            let n = rep.readings.len();
            assert!(n >= 2 && rep.readings[n - 2].tip_angle_deg < PEIRCE_ANGLE_DEG);
            assert!(rep.readings[n - 1].tip_angle_deg >= PEIRCE_ANGLE_DEG);
            assert!(rep.largest_rest_speed_m_s < opt.rest_speed);
        }
    }
    println!("{report}");
    assert!(worst < 0.01, "{report}");
}

/// The bound: B within 5 % at 1 cm, hysteresis on. Not met (see
/// docs/lab.md, cantilever): at 1 cm the 41.5° overhang of these fabrics
/// (2.4–4.2 cm) spans 2–4 rows, and the discrete strip reads B 5–18 % high
/// without hysteresis (0.1–0.7 % at 0.25 cm): a strip of n free rows deflects
/// `[n(n+1)/(n+½)²]²` of the continuum (the discrete clamp's test above), so
/// meeting the bound needs a bending element of higher order along the
/// thread, not a different reading; the KES loop's half width
/// 2HB/2 adds to the moment of a strip loaded from flat (the loading branch
/// Bκ + 2HB/2), +14 … +74 % at 1 cm, +0.6 … +50 % at 0.25 cm (cotton
/// broadcloth, whose 2HB exceeds its B).
#[test]
#[ignore = "fails: B +14 … +74 % at 1 cm (discretisation and the KES loop's 2HB), see docs/lab.md"]
fn every_shipped_fabric_gives_back_its_b_at_1_cm() {
    let mut report = String::new();
    let mut worst = 0.0f64;
    for path in support::shipped_fabrics() {
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let f = garment_sim::io::load_fabric(&path).unwrap();
        for dir in Direction::ALL {
            let rep = run(&f, dir, &CantileverOptions::default(), &mut |_, _| {}).unwrap();
            report.push_str(&format!(
                "{stem} {}: overhang {:.2} cm, c {:.3} cm, B {:.4} vs fabric {:.4} gf·cm²/cm ({:+.1} %)\n",
                dir.name(),
                100.0 * rep.overhang_m,
                100.0 * rep.bending_length_m,
                rep.flexural_rigidity_gf_cm2_cm,
                rep.fabric_b_gf_cm2_cm,
                100.0 * rep.relative_error
            ));
            worst = worst.max(rep.relative_error.abs());
        }
    }
    println!("{report}");
    assert!(worst < 0.05, "{report}");
}
