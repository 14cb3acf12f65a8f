//! Dressing (`dressing:` in a trial file, docs/bodies.md): a gripper pulls
//! a sleeve of the garment over an arm of the body, from past the
//! fingertips to the shoulder; the run reports how far the sleeve's opening
//! has travelled along the arm and the force on the arm at every step.
//!
//! Phases:
//! 1. **Sewing** on the body, as every trial sews ([`crate::trial`]).
//! 2. **Placement.** The sewn garment is moved as a rigid body onto the
//!    arm's axis past the fingertips: holding the armhole (`grip: armhole`,
//!    the default), threaded on the hand through its widest opening other
//!    than the sleeve's (a T-shirt's hem), the armhole's centre `beyond` m
//!    past the fingertips; holding the cuff (`grip: cuff`), the cuff there
//!    across the axis and the rest of the garment beyond it. Of the turns
//!    about the axis, the one that leaves the garment farthest from the body.
//! 3. **Dressing.** Gravity on. The gripper holds the held opening's
//!    vertices (pins): for `hang` s it opens them into a ring of their own
//!    length and holds still, then moves along the arm at `speed` m/s
//!    (along the axis), the ring round the arm's section with at least
//!    `clearance` m to spare, to the shoulder or as far as it passes, and
//!    holds there for `hold` s. Holding the armhole, it also holds the
//!    sleeve's cuff open a sleeve's length ahead and lets it go past the
//!    wrist. Where a ring across the axis would meet the body short of the
//!    shoulder, the gripper tilts it like an armhole seam over the last
//!    10 cm of the axis (`TILT_RAMP`). With a `force_limit`, the gripper
//!    stops where it is once the garment pulls on it with more than that
//!    (a robot's safety stop). With `hand: hull` (the default) the cloth
//!    meets the hand's convex hull (an obstacle of its own, counted as the
//!    hand in every force) instead of the mesh's fingers and thumb.
//!
//! The arm comes from the body mesh alone ([`Arm::of`]).

use crate::collision::Obstacle;
use crate::garment::Garment;
use crate::run::{Control, Run};
use crate::set::Handle;
use crate::solver::{Pin, PinPath, Simulation};
use crate::trial::body_forces;
use anyhow::{bail, Context, Result};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BinaryHeap;
use std::path::Path;

type V3 = Vector3<f64>;

/// Which arm (the wearer's: the left hand is toward +x in the body frame of
/// the shipped bodies).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    Left,
    Right,
}

/// Which end of the sleeve the gripper holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Grip {
    /// The sleeve's top, where it is sewn into the armhole, as a carer
    /// dresses an arm: the garment starts threaded on the hand through its
    /// widest opening (a T-shirt's hem), the hand enters the sleeve from
    /// inside the garment, leaves it at the cuff, and the armhole is drawn
    /// up to the shoulder.
    #[default]
    Armhole,
    /// The sleeve's free end (its cuff), the garment beyond it, away from
    /// the body: the hand enters the cuff and the sleeve goes on the arm
    /// upside down; once the armhole passes the hand, the garment's body is
    /// dragged over it (docs/bodies.md).
    Cuff,
}

/// What the cloth meets at the hand while dressing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Hand {
    /// The body's mesh as it is (fingers apart, the thumb out).
    Mesh,
    /// The hand's convex hull, as a person being dressed holds the hand
    /// closed: the cloth slides over it and cannot enter the gaps between
    /// the fingers or round the thumb's web, which at a garment's spacing
    /// are narrower than a cell (docs/bodies.md). The hull is an obstacle
    /// of its own; its contacts count as the hand's in every force.
    #[default]
    Hull,
}

/// The `dressing:` section of a trial file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DressingFile {
    pub arm: Side,
    /// Which end of the sleeve the gripper holds (`armhole` when absent).
    #[serde(default)]
    pub grip: Grip,
    /// Gripper speed along the arm's axis, m/s.
    #[serde(default = "DressingFile::d_speed")]
    pub speed: f64,
    /// Time the gripper holds still at the start (the garment swings down), s.
    #[serde(default = "DressingFile::d_hang")]
    pub hang: f64,
    /// Time it holds at the shoulder at the end, s.
    #[serde(default = "DressingFile::d_hold")]
    pub hold: f64,
    /// Where the held opening's centre starts: this far past the fingertips
    /// along the hand, m.
    #[serde(default = "DressingFile::d_beyond")]
    pub beyond: f64,
    /// The gripper's safety stop: once the garment pulls on it with more
    /// than this, N, it stops where it is and holds for `hold` s (none: it
    /// follows its path whatever the force).
    #[serde(default)]
    pub force_limit: Option<f64>,
    /// Least clearance of the held cuff from the arm's section, m (the
    /// hoop is made rounder than that where the cuff is long enough).
    #[serde(default = "DressingFile::d_clearance")]
    pub clearance: f64,
    /// The body's vertices and edges meet the cloth's triangles and edges
    /// while dressing (`Params::obstacle_edges`), so that fingers thinner
    /// than the cloth's spacing cannot pass between its vertices (off when
    /// absent; docs/bodies.md tells what it changes).
    #[serde(default)]
    pub edge_contacts: bool,
    /// What the cloth meets at the hand (`hull` when absent).
    #[serde(default)]
    pub hand: Hand,
}

impl DressingFile {
    fn d_speed() -> f64 {
        0.15
    }
    fn d_hang() -> f64 {
        0.5
    }
    fn d_hold() -> f64 {
        0.5
    }
    fn d_beyond() -> f64 {
        0.08
    }
    fn d_clearance() -> f64 {
        0.01
    }

    pub fn check(&self) -> Result<()> {
        use crate::limits::check_range;
        check_range(
            "dressing.speed",
            self.speed,
            0.01,
            2.0,
            "m/s",
            "a hand's pace",
        )?;
        check_range("dressing.hang", self.hang, 0.0, 10.0, "s", "a pause")?;
        check_range("dressing.hold", self.hold, 0.0, 10.0, "s", "a pause")?;
        if let Some(f) = self.force_limit {
            check_range("dressing.force_limit", f, 0.1, 1e5, "N", "a gripper's pull")?;
        }
        check_range(
            "dressing.beyond",
            self.beyond,
            0.0,
            0.5,
            "m",
            "a start near the hand",
        )?;
        check_range(
            "dressing.clearance",
            self.clearance,
            0.005,
            0.2,
            "m",
            "a gap between the cuff and the arm",
        )?;
        Ok(())
    }
}

/// A level set of the geodesic distance from the fingertip: a ring around
/// the arm.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Ring {
    /// Geodesic distance from the fingertip, m.
    pub level: f64,
    /// Mean of the points where the level crosses the mesh's edges.
    pub centre: [f64; 3],
    /// Their mean distance from it, m.
    pub radius: f64,
}

/// An arm found on a body mesh.
///
/// The rule: the **fingertip** is the body's vertex farthest toward the
/// arm's side (largest x for the left arm, smallest for the right). Rings
/// are the level sets, every 1 cm, of the geodesic distance from it (the
/// shortest path along the mesh's edges); each ring's centre is the mean of
/// the points where the level crosses an edge, its radius their mean
/// distance from that centre. The **wrist** is the narrowest ring between
/// 10 and 30 cm from the fingertip (an adult's hand is 17–20 cm long). The
/// **shoulder** is the last ring before the rings start to widen into the
/// torso: the ring 3 cm before the first ring (past the wrist) whose radius
/// exceeds that of the ring 3 cm before it by more than 9 mm (along the
/// arm they widen by at most a few mm in 3 cm). The **axis** runs from a
/// start point on the wrist–fingertip line `beyond` m past the farthest
/// hand vertex, along that line (1 cm apart) to the wrist, then through the
/// rings' centres to the shoulder. The arm's **vertices** are the body's
/// vertices nearer the fingertip (geodesically) than the shoulder ring.
#[derive(Debug, Clone)]
pub struct Arm {
    pub fingertip: V3,
    pub rings: Vec<Ring>,
    /// Indices into `rings`.
    pub wrist_ring: usize,
    pub shoulder_ring: usize,
    /// The axis, from the start point past the fingertips to the shoulder.
    pub axis: Vec<V3>,
    /// Arc length of the axis at each of its points, m.
    pub s: Vec<f64>,
    /// Index of the wrist on the axis.
    pub wrist_at: usize,
    /// Body vertices of the arm.
    pub vertices: Vec<bool>,
    /// Geodesic distance of every body vertex from the fingertip, m.
    pub geodesic: Vec<f64>,
}

#[derive(PartialEq)]
struct Near(f64, usize);
impl Eq for Near {}
impl PartialOrd for Near {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Near {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Shortest distances along the mesh's edges from vertex `from`.
pub fn geodesic(v: &[V3], edges: &[(usize, usize)], from: usize) -> Vec<f64> {
    let mut adj: Vec<Vec<(usize, f64)>> = vec![Vec::new(); v.len()];
    for &(a, b) in edges {
        let d = (v[a] - v[b]).norm();
        adj[a].push((b, d));
        adj[b].push((a, d));
    }
    let mut g = vec![f64::INFINITY; v.len()];
    g[from] = 0.0;
    let mut heap = BinaryHeap::new();
    heap.push(Near(0.0, from));
    while let Some(Near(d, a)) = heap.pop() {
        if d > g[a] {
            continue;
        }
        for &(b, w) in &adj[a] {
            if d + w < g[b] {
                g[b] = d + w;
                heap.push(Near(d + w, b));
            }
        }
    }
    g
}

fn mesh_edges(t: &[[u32; 3]]) -> Vec<(usize, usize)> {
    let mut e: Vec<(usize, usize)> = t
        .iter()
        .flat_map(|tri| {
            (0..3).map(move |k| {
                let (a, b) = (tri[k] as usize, tri[(k + 1) % 3] as usize);
                (a.min(b), a.max(b))
            })
        })
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

/// Nearest point of a polyline to `p`: its arc length from the first point
/// and its distance from `p`.
pub fn project_on_polyline(axis: &[V3], p: &V3) -> (f64, f64) {
    if axis.len() == 1 {
        return (0.0, (p - axis[0]).norm());
    }
    let mut best = (0.0, f64::INFINITY);
    let mut s0 = 0.0;
    for w in axis.windows(2) {
        let d = w[1] - w[0];
        let l = d.norm();
        let u = if l > 0.0 {
            ((p - w[0]).dot(&d) / (l * l)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let dist = (w[0] + d * u - p).norm();
        if dist < best.1 {
            best = (s0 + u * l, dist);
        }
        s0 += l;
    }
    best
}

/// How far a ring of cloth vertices (the sleeve's opening) has travelled
/// along the axis: its centroid's nearest point on the axis, as the arc
/// length from the axis point at arc length `from` (the wrist), m, and the
/// centroid's distance from the axis, m.
pub fn progress(axis: &[V3], from: f64, ring: &[V3]) -> (f64, f64) {
    let c = ring.iter().sum::<V3>() / ring.len().max(1) as f64;
    let (s, d) = project_on_polyline(axis, &c);
    (s - from, d)
}

fn arc_lengths(p: &[V3]) -> Vec<f64> {
    let mut s = vec![0.0];
    for w in p.windows(2) {
        s.push(s.last().expect("one") + (w[1] - w[0]).norm());
    }
    s
}

impl Arm {
    /// Finds the arm on a closed body mesh (world positions); see [`Arm`].
    pub fn of(v: &[V3], t: &[[u32; 3]], side: Side, beyond: f64) -> Result<Arm> {
        let sign = match side {
            Side::Left => 1.0,
            Side::Right => -1.0,
        };
        let tip = (0..v.len())
            .max_by(|&a, &b| (sign * v[a].x).total_cmp(&(sign * v[b].x)))
            .context("the body has no vertices")?;
        let edges = mesh_edges(t);
        let g = geodesic(v, &edges, tip);
        let top = g
            .iter()
            .copied()
            .filter(|d| d.is_finite())
            .fold(0.0, f64::max);
        let mut rings = Vec::new();
        let mut k = 1;
        while k as f64 * 0.01 < top.min(1.5) {
            let level = k as f64 * 0.01;
            let pts: Vec<V3> = edges
                .iter()
                .filter(|&&(a, b)| (g[a] - level) * (g[b] - level) < 0.0)
                .map(|&(a, b)| {
                    let f = (level - g[a]) / (g[b] - g[a]);
                    v[a] + (v[b] - v[a]) * f
                })
                .collect();
            if pts.len() >= 3 {
                let c = pts.iter().sum::<V3>() / pts.len() as f64;
                let r = pts.iter().map(|p| (p - c).norm()).sum::<f64>() / pts.len() as f64;
                rings.push(Ring {
                    level,
                    centre: c.into(),
                    radius: r,
                });
            }
            k += 1;
        }
        let wrist_ring = (0..rings.len())
            .filter(|&i| (0.10 - 1e-9..=0.30 + 1e-9).contains(&rings[i].level))
            .min_by(|&a, &b| rings[a].radius.total_cmp(&rings[b].radius))
            .context("no ring 10–30 cm from the fingertip: is this an arm?")?;
        let back = |i: usize| {
            (0..i)
                .rev()
                .find(|&j| rings[i].level - rings[j].level >= 0.03 - 1e-9)
        };
        let shoulder_ring = (wrist_ring + 1..rings.len())
            .find_map(|i| {
                let j = back(i)?;
                (j >= wrist_ring && rings[i].radius - rings[j].radius > 0.009).then_some(j)
            })
            .context("the rings past the wrist never widen into a torso: no shoulder found")?;
        if shoulder_ring <= wrist_ring + 5 {
            bail!("the arm found is under 5 cm long (wrist to shoulder)");
        }
        let wrist = V3::from(rings[wrist_ring].centre);
        let fingertip = v[tip];
        let u = (fingertip - wrist).normalize();
        let hand_end = (0..v.len())
            .filter(|&i| g[i] < rings[wrist_ring].level)
            .map(|i| (v[i] - wrist).dot(&u))
            .fold(0.0, f64::max);
        let start_len = hand_end + beyond;
        let n = (start_len / 0.01).ceil() as usize;
        let mut axis: Vec<V3> = (0..n)
            .map(|k| wrist + u * (start_len * (n - k) as f64 / n as f64))
            .collect();
        let wrist_at = axis.len();
        axis.extend(
            rings[wrist_ring..=shoulder_ring]
                .iter()
                .map(|r| V3::from(r.centre)),
        );
        let s = arc_lengths(&axis);
        let level = rings[shoulder_ring].level;
        Ok(Arm {
            fingertip,
            vertices: g.iter().map(|d| *d <= level).collect(),
            rings,
            wrist_ring,
            shoulder_ring,
            axis,
            s,
            wrist_at,
            geodesic: g,
        })
    }

    pub fn wrist(&self) -> V3 {
        self.axis[self.wrist_at]
    }
    pub fn shoulder(&self) -> V3 {
        *self.axis.last().expect("an axis")
    }
    /// Wrist to shoulder along the axis, m.
    pub fn length(&self) -> f64 {
        self.s.last().expect("an axis") - self.s[self.wrist_at]
    }
    /// The unit tangent of the axis at its point k.
    fn tangent(&self, k: usize) -> V3 {
        let a = self.axis[k.saturating_sub(1)];
        let b = self.axis[(k + 1).min(self.axis.len() - 1)];
        (b - a).normalize()
    }
}

/// The direction across `t` nearest to +z (the gripper rides on top).
fn up_across(t: &V3) -> V3 {
    let z = V3::z();
    let u = z - t * z.dot(t);
    if u.norm() > 1e-6 {
        u.normalize()
    } else {
        t.cross(&V3::x()).normalize()
    }
}

/// The dressing once set up: the arm, the cuff, the gripper.
#[derive(Debug, Clone)]
pub struct Dressing {
    pub arm: Arm,
    /// The held opening's vertices (the armhole's or the cuff's, as
    /// `DressingFile::grip` says), in order around it.
    pub cuff: Vec<usize>,
    /// Its length around as the gripper holds it open, m: as cut (the
    /// pattern's) holding the armhole, as sewn holding the cuff.
    pub held_opening_m: f64,
    /// The sleeve's free end (its cuff) vertices, in order around it.
    pub sleeve_end: Vec<usize>,
    /// The vertices the gripper holds (the held opening's, and holding the
    /// armhole the cuff's until it is let go; each once).
    pub gripped: Vec<usize>,
    /// The cloth vertices of the sleeve: the panels the cuff's edges belong
    /// to.
    pub sleeve: Vec<bool>,
    /// Simulated times at which the gripper starts to move, arrives at the
    /// end of its path, and the run ends, s.
    pub t_move: f64,
    pub t_arrive: f64,
    pub t_end: f64,
    /// When the gripper lets the sleeve's cuff go, s, and its vertices
    /// (holding the armhole, it holds the cuff open over the hand first).
    pub release: Option<(f64, Vec<usize>)>,
    /// Holding the armhole: the length around of the opening the garment
    /// was threaded on the arm through, m.
    pub entry_opening_m: Option<f64>,
    /// The gripper's path: the ring's centre at each waypoint (at the
    /// start, the first cuff vertex), m.
    pub gripper_path: Vec<(f64, V3)>,
    /// The gripper's path ends at this axis point (the shoulder, or as far
    /// as the cuff passes round the arm).
    pub path_end: usize,
    /// How far the hoop is tilted from across the axis at the path's end,
    /// degrees (0: it reaches its end untilted).
    pub end_tilt_deg: f64,
    pub body: Handle<Obstacle>,
    /// `hand: hull`: the hand's hull, an obstacle of its own.
    pub hand: Option<Handle<Obstacle>>,
    /// The body's mesh (world), for the force split.
    body_vertices: Vec<V3>,
    body_triangles: Vec<[u32; 3]>,
}

/// One step of the dressing (a row of `dressing.csv`).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct DressingRow {
    pub time_s: f64,
    /// The held vertices' mean (the ring's centre), m.
    pub gripper: [f64; 3],
    /// The held opening's centroid's travel along the arm from the wrist, m
    /// (negative: not yet at the wrist), and as a fraction of wrist →
    /// shoulder.
    pub progress_m: f64,
    pub progress: f64,
    /// The same for the sleeve's free end (its cuff), m and fraction.
    pub sleeve_end_progress_m: f64,
    pub sleeve_end_progress: f64,
    /// The held opening's centroid's distance from the arm's axis, m.
    pub off_axis_m: f64,
    /// Force of the garment on the arm (Σ of its contacts' forces), N.
    pub arm_force: [f64; 3],
    pub arm_force_n: f64,
    /// Σ of those contacts' normal forces, N.
    pub arm_normal_force_n: f64,
    pub arm_contacts: usize,
    /// The part of the force on the arm that is on the hand (the arm's
    /// vertices before the wrist ring), N (size of the sum).
    pub hand_force_n: f64,
    /// The rest of it: the force on the arm past the wrist (forearm and
    /// upper arm), N (size of the sum).
    pub wrist_to_shoulder_force_n: f64,
    /// The part of the force on the arm that the sleeve's panels exert, N
    /// (the rest is the garment's other panels).
    pub sleeve_force_n: f64,
    /// Where along the arm the force past the wrist acts: those contacts'
    /// mean position along the axis weighted by their forces' sizes, from
    /// the wrist, m (NaN with no contact there).
    pub wrist_to_shoulder_force_at_m: f64,
    /// Force of the garment on the whole body, N.
    pub body_force_n: f64,
    pub body_contacts: usize,
    /// Force of the garment on the gripper (the opposite of the pins'
    /// reactions on the cloth), N.
    pub gripper_force: [f64; 3],
    pub gripper_force_n: f64,
}

/// What `fit.json` says of a dressing.
#[derive(Debug, Clone, Serialize)]
pub struct DressingReport {
    pub arm: Side,
    pub fingertip: [f64; 3],
    pub wrist: [f64; 3],
    pub shoulder: [f64; 3],
    /// Wrist to shoulder along the axis, m.
    pub arm_length_m: f64,
    /// The arm's body vertices.
    pub arm_vertices: usize,
    pub cuff_vertices: usize,
    /// Which end of the sleeve the gripper held.
    pub grip: Grip,
    /// What the cloth met at the hand: the body's mesh or the hand's hull.
    pub hand: Hand,
    /// Holding the armhole: the length around of the opening the arm was
    /// threaded through (a T-shirt's hem), m.
    pub entry_opening_m: Option<f64>,
    /// The sleeve's free end (cuff) at the end: its centroid's travel along
    /// the arm from the wrist, m.
    pub final_sleeve_end_progress_m: f64,
    pub gripped_vertices: usize,
    /// The held opening's length around as the gripper holds it, m.
    pub held_opening_m: f64,
    /// The gripper's path along the axis, m, and its speed, m/s.
    pub path_length_m: f64,
    /// Where the path ends (the hoop's centre), as progress from the wrist,
    /// m and fraction of wrist → shoulder.
    pub path_end_progress_m: f64,
    pub path_end_progress: f64,
    /// The hoop's tilt from across the axis there, degrees.
    pub path_end_tilt_deg: f64,
    pub speed_m_s: f64,
    /// The gripper's force limit, N, and when it stopped the gripper, s
    /// (`null`: no limit / never).
    pub force_limit_n: Option<f64>,
    pub safety_stop_s: Option<f64>,
    pub duration_s: f64,
    pub steps: usize,
    pub ms_per_step: f64,
    /// At the end.
    pub final_progress_m: f64,
    pub final_progress: f64,
    pub final_off_axis_m: f64,
    /// Distance of the cuff's centroid from the shoulder point at the end, m.
    pub final_distance_to_shoulder_m: f64,
    /// Largest force on the arm, N, and when, s.
    pub peak_arm_force_n: f64,
    pub peak_arm_force_time_s: f64,
    /// Largest force on the hand (the arm's vertices before the wrist), N,
    /// and when, s.
    pub peak_hand_force_n: f64,
    pub peak_hand_force_time_s: f64,
    /// Largest force on the arm past the wrist (forearm and upper arm), N;
    /// when, s; where along the arm it acted (from the wrist, m); the cuff's
    /// progress then.
    pub peak_wrist_to_shoulder_force_n: f64,
    pub peak_wrist_to_shoulder_force_time_s: f64,
    pub peak_wrist_to_shoulder_force_at_m: f64,
    pub peak_wrist_to_shoulder_force_progress: f64,
    pub peak_body_force_n: f64,
    pub peak_gripper_force_n: f64,
    /// First time the garment touched the arm, s (`null`: never).
    pub first_arm_contact_s: Option<f64>,
    /// The run was stopped before its end (a signal: Ctrl-C, SIGTERM); the
    /// rows and the final state are those of the steps taken.
    pub stopped_early: bool,
    /// The dressing was cut short at this long after sewing (`trial
    /// --max-time`), s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_limit_s: Option<f64>,
}

/// The garment's cuff on the chosen arm, in order around it: the vertices
/// of the pattern edges that no seam joins whose centroid lies within 8 cm
/// of the arm's axis (wrist to shoulder), as sewn on the body; the edges
/// chained end to nearest end (a vertex where two panels meet comes twice,
/// once from each).
pub fn find_cuff(g: &Garment, x: &[V3], arm: &Arm) -> Result<Vec<usize>> {
    let sewn = sewn_edges(g);
    let upper = &arm.axis[arm.wrist_at..];
    let mut edges: Vec<Vec<usize>> = Vec::new();
    for (p, panel) in g.panels.iter().enumerate() {
        for (e, verts) in panel.edge_vertices.iter().enumerate() {
            if sewn.contains(&(p, e)) || verts.is_empty() {
                continue;
            }
            let c = verts.iter().map(|(i, _)| x[*i]).sum::<V3>() / verts.len() as f64;
            if project_on_polyline(upper, &c).1 < 0.08 {
                edges.push(verts.iter().map(|(i, _)| *i).collect());
            }
        }
    }
    if edges.iter().map(Vec::len).sum::<usize>() < 3 {
        bail!(
            "no sleeve opening found on the arm: no unsewn pattern edge lies within 8 cm of \
             the arm's axis once the garment is sewn on the body"
        );
    }
    Ok(chain(edges, x))
}

/// Pattern edges' vertex runs chained end to nearest end into one loop.
fn chain(mut edges: Vec<Vec<usize>>, x: &[V3]) -> Vec<usize> {
    let mut cuff = edges.remove(0);
    while !edges.is_empty() {
        let end = x[*cuff.last().expect("non-empty")];
        let (k, flip) = (0..edges.len())
            .flat_map(|k| [(k, false), (k, true)])
            .min_by(|a, b| {
                let d = |&(k, f): &(usize, bool)| {
                    let e = &edges[k];
                    (x[if f { e[e.len() - 1] } else { e[0] }] - end).norm()
                };
                d(a).total_cmp(&d(b))
            })
            .expect("edges left");
        let mut e = edges.remove(k);
        if flip {
            e.reverse();
        }
        cuff.extend(e);
    }
    cuff
}

/// The distances as cut between each vertex of a ring of pattern-edge
/// vertices and the next (the last to the first), m: along a pattern edge
/// both lie on, their fractions' difference times its length; from one edge
/// to another, each one's distance from its edge's nearer end (the corner
/// where the two edges meet once sewn).
fn cut_gaps(g: &Garment, ring: &[usize]) -> Vec<f64> {
    let on: std::collections::HashSet<usize> = ring.iter().copied().collect();
    // a vertex's place on a pattern edge: (panel, edge), the edge's length,
    // the vertex's fraction of it
    type Place = ((usize, usize), f64, f64);
    // each ring vertex's places on the pattern edges that have two or more
    // of the ring's vertices
    let mut at: std::collections::HashMap<usize, Vec<Place>> = std::collections::HashMap::new();
    for (p, panel) in g.panels.iter().enumerate() {
        for (e, ev) in panel.edge_vertices.iter().enumerate() {
            if ev.iter().filter(|(v, _)| on.contains(v)).count() < 2 {
                continue;
            }
            for &(v, t) in ev.iter().filter(|(v, _)| on.contains(v)) {
                at.entry(v)
                    .or_default()
                    .push(((p, e), panel.edge_lengths[e], t));
            }
        }
    }
    let n = ring.len();
    (0..n)
        .map(|k| {
            let (a, b) = (ring[k], ring[(k + 1) % n]);
            let (pa, pb) = (at.get(&a), at.get(&b));
            // every vertex of a ring of pattern edges has a place
            let (Some(pa), Some(pb)) = (pa, pb) else {
                unreachable!("vertex {a} or {b} of the ring is on none of its edges")
            };
            let shared = pa.iter().find_map(|(ea, l, ta)| {
                pb.iter()
                    .find(|(eb, _, _)| eb == ea)
                    .map(|(_, _, tb)| (ta - tb).abs() * l)
            });
            shared.unwrap_or_else(|| {
                let end = |p: &[Place]| {
                    p.iter()
                        .map(|(_, l, t)| t.min(1.0 - t) * l)
                        .fold(f64::INFINITY, f64::min)
                };
                end(pa) + end(pb)
            })
        })
        .collect()
}

/// The mean of some of the positions `x`.
fn centroid(x: &[V3], ring: &[usize]) -> V3 {
    ring.iter().map(|&i| x[i]).sum::<V3>() / ring.len() as f64
}

/// The normal of the plane that best fits some of the positions `x` about
/// `c` (their covariance's weakest direction), either sign.
fn plane_normal(x: &[V3], ring: &[usize], c: &V3) -> V3 {
    let mut cov = Matrix3::zeros();
    for &i in ring {
        let r = x[i] - c;
        cov += r * r.transpose();
    }
    let eig = cov.symmetric_eigen();
    eig.eigenvectors.column(eig.eigenvalues.imin()).into()
}

/// The garment's pattern edges that a seam joins, as (panel, edge).
fn sewn_edges(g: &Garment) -> std::collections::HashSet<(usize, usize)> {
    g.seams.iter().flat_map(|s| [s.a, s.b]).collect()
}

/// Pins for `verts`, each from its place `x` at `t0` along its points of
/// `rings` (one per vertex, in `verts`' order) at `times`.
fn ring_pins(verts: &[usize], x: &[V3], t0: f64, times: &[f64], rings: &[Vec<V3>]) -> Vec<Pin> {
    verts
        .iter()
        .enumerate()
        .map(|(j, &v)| {
            let mut w = vec![(t0, x[v])];
            w.extend(times.iter().zip(rings).map(|(t, r)| (*t, r[j])));
            Pin::new(v, PinPath::Waypoints(w))
        })
        .collect()
}

/// The panels a set of vertices belongs to.
fn panels_of(g: &Garment, v: &[usize]) -> Vec<bool> {
    g.panels
        .iter()
        .map(|p| v.iter().any(|i| (p.first..p.first + p.count).contains(i)))
        .collect()
}

/// The sleeve's armhole, in order around it: the sleeve panels' (the cuff's
/// panels') vertices on the pattern edges sewn to other panels.
pub fn find_armhole(g: &Garment, x: &[V3], cuff: &[usize]) -> Result<Vec<usize>> {
    let sleeve = panels_of(g, cuff);
    let edges: Vec<Vec<usize>> = g
        .seams
        .iter()
        .filter(|s| sleeve[s.a.0] != sleeve[s.b.0])
        .map(|s| {
            let (p, e) = if sleeve[s.a.0] { s.a } else { s.b };
            g.panels[p].edge_vertices[e]
                .iter()
                .map(|(i, _)| *i)
                .collect()
        })
        .collect();
    if edges.iter().map(Vec::len).sum::<usize>() < 3 {
        bail!(
            "the sleeve ({}) is sewn to no other panel: no armhole to hold",
            g.panels
                .iter()
                .zip(&sleeve)
                .filter(|(_, s)| **s)
                .map(|(p, _)| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(chain(edges, x))
}

/// The garment's openings as sewn: its unsewn pattern edges grouped where
/// their ends meet (within `tol`, m), each with its vertices and length
/// around, m; the widest first.
pub fn openings(g: &Garment, x: &[V3], tol: f64) -> Vec<(Vec<usize>, f64)> {
    let sewn = sewn_edges(g);
    let edges: Vec<(Vec<usize>, f64)> = g
        .panels
        .iter()
        .enumerate()
        .flat_map(|(p, panel)| {
            let sewn = &sewn;
            panel
                .edge_vertices
                .iter()
                .enumerate()
                .filter(move |(e, v)| !sewn.contains(&(p, *e)) && v.len() >= 2)
                .map(|(_, v)| {
                    let v: Vec<usize> = v.iter().map(|(i, _)| *i).collect();
                    let l = v.windows(2).map(|w| (x[w[1]] - x[w[0]]).norm()).sum();
                    (v, l)
                })
        })
        .collect();
    let n = edges.len();
    let mut group: Vec<usize> = (0..n).collect();
    fn root(g: &mut [usize], mut i: usize) -> usize {
        while g[i] != i {
            g[i] = g[g[i]];
            i = g[i];
        }
        i
    }
    let ends = |k: usize| {
        let v = &edges[k].0;
        [x[v[0]], x[v[v.len() - 1]]]
    };
    for a in 0..n {
        for b in a + 1..n {
            let near = ends(a)
                .iter()
                .any(|p| ends(b).iter().any(|q| (p - q).norm() <= tol));
            if near {
                let (ra, rb) = (root(&mut group, a), root(&mut group, b));
                group[ra] = rb;
            }
        }
    }
    let mut out: Vec<(Vec<usize>, f64)> = Vec::new();
    let mut of_root = std::collections::HashMap::new();
    for k in 0..n {
        let r = root(&mut group, k);
        let slot = *of_root.entry(r).or_insert_with(|| {
            out.push((Vec::new(), 0.0));
            out.len() - 1
        });
        out[slot].0.extend(&edges[k].0);
        out[slot].1 += edges[k].1;
    }
    out.sort_by(|a, b| b.1.total_cmp(&a.1));
    out
}

/// A ring of garment vertices the gripper holds: its length around as
/// sewn, each vertex's fraction of it, which way it turns about the axis
/// as placed (±1) and where its first vertex is in the axis' frame.
#[derive(Default)]
struct HeldRing {
    perimeter: f64,
    fractions: Vec<f64>,
    turn: f64,
    first: (f64, f64),
}

/// `hand: hull`: the hand's convex hull, as an obstacle and as the vertices
/// and edges the hoops before the wrist are cut from.
struct HandHull {
    obstacle: Obstacle,
    vertices: Vec<V3>,
    edges: Vec<(usize, usize)>,
}

/// Where a hoop's section is cut from: vertices, edges, and which vertices
/// count.
type Section<'a> = (&'a [V3], &'a [(usize, usize)], &'a dyn Fn(usize) -> bool);

/// A hoop at an axis point (its index), and the tilt of its plane from
/// across the axis.
type PlacedHoop = (usize, Hoop, UnitQuaternion<f64>);

/// The length of the axis, before the shoulder point, over which the
/// gripper tilts the hoop when a hoop across the axis would meet the body
/// short of the shoulder, m.
const TILT_RAMP: f64 = 0.10;

/// A hoop: the closed curve the gripper holds the cuff along, across the
/// axis, as a dense polygon counter-clockwise about `normal`.
#[derive(Debug, Clone)]
struct Hoop {
    centre: V3,
    curve: Vec<V3>,
}

impl Hoop {
    /// A circle of perimeter `l` about `centre`, across `normal`.
    fn circle(centre: V3, normal: V3, e1: V3, l: f64) -> Hoop {
        let r = l / std::f64::consts::TAU;
        let e2 = normal.cross(&e1);
        let curve = (0..720)
            .map(|j| {
                let a = std::f64::consts::TAU * j as f64 / 720.0;
                centre + (e1 * a.cos() + e2 * a.sin()) * r
            })
            .collect();
        Hoop { centre, curve }
    }

    /// The points at the given fractions of the perimeter, from the point
    /// in direction `from` of the centre, turning about the normal with
    /// sign `turn`.
    fn points(&self, fractions: &[f64], from: &V3, turn: f64) -> Vec<V3> {
        let n = self.curve.len();
        let k0 = (0..n)
            .max_by(|&a, &b| {
                let c = |k: usize| (self.curve[k] - self.centre).normalize().dot(from);
                c(a).total_cmp(&c(b))
            })
            .expect("a curve");
        let at = |j: usize| {
            let k = if turn >= 0.0 {
                (k0 + j) % n
            } else {
                (k0 + n - j % n) % n
            };
            self.curve[k]
        };
        let mut cum = vec![0.0; n + 1];
        for j in 1..=n {
            cum[j] = cum[j - 1] + (at(j) - at(j - 1)).norm();
        }
        let total = cum[n];
        fractions
            .iter()
            .map(|f| {
                let target = f.rem_euclid(1.0) * total;
                let j = cum.partition_point(|c| *c < target).clamp(1, n);
                let w = (target - cum[j - 1]) / (cum[j] - cum[j - 1]).max(1e-300);
                at(j - 1) + (at(j) - at(j - 1)) * w
            })
            .collect()
    }
}

/// The convex hull of `pts` grown by `r` (its Minkowski sum with a disc),
/// counter-clockwise, arcs every 3° or finer; and its perimeter (the hull's
/// plus 2π r).
pub fn grown_hull(pts: &[[f64; 2]], r: f64) -> (Vec<[f64; 2]>, f64) {
    let mut hull = crate::cloth::convex_hull(pts);
    let area: f64 = (0..hull.len())
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum();
    if area < 0.0 {
        hull.reverse();
    }
    let n = hull.len();
    if n < 3 {
        return (Vec::new(), 0.0);
    }
    let normal = |i: usize| {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l = (dx * dx + dy * dy).sqrt();
        (-dx / l).atan2(dy / l) // angle of the outward normal (dy, -dx)
    };
    let mut out = Vec::new();
    let mut perimeter = 0.0;
    for i in 0..n {
        let (a0, mut a1) = (normal((i + n - 1) % n), normal(i));
        while a1 < a0 {
            a1 += std::f64::consts::TAU;
        }
        let steps = ((a1 - a0) / 3f64.to_radians()).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let a = a0 + (a1 - a0) * k as f64 / steps as f64;
            out.push([hull[i][0] + r * a.cos(), hull[i][1] + r * a.sin()]);
        }
        let b = hull[(i + 1) % n];
        perimeter += ((b[0] - hull[i][0]).powi(2) + (b[1] - hull[i][1]).powi(2)).sqrt();
    }
    (out, perimeter + std::f64::consts::TAU * r)
}

/// The gripper's path: its hoops, the held ring's places on them, how many
/// axis points it reaches and how far its last hoop is tilted, degrees.
struct GripperPath {
    hoops: Vec<PlacedHoop>,
    rings: Vec<Vec<V3>>,
    reach: usize,
    end_tilt: f64,
}

/// When the gripper lets the sleeve's cuff go, s, and its vertices.
type Release = (f64, Vec<usize>);

/// What the gripper's path is planned from (phase 3): the arm and its
/// frames, the body's section meshes, the garment as sewn (`x0`) and as
/// placed past the fingertips (`x`), and the cuff's held ring.
struct PathPlan<'a> {
    arm: &'a Arm,
    d: &'a DressingFile,
    g: &'a Garment,
    ob: &'a Obstacle,
    hull: &'a Option<HandHull>,
    bv: &'a [V3],
    bedges: Vec<(usize, usize)>,
    x0: &'a [V3],
    x: &'a [V3],
    /// Frames carried along the axis without turning about it.
    e1: Vec<V3>,
    /// The axis' direction at its start (into the arm).
    t0v: V3,
    start: V3,
    /// Holding a seam, the direction each ring's plane normal is turned
    /// toward; holding the cuff, `None`.
    toward: Option<V3>,
    contact: f64,
    lim_hand: f64,
    lim_arm: f64,
    /// The held ring's vertex count.
    nc: usize,
    /// The cuff's held ring.
    held: HeldRing,
}

/// The `hand: hull` obstacle: the convex hull of the hand's body vertices,
/// with the body's contact layer and friction (`None` for `hand: mesh`).
fn hand_hull(
    ob: &Obstacle,
    bv: &[V3],
    arm: &Arm,
    lim_hand: f64,
    d: &DressingFile,
) -> Result<Option<HandHull>> {
    Ok(match d.hand {
        Hand::Mesh => None,
        Hand::Hull => {
            let pts: Vec<nalgebra::Point3<f64>> = (0..bv.len())
                .filter(|&i| arm.vertices[i] && arm.geodesic[i] <= lim_hand)
                .map(|i| bv[i].into())
                .collect();
            if pts.len() < 4 {
                bail!(
                    "dressing.hand: hull: the hand has {} body vertices, too few for a hull",
                    pts.len()
                );
            }
            let (hv, ht) = parry3d_f64::transformation::convex_hull(&pts);
            let vertices: Vec<V3> = hv.iter().map(|p| p.coords).collect();
            let edges = mesh_edges(&ht);
            let obstacle = Obstacle::new(
                &format!("{}_hand_hull", ob.id),
                crate::collision::ShapeSpec::Triangles {
                    vertices: vertices.iter().map(|p| [p.x, p.y, p.z]).collect(),
                    triangles: ht,
                },
                nalgebra::Isometry3::identity(),
                ob.thickness,
                ob.friction,
            )?;
            Some(HandHull {
                obstacle,
                vertices,
                edges,
            })
        }
    })
}

/// Distance of `p` from the skin (or the hand's hull), m.
fn skin_distance(ob: &Obstacle, hull: &Option<HandHull>, p: &V3) -> f64 {
    let d = ob.proximity(p).distance;
    match hull {
        Some(h) => d.min(h.obstacle.proximity(p).distance),
        None => d,
    }
}

/// The direction of the garment from the held ring (centroid `c`) that is
/// turned away from the body along the axis; holding the armhole, also the
/// length around of the opening the arm enters by, m.
fn garment_direction(
    g: &Garment,
    x0: &[V3],
    cuff: &[usize],
    sleeve_end: &[usize],
    c: &V3,
    grip: Grip,
) -> Result<(V3, Option<f64>)> {
    Ok(match grip {
        Grip::Cuff => {
            // the cuff's plane (normal: the covariance's weakest
            // direction), toward the garment's centroid
            let gc = x0.iter().sum::<V3>() / x0.len() as f64;
            let n = plane_normal(x0, cuff, c);
            let n = if n.dot(&(gc - c)) < 0.0 { -n } else { n };
            (n, None)
        }
        Grip::Armhole => {
            // the garment's widest opening other than the sleeve's
            // (a T-shirt's hem) toward the shoulder: the arm goes in
            // there and out through the armhole
            let sleeve = panels_of(g, sleeve_end);
            let entry = openings(g, x0, 0.03)
                .into_iter()
                .find(|(v, _)| !panels_of(g, v).iter().zip(&sleeve).any(|(a, b)| *a && *b))
                .context(
                    "the garment has no opening besides the sleeve's to thread the arm through",
                )?;
            let e = centroid(x0, &entry.0);
            ((c - e).normalize(), Some(entry.1))
        }
    })
}

/// The sewn garment moved past the fingertips, its held ring (centroid `c`)
/// at `start`, its direction `n` turned onto `out`, at the one of 24 turns
/// about the axis farthest from the skin.
fn place_past_fingertips(
    x0: &[V3],
    start: V3,
    c: V3,
    n: V3,
    out: V3,
    contact: f64,
    skin: impl Fn(&V3) -> f64,
) -> Result<Vec<V3>> {
    let base = UnitQuaternion::rotation_between(&n, &out).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(up_across(&out)),
            std::f64::consts::PI,
        )
    });
    let mut best: Option<(f64, Vec<V3>)> = None;
    for r in 0..24 {
        let roll = UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(out),
            r as f64 * std::f64::consts::TAU / 24.0,
        );
        let q = roll * base;
        let placed: Vec<V3> = x0.iter().map(|p| start + q * (p - c)).collect();
        let near = placed.iter().map(&skin).fold(f64::INFINITY, f64::min);
        if best.as_ref().is_none_or(|b| near > b.0) {
            best = Some((near, placed));
        }
    }
    let (near, placed) = best.expect("24 turns tried");
    if near < contact {
        bail!(
            "the garment, placed past the fingertips, comes within {:.1} mm of the body \
             (under the contact distance {:.1} mm) at every turn about the arm's axis: \
             start it farther (dressing.beyond)",
            1e3 * near,
            1e3 * contact
        );
    }
    Ok(placed)
}

/// Frames carried along the arm's axis without turning about it, the first
/// across `-out`.
fn carried_frames(arm: &Arm, out: &V3) -> Vec<V3> {
    let m = arm.axis.len();
    let mut e1 = vec![up_across(&(-out)); m];
    for k in 1..m {
        let t = arm.tangent(k);
        let p = e1[k - 1] - t * e1[k - 1].dot(&t);
        e1[k] = if p.norm() > 1e-9 {
            p.normalize()
        } else {
            up_across(&t)
        };
    }
    e1
}

/// The cloth vertices of the panels the cuff's vertices belong to.
fn sleeve_mask(g: &Garment, cuff: &[usize], len: usize) -> Vec<bool> {
    let mut sleeve = vec![false; len];
    for p in &g.panels {
        let r = p.first..p.first + p.count;
        if cuff.iter().any(|c| r.contains(c)) {
            sleeve[r].iter_mut().for_each(|b| *b = true);
        }
    }
    sleeve
}

impl PathPlan<'_> {
    /// Distance of `p` from the skin (or the hand's hull), m.
    fn skin(&self, p: &V3) -> f64 {
        skin_distance(self.ob, self.hull, p)
    }

    /// A held ring: its length around as sewn (the hoop's perimeter), each
    /// vertex's fraction of it, which way the placed ring turns about the
    /// axis and where it begins. `toward`: holding a seam, each ring is read
    /// in its own plane (normal turned toward `toward`, then onto the axis),
    /// so that rings placed askew keep their twist; holding the cuff (placed
    /// across the axis), about the axis. Holding the armhole, the rings open
    /// to their lengths as cut (the pattern's), whatever the sewing left
    /// stretched or open; holding the cuff, to its length as sewn.
    fn ring_of(&self, ring: &[usize]) -> HeldRing {
        let (g, x0, x, t0v, e1) = (self.g, self.x0, self.x, self.t0v, &self.e1);
        let nc = ring.len();
        let gaps: Vec<f64> = match self.d.grip {
            Grip::Armhole => cut_gaps(g, ring),
            Grip::Cuff => (0..nc)
                .map(|k| (x0[ring[(k + 1) % nc]] - x0[ring[k]]).norm())
                .collect(),
        };
        let mut s_of = vec![0.0; nc];
        for k in 1..nc {
            s_of[k] = s_of[k - 1] + gaps[k - 1];
        }
        let perimeter = s_of[nc - 1] + gaps[nc - 1];
        let (c, q) = match self.toward {
            None => (self.start, UnitQuaternion::identity()),
            Some(dir) => {
                let c = centroid(x, ring);
                let mut n = plane_normal(x, ring, &c);
                if n.dot(&dir) < 0.0 {
                    n = -n;
                }
                let q = UnitQuaternion::rotation_between(&n, &t0v)
                    .unwrap_or_else(UnitQuaternion::identity);
                (c, q)
            }
        };
        let at = |i: usize| q * (x[ring[i]] - c);
        let w: f64 = (0..nc)
            .map(|k| at(k).cross(&at((k + 1) % nc)).dot(&t0v))
            .sum();
        let r = at(0);
        let r = r - t0v * r.dot(&t0v);
        HeldRing {
            perimeter,
            fractions: s_of.iter().map(|s| s / perimeter).collect(),
            turn: if w >= 0.0 { 1.0 } else { -1.0 },
            first: (r.dot(&e1[0]), r.dot(&t0v.cross(&e1[0]))),
        }
    }

    /// The hoop at axis point `k` for a ring of length `perimeter`: round
    /// where nothing of the body is near (past the fingertips), else around
    /// the arm's section: where the plane across the axis cuts the edges of
    /// the hand's (before the wrist) or the arm's vertices (after), within
    /// 15 cm (hand) or 10 cm (arm) of the axis, and those vertices within
    /// 1 cm of the plane; the torso is left to the check of the whole path.
    /// `tilt` turns the plane (and the frame in it) about the axis point.
    /// `None`: past the wrist, the ring is too short to pass round.
    fn hoop_at(
        &self,
        k: usize,
        tilt: &UnitQuaternion<f64>,
        perimeter: f64,
    ) -> Result<Option<Hoop>> {
        let (arm, d) = (self.arm, self.d);
        let t = tilt * if k == 0 { self.t0v } else { arm.tangent(k) };
        let a3 = arm.axis[k];
        let u1 = tilt * self.e1[k];
        let u2 = t.cross(&u1);
        let (lim, reach) = if k < arm.wrist_at {
            (self.lim_hand, 0.15)
        } else {
            (self.lim_arm, 0.10)
        };
        // the hand's hull where there is one, else the body's mesh
        let (vs, es, keep): Section = match self.hull {
            Some(h) if k < arm.wrist_at => (&h.vertices, &h.edges, &|_| true),
            _ => (self.bv, &self.bedges, &|i| arm.geodesic[i] <= lim),
        };
        let pts: Vec<[f64; 2]> = es
            .iter()
            .filter(|&&(i, j)| keep(i) || keep(j))
            .filter_map(|&(i, j)| {
                let (di, dj) = ((vs[i] - a3).dot(&t), (vs[j] - a3).dot(&t));
                if di * dj > 0.0 || di == dj {
                    return None;
                }
                let p = vs[i] + (vs[j] - vs[i]) * (di / (di - dj)) - a3;
                (p.norm() <= reach).then(|| [p.dot(&u1), p.dot(&u2)])
            })
            .chain(
                // and the vertices within a centimetre of the plane
                (0..vs.len())
                    .filter(|&i| keep(i))
                    .map(|i| vs[i] - a3)
                    .filter(|p| p.dot(&t).abs() <= 0.01 && p.norm() <= reach)
                    .map(|p| [p.dot(&u1), p.dot(&u2)]),
            )
            .collect();
        if pts.len() < 3 {
            return Ok(Some(Hoop::circle(a3, t, u1, perimeter)));
        }
        // the section's convex hull grown as far as the cuff's length
        // allows (the same gap all round), at least by the clearance
        let (_, p0) = grown_hull(&pts, 0.0);
        let grow = (perimeter - p0) / std::f64::consts::TAU;
        if grow < d.clearance && k > arm.wrist_at + 5 {
            return Ok(None);
        }
        if grow < d.clearance {
            bail!(
                "the cuff ({:.1} cm around) is too small to pass the arm {:.0} cm \
                 from the wrist near ({:.3}, {:.3}, {:.3}) m: the arm's section there \
                 is {:.1} cm around (convex hull), {:.1} cm with the clearance; lower \
                 dressing.clearance",
                100.0 * perimeter,
                100.0 * (arm.s[k] - arm.s[arm.wrist_at]),
                a3.x,
                a3.y,
                a3.z,
                100.0 * p0,
                100.0 * (p0 + std::f64::consts::TAU * d.clearance)
            );
        }
        let (curve, _) = grown_hull(&pts, grow);
        let curve: Vec<V3> = curve.iter().map(|q| a3 + u1 * q[0] + u2 * q[1]).collect();
        let centre = curve.iter().sum::<V3>() / curve.len() as f64;
        Ok(Some(Hoop { centre, curve }))
    }

    /// The direction from a hoop's centre at axis point `k` (tilted by
    /// `tilt`) in which a ring's first vertex `first` lies.
    fn from(&self, k: usize, tilt: &UnitQuaternion<f64>, first: (f64, f64)) -> V3 {
        let e1 = &self.e1;
        let (u1, u2) = (
            e1[k],
            if k == 0 {
                self.t0v
            } else {
                self.arm.tangent(k)
            }
            .cross(&e1[k]),
        );
        tilt * (u1 * first.0 + u2 * first.1)
    }

    /// The cuff vertices' places on a run of hoops.
    fn rings_of(&self, hoops: &[PlacedHoop]) -> Vec<Vec<V3>> {
        let held = &self.held;
        hoops
            .iter()
            .map(|(k, h, q)| h.points(&held.fractions, &self.from(*k, q, held.first), held.turn))
            .collect()
    }

    /// How many legs of a path (the cuff as placed, then its rings) clear
    /// the skin by the contact distance, every cuff vertex at every
    /// waypoint and halfway between; before the wrist a leg too near is an
    /// error, past it the path ends there.
    fn clear_legs(&self, legs: &[Vec<V3>], from_leg: usize) -> Result<usize> {
        let (arm, contact) = (self.arm, self.contact);
        for (q, w) in legs.windows(2).enumerate().skip(from_leg) {
            for f in [0.0, 0.5, 1.0] {
                for j in 0..self.nc {
                    let p = w[0][j] + (w[1][j] - w[0][j]) * f;
                    let gap = self.skin(&p);
                    if gap < contact && q > arm.wrist_at + 5 {
                        return Ok(q);
                    }
                    if gap < contact {
                        bail!(
                            "the gripper would hold the cuff {:.1} mm from the skin at \
                             ({:.3}, {:.3}, {:.3}) m ({:.0} % of the way): lower \
                             dressing.clearance or start farther (dressing.beyond)",
                            1e3 * gap,
                            p.x,
                            p.y,
                            p.z,
                            100.0 * (q as f64 + f) / (legs.len() - 1) as f64
                        );
                    }
                }
            }
        }
        Ok(legs.len() - 1)
    }

    /// The untilted hoops along the axis and the cuff's rings on them, as
    /// far as the path clears the skin (their count).
    fn level_path(&self, placed_cuff: &[V3]) -> Result<GripperPath> {
        let m = self.arm.axis.len();
        let level = UnitQuaternion::identity();
        let mut hoops: Vec<PlacedHoop> = Vec::with_capacity(m);
        for k in 0..m {
            match self.hoop_at(k, &level, self.held.perimeter)? {
                Some(h) => hoops.push((k, h, level)),
                None => break,
            }
        }
        let mut rings = self.rings_of(&hoops);
        let legs: Vec<Vec<V3>> = std::iter::once(placed_cuff.to_vec())
            .chain(rings.iter().cloned())
            .collect();
        let reach = self.clear_legs(&legs, 0)?;
        hoops.truncate(reach);
        rings.truncate(reach);
        Ok(GripperPath {
            hoops,
            rings,
            reach,
            end_tilt: 0.0,
        })
    }

    /// Where a hoop across the axis meets the body short of the shoulder
    /// (the torso, where the arm joins it), the gripper tilts it like an
    /// armhole seam: over the last `TILT_RAMP` m of the axis the hoop's
    /// plane turns about a line across the axis, evenly up to `tilt_max` at
    /// the shoulder point; of 12 directions of that line and tilts up to
    /// 60° every 10°, the one whose path goes farthest (the least tilt of
    /// those). Returns the path reached, its length and the tilt at its
    /// end, degrees (unchanged, 0°, when no tilt goes farther).
    fn tilted_path(&self, placed_cuff: &[V3], level: GripperPath) -> Result<GripperPath> {
        let arm = self.arm;
        let (e1, m) = (&self.e1, arm.axis.len());
        let (hoops, rings, reach) = (&level.hoops, &level.rings, level.reach);
        if !(reach < m && reach > arm.wrist_at + 5) {
            return Ok(level);
        }
        let s_end = arm.s[m - 1];
        let k0 = (arm.wrist_at..reach)
            .find(|&k| arm.s[k] >= (s_end - TILT_RAMP).min(arm.s[reach - 1] - 0.02))
            .unwrap_or(reach - 1);
        let mut best: Option<(usize, f64, Vec<PlacedHoop>)> = None;
        for deg in (1..=6).map(|i| 10.0 * i as f64) {
            for dir in 0..12 {
                let phi = std::f64::consts::TAU * dir as f64 / 12.0;
                let mut run: Vec<PlacedHoop> = hoops[..k0].to_vec();
                for k in k0..m {
                    let t = arm.tangent(k);
                    let (u1, u2) = (e1[k], t.cross(&e1[k]));
                    let line = nalgebra::Unit::new_normalize(u1 * phi.cos() + u2 * phi.sin());
                    let f = ((arm.s[k] - arm.s[k0]) / (s_end - arm.s[k0])).clamp(0.0, 1.0);
                    let q = UnitQuaternion::from_axis_angle(&line, (deg * f).to_radians());
                    match self.hoop_at(k, &q, self.held.perimeter)? {
                        Some(h) => run.push((k, h, q)),
                        None => break,
                    }
                }
                let r = self.rings_of(&run[k0..]);
                let legs: Vec<Vec<V3>> = std::iter::once(placed_cuff.to_vec())
                    .chain(rings[..k0].iter().cloned())
                    .chain(r)
                    .collect();
                let got = self.clear_legs(&legs, k0)?;
                if got > best.as_ref().map_or(reach, |b| b.0) {
                    run.truncate(got);
                    best = Some((got, deg, run));
                }
            }
        }
        Ok(match best {
            Some((got, deg, run)) => {
                let end_tilt =
                    deg * ((arm.s[got - 1] - arm.s[k0]) / (s_end - arm.s[k0])).clamp(0.0, 1.0);
                let rings = self.rings_of(&run);
                GripperPath {
                    hoops: run,
                    rings,
                    reach: got,
                    end_tilt,
                }
            }
            None => level,
        })
    }

    /// Holding the armhole, the gripper also holds the sleeve's cuff open a
    /// sleeve's length ahead of it on the axis, until the cuff has passed
    /// the hand (as a carer slips a sleeve over the hand before drawing it
    /// up the arm); then lets it go. The cuff's pins and its release (time
    /// and vertices).
    fn sleeve_cuff_pins(
        &self,
        cuff: &[usize],
        sleeve_end: &[usize],
        out: V3,
        t_start: f64,
        times: &[f64],
    ) -> Result<(Vec<Pin>, Release)> {
        let (arm, x0, x, e1) = (self.arm, self.x0, self.x, &self.e1);
        let m = times.len();
        let level = UnitQuaternion::identity();
        let ends: Vec<usize> = sleeve_end
            .iter()
            .copied()
            .filter(|v| !cuff.contains(v))
            .collect();
        let end = self.ring_of(&ends);
        let step = arm.s[1] - arm.s[0];
        let lag = ((centroid(x0, &ends) - centroid(x0, cuff)).norm() / step).round() as usize;
        let k_rel = arm.wrist_at + 2 + lag;
        if k_rel >= m {
            bail!(
                "the gripper's path ends {:.0} cm past the wrist, before the sleeve's cuff \
                 ({:.0} cm from the armhole) has passed the hand",
                100.0 * (arm.s[m - 1] - arm.s[arm.wrist_at]),
                100.0 * lag as f64 * step
            );
        }
        let mut legs = Vec::with_capacity(k_rel + 1);
        for k in 0..=k_rel {
            let (at, hoop) = if k >= lag {
                let h = self
                    .hoop_at(k - lag, &level, end.perimeter)?
                    .with_context(|| {
                        format!(
                            "the sleeve's cuff ({:.1} cm around) is too small to pass the arm \
                             near the wrist",
                            100.0 * end.perimeter
                        )
                    })?;
                (k - lag, h)
            } else {
                let c = arm.axis[0] + out * ((lag - k) as f64 * step);
                (0, Hoop::circle(c, self.t0v, e1[0], end.perimeter))
            };
            legs.push(hoop.points(&end.fractions, &self.from(at, &level, end.first), end.turn));
        }
        let placed_ends: Vec<V3> = ends.iter().map(|&i| x[i]).collect();
        let path: Vec<Vec<V3>> = std::iter::once(placed_ends)
            .chain(legs.iter().cloned())
            .collect();
        self.clear_legs(&path, 0)?;
        let pins = ring_pins(&ends, x, t_start, &times[..=k_rel], &legs);
        Ok((pins, (times[k_rel], ends)))
    }
}

impl Dressing {
    /// Places the sewn garment past the fingertips and sets the gripper's
    /// pins (see the module's phases 2 and 3).
    pub fn set_up(
        sim: &mut Simulation,
        g: &Garment,
        body: Handle<Obstacle>,
        d: &DressingFile,
    ) -> Result<Dressing> {
        d.check()?;
        let ob = sim.obstacles().get(body).context("no body")?.clone();
        let (bv, bt) = body_forces::world_mesh(&ob).context("the body is not a triangle mesh")?;
        let arm = Arm::of(&bv, &bt, d.arm, d.beyond)?;
        let lim_hand = arm.rings[arm.wrist_ring].level;
        // `hand: hull`: the hand's convex hull, an obstacle of its own, with
        // the body's contact layer and friction
        let hull: Option<HandHull> = hand_hull(&ob, &bv, &arm, lim_hand, d)?;
        let sleeve_end = find_cuff(g, sim.cloth.positions(), &arm)?;
        let x0 = sim.cloth.positions().to_vec();
        // the held ring (called the cuff below whichever it is): holding the
        // armhole, the sleeve's side of its seam
        let cuff = match d.grip {
            Grip::Cuff => sleeve_end.clone(),
            Grip::Armhole => find_armhole(g, &x0, &sleeve_end)?,
        };
        let c = centroid(&x0, &cuff);
        let start = arm.axis[0];
        let out = (arm.axis[0] - arm.axis[1]).normalize();
        // the direction of the garment from the held ring that is turned
        // away from the body along the axis (`out`)
        let (n, entry_opening_m) = garment_direction(g, &x0, &cuff, &sleeve_end, &c, d.grip)?;
        let contact = ob.thickness + sim.params().cloth_thickness;
        let placed = place_past_fingertips(&x0, start, c, n, out, contact, |p| {
            skin_distance(&ob, &hull, p)
        })?;
        sim.cloth.set_positions(&placed)?;
        sim.cloth.stop();
        let x = sim.cloth.positions().to_vec();
        let e1 = carried_frames(&arm, &out);
        let t0v = -out;
        let toward: Option<V3> = match d.grip {
            Grip::Cuff => None,
            Grip::Armhole => Some(centroid(&x, &cuff) - centroid(&x, &sleeve_end)),
        };
        let mut plan = PathPlan {
            arm: &arm,
            d,
            g,
            ob: &ob,
            hull: &hull,
            bv: &bv,
            bedges: mesh_edges(&bt),
            x0: &x0,
            x: &x,
            e1,
            t0v,
            start,
            toward,
            contact,
            lim_hand,
            lim_arm: arm.rings[arm.shoulder_ring].level,
            nc: cuff.len(),
            held: HeldRing::default(),
        };
        plan.held = plan.ring_of(&cuff);
        let perimeter = plan.held.perimeter;
        let placed_cuff: Vec<V3> = cuff.iter().map(|&i| x[i]).collect();
        let level = plan.level_path(&placed_cuff)?;
        let GripperPath {
            hoops,
            rings,
            reach: m,
            end_tilt,
        } = plan.tilted_path(&placed_cuff, level)?;
        let t_start = sim.time;
        let t_move = t_start + d.hang;
        let times: Vec<f64> = (0..m).map(|k| t_move + arm.s[k] / d.speed).collect();
        let mut pins = ring_pins(&cuff, &x, t_start, &times, &rings[..m]);
        let mut gripped = cuff.clone();
        let mut release = None;
        if d.grip == Grip::Armhole {
            let (end_pins, rel) =
                plan.sleeve_cuff_pins(&cuff, &sleeve_end, out, t_start, &times)?;
            pins.extend(end_pins);
            gripped.extend(&rel.1);
            release = Some(rel);
        }
        sim.set_pins(pins)?;
        let hand = hull.map(|h| sim.add_obstacle(h.obstacle));
        let gripper_path = std::iter::once((t_start, x[cuff[0]]))
            .chain((0..m).map(|k| (times[k], hoops[k].1.centre)))
            .collect();
        let t_arrive = times[m - 1];
        gripped.sort_unstable();
        gripped.dedup();
        let sleeve = sleeve_mask(g, &cuff, x.len());
        Ok(Dressing {
            arm,
            cuff,
            held_opening_m: perimeter,
            sleeve_end,
            gripped,
            sleeve,
            t_move,
            t_arrive,
            release,
            entry_opening_m,
            t_end: t_arrive + d.hold,
            gripper_path,
            path_end: m - 1,
            end_tilt_deg: end_tilt,
            body,
            hand,
            body_vertices: bv,
            body_triangles: bt,
        })
    }

    /// The row of the step just taken.
    pub fn row(&self, sim: &Simulation) -> DressingRow {
        let x = sim.cloth.positions();
        let ring: Vec<V3> = self.cuff.iter().map(|&i| x[i]).collect();
        let (p, off) = progress(&self.arm.axis, self.arm.s[self.arm.wrist_at], &ring);
        let end: Vec<V3> = self.sleeve_end.iter().map(|&i| x[i]).collect();
        let (p_end, _) = progress(&self.arm.axis, self.arm.s[self.arm.wrist_at], &end);
        let contacts = body_forces::contacts_with(sim, self.body).unwrap_or_default();
        let ob = sim.obstacles().get(self.body);
        let (mut fa, mut na, mut ca, mut fb) = (V3::zeros(), 0.0, 0, V3::zeros());
        let (mut fh, mut fw, mut fs) = (V3::zeros(), V3::zeros(), V3::zeros());
        let (mut nw, mut at) = (0.0, 0.0);
        let wrist_s = self.arm.s[self.arm.wrist_at];
        let hand_level = self.arm.rings[self.arm.wrist_ring].level;
        // where on the body each contact acts: off the arm (None), on the
        // hand (true) or past the wrist (false), from the corner of largest
        // weight of the body triangle holding it; every contact with the
        // hand's hull is the hand's
        let on_arm = |c: &body_forces::BodyContact| -> Option<bool> {
            let ob = ob?;
            let (k, w) = body_forces::holding_triangle(
                ob,
                &self.body_vertices,
                &self.body_triangles,
                &c.point,
            );
            let corner = (0..3).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap_or(0);
            let v = self.body_triangles[k][corner] as usize;
            self.arm.vertices[v].then(|| self.arm.geodesic[v] < hand_level)
        };
        let on_hull = self
            .hand
            .and_then(|h| body_forces::contacts_with(sim, h))
            .unwrap_or_default();
        let all = (contacts.iter().map(|c| (c, on_arm(c))))
            .chain(on_hull.iter().map(|c| (c, Some(true))));
        for (c, on) in all {
            fb += c.force;
            let Some(hand) = on else { continue };
            fa += c.force;
            na += c.normal_force();
            ca += 1;
            if hand {
                fh += c.force;
            } else {
                fw += c.force;
                let f = c.force.norm();
                nw += f;
                at += f * (project_on_polyline(&self.arm.axis, &c.point).0 - wrist_s);
            }
            if self.sleeve[c.vertex] {
                fs += c.force;
            }
        }
        let pf = sim.pin_forces();
        let on_gripper: V3 = -self.gripped.iter().map(|&i| pf[i]).sum::<V3>();
        let gr = self.gripped.iter().map(|&i| x[i]).sum::<V3>() / self.gripped.len() as f64;
        DressingRow {
            time_s: sim.time,
            gripper: gr.into(),
            progress_m: p,
            progress: p / self.arm.length(),
            sleeve_end_progress_m: p_end,
            sleeve_end_progress: p_end / self.arm.length(),
            off_axis_m: off,
            arm_force: fa.into(),
            arm_force_n: fa.norm(),
            arm_normal_force_n: na,
            arm_contacts: ca,
            hand_force_n: fh.norm(),
            wrist_to_shoulder_force_n: fw.norm(),
            sleeve_force_n: fs.norm(),
            wrist_to_shoulder_force_at_m: if nw > 0.0 { at / nw } else { f64::NAN },
            body_force_n: fb.norm(),
            body_contacts: contacts.len() + on_hull.len(),
            gripper_force: on_gripper.into(),
            gripper_force_n: on_gripper.norm(),
        }
    }

    /// Runs the dressing to its end, each step through `run` (the run
    /// interface); `on_step(sim, self, row)` after every step, whose
    /// [`Control::Stop`] ends it early. The rows, one per step.
    /// With a `force_limit`, the gripper stops where it is at the first
    /// step the limit is passed ([`Dressing::safety_stop`]) and the run
    /// ends `hold` s later.
    pub fn run(
        &self,
        sim: &mut Simulation,
        d: &DressingFile,
        run: &mut Run,
        on_step: &mut dyn FnMut(&Simulation, &Dressing, &DressingRow) -> Result<Control>,
    ) -> Result<Vec<DressingRow>> {
        let mut rows = Vec::new();
        let mut t_end = self.t_end;
        let mut stopped = false;
        let mut released = false;
        while sim.time < t_end - 1e-9 {
            if let Some((t, ends)) = &self.release {
                if !released && sim.time >= t - 1e-9 {
                    let kept: Vec<Pin> = sim
                        .pins()
                        .as_slice()
                        .iter()
                        .filter(|p| !ends.contains(&p.vertex))
                        .cloned()
                        .collect();
                    sim.set_pins(kept)?;
                    released = true;
                }
            }
            let t = sim.time;
            run.step(sim)
                .map_err(|e| anyhow::anyhow!("dressing, t = {t:.4} s: {}", e.error))?;
            let r = self.row(sim);
            let next = on_step(sim, self, &r)?;
            rows.push(r);
            if next == Control::Stop {
                break;
            }
            if !stopped && self.over_limit(d, &r) {
                // every pin holds where its path is now
                let now = sim.time;
                let held: Vec<Pin> = sim
                    .pins()
                    .as_slice()
                    .iter()
                    .map(|p| Pin::new(p.vertex, PinPath::Fixed(p.path.at(now).0)))
                    .collect();
                sim.set_pins(held)?;
                t_end = now + d.hold;
                stopped = true;
            }
        }
        Ok(rows)
    }

    /// Whether the garment pulls on the moving gripper (after `hang`,
    /// before it arrives) with more than the force limit.
    fn over_limit(&self, d: &DressingFile, r: &DressingRow) -> bool {
        d.force_limit.is_some_and(|f| {
            r.time_s > self.t_move && r.time_s < self.t_arrive && r.gripper_force_n > f
        })
    }

    /// When the gripper's safety stop acted: the first row over the limit
    /// (see [`Dressing::run`]).
    pub fn safety_stop(&self, d: &DressingFile, rows: &[DressingRow]) -> Option<f64> {
        rows.iter()
            .find(|r| self.over_limit(d, r))
            .map(|r| r.time_s)
    }

    /// The report of a run's rows.
    pub fn report(&self, d: &DressingFile, rows: &[DressingRow], wall_s: f64) -> DressingReport {
        let last = rows.last().copied();
        let peak = |f: fn(&DressingRow) -> f64| {
            rows.iter()
                .map(|r| (r.time_s, f(r)))
                .fold((0.0, 0.0), |a, b| if b.1 > a.1 { b } else { a })
        };
        let (ta, fa) = peak(|r| r.arm_force_n);
        let (th, fh) = peak(|r| r.hand_force_n);
        let w = rows
            .iter()
            .filter(|r| r.wrist_to_shoulder_force_n > 0.0)
            .max_by(|a, b| {
                a.wrist_to_shoulder_force_n
                    .total_cmp(&b.wrist_to_shoulder_force_n)
            });
        DressingReport {
            arm: d.arm,
            fingertip: self.arm.fingertip.into(),
            wrist: self.arm.wrist().into(),
            shoulder: self.arm.shoulder().into(),
            arm_length_m: self.arm.length(),
            arm_vertices: self.arm.vertices.iter().filter(|b| **b).count(),
            cuff_vertices: self.cuff.len(),
            grip: d.grip,
            hand: d.hand,
            entry_opening_m: self.entry_opening_m,
            final_sleeve_end_progress_m: last.map_or(f64::NAN, |r| r.sleeve_end_progress_m),
            gripped_vertices: self.gripped.len(),
            held_opening_m: self.held_opening_m,
            path_length_m: self.arm.s[self.path_end],
            path_end_progress_m: self.arm.s[self.path_end] - self.arm.s[self.arm.wrist_at],
            path_end_progress: (self.arm.s[self.path_end] - self.arm.s[self.arm.wrist_at])
                / self.arm.length(),
            path_end_tilt_deg: self.end_tilt_deg,
            speed_m_s: d.speed,
            force_limit_n: d.force_limit,
            safety_stop_s: self.safety_stop(d, rows),
            duration_s: rows.last().map_or(0.0, |r| r.time_s) - self.gripper_path[0].0,
            steps: rows.len(),
            ms_per_step: 1e3 * wall_s / rows.len().max(1) as f64,
            final_progress_m: last.map_or(f64::NAN, |r| r.progress_m),
            final_progress: last.map_or(f64::NAN, |r| r.progress),
            final_off_axis_m: last.map_or(f64::NAN, |r| r.off_axis_m),
            final_distance_to_shoulder_m: f64::NAN,
            peak_arm_force_n: fa,
            peak_arm_force_time_s: ta,
            peak_hand_force_n: fh,
            peak_hand_force_time_s: th,
            peak_wrist_to_shoulder_force_n: w.map_or(0.0, |r| r.wrist_to_shoulder_force_n),
            peak_wrist_to_shoulder_force_time_s: w.map_or(0.0, |r| r.time_s),
            peak_wrist_to_shoulder_force_at_m: w
                .map_or(f64::NAN, |r| r.wrist_to_shoulder_force_at_m),
            peak_wrist_to_shoulder_force_progress: w.map_or(f64::NAN, |r| r.progress),
            peak_body_force_n: peak(|r| r.body_force_n).1,
            peak_gripper_force_n: peak(|r| r.gripper_force_n).1,
            first_arm_contact_s: rows.iter().find(|r| r.arm_contacts > 0).map(|r| r.time_s),
            stopped_early: false,
            time_limit_s: None,
        }
    }

    /// The cuff's centroid now.
    pub fn cuff_centroid(&self, sim: &Simulation) -> V3 {
        centroid(sim.cloth.positions(), &self.cuff)
    }
}

/// Writes `dressing.csv`: one row per step.
pub fn write_csv(rows: &[DressingRow], path: &Path) -> Result<()> {
    crate::io::write_atomic(path, |w| {
        writeln!(
            w,
            "time_s,gripper_x_m,gripper_y_m,gripper_z_m,progress_m,progress,off_axis_m,\
             arm_force_x_n,arm_force_y_n,arm_force_z_n,arm_force_n,arm_normal_force_n,\
             arm_contacts,body_force_n,body_contacts,gripper_force_x_n,gripper_force_y_n,\
             gripper_force_z_n,gripper_force_n,hand_force_n,wrist_to_shoulder_force_n,\
             sleeve_force_n,wrist_to_shoulder_force_at_m,sleeve_end_progress_m"
        )?;
        for r in rows {
            let (g, a, f) = (r.gripper, r.arm_force, r.gripper_force);
            writeln!(
                w,
                "{:.4},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{},\
                 {:.6e},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6},{:.6}",
                r.time_s,
                g[0],
                g[1],
                g[2],
                r.progress_m,
                r.progress,
                r.off_axis_m,
                a[0],
                a[1],
                a[2],
                r.arm_force_n,
                r.arm_normal_force_n,
                r.arm_contacts,
                r.body_force_n,
                r.body_contacts,
                f[0],
                f[1],
                f[2],
                r.gripper_force_n,
                r.hand_force_n,
                r.wrist_to_shoulder_force_n,
                r.sleeve_force_n,
                r.wrist_to_shoulder_force_at_m,
                r.sleeve_end_progress_m
            )?;
        }
        Ok(())
    })
}

/// Writes `dressing.png`: the progress (top) and the forces (bottom)
/// against time.
pub fn write_png(rows: &[DressingRow], title: &str, path: &Path) -> Result<()> {
    use crate::pictures::plot::LinePlot;
    let t: Vec<f64> = rows.iter().map(|r| r.time_s).collect();
    let col = |f: fn(&DressingRow) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    let prog = col(|r| r.progress);
    let end = col(|r| r.sleeve_end_progress);
    let mut top = LinePlot::columns(
        &format!("{title}: the sleeve's opening along the arm"),
        "time (s)",
        "progress (wrist 0, shoulder 1)",
        &t,
        &[
            ("held opening's centroid", &prog),
            ("the sleeve's cuff", &end),
        ],
    );
    top.size = (900, 400);
    let (arm, hand, body, grip) = (
        col(|r| r.arm_force_n),
        col(|r| r.hand_force_n),
        col(|r| r.body_force_n),
        col(|r| r.gripper_force_n),
    );
    let mut middle = LinePlot::columns(
        &format!("{title}: forces"),
        "time (s)",
        "force (N)",
        &t,
        &[
            ("on the arm", &arm),
            ("on the hand", &hand),
            ("on the body", &body),
            ("on the gripper", &grip),
        ],
    );
    middle.size = (900, 400);
    let (w, sl) = (
        col(|r| r.wrist_to_shoulder_force_n),
        col(|r| r.sleeve_force_n),
    );
    let mut bottom = LinePlot::columns(
        &format!("{title}: force on the arm past the wrist"),
        "time (s)",
        "force (N)",
        &t,
        &[
            ("wrist to shoulder", &w),
            ("by the sleeve (hand and arm)", &sl),
        ],
    );
    bottom.size = (900, 400);
    let panels = [top.render(), middle.render(), bottom.render()];
    let mut img = crate::pictures::plot::Image::new(900, 1200, crate::pictures::plot::WHITE);
    for (k, p) in panels.iter().enumerate() {
        for y in 0..400 {
            for x in 0..900 {
                img.set(x as i64, (400 * k + y) as i64, p.get(x, y));
            }
        }
    }
    img.save_png(path)
}
