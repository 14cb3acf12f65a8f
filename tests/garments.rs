//! Garments (issue 20): panels cut to their grain, seams that close, trials
//! on a body and their bad inputs.

mod support;
use garment_sim::fabric::Fabric;
use garment_sim::garment::{Garment, PanelCut, SeamSpec};
use garment_sim::solver::{LinearSolverKind, Params, Pin, PinPath, Simulation};
use garment_sim::trial::{self, SettleFile, SewingFile};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fabric(name: &str) -> Fabric {
    garment_sim::io::load_fabric(&root().join(format!("config/fabrics/{name}.yaml"))).unwrap()
}

/// A w × h rectangle with edges 0 bottom, 1 right, 2 top, 3 left
/// (counter-clockwise), its plane stood up in x–z (panel y is world z).
fn rect(name: &str, w: f64, h: f64, at: [f64; 3], grain_deg: f64) -> PanelCut {
    PanelCut {
        name: name.into(),
        edges: vec![
            vec![[0.0, 0.0], [w, 0.0]],
            vec![[w, 0.0], [w, h]],
            vec![[w, h], [0.0, h]],
            vec![[0.0, h], [0.0, 0.0]],
        ],
        grain: [grain_deg.to_radians().cos(), grain_deg.to_radians().sin()],
        placement: Isometry3::from_parts(
            Translation3::new(at[0], at[1], at[2]),
            UnitQuaternion::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0),
        ),
    }
}

fn params(dt: f64) -> Params {
    Params {
        dt,
        linear_solver: LinearSolverKind::Cholesky,
        threads: 1,
        ..Params::default()
    }
}

/// Pins every vertex within 1 mm of the highest.
fn pin_top(sim: &mut Simulation) {
    let top = sim.cloth.x.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let pins = (0..sim.cloth.len())
        .filter(|&i| sim.cloth.x[i].z > top - 1e-3)
        .map(|i| Pin::new(i, PinPath::Fixed(sim.cloth.x[i])))
        .collect();
    sim.set_pins(pins).unwrap();
}

#[test]
fn two_panels_sewn_along_one_edge_close_under_a_millimetre() {
    // panel b hangs 5 cm below panel a, whose top edge is held; the seam
    // joins a's bottom edge (0) to b's top edge (2)
    let a = rect("a", 0.2, 0.15, [0.0, 0.0, 0.35], 90.0);
    let b = rect("b", 0.2, 0.15, [0.0, 0.0, 0.15], 90.0);
    let seam = SeamSpec {
        a: (0, 0),
        b: (1, 2),
        stiffness: garment_sim::pattern::DEFAULT_SEAM_STIFFNESS,
        damping: garment_sim::pattern::DEFAULT_SEAM_DAMPING,
    };
    let f = fabric("wool_tropical");
    let g = Garment::build(&[a, b], &[seam], 0.02, f.areal_mass).unwrap();
    assert!(
        g.seams[0].reversed,
        "a's bottom runs left to right, b's top right to left"
    );
    let (gap0, _) = g.largest_gap(&g.cloth.x);
    assert!(
        gap0 >= 0.05 - 1e-9,
        "the panels start at least 5 cm apart: {gap0}"
    );
    let mut sim = Simulation::new(g.cloth.clone(), f, params(0.005)).unwrap();
    pin_top(&mut sim);
    let st = trial::run(
        &mut sim,
        &SewingFile::default(),
        &SettleFile::default(),
        None,
        &mut |_, _, _| {},
        &|| false,
    )
    .unwrap();
    let (gap, _) = g.largest_gap(&sim.cloth.x);
    assert!(st.settle_time_s.is_some(), "settles: {st:?}");
    assert!(gap < 1e-3, "largest seam gap {:.3} mm", gap * 1e3);
    // b hangs from the seam: its lowest point is near 0.35 − 0.15 = 0.20 m
    let low = sim.cloth.x.iter().map(|p| p.z).fold(f64::MAX, f64::min);
    assert!((low - 0.20).abs() < 0.01, "lowest point {low}");
}

#[test]
fn warp_springs_follow_the_grain() {
    // a panel cut at 30°: every warp spring lies along the grain in the
    // panel, every weft spring across it
    let f = fabric("wool_tropical");
    let mut p = rect("p", 0.3, 0.2, [0.0, 0.0, 0.0], 30.0);
    p.placement = Isometry3::identity();
    let g = Garment::build(&[p], &[], 0.02, f.areal_mass).unwrap();
    let grain = Vector3::new(30f64.to_radians().cos(), 30f64.to_radians().sin(), 0.0);
    let mut n = 0;
    for s in &g.cloth.tension {
        let d = (g.cloth.x[s.b] - g.cloth.x[s.a]).normalize();
        let c = d.dot(&grain).abs();
        if s.weft {
            assert!(
                c < 1e-3 || (g.cloth.x[s.b] - g.cloth.x[s.a]).norm() < 0.999 * s.l0.max(0.02),
                "weft spring along {d}"
            );
        } else if (c - 1.0).abs() > 1e-9 {
            // only springs moved onto the border may turn
            assert!(
                (g.cloth.x[s.b] - g.cloth.x[s.a]).norm() < 0.02 - 1e-9,
                "warp spring along {d}"
            );
        } else {
            n += 1;
        }
    }
    assert!(n > 100, "{n} warp springs along the grain");
}

/// Writes a closed vertical cylinder (radius r, height h, base at z = 0) as OBJ.
fn cylinder_obj(path: &Path, r: f64, h: f64) {
    let n = 48;
    let mut s = String::new();
    for z in [0.0, h] {
        for k in 0..n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            s += &format!("v {} {} {z}\n", r * a.cos(), r * a.sin());
        }
    }
    s += &format!("v 0 0 0\nv 0 0 {h}\n");
    for k in 0..n {
        let (a, b) = (k + 1, (k + 1) % n + 1);
        s += &format!("f {a} {b} {}\nf {a} {} {}\n", n + b, n + b, n + a);
        s += &format!(
            "f {} {b} {a}\nf {} {} {}\n",
            2 * n + 1,
            2 * n + 2,
            n + a,
            n + b
        );
    }
    std::fs::write(path, s).unwrap();
}

fn tube_files(dir: &Path, width: f64) -> PathBuf {
    cylinder_obj(&dir.join("cylinder.obj"), 0.15, 1.0);
    let fab = root().join("config/fabrics/wool_tropical.yaml");
    std::fs::write(
        dir.join("tube.garment.yaml"),
        format!(
            "fabric: {}\npanels:\n  front:\n    vertices: [[0, 0], [{width}, 0], [{width}, 0.3], [0, 0.3]]\n    translation: [{}, -0.2, 0.6]\n    rotation_deg: [90, 0, 0]\n  back:\n    vertices: [[0, 0], [{width}, 0], [{width}, 0.3], [0, 0.3]]\n    translation: [{}, 0.2, 0.6]\n    rotation_deg: [90, 0, 180]\nseams:\n  - {{a: [front, 1], b: [back, 3]}}\n  - {{a: [front, 3], b: [back, 1]}}\n",
            fab.display(),
            -width / 2.0,
            width / 2.0
        ),
    )
    .unwrap();
    let t = dir.join("tube.trial.yaml");
    std::fs::write(
        &t,
        "garment: tube.garment.yaml\nbody: {obj: cylinder.obj, skin_offset: 0.003, friction: 0.5, girths: {mid: 0.75}}\nspacing: 0.02\ndt: 0.005\n",
    )
    .unwrap();
    t
}

/// A JSON list of numbers.
fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_f64().unwrap())
        .collect()
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Vertices of an ASCII PLY written by `trial` (x, y, z first).
fn ply_points(p: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(p).unwrap();
    let n: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    text.lines()
        .skip_while(|l| *l != "end_header")
        .skip(1)
        .take(n)
        .map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .take(3)
                .map(|s| s.parse().unwrap())
                .collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

#[test]
fn a_tube_sewn_on_both_sides_hangs_round_on_a_cylinder() {
    // two 46 cm panels make a 92 cm tube, 2.4 % short of the 94.2 cm
    // cylinder: it is sewn around it and held by friction
    let s = support::Scratch::new("garment_tube");
    let t = tube_files(&s, 0.46);
    let out = s.join("out");
    let o = support::garment_sim()
        .args(["trial", t.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = read_json(&out.join("fit.json"));
    assert!(fit["run"]["settle_time_s"].is_number(), "{fit}");
    assert!(fit["largest_seam_gap_mm"].as_f64().unwrap() < 1.0, "{fit}");
    assert_eq!(fit["body_penetrations"].as_u64(), Some(0));
    assert_eq!(
        fit["warnings"].as_array().unwrap().len(),
        0,
        "{}",
        fit["warnings"]
    );
    // round: every vertex at the contact distance (3 mm skin offset + 2 mm
    // cloth thickness) from the cylinder's surface, ±2 mm
    let pts = ply_points(&out.join("garment.ply"));
    for p in &pts {
        let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
        assert!((r - 0.155).abs() < 0.002, "radius {r} at {p:?}");
        assert!(p[2] > 0.4 && p[2] < 1.0, "slid: {p:?}");
    }
    // the girth at mid-height: the cylinder's 94.2 cm (hull of a 48-gon)
    let g = &fit["girths"]["mid"];
    let body = g["body_cm"].as_f64().unwrap();
    assert!(
        (body - 100.0 * std::f64::consts::TAU * 0.15).abs() < 0.2,
        "{g}"
    );
    let ease = g["ease_cm"].as_f64().unwrap();
    assert!(ease > 0.0 && ease < 2.0 * std::f64::consts::PI * 0.5, "{g}");
    for f in ["garment.obj", "fit_strain.png", "fit_pressure.png"] {
        assert!(out.join(f).exists(), "{f}");
    }
}

/// Runs `trial` and checks the refusal names every needle.
fn refused(trial: &Path, needles: &[&str]) {
    let o = support::garment_sim()
        .args(["trial", trial.to_str().unwrap(), "--out"])
        .arg(trial.parent().unwrap().join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "error lacks {n:?}: {err}");
    }
}

#[test]
fn bad_garments_are_refused_naming_the_file_the_panel_and_the_edge() {
    let s = support::Scratch::new("garment_bad");
    let t = tube_files(&s, 0.46);
    let g = s.join("tube.garment.yaml");
    let good = std::fs::read_to_string(&g).unwrap();
    let with = |from: &str, to: &str| {
        assert!(good.contains(from), "{from}");
        std::fs::write(&g, good.replace(from, to)).unwrap();
    };
    // a self-intersecting outline
    with(
        "[[0, 0], [0.46, 0], [0.46, 0.3], [0, 0.3]]\n    translation: [-0.23",
        "[[0, 0], [0.46, 0.3], [0.46, 0], [0, 0.3]]\n    translation: [-0.23",
    );
    refused(
        &t,
        &[
            "tube.garment.yaml",
            "\"front\"",
            "crosses itself",
            "edge 0 crosses edge 2",
        ],
    );
    // a stitch naming a missing panel, a missing edge
    with("a: [front, 1]", "a: [frnt, 1]");
    refused(
        &t,
        &["tube.garment.yaml", "seam 0", "\"frnt\" does not exist"],
    );
    with("a: [front, 1]", "a: [front, 7]");
    refused(
        &t,
        &[
            "tube.garment.yaml",
            "seam 0",
            "\"front\" has edges 0–3, not 7",
        ],
    );
    // stitched edges of wildly different lengths: the 46 cm bottom to a 30 cm side is
    // fine (1.5×), a panel 4× shorter is not
    with(
        "  back:\n    vertices: [[0, 0], [0.46, 0], [0.46, 0.3], [0, 0.3]]",
        "  back:\n    vertices: [[0, 0], [0.46, 0], [0.46, 0.075], [0, 0.075]]",
    );
    refused(
        &t,
        &[
            "seam 0",
            "edge 1 of panel \"front\" is 30.0 cm",
            "7.5 cm",
            "MAX_SEAM_RATIO",
        ],
    );
    // a pattern in the wrong unit: cm read as m
    with(
        "[[0, 0], [0.46, 0], [0.46, 0.3], [0, 0.3]]\n    translation: [-0.23",
        "[[0, 0], [46, 0], [46, 30], [0, 30]]\n    translation: [-0.23",
    );
    refused(&t, &["\"front\" is 46.00 m across", "wrong unit"]);
    // a panel that starts inside the body
    with(
        "translation: [-0.23, -0.2, 0.6]",
        "translation: [-0.23, -0.05, 0.6]",
    );
    refused(
        &t,
        &[
            "panel \"front\" starts inside the body",
            "cm under the skin",
        ],
    );
    std::fs::write(&g, &good).unwrap();
    // a body with a hole: drop one face
    let obj = s.join("cylinder.obj");
    let mesh = std::fs::read_to_string(&obj).unwrap();
    let holed: Vec<&str> = mesh.lines().collect();
    let first_face = holed.iter().position(|l| l.starts_with("f ")).unwrap();
    let mut h = holed.clone();
    h.remove(first_face);
    std::fs::write(&obj, h.join("\n")).unwrap();
    refused(
        &t,
        &[
            "cylinder.obj",
            "not shared by exactly two triangles",
            "closed",
        ],
    );
    // degenerate faces are dropped (the repair) and the trial builds
    let mut d = mesh.clone();
    d += "f 1 1 2\nf 3 3 3\n";
    std::fs::write(&obj, d).unwrap();
    let (_, check) = trial::load_body(&obj, 1.0).unwrap();
    assert_eq!(check.degenerate_dropped, 2);
}

#[test]
fn the_garmentcode_importer_agrees_with_pygarment() {
    // panel areas, stitched edge lengths and placed vertices of every shipped
    // pattern against pygarment 2.0.2's own edges (tests/garmentcode_reference.py)
    support::require_python_in(
        "python3",
        "scipy, svgpathtools",
        "python3 -m pip install -r tests/requirements.txt && python3 -m pip install --no-deps pygarment==2.0.2",
    );
    let mut checked = (0, 0);
    for name in ["tshirt", "skirt", "trousers"] {
        let spec = root().join(format!("assets/garments/{name}_specification.json"));
        let o = std::process::Command::new("python3")
            .arg(root().join("tests/garmentcode_reference.py"))
            .arg(&spec)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let pat = garment_sim::pattern::garmentcode::load(&spec).unwrap();
        for p in &pat.panels {
            let poly: Vec<[f64; 2]> = p
                .edges
                .iter()
                .flat_map(|e| e[..e.len() - 1].to_vec())
                .collect();
            let ours = 1e4 * garment_sim::cloth::polygon_area(&poly).abs();
            let theirs = r["panels"][&p.name]["area_cm2"].as_f64().unwrap();
            assert!(
                (ours - theirs).abs() <= 0.005 * theirs,
                "{name} {}: area {ours:.2} cm², pygarment {theirs:.2} cm²",
                p.name
            );
            // placed vertices (GarmentCode's frame, cm)
            for (k, v) in r["panels"][&p.name]["vertices_3d_cm"]
                .as_array()
                .unwrap()
                .iter()
                .enumerate()
            {
                let v: Vec<f64> = v
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|c| c.as_f64().unwrap())
                    .collect();
                let q = r["panels"][&p.name]["vertices_cm"][k].as_array().unwrap();
                let local =
                    Vector3::new(q[0].as_f64().unwrap(), q[1].as_f64().unwrap(), 0.0) * pat.unit;
                let ours = p.rotation * local + p.translation;
                let d = (ours - Vector3::new(v[0], v[1], v[2]) * pat.unit).norm();
                assert!(
                    d < 1e-6,
                    "{name} {} vertex {k}: {d} m from pygarment's",
                    p.name
                );
            }
            checked.0 += 1;
        }
        for s in r["stitches"].as_array().unwrap() {
            for side in ["a", "b"] {
                let panel = s[side]["panel"].as_str().unwrap();
                let edge = s[side]["edge"].as_u64().unwrap() as usize;
                let theirs = s[side]["length_cm"].as_f64().unwrap();
                let p = pat.panels.iter().find(|p| p.name == panel).unwrap();
                let ours = 100.0 * garment_sim::garment::polyline_length(&p.edges[edge]);
                assert!(
                    (ours - theirs).abs() <= 0.005 * theirs,
                    "{name} {panel}:{edge}: {ours:.3} cm, pygarment {theirs:.3} cm"
                );
                checked.1 += 1;
            }
        }
    }
    assert!(checked.0 >= 16 && checked.1 >= 80, "{checked:?}");
}

/// Is `p` inside the closed triangle mesh? Ray parity along a fixed skew
/// direction (independent of the contact code's pseudo-normals).
fn inside_mesh(p: Vector3<f64>, v: &[[f64; 3]], t: &[[u32; 3]]) -> bool {
    let d = Vector3::new(0.5773, 0.5774, 0.5775).normalize();
    let mut hits = 0;
    for tri in t {
        let a = Vector3::from(v[tri[0] as usize]);
        let b = Vector3::from(v[tri[1] as usize]);
        let c = Vector3::from(v[tri[2] as usize]);
        // Möller–Trumbore
        let (e1, e2) = (b - a, c - a);
        let h = d.cross(&e2);
        let det = e1.dot(&h);
        if det.abs() < 1e-14 {
            continue;
        }
        let s = p - a;
        let u = s.dot(&h) / det;
        let q = s.cross(&e1);
        let w = d.dot(&q) / det;
        let dist = e2.dot(&q) / det;
        if u >= 0.0 && w >= 0.0 && u + w <= 1.0 && dist > 0.0 {
            hits += 1;
        }
    }
    hits % 2 == 1
}

/// The garment of a trial's output `out` lies on the shipped body: no
/// vertex inside it (ray parity, not the contact code), nothing slid off
/// (its top above `top_above`, m).
fn on_the_body(out: &Path, top_above: f64) {
    let ((bv, bt), _) = trial::load_body(&root().join("assets/bodies/anny/body.obj"), 1.0).unwrap();
    let pts = ply_points(&out.join("garment.ply"));
    let inside = pts
        .iter()
        .filter(|p| inside_mesh(Vector3::new(p[0], p[1], p[2]), &bv, &bt))
        .count();
    assert_eq!(inside, 0, "{inside} vertices inside the body");
    let top = pts.iter().map(|p| p[2]).fold(f64::MIN, f64::max);
    assert!(top > top_above, "the garment's top is at {top} m");
}

/// The skirt hangs from the hips: its waist stays above them.
fn skirt_on_the_body(out: &Path) {
    on_the_body(out, 0.95);
}

#[test]
fn the_shipped_skirt_settles_on_a_frictionless_body_in_equilibrium() {
    // the shipped skirt and body, the skin frictionless (held by the hips'
    // shape alone), at 2 cm
    let s = support::Scratch::new("garment_skirt");
    let t = s.join("skirt.yaml");
    std::fs::write(
        &t,
        format!(
            "garment: {}\nbody:\n  obj: {}\n  skin_offset: 0.003\n  friction: 0.0\n  girths: {{waist: 1.0876, hips: 0.8826}}\nspacing: 0.02\ndt: 0.005\n",
            root().join("assets/garments/skirt.garment.yaml").display(),
            root().join("assets/bodies/anny/body.obj").display()
        ),
    )
    .unwrap();
    let out = s.join("out");
    let o = support::garment_sim()
        .args(["trial", t.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = read_json(&out.join("fit.json"));
    eprintln!("{}", serde_json::to_string_pretty(&fit["run"]).unwrap());
    assert!(
        fit["run"]["settle_time_s"].is_number(),
        "not settled: {}",
        fit["run"]
    );
    assert!(fit["run"]["final_rms_speed_m_s"].as_f64().unwrap() < 0.005);
    assert!(fit["largest_seam_gap_mm"].as_f64().unwrap() < 2.0, "{fit}");
    // equilibrium: the force on the body is the skirt's weight, straight down
    let w = fit["weight_n"].as_f64().unwrap();
    let f = numbers(&fit["contact_force_n"]);
    assert!((-f[2] / w - 1.0).abs() < 0.02, "{f:?} vs {w}");
    assert!(f[0].hypot(f[1]) < 0.02 * w, "{f:?}");
    // frictionless: the contact force is all pressure; the pressure map
    // integrates to it
    let pf = numbers(&fit["pressure_force_n"]);
    for k in 0..3 {
        assert!(
            (pf[k] - f[k]).abs() < 0.02 * w,
            "pressure {pf:?} vs contact {f:?}"
        );
    }
    // no vertex inside the body (ray parity, not the contact code), nothing
    // slid off: the waist stays above the hips
    skirt_on_the_body(&out);
    assert!(out.join("fit_pressure.png").exists());
}

#[test]
fn the_shipped_skirt_trial_settles_on_the_body_in_equilibrium() {
    // the shipped trial as it is (cloth–skin friction 0.5), at 2 cm
    let s = support::Scratch::new("garment_skirt_trial");
    let out = s.join("out");
    let t = root().join("config/trials/skirt_on_anny.yaml");
    let o = support::garment_sim()
        .args([
            "trial",
            t.to_str().unwrap(),
            "--spacing",
            "0.02",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = read_json(&out.join("fit.json"));
    eprintln!("{}", serde_json::to_string_pretty(&fit["run"]).unwrap());
    assert!(
        fit["run"]["settle_time_s"].is_number(),
        "not settled: {}",
        fit["run"]
    );
    assert!(fit["largest_seam_gap_mm"].as_f64().unwrap() < 2.0, "{fit}");
    assert_eq!(
        fit["warnings"].as_array().unwrap().len(),
        0,
        "{}",
        fit["warnings"]
    );
    let w = fit["weight_n"].as_f64().unwrap();
    let f = numbers(&fit["contact_force_n"]);
    let size = fit["contact_force_magnitude_n"].as_f64().unwrap();
    eprintln!("weight {w} N, force on the body {f:?} N");
    assert!((size / w - 1.0).abs() < 0.02 && f[2] < 0.0, "{f:?} vs {w}");
    skirt_on_the_body(&out);
}

#[test]
fn the_shipped_tshirt_trial_settles_on_the_body_in_equilibrium() {
    // the shipped trial as it is: 1 cm, cloth–skin friction 0.5 (at 2 cm
    // the underarm is too coarse for the armpit and keeps moving)
    let s = support::Scratch::new("garment_tshirt_trial");
    let out = s.join("out");
    let t = root().join("config/trials/tshirt_on_anny.yaml");
    let o = support::garment_sim()
        .args(["trial", t.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = read_json(&out.join("fit.json"));
    eprintln!("{}", serde_json::to_string_pretty(&fit["run"]).unwrap());
    assert!(
        fit["run"]["settle_time_s"].is_number(),
        "not settled: {}",
        fit["run"]
    );
    assert!(fit["run"]["final_rms_speed_m_s"].as_f64().unwrap() < 0.005);
    assert!(fit["largest_seam_gap_mm"].as_f64().unwrap() < 2.0, "{fit}");
    assert_eq!(
        fit["warnings"].as_array().unwrap().len(),
        0,
        "{}",
        fit["warnings"]
    );
    // the body carries the shirt's weight, straight down
    let w = fit["weight_n"].as_f64().unwrap();
    let f = numbers(&fit["contact_force_n"]);
    eprintln!("weight {w} N, force on the body {f:?} N");
    assert!((-f[2] / w - 1.0).abs() < 0.02, "{f:?} vs {w}");
    assert!(f[0].hypot(f[1]) < 0.02 * w, "{f:?}");
    // on the shoulders (the body's are at 1.38–1.40 m), nothing inside
    on_the_body(&out, 1.38);
}

#[test]
fn a_garment_too_small_for_the_body_is_reported_not_silent() {
    // a 60 cm tube for a 94 cm cylinder: the run ends (exit 0, the fit is
    // written) and fit.json and the error output say what is wrong
    let s = support::Scratch::new("garment_small");
    let t = tube_files(&s, 0.30);
    let out = s.join("out");
    let o = support::garment_sim()
        .args([
            "trial",
            t.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--max-time",
            "1",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let fit = read_json(&out.join("fit.json"));
    let w: Vec<String> = fit["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect();
    assert!(
        w.iter()
            .any(|w| w.contains("stretched") || w.contains("is open by")),
        "{w:?}"
    );
    assert!(err.contains("warning: "), "{err}");
}
