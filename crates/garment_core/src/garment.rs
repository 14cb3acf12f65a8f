//! Garments (MODEL.md §8): pattern panels cut from the warp/weft grid and
//! joined by seams.
//!
//! Each panel is a [`Cloth::clipped_to_outline`] grid whose warp follows the
//! panel's grain, placed in the world by the pattern's placement; the panels
//! become one [`Cloth`] ([`Cloth::merge`]) whose seams are
//! [`crate::cloth::Stitch`]es. A seam joins edge `a` of one panel to edge
//! `b` of another: every border vertex of either edge is stitched to the
//! point of the other edge at the same fraction of its length (measured
//! along the edge, from the ends the seam pairs), interpolated between the
//! two vertices of that edge around it. The two edges need not have the
//! same length nor the same sampling.

use crate::cloth::{Border, Cloth, HingeLayout, Outline, PanelSpec, Stitch};
use crate::collision::Obstacle;
use crate::error::{fail, Result};
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

/// One pattern piece, in its own plane (panel coordinates, m).
#[derive(Debug, Clone)]
pub struct PanelCut {
    /// The panel's name.
    pub name: String,
    /// The edges in order around the outline: each a polyline (first point
    /// its start, last its end, the end of one the start of the next).
    pub edges: Vec<Vec<[f64; 2]>>,
    /// Warp direction in panel coordinates (normalised here).
    pub grain: [f64; 2],
    /// Maps the panel plane (x, y, 0) to the world.
    pub placement: Isometry3<f64>,
    /// How the panel's bending hinges are laid out on its grid.
    pub hinges: HingeLayout,
    /// How its grid meets its outline: [`Border::Conforming`] (every corner
    /// a vertex, nothing across the outline) or [`Border::OnOutline`].
    pub border: Border,
}

impl PanelCut {
    /// The outline polygon (the edges' points, each shared point once).
    pub fn polygon(&self) -> Vec<[f64; 2]> {
        self.edges
            .iter()
            .flat_map(|e| e[..e.len() - 1].iter().copied())
            .collect()
    }

    /// Length of edge `e`, m.
    pub fn edge_length(&self, e: usize) -> f64 {
        polyline_length(&self.edges[e])
    }
}

/// Length of a polyline.
pub fn polyline_length(p: &[[f64; 2]]) -> f64 {
    p.windows(2)
        .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
        .sum()
}

/// A seam between edge `a.1` of panel `a.0` and edge `b.1` of panel `b.0`.
#[derive(Debug, Clone)]
pub struct SeamSpec {
    /// (panel, edge) of one side.
    pub a: (usize, usize),
    /// (panel, edge) of the other side.
    pub b: (usize, usize),
    /// Stiffness per metre of seam, N/m per m (a stitch standing for a
    /// length ℓ of seam gets `k = stiffness · ℓ / 2`, the two edges' stitches
    /// sharing the seam).
    pub stiffness: f64,
    /// Damping time of the stitches, s (`d = damping · k`).
    pub damping: f64,
}

/// A panel of a built garment.
#[derive(Debug, Clone)]
pub struct Panel {
    /// The panel's name.
    pub name: String,
    /// Its vertices are `first..first + count` of the garment's cloth.
    pub first: usize,
    /// Number of its vertices.
    pub count: usize,
    /// Panel coordinates of each of its vertices, m.
    pub uv: Vec<[f64; 2]>,
    /// Border vertices on each pattern edge (garment indices), with their
    /// fraction of the edge's length from its start, sorted by it.
    pub edge_vertices: Vec<Vec<(usize, f64)>>,
    /// Length of each pattern edge, m.
    pub edge_lengths: Vec<f64>,
    /// Grain direction (warp) in the pattern's plane.
    pub grain: [f64; 2],
    /// Area of the panel, m².
    pub area: f64,
    /// Nodes of the panel's warp/weft grid along warp and weft. Its lines
    /// pass through the panel's origin; node (0, 0) is the grid's corner at
    /// or just outside the outline's lowest warp and weft coordinates, node
    /// (i, j) lies `i` spacings from it along the grain and `j` across.
    pub grid: [usize; 2],
    /// Garment vertex of grid node `j·grid[0] + i`, or
    /// [`crate::cloth::REMOVED`] for a node outside the outline.
    pub grid_vertex: Vec<usize>,
}

impl Panel {
    /// The garment vertex of this panel's grid node (i along warp, j along
    /// weft).
    pub fn vertex(&self, i: usize, j: usize) -> Result<usize> {
        let [nx, ny] = self.grid;
        if i >= nx || j >= ny {
            fail!(
                mesh,
                "grid node ({i}, {j}) is outside panel {:?}'s {nx} × {ny} grid",
                self.name
            );
        }
        match self.grid_vertex[j * nx + i] {
            crate::cloth::REMOVED => fail!(
                mesh,
                "grid node ({i}, {j}) of panel {:?} lies outside its outline",
                self.name
            ),
            v => Ok(v),
        }
    }
}

/// A built seam: its stitches are `stitches` of the cloth's seams.
#[derive(Debug, Clone)]
pub struct Seam {
    /// (panel, edge) of one side.
    pub a: (usize, usize),
    /// (panel, edge) of the other side.
    pub b: (usize, usize),
    /// The seam runs from `b`'s end to its start (it does for two panels
    /// facing each other).
    pub reversed: bool,
    /// Its stitches in the cloth's `seams`.
    pub stitches: std::ops::Range<usize>,
}

/// Panels and seams as one cloth.
#[derive(Debug, Clone)]
pub struct Garment {
    /// The panels as one cloth, stitched.
    pub cloth: Cloth,
    /// The panels.
    pub panels: Vec<Panel>,
    /// The seams.
    pub seams: Vec<Seam>,
    /// The panels [`Garment::bring_out`] moved out of a body.
    pub moved: Vec<PanelMove>,
}

/// A panel moved out of a body before sewing.
#[derive(Debug, Clone)]
pub struct PanelMove {
    /// The panel moved.
    pub panel: usize,
    /// How deep under the skin its deepest vertex started, m.
    pub depth: f64,
    /// How far it moved, m, and along which unit direction.
    pub distance: f64,
    /// Unit direction of the move.
    pub direction: Vector3<f64>,
}

impl PanelMove {
    /// The move in words, naming the panel of `g`.
    pub fn note(&self, g: &Garment) -> String {
        format!(
            "panel {:?} started {:.1} cm under the skin: moved {:.1} cm out along ({:.2}, {:.2}, \
             {:.2}) before sewing",
            g.panels[self.panel].name,
            100.0 * self.depth,
            100.0 * self.distance,
            self.direction.x,
            self.direction.y,
            self.direction.z
        )
    }
}

/// Farthest [`Garment::bring_out`] moves a panel, m.
pub const MAX_BRING_OUT: f64 = 0.3;

impl Garment {
    /// Cuts every panel at `spacing` (warp and weft, m) with `areal_mass`
    /// (kg/m²) and sews the seams.
    pub fn build(
        cuts: &[PanelCut],
        seams: &[SeamSpec],
        spacing: f64,
        areal_mass: f64,
    ) -> Result<Garment> {
        Garment::build_with_fabrics(cuts, &vec![0; cuts.len()], seams, spacing, &[areal_mass])
    }

    /// [`Garment::build`] for panels cut from several fabrics: panel `k`
    /// from fabric `fabric_of[k]`, whose areal mass is
    /// `areal_masses[fabric_of[k]]`. With more than one fabric the cloth's
    /// `vertex_fabric` says whose each vertex is (for
    /// [`crate::solver::Simulation::with_fabrics`]).
    pub fn build_with_fabrics(
        cuts: &[PanelCut],
        fabric_of: &[u16],
        seams: &[SeamSpec],
        spacing: f64,
        areal_masses: &[f64],
    ) -> Result<Garment> {
        if cuts.is_empty() {
            fail!(invalid, "a garment needs at least one panel");
        }
        if fabric_of.len() != cuts.len() {
            fail!(
                length("fabric indices", fabric_of.len(), cuts.len()),
                "{} panels but {} fabric indices",
                cuts.len(),
                fabric_of.len()
            );
        }
        let mut parts = Vec::new();
        let mut panels = Vec::new();
        let mut first = 0;
        for (cut, &k) in cuts.iter().zip(fabric_of) {
            let Some(&areal_mass) = areal_masses.get(usize::from(k)) else {
                fail!(
                    index("fabric", usize::from(k), areal_masses.len()),
                    "panel {:?}: fabric {k}, but there are {} fabrics",
                    cut.name,
                    areal_masses.len()
                );
            };
            let (mut cloth, panel) = cut_panel(cut, spacing, areal_mass, first)?;
            if areal_masses.len() > 1 {
                cloth.vertex_fabric = vec![k; cloth.len()];
            }
            first += cloth.len();
            parts.push(cloth);
            panels.push(panel);
        }
        let mut cloth = Cloth::merge(parts)?;
        let mut built = Vec::new();
        for (k, s) in seams.iter().enumerate() {
            for (side, (p, e)) in [("a", s.a), ("b", s.b)] {
                if p >= panels.len() || e >= cuts[p].edges.len() {
                    fail!(
                        invalid,
                        "seam {k}: side {side} names panel {p} edge {e}, which does not exist"
                    );
                }
            }
            if !(s.stiffness.is_finite() && s.stiffness > 0.0) {
                fail!(
                    bound("stiffness", s.stiffness),
                    "seam {k}: stiffness {} N/m per m must be > 0",
                    s.stiffness
                );
            }
            if !(s.damping.is_finite() && s.damping >= 0.0) {
                fail!(
                    bound("damping", s.damping),
                    "seam {k}: damping {} s must be ≥ 0",
                    s.damping
                );
            }
            // each edge's border vertices, their fractions stretched to run
            // 0 → 1 from the first to the last (a corner the grid did not keep
            // leaves the first a little way along): the ends of the two edges
            // meet
            let span = |ev: &[(usize, f64)]| -> Vec<(usize, f64)> {
                let (t0, t1) = match (ev.first(), ev.last()) {
                    (Some(a), Some(b)) if b.1 > a.1 => (a.1, b.1),
                    _ => return ev.to_vec(),
                };
                ev.iter().map(|&(v, t)| (v, (t - t0) / (t1 - t0))).collect()
            };
            let (ea, eb) = (
                &span(&panels[s.a.0].edge_vertices[s.a.1]),
                &span(&panels[s.b.0].edge_vertices[s.b.1]),
            );
            for (side, (p, e), ev) in [("a", s.a, ea), ("b", s.b, eb)] {
                if ev.is_empty() {
                    fail!(
                        mesh,
                        "seam {k}: edge {e} of panel {:?} (side {side}) has {} border vertices at \
                         spacing {spacing} m; it needs one: use a finer spacing",
                        panels[p].name,
                        ev.len()
                    );
                }
            }
            // which end of b meets a's start: the nearer one where the
            // pattern places them
            let end = |ev: &[(usize, f64)], last: bool| {
                cloth.x[if last { ev[ev.len() - 1].0 } else { ev[0].0 }]
            };
            let straight =
                (end(ea, false) - end(eb, false)).norm() + (end(ea, true) - end(eb, true)).norm();
            let crossed =
                (end(ea, false) - end(eb, true)).norm() + (end(ea, true) - end(eb, false)).norm();
            let reversed = crossed < straight;
            let la = panels[s.a.0].edge_lengths[s.a.1];
            let lb = panels[s.b.0].edge_lengths[s.b.1];
            let start = cloth.seams.len();
            for (from, onto, lfrom) in [(ea, eb, la), (eb, ea, lb)] {
                for (idx, &(v, t)) in from.iter().enumerate() {
                    // seam length this vertex stands for
                    let lo = if idx == 0 {
                        t
                    } else {
                        0.5 * (t + from[idx - 1].1)
                    };
                    let hi = if idx + 1 == from.len() {
                        t.max(1.0)
                    } else {
                        0.5 * (t + from[idx + 1].1)
                    };
                    let ell = (hi - lo).max(0.0) * lfrom;
                    let target = if reversed { 1.0 - t } else { t };
                    let (v0, v1, w) = bracket(onto, target);
                    let k = s.stiffness * ell / 2.0;
                    cloth.seams.push(Stitch {
                        v: [v, v0, v1],
                        c: [1.0, -(1.0 - w), -w],
                        k,
                        d: s.damping * k,
                    });
                }
            }
            built.push(Seam {
                a: s.a,
                b: s.b,
                reversed,
                stitches: start..cloth.seams.len(),
            });
        }
        Ok(Garment {
            cloth,
            panels,
            seams: built,
            moved: Vec::new(),
        })
    }

    /// Moves every panel with a vertex inside the body out of it, rigidly
    /// (the panel stays flat, at rest), along the depth-weighted mean of the
    /// body's outward normals at its vertices inside, by the least multiple of
    /// 2.5 mm that puts all its vertices at least the body's thickness outside
    /// the skin. A panel that no move within [`MAX_BRING_OUT`] frees is an
    /// error naming it. The moves are kept in [`Garment::moved`].
    pub fn bring_out(&mut self, body: &Obstacle) -> Result<()> {
        let g = self;
        let clear = body.thickness.max(1e-3);
        let mut moves = Vec::new();
        for (k, p) in g.panels.iter().enumerate() {
            let range = p.first..p.first + p.count;
            let mut push = Vector3::zeros();
            let mut depth: f64 = 0.0;
            let mut worst = None;
            for i in range.clone() {
                let q = body.proximity(&g.cloth.x[i]);
                if q.distance < 0.0 {
                    push += q.normal * -q.distance;
                    if -q.distance > depth {
                        depth = -q.distance;
                        worst = Some(i);
                    }
                }
            }
            let Some(worst) = worst else { continue };
            let direction = push.try_normalize(1e-12).unwrap_or(Vector3::z());
            let free = |d: f64| {
                range
                    .clone()
                    .all(|i| body.proximity(&(g.cloth.x[i] + direction * d)).distance >= clear)
            };
            let steps = (MAX_BRING_OUT / 2.5e-3).round() as usize;
            let Some(d) = (1..=steps).map(|n| n as f64 * 2.5e-3).find(|&d| free(d)) else {
                let x = g.cloth.x[worst];
                fail!(placement,
                    "panel {:?} starts inside the body (its vertex {} at ({:.3}, {:.3}, {:.3}) m lies \
                     {:.1} cm under the skin) and no move of up to {:.0} cm along the body's normals \
                     frees it: move the panel (its placement) or the body (body.pose)",
                    p.name,
                    worst - p.first,
                    x.x,
                    x.y,
                    x.z,
                    100.0 * depth,
                    100.0 * MAX_BRING_OUT
                );
            };
            moves.push(PanelMove {
                panel: k,
                depth,
                distance: d,
                direction,
            });
        }
        for m in &moves {
            let p = &g.panels[m.panel];
            for x in &mut g.cloth.x[p.first..p.first + p.count] {
                *x += m.direction * m.distance;
            }
        }
        g.moved = moves;
        Ok(())
    }

    /// The largest seam gap, m (the distance between a stitched vertex and
    /// its point on the other edge), and the seam it is on.
    pub fn largest_gap(&self, x: &[Vector3<f64>]) -> (f64, Option<usize>) {
        let mut best = (0.0, None);
        for (k, s) in self.seams.iter().enumerate() {
            for st in &self.cloth.seams[s.stitches.clone()] {
                let g = st.gap(x).norm();
                if g > best.0 {
                    best = (g, Some(k));
                }
            }
        }
        best
    }

    /// The panel called `name`.
    pub fn panel(&self, name: &str) -> Result<&Panel> {
        match self.panels.iter().find(|p| p.name == name) {
            Some(p) => Ok(p),
            None => fail!(
                invalid,
                "no panel {name:?} (the garment's panels: {})",
                self.panels
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }

    /// The panel a vertex belongs to.
    pub fn panel_of(&self, v: usize) -> usize {
        self.panels
            .iter()
            .position(|p| v >= p.first && v < p.first + p.count)
            .unwrap_or(0)
    }
}

/// The two vertices of an edge around fraction `t` and the weight of the
/// second (clamped at the edge's ends).
fn bracket(ev: &[(usize, f64)], t: f64) -> (usize, usize, f64) {
    if ev.len() == 1 {
        return (ev[0].0, ev[0].0, 0.0);
    }
    if t <= ev[0].1 {
        return (ev[0].0, ev[1].0, 0.0);
    }
    for w in ev.windows(2) {
        if t <= w[1].1 {
            let span = w[1].1 - w[0].1;
            let f = if span > 0.0 { (t - w[0].1) / span } else { 0.0 };
            return (w[0].0, w[1].0, f);
        }
    }
    let n = ev.len();
    (ev[n - 2].0, ev[n - 1].0, 1.0)
}

/// Cuts one panel: its grid in material coordinates (warp along the grain),
/// placed in the world, and the border vertices of each of its edges.
fn cut_panel(
    cut: &PanelCut,
    spacing: f64,
    areal_mass: f64,
    first: usize,
) -> Result<(Cloth, Panel)> {
    let name = &cut.name;
    if cut.edges.is_empty() || cut.edges.iter().any(|e| e.len() < 2) {
        fail!(
            mesh,
            "panel {name:?}: needs edges of at least two points each"
        );
    }
    let poly = cut.polygon();
    if poly.iter().flatten().any(|c| !c.is_finite()) {
        fail!(mesh, "panel {name:?}: outline has a non-finite point");
    }
    if let Some((i, j)) = self_intersection(&cut.edges) {
        fail!(
            mesh,
            "panel {name:?}: its outline crosses itself (edge {i} crosses edge {j}); a panel must \
             be a simple closed outline"
        );
    }
    let gl = (cut.grain[0].powi(2) + cut.grain[1].powi(2)).sqrt();
    if !(gl.is_finite() && gl > 1e-9) {
        fail!(
            mesh,
            "panel {name:?}: grain {:?} must be a non-zero direction",
            cut.grain
        );
    }
    let g = [cut.grain[0] / gl, cut.grain[1] / gl];
    // material frame: u along the grain, v a quarter turn from it
    let to_uv = |p: [f64; 2]| [p[0] * g[0] + p[1] * g[1], -p[0] * g[1] + p[1] * g[0]];
    let from_uv = |m: [f64; 2]| [m[0] * g[0] - m[1] * g[1], m[0] * g[1] + m[1] * g[0]];
    let outline = Outline::Polygon(poly.iter().map(|&p| to_uv(p)).collect());
    let theta = g[1].atan2(g[0]);
    let pose = cut.placement
        * Isometry3::from_parts(
            Default::default(),
            UnitQuaternion::from_euler_angles(0.0, 0.0, theta),
        );
    // every edge's start is a corner (the end of the one before it)
    let corners: Vec<[f64; 2]> = cut.edges.iter().map(|e| to_uv(e[0])).collect();
    let (cloth, corner_vertex) = Cloth::panel_with_corners(&PanelSpec {
        border: cut.border,
        hinges: cut.hinges,
        corners,
        ..PanelSpec::new(&outline, [spacing, spacing], [0.0, 0.0], &pose, areal_mass)
    })
    .map_err(|e| e.prefixed(&format!("panel {name:?}: ")))?;
    let uv: Vec<[f64; 2]> = cloth.material.iter().map(|&m| from_uv(m)).collect();
    // border vertices: on an edge of the triangulation used by one triangle
    let mut count = std::collections::HashMap::new();
    for t in &cloth.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0usize) += 1;
        }
    }
    let mut border = vec![false; cloth.len()];
    for (&(a, b), &c) in &count {
        if c == 1 {
            border[a] = true;
            border[b] = true;
        }
    }
    let lengths: Vec<f64> = (0..cut.edges.len()).map(|e| cut.edge_length(e)).collect();
    let edge_vertices = if cut.border == Border::Conforming {
        conforming_edges(cut, &uv, &border, corner_vertex, &lengths, spacing, first)
    } else {
        let ev = outline_edges(cut, &uv, &border, &lengths, spacing, first);
        // an edge too short to hold a border vertex: the panel is cut
        // conforming, every corner a vertex
        if ev.iter().any(|e| e.is_empty()) {
            let conforming = PanelCut {
                border: Border::Conforming,
                ..cut.clone()
            };
            return cut_panel(&conforming, spacing, areal_mass, first);
        }
        ev
    };
    let area = crate::cloth::polygon_area(&poly).abs();
    let grid_vertex = (0..cloth.ny)
        .flat_map(|j| (0..cloth.nx).map(move |i| (i, j)))
        .map(|(i, j)| {
            cloth
                .index(i, j)
                .map_or(crate::cloth::REMOVED, |v| first + v)
        })
        .collect();
    let panel = Panel {
        grid: [cloth.nx, cloth.ny],
        grid_vertex,
        name: name.clone(),
        first,
        count: cloth.len(),
        uv,
        edge_vertices,
        edge_lengths: lengths,
        grain: g,
        area,
    };
    Ok((cloth, panel))
}

/// A conforming panel's edges: each runs from its start corner's vertex
/// (fraction 0) through the border vertices whose nearest point of the
/// outline lies within it to its end corner's (1).
#[allow(clippy::too_many_arguments)]
fn conforming_edges(
    cut: &PanelCut,
    uv: &[[f64; 2]],
    border: &[bool],
    corner_vertex: Vec<Option<usize>>,
    lengths: &[f64],
    spacing: f64,
    first: usize,
) -> Vec<Vec<(usize, f64)>> {
    let ne = cut.edges.len();
    // each corner's vertex: the one the grid placed there or, for a corner
    // whose node was dropped, the nearest border vertex
    let corner_vertex: Vec<usize> = corner_vertex
        .iter()
        .zip(&cut.edges)
        .map(|(&cv, e)| {
            cv.unwrap_or_else(|| {
                let c = e[0];
                (0..uv.len())
                    .filter(|&v| border[v])
                    .min_by(|&a, &b| {
                        let d = |v: usize| (uv[v][0] - c[0]).powi(2) + (uv[v][1] - c[1]).powi(2);
                        d(a).total_cmp(&d(b))
                    })
                    .unwrap_or(0)
            })
        })
        .collect();
    let is_corner = {
        let mut f = vec![false; uv.len()];
        for &v in &corner_vertex {
            f[v] = true;
        }
        f
    };
    // each edge: its start corner, the border vertices whose nearest point
    // of the outline lies within it, its end corner
    let mut edge_vertices: Vec<Vec<(usize, f64)>> = (0..ne)
        .map(|e| vec![(first + corner_vertex[e], 0.0)])
        .collect();
    for (v, &p) in uv.iter().enumerate() {
        if !border[v] || is_corner[v] {
            continue;
        }
        let near = near_edges(cut, p, lengths);
        let (e, &(d, t)) = near
            .iter()
            .enumerate()
            .min_by(|a, b| a.1 .0.total_cmp(&b.1 .0))
            .expect("a panel has edges");
        // a vertex off the outline (the staircase where no node could be
        // moved onto it), or one nearest a corner, which has its own vertex
        if d > 0.75 * spacing || t <= 0.0 || t >= 1.0 {
            continue;
        }
        edge_vertices[e].push((first + v, t));
    }
    for (e, ev) in edge_vertices.iter_mut().enumerate() {
        ev[1..].sort_by(|a, b| a.1.total_cmp(&b.1));
        ev.push((first + corner_vertex[(e + 1) % ne], 1.0));
    }
    edge_vertices
}

/// A panel's edges with its border on the outline: every border vertex
/// within 0.75 spacing of the outline on its nearest edge (a corner on
/// both), sorted by the fraction of the edge's length.
fn outline_edges(
    cut: &PanelCut,
    uv: &[[f64; 2]],
    border: &[bool],
    lengths: &[f64],
    spacing: f64,
    first: usize,
) -> Vec<Vec<(usize, f64)>> {
    let mut edge_vertices = vec![Vec::new(); cut.edges.len()];
    for (v, &p) in uv.iter().enumerate() {
        if !border[v] {
            continue;
        }
        // the nearest edge (every edge as near: a corner is on two), and the
        // fraction of its length there
        let near = near_edges(cut, p, lengths);
        let d = near.iter().map(|n| n.0).fold(f64::INFINITY, f64::min);
        if d > 0.75 * spacing {
            continue;
        }
        for (e, &(de, t)) in near.iter().enumerate() {
            if de <= d + 1e-6 * spacing {
                edge_vertices[e].push((first + v, t));
            }
        }
    }
    for ev in &mut edge_vertices {
        ev.sort_by(|a, b| a.1.total_cmp(&b.1));
    }
    edge_vertices
}

/// For each edge of the panel, the distance from `p` to it and the fraction
/// of its length at the nearest point.
fn near_edges(cut: &PanelCut, p: [f64; 2], lengths: &[f64]) -> Vec<(f64, f64)> {
    (cut.edges.iter().enumerate())
        .map(|(e, pts)| nearest_on_polyline(pts, p, lengths[e]))
        .collect()
}

/// Distance from `p` to a polyline of length `len`, and the fraction of the
/// length at the nearest point.
fn nearest_on_polyline(pts: &[[f64; 2]], p: [f64; 2], len: f64) -> (f64, f64) {
    let mut best = (f64::INFINITY, 0.0);
    let mut along = 0.0;
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l = (dx * dx + dy * dy).sqrt();
        let t = if l > 0.0 {
            (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (l * l)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = ((p[0] - a[0] - t * dx).powi(2) + (p[1] - a[1] - t * dy).powi(2)).sqrt();
        if d < best.0 {
            best = (d, (along + t * l) / len.max(1e-300));
        }
        along += l;
    }
    best
}

/// Two non-adjacent segments of the outline that cross: the edges they
/// belong to.
fn self_intersection(edges: &[Vec<[f64; 2]>]) -> Option<(usize, usize)> {
    let mut segs = Vec::new();
    for (e, pts) in edges.iter().enumerate() {
        for w in pts.windows(2) {
            segs.push((w[0], w[1], e));
        }
    }
    let n = segs.len();
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    for i in 0..n {
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            let (p, q, ei) = segs[i];
            let (r, s, ej) = segs[j];
            let d1 = cross(r, s, p);
            let d2 = cross(r, s, q);
            let d3 = cross(p, q, r);
            let d4 = cross(p, q, s);
            if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
                && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
            {
                return Some((ei, ej));
            }
        }
    }
    None
}

/// A point of a panel's plane in the world.
pub fn place(placement: &Isometry3<f64>, p: [f64; 2]) -> Vector3<f64> {
    (placement * Point3::new(p[0], p[1], 0.0)).coords
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(name: &str, w: f64, h: f64, at: Isometry3<f64>) -> PanelCut {
        PanelCut {
            hinges: HingeLayout::Skewed,
            border: Border::Conforming,
            name: name.into(),
            edges: vec![
                vec![[0.0, 0.0], [w, 0.0]],
                vec![[w, 0.0], [w, h]],
                vec![[w, h], [0.0, h]],
                vec![[0.0, h], [0.0, 0.0]],
            ],
            grain: [0.0, 1.0],
            placement: at,
        }
    }

    #[test]
    fn seams_pair_every_border_vertex_of_both_edges() {
        let a = rect("a", 0.2, 0.1, Isometry3::identity());
        let b = rect("b", 0.2, 0.1, Isometry3::translation(0.0, 0.15, 0.0));
        // a's top edge (2) runs right to left; b's bottom edge (0) left to right
        let g = Garment::build(
            &[a, b],
            &[SeamSpec {
                a: (0, 2),
                b: (1, 0),
                stiffness: 1000.0,
                damping: 0.0,
            }],
            0.02,
            0.2,
        )
        .unwrap();
        let s = &g.seams[0];
        assert!(s.reversed);
        let na = g.panels[0].edge_vertices[2].len();
        let nb = g.panels[1].edge_vertices[0].len();
        assert_eq!((na, nb), (11, 11));
        assert_eq!(s.stitches.len(), na + nb);
        // every stitch spans the 5 cm between the placed edges
        for st in &g.cloth.seams {
            assert!((st.gap(&g.cloth.x).norm() - 0.05).abs() < 1e-9);
        }
        // stiffness sums to the seam's: 1000 N/m per m × 0.2 m
        let k: f64 = g.cloth.seams.iter().map(|s| s.k).sum();
        assert!((k - 200.0).abs() < 1e-9, "{k}");
    }

    /// A panel with a dart (a notch 18 cm deep, 4.4 cm open) and a facing
    /// edge of 5.7 mm, cut at 0.5 to 3 cm: every corner is a vertex where
    /// the pattern puts it, every edge runs from its start corner to its end
    /// corner, no spring bridges the dart's notch, the mass is the areal
    /// mass times the outline's area, and the dart's legs sew.
    #[test]
    fn a_panel_with_a_dart_and_a_short_edge_is_cut_to_its_corners_at_any_spacing() {
        let pts = [
            [0.0, 0.0],
            [0.3, 0.0],
            [0.3, 0.4],
            [0.172, 0.4],
            [0.15, 0.22],
            [0.128, 0.4],
            [0.004, 0.4],
            [0.0, 0.396],
        ];
        let n = pts.len();
        let cut = PanelCut {
            hinges: HingeLayout::Skewed,
            border: Border::Conforming,
            name: "darted".into(),
            edges: (0..n).map(|k| vec![pts[k], pts[(k + 1) % n]]).collect(),
            grain: [0.0, 1.0],
            placement: Isometry3::identity(),
        };
        let shoelace: f64 = (0..n)
            .map(|k| pts[k][0] * pts[(k + 1) % n][1] - pts[(k + 1) % n][0] * pts[k][1])
            .sum::<f64>()
            / 2.0;
        for spacing in [0.005, 0.01, 0.02, 0.03] {
            let dart = SeamSpec {
                a: (0, 3),
                b: (0, 4),
                stiffness: 1000.0,
                damping: 0.0,
            };
            let g = Garment::build(std::slice::from_ref(&cut), &[dart], spacing, 0.2)
                .unwrap_or_else(|e| panic!("{spacing} m: {e:#}"));
            let p = &g.panels[0];
            let at = |v: usize| p.uv[v - p.first];
            for (e, ev) in p.edge_vertices.iter().enumerate() {
                let (s, t) = (pts[e], pts[(e + 1) % n]);
                let (v0, v1) = (ev[0], ev[ev.len() - 1]);
                assert_eq!((v0.1, v1.1), (0.0, 1.0), "{spacing} m, edge {e}");
                // the corners merged on the 5.7 mm edge at 3 cm (under a
                // quarter spacing) share the first corner's place
                let near = |q: [f64; 2], c: [f64; 2]| {
                    ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2)).sqrt()
                        <= if e == 5 || e == 6 || e == 7 {
                            0.25 * spacing
                        } else {
                            1e-12
                        }
                };
                assert!(
                    near(at(v0.0), s),
                    "{spacing} m, edge {e} starts at {:?}, not {s:?}",
                    at(v0.0)
                );
                assert!(
                    near(at(v1.0), t),
                    "{spacing} m, edge {e} ends at {:?}, not {t:?}",
                    at(v1.0)
                );
                assert!(
                    ev.windows(2).all(|w| w[0].1 <= w[1].1),
                    "{spacing} m, edge {e}"
                );
            }
            // the dart's tip is a vertex, exactly
            assert!(p.uv.iter().any(|q| q == &[0.15, 0.22]), "{spacing} m");
            // no tension spring crosses the notch (the line u = 0.15 above
            // the tip, at v > 0.22)
            for sp in &g.cloth.tension {
                let (a, b) = (p.uv[sp.a], p.uv[sp.b]);
                if (a[0] - 0.15) * (b[0] - 0.15) < 0.0 {
                    let f = (0.15 - a[0]) / (b[0] - a[0]);
                    let v = a[1] + f * (b[1] - a[1]);
                    assert!(
                        v <= 0.22 + 1e-9,
                        "{spacing} m: a spring crosses the notch at v = {v}"
                    );
                }
            }
            let mass = g.cloth.total_mass();
            assert!(
                (mass / (0.2 * shoelace) - 1.0).abs() < 0.05,
                "{spacing} m: {mass} kg against {}",
                0.2 * shoelace
            );
            // every stitch of the dart joins the two legs: at the tip both
            // sides are the one tip vertex, so its gap there is zero
            assert!(!g.seams[0].stitches.is_empty());
            let tip = g.cloth.seams[g.seams[0].stitches.clone()]
                .iter()
                .map(|st| st.gap(&g.cloth.x).norm())
                .fold(f64::INFINITY, f64::min);
            assert!(tip < 1e-12, "{spacing} m: {tip}");
            // cut on its outline, the panel is not refused either: where an
            // edge holds no border vertex it is cut conforming
            let dart = SeamSpec {
                a: (0, 3),
                b: (0, 4),
                stiffness: 1000.0,
                damping: 0.0,
            };
            let on = PanelCut {
                border: Border::OnOutline,
                ..cut.clone()
            };
            let g = Garment::build(&[on], &[dart], spacing, 0.2)
                .unwrap_or_else(|e| panic!("on the outline, {spacing} m: {e:#}"));
            assert!(g.panels[0].edge_vertices.iter().all(|e| !e.is_empty()));
        }
    }

    #[test]
    fn a_crossing_outline_is_refused_naming_the_edges() {
        let bow = PanelCut {
            hinges: HingeLayout::Skewed,
            border: Border::Conforming,
            name: "bow".into(),
            edges: vec![
                vec![[0.0, 0.0], [0.2, 0.2]],
                vec![[0.2, 0.2], [0.2, 0.0]],
                vec![[0.2, 0.0], [0.0, 0.2]],
                vec![[0.0, 0.2], [0.0, 0.0]],
            ],
            grain: [0.0, 1.0],
            placement: Isometry3::identity(),
        };
        let e = Garment::build(&[bow], &[], 0.02, 0.2)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"bow\"") && e.contains("edge 0 crosses edge 2"),
            "{e}"
        );
    }
}
