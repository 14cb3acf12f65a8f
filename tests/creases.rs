//! A vertex in a crease — two obstacle surfaces at once, a V-groove of two
//! boxes or of one triangle mesh — is held by both in the same step: it
//! comes to rest there, each wall carrying the share of its weight the
//! closed form of the groove gives (Lami), and dragged along the crease it
//! slides against the friction of both walls (μ times the sum of their
//! normal forces).

use garment_sim::cloth::{Cloth, GridSpec};
use garment_sim::collision::{Obstacle, ShapeSpec};
use garment_sim::fabric::Fabric;
use garment_sim::solver::{Params, Pin, PinPath, Simulation};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::path::Path;

/// Obstacle thickness and cloth thickness: the contact distance, m.
const OB_T: f64 = 0.006;
const E: f64 = OB_T + 0.002;
const G: f64 = 9.81;
const MU: f64 = 0.3;

/// A V-groove along x whose walls rise from the x axis at `ta` (on the −y
/// side) and `tb` (on the +y side) from the horizontal.
struct Groove {
    /// The walls' unit normals, pointing into the groove.
    na: Vector3<f64>,
    nb: Vector3<f64>,
    /// Where a vertex touches both: at the contact distance from each wall.
    bottom: Vector3<f64>,
    /// The closed form (Lami): the share of a weight each wall carries.
    share_a: f64,
    share_b: f64,
}

impl Groove {
    fn new(ta: f64, tb: f64) -> Groove {
        let na = Vector3::new(0.0, ta.sin(), ta.cos());
        let nb = Vector3::new(0.0, -tb.sin(), tb.cos());
        // bottom · na = bottom · nb = E, bottom ⊥ x
        let det = na.y * nb.z - na.z * nb.y;
        let bottom = Vector3::new(0.0, E * (nb.z - na.z) / det, E * (na.y - nb.y) / det);
        let s = (ta + tb).sin();
        Groove {
            na,
            nb,
            bottom,
            share_a: tb.sin() / s,
            share_b: ta.sin() / s,
        }
    }

    /// The walls as two boxes 4 cm thick, each ending at the crease line.
    fn boxes(&self) -> Vec<Obstacle> {
        [(self.na, -1.0), (self.nb, 1.0)]
            .iter()
            .enumerate()
            .map(|(k, &(n, side))| {
                // local z onto n (a rotation about x), local y along the wall
                let angle = (-n.y).atan2(n.z);
                let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), angle);
                let up = rot * Vector3::y() * side;
                let centre = up * 0.15 - n * 0.02;
                Obstacle::new(
                    &format!("wall{k}"),
                    ShapeSpec::Box {
                        size: [0.4, 0.3, 0.04],
                    },
                    Isometry3::from_parts(Translation3::from(centre), rot),
                    OB_T,
                    MU,
                )
                .unwrap()
            })
            .collect()
    }

    /// The walls as one open triangle mesh: two 0.4 × 0.3 m rectangles
    /// sharing the crease line.
    fn mesh(&self) -> Obstacle {
        let up = |n: Vector3<f64>| Vector3::x().cross(&n) * n.y.signum();
        let (ua, ub) = (up(self.na), up(self.nb));
        let v = |p: Vector3<f64>| [p.x, p.y, p.z];
        let (x0, x1) = (Vector3::x() * -0.2, Vector3::x() * 0.2);
        let vertices = vec![
            v(x0),
            v(x1),
            v(x0 + ua * 0.3),
            v(x1 + ua * 0.3),
            v(x0 + ub * 0.3),
            v(x1 + ub * 0.3),
        ];
        let triangles = vec![[0, 2, 1], [1, 2, 3], [0, 1, 4], [1, 5, 4]];
        Obstacle::new(
            "groove",
            ShapeSpec::Triangles {
                vertices,
                triangles,
            },
            Isometry3::identity(),
            OB_T,
            MU,
        )
        .unwrap()
    }
}

/// A strip 6 cm along the crease and 1 cm high, standing upright over it:
/// its lower row released 0.1 mm below the crease's bottom (inside both
/// contact distances: the step's position correction puts it on the
/// bottom), its upper row pinned 1 cm above that bottom (the strip's rest
/// height, so at rest the lower row carries only its own weight), still or
/// dragged along x at `drag` m/s from t = 0.2 s. Returns the simulation and
/// the lower row.
fn strip_in(g: &Groove, obstacles: Vec<Obstacle>, drag: f64) -> (Simulation, Vec<usize>) {
    let f: Fabric = garment_sim::io::load_fabric(Path::new("tests/data/acrylic_test.yaml"))
        .unwrap()
        .without_hysteresis();
    let up = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
    let corner = g.bottom + Vector3::new(-0.03, 0.0, -1e-4);
    let spec = GridSpec {
        size: [0.06, 0.01],
        spacing: [0.02, 0.01],
        pose: Isometry3::from_parts(Translation3::from(corner), up),
    };
    let cloth = Cloth::grid(&spec, f.areal_mass).unwrap();
    let lower: Vec<usize> = (0..4).map(|i| cloth.index(i, 0).unwrap()).collect();
    let upper: Vec<usize> = (0..4).map(|i| cloth.index(i, 1).unwrap()).collect();
    let mut sim = Simulation::new(
        cloth,
        f,
        Params {
            dt: 1e-3,
            ..Params::default()
        },
    )
    .unwrap();
    for o in obstacles {
        sim.add_obstacle(o);
    }
    let pins = upper
        .iter()
        .map(|&k| {
            let p = sim.cloth.positions()[k] + Vector3::z() * 1e-4;
            let path = if drag == 0.0 {
                PinPath::Fixed(p)
            } else {
                PinPath::Waypoints(vec![(0.2, p), (2.2, p + Vector3::x() * 2.0 * drag)])
            };
            Pin::new(k, path)
        })
        .collect();
    sim.set_pins(pins).unwrap();
    (sim, lower)
}

/// Over the last `n` of `steps` steps: the lower row's mean force from the
/// walls resolved along their normals (λa, λb) and along the crease, per
/// unit weight; its largest speed across the crease and mean speed along
/// it, m/s; and its least and largest distance to either wall's plane, m.
struct Held {
    la: f64,
    lb: f64,
    along: f64,
    across_speed: f64,
    along_speed: f64,
    nearest: f64,
    farthest: f64,
}

fn run(g: &Groove, sim: &mut Simulation, lower: &[usize], steps: usize, n: usize) -> Held {
    let mut h = Held {
        la: 0.0,
        lb: 0.0,
        along: 0.0,
        across_speed: 0.0,
        along_speed: 0.0,
        nearest: f64::INFINITY,
        farthest: 0.0,
    };
    let c = g.na.dot(&g.nb);
    let weight: f64 = lower.iter().map(|&k| sim.cloth.mass[k]).sum::<f64>() * G;
    for s in 0..steps {
        sim.step().unwrap();
        for &k in lower {
            let p = sim.cloth.positions()[k];
            let (da, db) = (p.dot(&g.na), p.dot(&g.nb));
            h.nearest = h.nearest.min(da.min(db));
            if s + n >= steps {
                h.farthest = h.farthest.max(da.max(db));
                let f = sim.contact_forces()[k];
                let (fa, fb) = (f.dot(&g.na), f.dot(&g.nb));
                h.la += (fa - c * fb) / (1.0 - c * c) / weight / n as f64;
                h.lb += (fb - c * fa) / (1.0 - c * c) / weight / n as f64;
                h.along += f.x / weight / n as f64;
                let v = sim.cloth.velocities()[k];
                h.across_speed = h.across_speed.max(v.yz().norm());
                h.along_speed += v.x / (n * lower.len()) as f64;
            }
        }
    }
    h
}

fn groove_rest(name: &str, ta: f64, tb: f64, mesh: bool) {
    let g = Groove::new(ta.to_radians(), tb.to_radians());
    let obs = if mesh { vec![g.mesh()] } else { g.boxes() };
    let (mut sim, lower) = strip_in(&g, obs, 0.0);
    let h = run(&g, &mut sim, &lower, 1000, 100);
    println!(
        "{name}: walls carry {:.4} and {:.4} of the weight (closed form {:.4}, {:.4}), \
         {:.2e} along the crease; speed ≤ {:.2e} m/s; distance to the walls {:.4}–{:.4} mm \
         (contact distance {:.1} mm)",
        h.la,
        h.lb,
        g.share_a,
        g.share_b,
        h.along,
        h.across_speed,
        h.nearest * 1e3,
        h.farthest * 1e3,
        E * 1e3
    );
    assert!(
        (h.la / g.share_a - 1.0).abs() < 0.01,
        "{name}: wall a {}",
        h.la
    );
    assert!(
        (h.lb / g.share_b - 1.0).abs() < 0.01,
        "{name}: wall b {}",
        h.lb
    );
    assert!(h.along.abs() < 0.01, "{name}: {} along the crease", h.along);
    assert!(
        h.across_speed < 1e-4,
        "{name}: moving at {} m/s",
        h.across_speed
    );
    // never inside a wall's contact layer by more than the solve's error,
    // and held on both at the contact distance
    assert!(h.nearest > E - 1e-5, "{name}: {} m from a wall", h.nearest);
    assert!(
        h.farthest < E + 1e-5,
        "{name}: {} m from a wall",
        h.farthest
    );
}

#[test]
fn a_strip_comes_to_rest_in_a_groove_of_two_boxes() {
    groove_rest("boxes 45°/45°", 45.0, 45.0, false);
    groove_rest("boxes 55°/25°", 55.0, 25.0, false);
}

#[test]
fn a_strip_comes_to_rest_in_a_groove_of_one_mesh() {
    groove_rest("mesh 45°/45°", 45.0, 45.0, true);
    groove_rest("mesh 55°/25°", 55.0, 25.0, true);
}

/// Dragged along the crease at 5 cm/s, the lower row slides with its pins
/// against kinetic friction from both walls: μ times the sum of their
/// normal forces, which keep the closed form's ratio.
#[test]
fn a_strip_dragged_along_a_crease_meets_both_walls_friction() {
    for (name, ta, tb, mesh) in [
        ("boxes 55°/25°", 55.0, 25.0, false),
        ("mesh 45°/45°", 45.0, 45.0, true),
    ] {
        let g = Groove::new(f64::to_radians(ta), f64::to_radians(tb));
        let obs = if mesh { vec![g.mesh()] } else { g.boxes() };
        let drag = 0.05;
        let (mut sim, lower) = strip_in(&g, obs, drag);
        let h = run(&g, &mut sim, &lower, 1000, 200);
        let ratio = -h.along / (h.la + h.lb);
        println!(
            "{name} dragged: friction {:.4} × the normal forces (μ = {MU}); walls' ratio {:.4} \
             (closed form {:.4}); sliding at {:.4} m/s, across ≤ {:.2e} m/s; distance to the \
             walls {:.4}–{:.4} mm",
            ratio,
            h.la / h.lb,
            g.share_a / g.share_b,
            h.along_speed,
            h.across_speed,
            h.nearest * 1e3,
            h.farthest * 1e3
        );
        assert!(
            (ratio / MU - 1.0).abs() < 0.02,
            "{name}: friction ratio {ratio}"
        );
        assert!(
            ((h.la / h.lb) / (g.share_a / g.share_b) - 1.0).abs() < 0.02,
            "{name}: walls' ratio {}",
            h.la / h.lb
        );
        assert!(
            (h.along_speed / drag - 1.0).abs() < 0.02,
            "{name}: {}",
            h.along_speed
        );
        assert!(
            h.across_speed < 1e-3,
            "{name}: {} m/s across",
            h.across_speed
        );
        assert!(h.nearest > E - 1e-5, "{name}: {} m from a wall", h.nearest);
    }
}
