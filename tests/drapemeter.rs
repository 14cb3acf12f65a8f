//! Drapemeter (thesis §2.3.2, Chu/Cusick) on a clipped circular grid.

mod support;
use garment_sim::cloth::{Border, Cloth, HingeLayout, Outline, PanelSpec, REMOVED};
use garment_sim::fabric::Fabric;
use garment_sim::lab::drapemeter::{run, ClampEdge, DrapeOptions};
use nalgebra::Isometry3;
use std::path::Path;

#[test]
fn drape_coefficient_falls_with_softer_bending() {
    let wool =
        garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml")).unwrap();
    let opt = DrapeOptions::default(); // 30 cm on 18 cm, 1 cm grid
    let mut dcs = Vec::new();
    for k in [10.0, 1.0, 0.25] {
        let f = support::with_bending_scaled(&wool, k);
        let (rep, cloth, _) = run(&f, &opt, &mut |_, _| {}).unwrap();
        println!(
            "B × {k}: DC {:.1} % (flat-normalised {:.1} %), {} nodes at {:?}, settled at {:?} s",
            100.0 * rep.drape_coefficient,
            100.0 * rep.drape_coefficient_flat_normalised,
            rep.nodes,
            rep.node_angles_deg,
            rep.settled_at_s
        );
        assert!(rep.settled_at_s.is_some(), "B × {k} did not settle");
        assert!(rep.drape_coefficient > 0.0 && rep.drape_coefficient < 1.0);
        assert!(rep.drape_coefficient < rep.flat_specimen_fraction);
        // the cloth hangs: its lowest point is well below the disk, but no
        // lower than the hanging length
        assert!(
            rep.drop_m > 0.02 && rep.drop_m < 0.061,
            "drop {}",
            rep.drop_m
        );
        assert!(cloth
            .positions()
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite())));
        // folds: a stiff specimen makes few, a limp one several (Cusick:
        // 3–12). B × 10 stays within the node prominence (10 % of the hanging
        // length, 6 mm): shallow waves, the shadow radius 14.5–14.9 cm
        assert!(rep.nodes <= 12, "{} nodes", rep.nodes);
        if k <= 1.0 {
            assert!(rep.nodes >= 2, "{} nodes", rep.nodes);
        }
        assert_eq!(rep.node_angles_deg.len(), rep.nodes);
        dcs.push((k, rep.drape_coefficient, rep.nodes));
    }
    // the measured fabric: Matsudaira 2015 gives 49.8 % and 5 nodes. The
    // simulation reads 58.7 % and 12 nodes at 1 cm (55.9 % and 8 nodes with
    // the grid's single skewed hinge, whose free diagonal fold let the
    // specimen fold more). Not a validation: the file's shear is a
    // placeholder (acrylic's G) and the coefficient depends strongly on it
    // (G / 10: 39.9 %), and folds may pass through each other (no
    // self-collision). Bound: 10 points.
    assert!((dcs[1].1 - 0.498).abs() < 0.10, "{dcs:?}");
    // stiffer drapes less, limper drapes more, by clear margins
    assert!(dcs[0].1 > dcs[1].1 + 0.08, "{dcs:?}");
    assert!(dcs[1].1 > dcs[2].1 + 0.05, "{dcs:?}");
    assert!(dcs[0].2 <= dcs[2].2, "{dcs:?}");
}

fn with_mass_scaled(f: &Fabric, k: f64) -> Fabric {
    let mut file = f.file.clone();
    file.areal_mass_mg_per_cm2 *= k;
    garment_sim::io::fabric_from_file(file, Path::new("config/fabrics")).unwrap()
}

/// At fixed rigidity a heavier specimen drapes more: gravity against bending
/// (and shear) sets the shape, through the bending length `(B / w)^(1/3)`
/// (Cusick 1968). Areal mass × 0.5, × 1, × 2 with every law unchanged; the
/// 1 cm grid as in the rigidity test above.
#[test]
fn drape_coefficient_falls_with_weight() {
    let wool =
        garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml")).unwrap();
    let opt = DrapeOptions::default();
    let mut dcs = Vec::new();
    for k in [0.5, 1.0, 2.0] {
        let f = with_mass_scaled(&wool, k);
        // the laws are those of the measured fabric: only the weight moved
        assert_eq!(f.warp.bending.elastic, wool.warp.bending.elastic);
        assert_eq!(f.shear.elastic, wool.shear.elastic);
        assert!((f.areal_mass - k * wool.areal_mass).abs() < 1e-12);
        let (rep, _, _) = run(&f, &opt, &mut |_, _| {}).unwrap();
        println!(
            "W × {k}: DC {:.1} %, {} nodes, drop {:.1} mm, settled at {:?} s",
            100.0 * rep.drape_coefficient,
            rep.nodes,
            1e3 * rep.drop_m,
            rep.settled_at_s
        );
        assert!(rep.settled_at_s.is_some(), "W × {k} did not settle");
        dcs.push((k, rep.drape_coefficient, rep.drop_m));
    }
    // measured (1 cm): 70.6, 58.7, 40.2 %; heavier drapes more, by clear
    // margins (5 points, against the seed's 1–4 points)
    for w in dcs.windows(2) {
        assert!(w[0].1 > w[1].1 + 0.05, "{dcs:?}");
    }
}

/// Grid refinement 1 cm → 0.5 cm changes the drape coefficient by less than
/// 3 points, for two seeds of the start perturbation.
///
/// Wool tropical, DC at 1 / 0.75 / 0.5 cm for seeds 1, 2, 3: 58.7, 58.7,
/// 58.7 % / 55.4, 56.7, 60.0 % / 56.1, 57.7, 59.0 % (largest change
/// 1 → 0.5 cm: 2.6 points). At the finer grids the seed picks the fold
/// pattern (8 to 12 nodes) and moves the coefficient by up to 4 points; at
/// 1 cm the grid holds one pattern (12 nodes). It was 55.9 % at 1 cm and
/// 49.1 % at 0.5 cm (6.8 points) with the grid's single skewed hinge, whose
/// fold along one cell diagonal costs no bending
/// ([`garment_sim::cloth::HingeLayout::MirrorSymmetric`]).
///
/// What remains is the net of two discretisation errors of opposite sign,
/// measured on seed 1:
/// - the clamp: the pinned vertices (radius ≤ 9 cm) end in a staircase inside
///   the rim, and the cloth bends down from it (only vertices meet the support
///   disk). The pinned region's convex hull has the area of a 8.74 cm disk at
///   1 cm, 8.88 cm at 0.5 cm: the coarse specimen hangs from a smaller clamp
///   and drapes more. With the shear law / 10 (bending and weight only) the
///   coefficient reads 39.9 % at 1 cm and 43.5 % at 0.5 cm; clamping out to
///   9.22 and 9.12 cm instead (hulls of 9.06 and 8.98 cm, the option
///   `ClampEdge::AreaMatched`) it reads 42.9 and 43.8 % (last test).
/// - the shear springs: a cell folding across one diagonal shortens the other,
///   which the diagonal springs read as shear (eq. 4.34/4.35 take the angle from
///   each diagonal's length alone); the strain grows as (κ·h)², so the coarse
///   grid resists folds more and drapes less. With both clamps matched as
///   above and the fabric's own shear: 61.9 % at 1 cm, 55.2 % at 0.5 cm; the
///   cells' Σ u² A where both diagonals change alike is 2.85e-6 against
///   1.00e-6, the shear proper (their difference) 1.63e-6 against 1.54e-6,
///   the tension strain the same (RMS 0.15 %).
///
/// The second belongs to the solver's shear element; until it is changed,
/// matching the clamp alone widens the gap (2.6 → 6.7 points), so the
/// drapemeter keeps the clamp within the disks by default.
#[test]
fn drape_coefficient_is_steady_under_grid_refinement() {
    let wool =
        garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml")).unwrap();
    let mut rows = Vec::new();
    for seed in [1, 2] {
        let mut dc = Vec::new();
        for spacing in [0.01, 0.005] {
            let opt = DrapeOptions {
                spacing,
                seed,
                ..Default::default()
            };
            let (rep, _, _) = run(&wool, &opt, &mut |_, _| {}).unwrap();
            println!(
                "seed {seed}, spacing {spacing}: DC {:.2} %, {} nodes, flat fraction {:.3}",
                100.0 * rep.drape_coefficient,
                rep.nodes,
                rep.flat_specimen_fraction
            );
            assert!(rep.settled_at_s.is_some());
            dc.push(rep.drape_coefficient);
        }
        rows.push((seed, dc[0], dc[1]));
    }
    for &(seed, coarse, fine) in &rows {
        assert!((coarse - fine).abs() < 0.03, "seed {seed}: {rows:?}");
    }
}

/// The pair of hinges per edge bends the same in every direction, and a
/// fold and its mirror image about the threads cost the same: the specimen
/// wrapped isometrically on a cylinder whose generators make an angle ψ with
/// the weft. The grid's single skewed hinge fails both (the control below).
#[test]
fn mirror_symmetric_hinges_bend_alike_in_every_direction() {
    use garment_sim::solver::{Params, Simulation};
    use nalgebra::Vector3;
    let wool = garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml"))
        .unwrap()
        .without_hysteresis();
    let outline = Outline::Circle {
        center: [0.0, 0.0],
        radius: 0.05,
    };
    let radius = 0.05;
    let bending = |symmetric: bool| -> Vec<f64> {
        let c = Cloth::panel(&PanelSpec {
            outline: outline.clone(),
            spacing: [0.005, 0.005],
            origin: [0.0, 0.0],
            pose: Isometry3::identity(),
            areal_mass: wool.areal_mass,
            border: Border::OnOutline,
            hinges: if symmetric {
                HingeLayout::MirrorSymmetric
            } else {
                HingeLayout::Skewed
            },
            corners: Vec::new(),
        })
        .unwrap();
        (0..8)
            .map(|k| {
                let psi = (k as f64 * 22.5f64).to_radians();
                let mut c = c.clone();
                for i in 0..c.len() {
                    let [u, v] = c.material[i];
                    // s across the generators, t along them
                    let (cs, sn) = (psi.cos(), psi.sin());
                    let (s, t) = (u * cs + v * sn, -u * sn + v * cs);
                    let (ps, pz) = (
                        radius * (s / radius).sin(),
                        radius * (1.0 - (s / radius).cos()),
                    );
                    c.set_position(i, Vector3::new(ps * cs - t * sn, ps * sn + t * cs, pz))
                        .unwrap();
                }
                Simulation::new(c, wool.clone(), Params::default())
                    .unwrap()
                    .energies()
                    .bending
            })
            .collect()
    };
    let pair = bending(true);
    let single = bending(false);
    println!(
        "bending energy (J) at ψ = 0, 22.5, … 157.5°:\n  pairs  {pair:?}\n  single {single:?}"
    );
    let spread = |e: &[f64]| {
        let (lo, hi) = e
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        (hi - lo) / hi
    };
    // every direction within 2 % (measured 0.7 %); the mirror images ψ and
    // 180° − ψ alike (measured to 1e-15)
    assert!(spread(&pair) < 0.02, "{pair:?}");
    for k in 1..4 {
        assert!((pair[k] - pair[8 - k]).abs() < 0.01 * pair[k], "{pair:?}");
    }
    // folds along the threads: as with the single hinge inside the piece
    // (next test); on the clipped border one of a pair is kept where the
    // single hinge had lost a wing: +3.8 % on this 10 cm disc at 0.5 cm
    for k in [0, 4] {
        assert!(
            pair[k] > single[k] && pair[k] < 1.05 * single[k],
            "{pair:?} {single:?}"
        );
    }
    // control: the single skewed hinge has a free fold direction
    assert!(spread(&single) > 0.9, "{single:?}");
}

/// An isotropic fabric (same warp and weft laws: wool tropical carries one
/// B and one 2HB, and the placeholders copied from acrylic are the same in
/// both directions) gives nodes spread evenly: every angular gap between
/// consecutive nodes within 25 % of 360°/n. The tolerance: node angles are
/// read from 1° bins smoothed over ±5° (±1°, a gap ±2°), and the square grid
/// keeps a 4-fold anisotropy, tension springs along the threads and shear
/// springs along the diagonals, that pulls the folds towards it (measured at
/// 1 cm: 12 nodes, gaps 27–35°, i.e. within 17 %). The start perturbation
/// (smooth, seeded, at most 0.2 mm) stands for the real specimen's
/// imperfection and only picks among the fold patterns; a perfect start
/// would fold along the grid's symmetry axes only. Control: the grid's
/// single skewed hinge gives gaps of 28–64° around 45° (8 nodes, 42 %).
///
/// Only at 1 cm, where every seed gives the same 12 nodes: at the finer grids
/// the seed picks among patterns and not all are even. 0.75 cm, seeds 1, 2,
/// 3: 9, 8, 9 nodes, worst gap 30, 27, 45 % off; 0.5 cm: 9, 10, 12 nodes, 45,
/// 67, 17 % off (a few gaps of 55–60° among 25–35° ones). These are
/// equilibria, not an early stop: run on to 2.5 s (RMS speed → 0) the
/// 0.75 cm patterns stay. A 9- or 10-fold pattern does not fit the grid's
/// 4-fold symmetry, and there is no self-collision to keep folds apart.
#[test]
fn isotropic_fabric_spreads_its_nodes_evenly() {
    let wool =
        garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml")).unwrap();
    assert_eq!(wool.warp.bending, wool.weft.bending);
    assert_eq!(wool.warp.tensile, wool.weft.tensile);
    let worst = |symmetric_hinges: bool| -> (usize, f64, Vec<f64>) {
        let opt = DrapeOptions {
            symmetric_hinges,
            ..Default::default()
        };
        let (rep, _, _) = run(&wool, &opt, &mut |_, _| {}).unwrap();
        let a = &rep.node_angles_deg;
        let n = a.len();
        assert!(n >= 3, "{a:?}");
        let gaps: Vec<f64> = (0..n)
            .map(|k| (a[(k + 1) % n] - a[k]).rem_euclid(360.0))
            .collect();
        let even = 360.0 / n as f64;
        let dev = gaps.iter().fold(0.0f64, |m, g| m.max((g - even).abs())) / even;
        println!(
            "symmetric hinges {symmetric_hinges}: {n} nodes at {a:?}, gaps {gaps:?}, worst {:.0} % of {even:.1}°",
            100.0 * dev
        );
        (n, dev, gaps)
    };
    let (_, dev, gaps) = worst(true);
    assert!(dev < 0.25, "{gaps:?}");
    let (_, dev, gaps) = worst(false);
    assert!(dev > 0.25, "control: {gaps:?}");
}

#[test]
fn border_on_the_circle_is_at_rest_and_covers_the_annulus() {
    use garment_sim::solver::{Params, Simulation};
    let wool =
        garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml")).unwrap();
    let outline = Outline::Circle {
        center: [0.0, 0.0],
        radius: 0.15,
    };
    let pose = Isometry3::identity();
    let stair = Cloth::clipped(&outline, [0.01, 0.01], [0.0, 0.0], &pose, wool.areal_mass).unwrap();
    let snap =
        Cloth::clipped_to_outline(&outline, [0.01, 0.01], [0.0, 0.0], &pose, wool.areal_mass)
            .unwrap();
    assert!(snap.len() > stair.len());
    // every moved node lies on the circle
    let on = snap
        .material
        .iter()
        .filter(|m| ((m[0] * m[0] + m[1] * m[1]).sqrt() - 0.15).abs() < 1e-4)
        .count();
    assert!(on >= 40, "{on} nodes on the circle");
    // same mass: the areal mass times the disc's area
    let want = wool.areal_mass * std::f64::consts::PI * 0.15 * 0.15;
    for c in [&stair, &snap] {
        assert!((c.total_mass() - want).abs() / want < 1e-3);
    }
    // the flat piece covers the disc: triangle area
    let area = |c: &Cloth| -> f64 {
        c.triangles
            .iter()
            .map(|t| {
                let (a, b, d) = (
                    c.positions()[t[0]],
                    c.positions()[t[1]],
                    c.positions()[t[2]],
                );
                0.5 * (b - a).cross(&(d - a)).norm()
            })
            .sum()
    };
    let disc = std::f64::consts::PI * 0.15 * 0.15;
    println!(
        "flat cover: staircase {:.4}, border on the circle {:.4}",
        area(&stair) / disc,
        area(&snap) / disc
    );
    assert!(area(&stair) / disc < 0.95);
    assert!(area(&snap) / disc > 0.98);
    // at rest when flat: no spring or hinge force anywhere
    let sim = Simulation::new(snap, wool, Params::default()).unwrap();
    let f = sim.internal_forces();
    let worst = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
    assert!(worst < 1e-12, "largest force on the flat piece {worst} N");
}

#[test]
fn clipped_disc_for_the_drapemeter() {
    // the drapemeter's specimen: mass and elements of the clipped grid
    let outline = Outline::Circle {
        center: [0.0, 0.0],
        radius: 0.15,
    };
    let c = Cloth::clipped(
        &outline,
        [0.01, 0.01],
        [0.0, 0.0],
        &Isometry3::identity(),
        0.1629,
    )
    .unwrap();
    let want = 0.1629 * std::f64::consts::PI * 0.15 * 0.15;
    let err = (c.total_mass() - want).abs() / want;
    assert!(err < 1e-3, "mass error {err}");
    let n = c.len();
    assert!(c.tension.iter().all(|s| s.a < n && s.b < n));
    assert!(c.shear.iter().all(|s| s.a < n && s.b < n));
    assert!(c.hinges.iter().all(|h| h.v.iter().all(|&v| v < n)));
    // every kept node is inside the circle, every removed one outside
    for j in 0..c.ny {
        for i in 0..c.nx {
            let v = c.grid_vertex[j * c.nx + i];
            if v != REMOVED {
                let [u, w] = c.material[v];
                assert!((u * u + w * w).sqrt() <= 0.15 + 1e-9);
            }
        }
    }
    assert_eq!(c.grid_vertex.iter().filter(|&&v| v != REMOVED).count(), n);
    // four-fold symmetric about the centre: as many vertices in each quadrant
    let q = |sx: f64, sy: f64| {
        c.material
            .iter()
            .filter(|m| m[0] * sx > 1e-9 && m[1] * sy > 1e-9)
            .count()
    };
    assert_eq!(q(1.0, 1.0), q(-1.0, 1.0));
    assert_eq!(q(1.0, 1.0), q(-1.0, -1.0));
}

/// `drapemeter ARGS` fails, and its error names `word`.
fn drapemeter_refused(args: &[&str], word: &str) {
    let o = support::garment_sim()
        .arg("drapemeter")
        .args(args)
        .output()
        .unwrap();
    assert!(!o.status.success(), "drapemeter {args:?} succeeded");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains(word), "{stderr}");
}

#[test]
fn drapemeter_command_writes_report_and_top_view() {
    let out = support::Scratch::new("drapemeter");
    let (stdout, rep) = support::lab_report(
        "drapemeter",
        &["config/fabrics/polyester_faille.yaml", "--spacing", "0.015"],
        &out,
    );
    assert!(stdout.contains("drape coefficient") && stdout.contains("nodes"));
    let dc = rep["drape_coefficient"].as_f64().unwrap();
    assert!(dc > 0.0 && dc < 1.0, "{dc}");
    assert_eq!(
        rep["nodes"].as_u64().unwrap() as usize,
        rep["node_angles_deg"].as_array().unwrap().len()
    );
    let png = std::fs::read(out.join("top_view.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    // a bad geometry is an error naming it
    drapemeter_refused(
        &[
            "config/fabrics/polyester_faille.yaml",
            "--disk",
            "0.4",
            "--out",
            out.to_str().unwrap(),
        ],
        "disk",
    );
}

/// A square of side `size` on a grid of `spacing`: with the grid's single
/// skewed hinge per edge, and with mirror-symmetric hinge pairs.
fn square_with_both_hinge_layouts(size: f64, spacing: f64, areal_mass: f64) -> (Cloth, Cloth) {
    let spec = garment_sim::cloth::GridSpec {
        size: [size, size],
        spacing: [spacing, spacing],
        pose: Isometry3::identity(),
    };
    let skewed = Cloth::grid(&spec, areal_mass).unwrap();
    let mirror = Cloth::panel(&PanelSpec {
        hinges: HingeLayout::MirrorSymmetric,
        ..PanelSpec::rectangle(&spec, areal_mass)
    })
    .unwrap();
    (skewed, mirror)
}

/// On a full rectangular grid, for a fold along the threads, the pairs of
/// hinges give the single hinge's bending energy (measured: equal to 1e-15):
/// on a cylinder along a thread both stencils see the same dihedral angle.
#[test]
fn hinge_pairs_match_the_single_hinge_on_folds_along_the_threads() {
    use garment_sim::solver::{Params, Simulation};
    use nalgebra::Vector3;
    let wool = garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml"))
        .unwrap()
        .without_hysteresis();
    let (single, pair) = square_with_both_hinge_layouts(0.1, 0.01, wool.areal_mass);
    // two half hinges where the grid had one
    assert_eq!(pair.hinges.len(), 2 * single.hinges.len());
    let radius = 0.04;
    for weft_axis in [false, true] {
        let energy = |c: &Cloth| {
            let mut c = c.clone();
            for i in 0..c.len() {
                let [u, v] = c.material[i];
                let (s, t) = if weft_axis { (u, v) } else { (v, u) };
                let (ps, pz) = (
                    radius * (s / radius).sin(),
                    radius * (1.0 - (s / radius).cos()),
                );
                c.set_position(
                    i,
                    if weft_axis {
                        Vector3::new(ps, t, pz)
                    } else {
                        Vector3::new(t, ps, pz)
                    },
                )
                .unwrap();
            }
            Simulation::new(c, wool.clone(), Params::default())
                .unwrap()
                .energies()
                .bending
        };
        let (es, ep) = (energy(&single), energy(&pair));
        println!(
            "generators along the {}: single {es:.6e} J, pairs {ep:.6e} J",
            if weft_axis { "weft" } else { "warp" }
        );
        assert!((ep - es).abs() < 1e-9 * es, "{es} {ep}");
    }
}

/// The clamp's staircase is one of the two errors left under refinement
/// (see `drape_coefficient_is_steady_under_grid_refinement`): with the shear
/// law / 10, so that the diagonal springs' response to folded cells does
/// not count, and the clamp's hull matched to the disks' area
/// ([`garment_sim::lab::drapemeter::area_matched_pin_radius`]), the drape
/// coefficient at 1 cm and 0.5 cm agrees within 1.5 points (measured 42.9
/// and 43.8 %, clamped out to 9.22 and 9.12 cm; with the clamp within the
/// disks 39.9 and 43.5 %, 3.6 points). The hulls are 9.06 and 8.98 cm
/// against 8.74 and 8.88 cm.
#[test]
fn area_matched_clamp_converges_under_refinement_with_soft_shear() {
    let mut wool =
        garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml")).unwrap();
    for c in wool.shear.elastic.c.iter_mut() {
        *c *= 0.1;
    }
    let hy = &mut wool.shear.hysteresis;
    (hy.h0, hy.h1, hy.h2) = (0.1 * hy.h0, 0.1 * hy.h1, 0.1 * hy.h2);
    let mut dc = Vec::new();
    for spacing in [0.01, 0.005] {
        for matched in [true, false] {
            let opt = DrapeOptions {
                spacing,
                clamp: if matched {
                    ClampEdge::AreaMatched
                } else {
                    ClampEdge::Rim
                },
                ..Default::default()
            };
            if !matched && spacing < 0.01 {
                continue; // the staircase at 0.5 cm: figure in the doc
            }
            let (rep, _, _) = run(&wool, &opt, &mut |_, _| {}).unwrap();
            println!(
                "spacing {spacing}, area-matched clamp {matched}: pinned to {:.2} cm, hull {:.3} cm, DC {:.2} %",
                100.0 * rep.pin_radius_m,
                100.0 * rep.clamp_radius_m,
                100.0 * rep.drape_coefficient
            );
            if matched {
                // the hull within a quarter cell of the rim
                assert!((rep.clamp_radius_m - 0.09).abs() < 0.25 * spacing);
                dc.push(rep.drape_coefficient);
            } else {
                assert!(rep.clamp_radius_m < 0.09 - 0.2 * spacing);
            }
        }
    }
    assert!((dc[0] - dc[1]).abs() < 0.015, "{dc:?}");
}

/// The egg-crate: every vertex of the grid alternately up and down by `a`
/// (`z = ±a` as `i + j` is even or odd), the grid drawn in so that every
/// thread segment keeps its length. Along each thread it is a zigzag of
/// curvature κ = 4a/h² (second difference), so a bending element that reads
/// curvature along the threads charges it `½ B κ²` per area for each
/// thread. No hinge of either layout sees it: the four vertices of every
/// hinge stencil stay coplanar, zero bending energy to round-off (1e-33
/// J/m²). With the diagonal springs (eq. 4.34, the default) it is held back
/// by their reading of both diagonals shortening as shear: wool tropical at
/// 1 cm, a = h/20: 2.3e-3 J/m² against `B κ²` = 2.6e-3 J/m² (a = h/10:
/// 3.7e-2 against 1.1e-2). The cells' measure (`Params::cell_shear`) reads
/// none, so it comes with the egg-crate guards, whose energy is `½ B κ²` per
/// thread by construction: 2.52e-3 and 1.04e-2 J/m² (within 4 %: the
/// border rows have no guard); without them the drapemeter's hem crumples
/// into the mode (docs/lab.md).
#[test]
fn the_egg_crate_costs_energy_with_either_shear_measure() {
    use garment_sim::solver::{Params, Simulation};
    use nalgebra::Vector3;
    let wool = garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml"))
        .unwrap()
        .without_hysteresis();
    let h = 0.01;
    let (skewed, mirror) = square_with_both_hinge_layouts(0.2, h, wool.areal_mass);
    let b = wool.warp.bending.elastic.c[0];
    for (name, c0) in [("skewed", skewed), ("mirror-symmetric", mirror)] {
        for frac in [0.05, 0.1] {
            let a = frac * h;
            let d = (h * h - 4.0 * a * a).sqrt() / h;
            let mut c = c0.clone();
            for i in 0..c.len() {
                let [u, v] = c.material[i];
                let odd = ((u / h).round() as i64 + (v / h).round() as i64) % 2 != 0;
                c.set_position(i, Vector3::new(u * d, v * d, if odd { -a } else { a }))
                    .unwrap();
            }
            let area = (0.2 * d).powi(2);
            let want = b * (4.0 * a / (h * h)).powi(2);
            let mut e = [(0.0, 0.0); 2];
            for (k, cell_shear) in [false, true].into_iter().enumerate() {
                let params = Params {
                    cell_shear,
                    ..Params::default()
                };
                let en = Simulation::new(c.clone(), wool.clone(), params)
                    .unwrap()
                    .energies();
                e[k] = (en.bending / area, en.shear / area);
            }
            println!(
                "{name}, a = {frac} h: diagonal springs: bending {:.3e}, shear {:.3e} J/m²; \
                 cells and guards: bending {:.3e}, shear {:.3e} J/m²; B κ² {want:.3e} J/m²",
                e[0].0, e[0].1, e[1].0, e[1].1
            );
            // the hinges alone: nothing (what the guards are for)
            assert!(e[0].0 < 1e-12 * want, "{name}: hinges {:e}", e[0].0);
            assert!(e[0].1 > 0.25 * want, "{name}, a = {frac} h: springs");
            assert!(e[1].1 < 1e-12 * want, "{name}: cells read {:e}", e[1].1);
            assert!(
                (e[1].0 / want - 1.0).abs() < 0.06,
                "{name}, a = {frac} h: guards"
            );
        }
    }
}

/// With the cells' shear measure and the egg-crate guards
/// (`DrapeOptions::cell_shear`), the soft polyester faille drapes alike at
/// 1 cm and 0.5 cm: 34.1 and 35.2 % (5 and 11 nodes; Matsudaira et al.
/// measured 28.3 %, 7 nodes), where the diagonal springs give 55.1
/// and 45.0 % (10 points apart: they read the faille's tight folds, about a
/// cell across at 1 cm, as shear). Without the guards the hem crumples into
/// the egg-crate instead of folding (docs/lab.md).
#[test]
fn cell_shear_drapes_the_soft_faille_alike_at_1_and_half_a_cm() {
    let faille =
        garment_sim::io::load_fabric(Path::new("config/fabrics/polyester_faille.yaml")).unwrap();
    let mut dc = Vec::new();
    for spacing in [0.01, 0.005] {
        let opt = DrapeOptions {
            spacing,
            cell_shear: true,
            ..Default::default()
        };
        let (rep, _, _) = run(&faille, &opt, &mut |_, _| {}).unwrap();
        println!(
            "spacing {spacing}: DC {:.2} %, {} nodes",
            100.0 * rep.drape_coefficient,
            rep.nodes
        );
        assert!(rep.settled_at_s.is_some());
        assert!(rep.nodes >= 4, "{} nodes", rep.nodes);
        dc.push(rep.drape_coefficient);
    }
    assert!((dc[0] - dc[1]).abs() < 0.03, "{dc:?}");
}

/// The switch reaches the simulation from each place a user sets it: the
/// drapemeter's `--cell-shear` (its report equals the library's run with
/// `DrapeOptions::cell_shear`, and differs from the default's), a scene
/// file's `cell_shear: true`, and `drape --cell-shear` over the file.
#[test]
fn cell_shear_is_set_from_the_command_line_and_the_scene_file() {
    use garment_sim::scene::{Overrides, Scene};
    let out = support::Scratch::new("cell_shear_cli");
    let o = support::garment_sim()
        .args([
            "drapemeter",
            "config/fabrics/polyester_faille.yaml",
            "--spacing",
            "0.015",
            "--cell-shear",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let faille =
        garment_sim::io::load_fabric(Path::new("config/fabrics/polyester_faille.yaml")).unwrap();
    let dc = |cell_shear| {
        let opt = DrapeOptions {
            spacing: 0.015,
            cell_shear,
            ..Default::default()
        };
        run(&faille, &opt, &mut |_, _| {})
            .unwrap()
            .0
            .drape_coefficient
    };
    let cli = rep["drape_coefficient"].as_f64().unwrap();
    assert_eq!(cli, dc(true));
    assert!((cli - dc(false)).abs() > 1e-3, "{cli} {}", dc(false));

    // the scene file's key, and the command line over it
    let text = std::fs::read_to_string("config/scenes/table_drape.yaml").unwrap();
    for dir in ["scenes", "fabrics"] {
        std::fs::create_dir_all(out.join(dir)).unwrap();
    }
    let scene_path = out.join("scenes/table_cell.yaml");
    std::fs::write(&scene_path, format!("{text}\ncell_shear: true\n")).unwrap();
    std::fs::copy(
        "config/fabrics/acrylic.yaml",
        out.join("fabrics/acrylic.yaml"),
    )
    .unwrap();
    let sc = Scene::load(&scene_path).unwrap();
    let small = Overrides {
        spacing: Some(0.05),
        ..Default::default()
    };
    let sim = sc.build(&small).unwrap();
    assert!(sim.cloth.shear.is_empty() && !sim.cloth.shear_cells.is_empty());
    assert!(!sim.cloth.guards.is_empty());
    let off = sc
        .build(&Overrides {
            cell_shear: Some(false),
            ..small.clone()
        })
        .unwrap();
    assert!(off.cloth.shear_cells.is_empty() && !off.cloth.shear.is_empty());
    // drape's flag: the energies written differ (the tension springs lose
    // the eq. 4.59 correction, the guards add to the bending column)
    let energies = |on: &str| {
        let dir = out.join(format!("drape_{on}"));
        let o = support::garment_sim()
            .arg("drape")
            .arg(&scene_path)
            .args([
                "--spacing",
                "0.05",
                "--duration",
                "0.05",
                "--cell-shear",
                on,
                "--out",
            ])
            .arg(&dir)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap())
                .unwrap();
        let want = if on == "true" { "cells" } else { "diagonals" };
        assert_eq!(summary["shear_measure"], want);
        std::fs::read_to_string(dir.join("energy.csv")).unwrap()
    };
    assert_ne!(energies("true"), energies("false"));
}

/// The grids' softness with the hysteresis off is the clamp's discrete edge
/// (docs/lab.md). Pinned to the vertices within the disks, the hanging cloth
/// bends from hinges on the last pinned vertices, whose curvature stands for
/// half a spacing either side: the specimen hangs as if clamped half a
/// spacing inside the rim, a first-order error (the cantilever's closed form,
/// tests/cantilever.rs). Pinned out to half a spacing beyond the rim, the
/// cantilever's clamp, the error is second order. Cotton broadcloth, elastic
/// laws: 66.5 / 70.8 % at 1 / 0.5 cm with the rim clamp, 73.7 / 72.5 % with
/// the half-spacing clamp (0.25 cm: 73.6 %).
#[test]
fn without_hysteresis_the_half_spacing_clamp_converges_from_1_cm() {
    let cotton =
        garment_sim::io::load_fabric(Path::new("config/fabrics/cotton_broadcloth.yaml")).unwrap();
    let mut dc = [[0.0; 2]; 2];
    for (i, out) in [false, true].into_iter().enumerate() {
        for (j, spacing) in [0.01, 0.005].into_iter().enumerate() {
            let opt = DrapeOptions {
                spacing,
                hysteresis: false,
                clamp: if out {
                    ClampEdge::HalfSpacingOut
                } else {
                    ClampEdge::Rim
                },
                ..Default::default()
            };
            let (rep, _, _) = run(&cotton, &opt, &mut |_, _| {}).unwrap();
            assert!(rep.settled_at_s.is_some());
            assert!(!rep.hysteresis);
            let want = 0.09 + if out { 0.5 * spacing } else { 0.0 };
            assert!((rep.pin_radius_m - want).abs() < 1e-12);
            dc[i][j] = rep.drape_coefficient;
            println!(
                "clamp half a spacing out {out}, spacing {spacing}: DC {:.2} % ({} nodes)",
                100.0 * rep.drape_coefficient,
                rep.nodes
            );
        }
    }
    let gap = |r: [f64; 2]| (r[0] - r[1]).abs();
    assert!(gap(dc[0]) > 0.035, "rim clamp: {dc:?}");
    assert!(gap(dc[1]) < 0.02, "half-spacing clamp: {dc:?}");
    // the coarse grid's error is the rim clamp's softness
    assert!(dc[0][0] < dc[0][1] && dc[0][0] < dc[1][0], "{dc:?}");
}

/// `--no-hysteresis` and `--clamp-half-spacing-out` reach the run and its
/// report; the two clamp options exclude each other.
#[test]
fn drapemeter_takes_the_elastic_laws_and_the_half_spacing_clamp_from_the_command_line() {
    let out = support::Scratch::new("drapemeter_opts");
    let (stdout, rep) = support::lab_report(
        "drapemeter",
        &[
            "config/fabrics/wool_tropical.yaml",
            "--spacing",
            "0.02",
            "--no-hysteresis",
            "--clamp-half-spacing-out",
        ],
        &out,
    );
    assert!(
        stdout.contains("clamped out to 10.00 cm, hysteresis off"),
        "{stdout}"
    );
    assert_eq!(rep["hysteresis"], serde_json::Value::Bool(false));
    assert!((rep["pin_radius_m"].as_f64().unwrap() - 0.10).abs() < 1e-12);
    // the same run through the library gives the same coefficient
    let wool =
        garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml")).unwrap();
    let opt = DrapeOptions {
        spacing: 0.02,
        hysteresis: false,
        clamp: ClampEdge::HalfSpacingOut,
        ..Default::default()
    };
    let (lib, _, _) = run(&wool, &opt, &mut |_, _| {}).unwrap();
    assert_eq!(
        rep["drape_coefficient"].as_f64().unwrap(),
        lib.drape_coefficient
    );
    drapemeter_refused(
        &[
            "config/fabrics/wool_tropical.yaml",
            "--clamp-half-spacing-out",
            "--clamp-area-matched",
        ],
        "clamp",
    );
}

/// `--specimens N` drapes N specimens with seeds seed … seed + N − 1, each
/// exactly as a single run with its seed, and `specimens.json` gives their
/// mean, sample standard deviation and standard error (computed here from the
/// specimens' own reports).
#[test]
fn drapemeter_averages_specimens_over_seeds() {
    let out = support::Scratch::new("drapemeter_specimens");
    let args = ["config/fabrics/wool_tropical.yaml", "--spacing", "0.02"];
    let stdout = support::lab_stdout(
        "drapemeter",
        &[&args[..], &["--seed", "4", "--specimens", "3"]].concat(),
        &out,
    );
    let read = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let numbers = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let sp = read(&out.join("specimens.json"));
    let seeds: Vec<u64> = numbers(&sp["seeds"]).iter().map(|&s| s as u64).collect();
    assert_eq!(seeds, [4, 5, 6]);
    let reps: Vec<serde_json::Value> = seeds
        .iter()
        .map(|s| read(&out.join(format!("specimen_{s}")).join("report.json")))
        .collect();
    let dc: Vec<f64> = reps
        .iter()
        .map(|r| r["drape_coefficient"].as_f64().unwrap())
        .collect();
    assert_eq!(numbers(&sp["drape_coefficients"]), dc);
    // each specimen's report names its seed
    for (r, s) in reps.iter().zip(&seeds) {
        assert_eq!(r["seed"].as_u64(), Some(*s));
    }
    let mean = dc.iter().sum::<f64>() / 3.0;
    let sd = (dc.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / 2.0).sqrt();
    let close = |k: &str, v: f64| {
        let got = sp[k].as_f64().unwrap();
        assert!((got - v).abs() < 1e-12, "{k}: {got} against {v}");
    };
    close("mean_drape_coefficient", mean);
    close("sd_drape_coefficient", sd);
    close("standard_error", sd / 3f64.sqrt());
    // at 2 cm the seed picks among resting shapes: the specimens differ
    assert!(sd > 0.01, "{dc:?}");
    let nodes: Vec<u64> = reps.iter().map(|r| r["nodes"].as_u64().unwrap()).collect();
    close(
        "mean_nodes",
        nodes.iter().sum::<u64>() as f64 / nodes.len() as f64,
    );
    assert!(
        stdout.contains(&format!("mean               {:.2} %", 100.0 * mean)),
        "{stdout}"
    );
    // specimen 5 is the single run with seed 5, bit for bit
    let single = support::Scratch::new("drapemeter_specimen_5");
    let (_, rep5) = support::lab_report(
        "drapemeter",
        &[&args[..], &["--seed", "5"]].concat(),
        &single,
    );
    assert_eq!(rep5["drape_coefficient"].as_f64().unwrap(), dc[1]);
    assert_eq!(rep5["node_angles_deg"], reps[1]["node_angles_deg"]);
    // no specimen at all is refused
    drapemeter_refused(&[&args[..], &["--specimens", "0"]].concat(), "specimens");
}

/// The hinge chain's dispersion, one likely cause of the coarse grids'
/// softness (docs/lab.md): across a fold the hinges sample the curvature of
/// a wave `a sin ku` as the second difference `(2 − 2 cos kh)/h²` in place
/// of `k²`, so a wave's bending energy is `[(2 − 2 cos kh)/(kh)²]²` of the
/// continuum's `½ B ∫ κ² dA`. A strip 24 cm × 4 cm bent into three
/// wavelengths of 8 cm along the warp (amplitude 0.1 mm: linear), elastic
/// law: 0.902 of the continuum at 1 cm (kh = 0.785), 0.975 at 0.5 cm,
/// 0.994 at 0.25 cm, each within 0.1 % of the closed form (measured 0.01 %).
#[test]
fn the_hinge_chain_bends_a_wave_softer_by_its_dispersion() {
    use garment_sim::lab::cantilever::fabric_bending;
    use garment_sim::lab::kes_lab::Direction;
    use garment_sim::solver::{Params, Simulation};
    use nalgebra::Vector3;
    let wool = garment_sim::io::load_fabric(Path::new("config/fabrics/wool_tropical.yaml"))
        .unwrap()
        .without_hysteresis();
    let (b_kes, _) = fabric_bending(&wool, Direction::Warp).unwrap();
    let b = b_kes * garment_sim::fabric::kes::GF_CM2_PER_CM;
    let (length, width, a) = (0.24, 0.04, 1e-4);
    let k = 2.0 * std::f64::consts::PI / 0.08;
    let continuum = 0.5 * b * a * a * k.powi(4) * (length / 2.0) * width;
    let mut report = String::new();
    for h in [0.01, 0.005, 0.0025] {
        let strip = Outline::Rectangle {
            size: [length, width],
        };
        let mut c = Cloth::panel(&PanelSpec {
            hinges: HingeLayout::MirrorSymmetric,
            ..PanelSpec::new(
                &strip,
                [h, h],
                [0.0, 0.0],
                &Isometry3::identity(),
                wool.areal_mass,
            )
        })
        .unwrap();
        for i in 0..c.len() {
            let [u, v] = c.material[i];
            c.set_position(i, Vector3::new(u, v, a * (k * u).sin()))
                .unwrap();
        }
        let e = Simulation::new(c, wool.clone(), Params::default())
            .unwrap()
            .energies()
            .bending;
        let kh = k * h;
        let want = ((2.0 - 2.0 * kh.cos()) / (kh * kh)).powi(2);
        report.push_str(&format!(
            "h = {h} m (kh = {kh:.3}): energy {e:.4e} J, continuum {continuum:.4e} J, ratio {:.4} (closed form {want:.4})\n",
            e / continuum
        ));
        assert!((e / continuum - want).abs() < 1e-3 * want, "{report}");
    }
    println!("{report}");
}
