//! Cantilever bending test (issue 24): Peirce's cantilever on every shipped
//! fabric, and a clamped strip at rest against the elastica of a linearly
//! elastic strip under its own weight, solved here independently.

mod support;
use garment_sim::fabric::kes::GF_CM2_PER_CM;
use garment_sim::fabric::law::{Law, LawState};
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

/// The bound: B within 5 % at 1 cm, hysteresis on. Not met, and
/// not reachable by the model's laws (docs/lab.md, cantilever): the
/// continuum slide of each fabric's hysteretic law reads 7 … 95 % above its
/// KES B (the test above; a strip loaded from flat follows the loading
/// branch, up to 2HB/2 above Bκ in moment), and the simulated slide
/// converges to that, not to B. At 1 cm the grid adds its own error: the
/// 41.5° overhang (2.4–4.2 cm) spans 2–4 rows, the elastic strip reads 5–18 %
/// high (a strip of n free rows deflects `[n(n+1)/(n+½)²]²` of the continuum,
/// the discrete clamp's test above) and the hysteretic one 20–36 points above
/// the continuum slide (wool tropical +48.8 % against +22.8 %).
#[test]
#[ignore = "fails: B +40 … +126 % at 1 cm; the hysteretic laws' own continuum slide reads +7 … +95 % (docs/lab.md)"]
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

/// κ at which the law, from memory `st`, gives the moment `m` (the law is
/// increasing in κ): Newton safeguarded by a bracket grown from `guess`.
fn curvature_for_moment(law: &Law, st: &LawState, m: f64, guess: f64, scale: f64) -> f64 {
    let f = |k: f64| law.eval(st, k).0 - m;
    let (mut lo, mut hi) = (guess - scale, guess + scale);
    while f(lo) > 0.0 {
        lo -= 2.0 * (hi - lo);
    }
    while f(hi) < 0.0 {
        hi += 2.0 * (hi - lo);
    }
    let mut k = guess.clamp(lo, hi);
    for _ in 0..100 {
        let (v, d) = law.eval(st, k);
        let r = v - m;
        if r.abs() <= 1e-13 * (m.abs() + 1e-9) {
            return k;
        }
        if r > 0.0 {
            hi = k;
        } else {
            lo = k;
        }
        let newton = k - r / d;
        k = if d > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo < 1e-14 * scale {
            break;
        }
    }
    k
}

/// Peirce's cantilever as a continuum: an inextensible strip whose bending
/// moment per width follows `law` (with its hysteretic memory, one per
/// material point, flat and unloaded on the platform) slid quasi-statically
/// over the edge in steps of `du`. At every overhang the strip is at rest:
/// `M' = −w (l − s) cos θ`, `θ' = κ` with `law(κ; memory) = M`, `θ(0) = 0`,
/// `M(l) = 0` (Heun's rule on the material points, bisection on the clamp
/// moment), then each point's memory is advanced to its curvature (the point
/// just past the edge in small increments from flat: the Dahl operator's
/// monotone path). Returns the overhang at which the tip line falls 41.5°
/// below the horizontal.
fn continuous_slide_overhang(law: &Law, w: f64, du: f64) -> f64 {
    let mut st = vec![LawState::at(0.0)];
    let mut kappa = vec![0.0];
    let scale = 100.0; // 1/m: a curvature of 1 cm⁻¹
    let mut prev_angle = 0.0;
    for k in 1.. {
        // material point i from the tip (u = i du); overhang l = k du; node
        // j along the overhang from the edge is material point k − j
        st.push(LawState::at(0.0));
        kappa.push(0.0);
        let l = k as f64 * du;
        let profile = |m0: f64, kap: &mut Vec<f64>| -> (f64, f64, f64) {
            let (mut th, mut m, mut x, mut z) = (0.0f64, m0, 0.0f64, 0.0f64);
            let mut kj = curvature_for_moment(law, &st[k], m, kap[k], scale);
            kap[k] = kj;
            for j in 0..k {
                let (s0, s1) = (j as f64 * du, (j + 1) as f64 * du);
                let i1 = k - j - 1;
                let th_p = th + du * kj;
                let m_p = m - du * w * (l - s0) * th.cos();
                let k_p = curvature_for_moment(law, &st[i1], m_p, kap[i1], scale);
                let th1 = th + 0.5 * du * (kj + k_p);
                let m1 = m - 0.5 * du * w * ((l - s0) * th.cos() + (l - s1) * th_p.cos());
                let k1 = curvature_for_moment(law, &st[i1], m1, k_p, scale);
                x += 0.5 * du * (th.cos() + th1.cos());
                z -= 0.5 * du * (th.sin() + th1.sin());
                th = th1;
                m = m1;
                kj = k1;
                kap[i1] = k1;
            }
            (m, x, z)
        };
        let (mut lo, mut hi) = (0.0, w * l * l / 2.0);
        // κ of the last solve: the starting guesses of the inversions
        let mut kap = std::mem::take(&mut kappa);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if profile(mid, &mut kap).0 < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let (_, x, z) = profile(0.5 * (lo + hi), &mut kap);
        // advance the memories: the edge's point from flat in small steps
        for n in 1..=64 {
            law.commit(&mut st[k], kap[k] * n as f64 / 64.0);
        }
        for i in 0..k {
            law.commit(&mut st[i], kap[i]);
        }
        kappa = kap;
        let angle = (-z).atan2(x).to_degrees();
        if angle >= PEIRCE_ANGLE_DEG {
            let t = (PEIRCE_ANGLE_DEG - prev_angle) / (angle - prev_angle);
            return (k as f64 - 1.0 + t) * du;
        }
        prev_angle = angle;
    }
    unreachable!()
}

/// The continuum slide's reading of B, relative to the fabric's B, for the
/// law of one direction with or without its hysteresis.
fn continuum_reading(
    f: &garment_sim::fabric::Fabric,
    dir: Direction,
    hysteresis: bool,
    du: f64,
) -> f64 {
    let (b, _) = fabric_bending(f, dir).unwrap();
    let law = f.dir(dir == Direction::Weft).bending;
    let law = if hysteresis {
        law
    } else {
        law.without_hysteresis()
    };
    let w = f.areal_mass * 9.81;
    let l = continuous_slide_overhang(&law, w, du);
    w * (l / 2.0).powi(3) / (b * GF_CM2_PER_CM) - 1.0
}

/// The continuum slide above reads back B for the elastic law (the elastica
/// puts the tip line of an overhang 2c at 41.49°), which checks the
/// integrator and its path; with the fabric's hysteresis it reads the
/// model's own quasi-static cantilever B, 7 … 95 % above the KES B: a strip
/// loaded from flat follows the loading branch, stiffer than B by up to
/// 2HB/2 in moment. These are the figures the simulated slide converges to
/// with hysteresis (next tests), so no grid can bring a hysteretic strip
/// within 5 % of the KES B where 2HB is large against the clamp's moment.
#[test]
fn the_continuum_slide_reads_b_for_the_elastic_law_and_more_with_hysteresis() {
    let mut report = String::new();
    for path in support::shipped_fabrics() {
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let f = garment_sim::io::load_fabric(&path).unwrap();
        for dir in Direction::ALL {
            let (b, hb) = fabric_bending(&f, dir).unwrap();
            let elastic = continuum_reading(&f, dir, false, 2e-4);
            let hyst = continuum_reading(&f, dir, true, 2e-4);
            report.push_str(&format!(
                "{stem} {} (B {b:.4}, 2HB {hb:.4}): elastic law {:+.3} %, with hysteresis {:+.2} %\n",
                dir.name(),
                100.0 * elastic,
                100.0 * hyst
            ));
            assert!(elastic.abs() < 1e-3, "{report}");
            // the loading branch is stiffer: more so the larger 2HB against B
            assert!(hyst > 0.05 && hyst < 1.0, "{report}");
        }
    }
    // the material step: halving it moves the hysteretic reading by < 0.05 %
    let f = garment_sim::io::load_fabric(std::path::Path::new(
        "config/fabrics/cotton_broadcloth.yaml",
    ))
    .unwrap();
    let (a, b) = (
        continuum_reading(&f, Direction::Warp, true, 2e-4),
        continuum_reading(&f, Direction::Warp, true, 1e-4),
    );
    assert!((a - b).abs() < 5e-4, "{a} vs {b}");
    println!("{report}");
}

fn slide(f: &garment_sim::fabric::Fabric, opt: &CantileverOptions) -> f64 {
    run(f, Direction::Warp, opt, &mut |_, _| {})
        .unwrap()
        .relative_error
}

/// A row's release is a step load; with the fabric's own damping the
/// overhang swings, each swing wears the hysteretic memories down, and the
/// reading depends on the step (wool tropical at 1 cm: +20.6 % at 2 ms,
/// +45.6 % at 10 ms). Run quasi-statically (the default: the overhang's
/// lowest mode critically damped in bending) the reading at rest is the same
/// for any step, slide speed and air damping, and the elastic strip's is
/// unchanged.
#[test]
fn the_quasi_static_slide_reads_the_same_for_any_step_speed_and_air_damping() {
    let path = std::path::Path::new("config/fabrics/wool_tropical.yaml");
    let f = garment_sim::io::load_fabric(path).unwrap();
    let base = CantileverOptions::default();
    let mut windy = f.clone();
    windy.damping.alpha *= 4.0;
    let reference = slide(&f, &base);
    let mut report = format!(
        "quasi-static, dt 2 ms, 2 mm/s: {:+.2} %\n",
        100.0 * reference
    );
    for (name, fabric, opt) in [
        (
            "dt 10 ms",
            &f,
            CantileverOptions {
                dt: 0.01,
                ..base.clone()
            },
        ),
        (
            "dt 0.5 ms",
            &f,
            CantileverOptions {
                dt: 5e-4,
                ..base.clone()
            },
        ),
        (
            "5 mm/s",
            &f,
            CantileverOptions {
                slide_speed: 5e-3,
                ..base.clone()
            },
        ),
        ("air damping × 4", &windy, base.clone()),
    ] {
        let e = slide(fabric, &opt);
        report.push_str(&format!("quasi-static, {name}: {:+.2} %\n", 100.0 * e));
        assert!((e - reference).abs() < 0.01, "{report}");
    }
    // the fabric's own damping: the swings make the step matter
    let own = CantileverOptions {
        quasi_static: false,
        ..base.clone()
    };
    let (a, b) = (
        slide(&f, &own),
        slide(
            &f,
            &CantileverOptions {
                dt: 0.01,
                ..own.clone()
            },
        ),
    );
    report.push_str(&format!(
        "fabric's damping: dt 2 ms {:+.2} %, dt 10 ms {:+.2} %\n",
        100.0 * a,
        100.0 * b
    ));
    assert!((a - b).abs() > 0.1, "{report}");
    // without hysteresis the damping changes nothing at rest
    let elastic = CantileverOptions {
        hysteresis: false,
        ..base.clone()
    };
    let (c, d) = (
        slide(&f, &elastic),
        slide(
            &f,
            &CantileverOptions {
                quasi_static: false,
                ..elastic
            },
        ),
    );
    report.push_str(&format!(
        "no hysteresis: quasi-static {:+.3} %, fabric's damping {:+.3} %\n",
        100.0 * c,
        100.0 * d
    ));
    assert!((c - d).abs() < 2e-3, "{report}");
    println!("{report}");
}

/// With hysteresis the simulated quasi-static slide converges, as the grid is
/// refined, to the continuum slide of the same law (solved above, with a
/// memory per material point): for every shipped fabric the gap at least
/// halves from 1 to 0.5 cm, and wool tropical's goes on to 0.25 cm, where it
/// is under 5 points (docs/lab.md has every fabric's sequence).
#[test]
fn the_hysteretic_slide_converges_to_the_continuum_slide() {
    let mut report = String::new();
    for path in support::shipped_fabrics() {
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let f = garment_sim::io::load_fabric(&path).unwrap();
        let want = continuum_reading(&f, Direction::Warp, true, 2e-4);
        report.push_str(&format!(
            "{stem} warp: continuum slide {:+.2} %;",
            100.0 * want
        ));
        let spacings: &[f64] = if stem == "wool_tropical" {
            &[0.01, 0.005, 0.0025]
        } else {
            &[0.01, 0.005]
        };
        let mut gaps = Vec::new();
        for &spacing in spacings {
            let e = slide(
                &f,
                &CantileverOptions {
                    spacing,
                    ..Default::default()
                },
            );
            gaps.push(e - want);
            report.push_str(&format!(
                " {} cm {:+.2} % (gap {:+.2})",
                100.0 * spacing,
                100.0 * e,
                100.0 * (e - want)
            ));
        }
        report.push('\n');
        assert!(gaps.iter().all(|&g| g > 0.0), "{report}");
        assert!(gaps.windows(2).all(|g| g[1] < 0.5 * g[0]), "{report}");
        if gaps.len() == 3 {
            assert!(gaps[2] < 0.05, "{report}");
        }
    }
    println!("{report}");
}

/// The command writes its report and two plots, says which bending damping
/// it ran with (quasi-static by default, the fabric's with
/// `--fabric-damping`), and refuses a bad option naming it.
#[test]
fn cantilever_command_reports_its_damping_and_writes_its_plots() {
    let out = support::Scratch::new("cantilever");
    let faille = "config/fabrics/polyester_faille.yaml";
    let f = garment_sim::io::load_fabric(std::path::Path::new(faille)).unwrap();
    let (stdout, rep) = support::lab_report("cantilever", &[faille, "--dir", "weft"], &out);
    assert!(stdout.contains("quasi-static"), "{stdout}");
    let c = rep["fabric_bending_length_m"].as_f64().unwrap();
    let beta = rep["beta_bend_s"].as_f64().unwrap();
    assert!(
        (beta + quasi_static_bend_damping(c, 9.81)).abs() < 1e-12,
        "{beta}"
    );
    // ω₁ = (1.8751²/4) √(g/c): the faille's c = 1.2 cm gives about 0.08 s
    assert!(beta < -0.07 && beta > -0.09, "{beta}");
    let b = rep["flexural_rigidity_gf_cm2_cm"].as_f64().unwrap();
    assert!(b > rep["fabric_b_gf_cm2_cm"].as_f64().unwrap(), "{b}");
    for png in ["strip.png", "readings.png"] {
        let bytes = std::fs::read(out.join(png)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    }
    let (stdout, rep) = support::lab_report("cantilever", &[faille, "--fabric-damping"], &out);
    assert!(stdout.contains("the fabric's"), "{stdout}");
    assert_eq!(rep["beta_bend_s"].as_f64().unwrap(), f.damping.beta_bend);
    let o = support::garment_sim()
        .args(["cantilever", faille, "--dt", "0", "--out"])
        .arg(&*out)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("dt"));
}
