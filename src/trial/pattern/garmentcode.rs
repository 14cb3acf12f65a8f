//! GarmentCode sewing patterns (`*_specification.json`; ETH's GarmentCode /
//! `pygarment`, MIT). Panels have 2D vertices in cm and a closed loop of
//! edges: straight, quadratic or cubic Bézier (control points relative to
//! the edge: `(u, v) ↦ S + u·d + v·n` with `d = E − S` and `n` its left
//! normal of the same length) or circular arcs (`[radius, large_arc, right]`,
//! SVG semantics: `right = 1` bulges to the right of S→E). A panel is placed
//! by a translation (cm) and Euler angles (degrees; `R = Rz·Ry·Rx`, as
//! GarmentCode's own mesher reads them). A stitch joins two panel edges;
//! a third item `"right_wrong"` sews the right side of one to the wrong side
//! of the other.
//!
//! GarmentCode's world is Y-up, the body facing +Z, floor at y = 0;
//! `garment_sim`'s is Z-up with the body facing −Y: the importer maps
//! `(x, y, z) ↦ (x, −z, y)` (a quarter turn about x), then adds the
//! garment file's offset.

use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde_json::Value;
use std::path::Path;

/// Longest segment a curved edge is sampled with, m.
pub const CURVE_STEP: f64 = 0.002;
/// Fewest segments of a curved edge.
pub const CURVE_MIN_SEGMENTS: usize = 16;

/// One panel as read: edges sampled as polylines (m, panel coordinates) and
/// its placement in GarmentCode's frame (m).
#[derive(Debug, Clone)]
pub struct GcPanel {
    pub name: String,
    pub edges: Vec<Vec<[f64; 2]>>,
    /// Rotation and translation (m) in GarmentCode's frame.
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
}

/// One stitch: (panel name, edge index) twice, and the right-to-wrong flag.
#[derive(Debug, Clone, PartialEq)]
pub struct GcStitch {
    pub a: (String, usize),
    pub b: (String, usize),
    pub right_wrong: bool,
}

#[derive(Debug, Clone)]
pub struct GcPattern {
    pub panels: Vec<GcPanel>,
    pub stitches: Vec<GcStitch>,
    /// Length unit of the file, m (0.01 for cm).
    pub unit: f64,
}

/// The quarter turn from GarmentCode's Y-up frame to the Z-up world.
pub fn y_up_to_z_up() -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(Matrix3::new(
        1.0, 0.0, 0.0, //
        0.0, 0.0, -1.0, //
        0.0, 1.0, 0.0,
    ))
}

impl GcPanel {
    /// Where the panel plane goes in the world, given the offset added
    /// after the frame change.
    pub fn placement(&self, offset: Vector3<f64>) -> Isometry3<f64> {
        let w = y_up_to_z_up();
        let r = w.matrix() * self.rotation;
        let t = w * self.translation + offset;
        Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_matrix(&r))
    }
}

/// Reads a GarmentCode specification file.
pub fn load(path: &Path) -> Result<GcPattern> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read GarmentCode pattern {}", path.display()))?;
    if text.len() > 16 << 20 {
        bail!(
            "GarmentCode pattern {}: {} bytes, more than 16 MiB",
            path.display(),
            text.len()
        );
    }
    let v: Value = serde_json::from_str(&text)
        .with_context(|| format!("GarmentCode pattern {}: invalid JSON", path.display()))?;
    parse(&v).with_context(|| format!("GarmentCode pattern {}", path.display()))
}

fn num(v: &Value, what: &str) -> Result<f64> {
    match v.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        _ => bail!("{what} = {v}: must be a finite number"),
    }
}

fn pair(v: &Value, what: &str) -> Result<[f64; 2]> {
    match v.as_array() {
        Some(a) if a.len() == 2 => Ok([num(&a[0], what)?, num(&a[1], what)?]),
        _ => bail!("{what} = {v}: must be [x, y]"),
    }
}

fn triple(v: Option<&Value>, what: &str) -> Result<[f64; 3]> {
    let Some(v) = v else {
        return Ok([0.0; 3]);
    };
    match v.as_array() {
        Some(a) if a.len() == 3 => Ok([num(&a[0], what)?, num(&a[1], what)?, num(&a[2], what)?]),
        _ => bail!("{what} = {v}: must be [x, y, z]"),
    }
}

/// Parses a specification (see the module's documentation).
pub fn parse(v: &Value) -> Result<GcPattern> {
    let unit = match v.pointer("/properties/units_in_meter") {
        None => 0.01,
        Some(u) => {
            let u = num(u, "properties.units_in_meter")?;
            if u.is_nan() || u <= 0.0 {
                bail!("properties.units_in_meter = {u}: must be > 0");
            }
            1.0 / u
        }
    };
    if let Some(c) = v.pointer("/properties/curvature_coords") {
        if c.as_str() != Some("relative") {
            bail!("properties.curvature_coords = {c}: only \"relative\" is supported");
        }
    }
    let panels = v
        .pointer("/pattern/panels")
        .and_then(Value::as_object)
        .context("pattern.panels: missing or not an object")?;
    let order: Vec<String> = match v.pointer("/pattern/panel_order").and_then(Value::as_array) {
        Some(o) => o
            .iter()
            .filter_map(|s| s.as_str().map(str::to_string))
            .filter(|s| panels.contains_key(s))
            .collect(),
        None => panels.keys().cloned().collect(),
    };
    let mut out = Vec::new();
    for name in order {
        let p = &panels[&name];
        out.push(parse_panel(&name, p, unit).with_context(|| format!("panel {name:?}"))?);
    }
    if out.is_empty() {
        bail!("pattern.panels: no panel");
    }
    let mut stitches = Vec::new();
    if let Some(list) = v.pointer("/pattern/stitches") {
        let list = list.as_array().context("pattern.stitches: not a list")?;
        for (k, s) in list.iter().enumerate() {
            stitches.push(parse_stitch(s).with_context(|| format!("stitch {k}"))?);
        }
    }
    Ok(GcPattern {
        panels: out,
        stitches,
        unit,
    })
}

fn parse_stitch(s: &Value) -> Result<GcStitch> {
    let items = s.as_array().context("must be a list of two edges")?;
    if items.len() < 2 || items.len() > 3 {
        bail!(
            "has {} items: needs two edges and an optional flag",
            items.len()
        );
    }
    let side = |v: &Value, which: &str| -> Result<(String, usize)> {
        let panel = v
            .get("panel")
            .and_then(Value::as_str)
            .with_context(|| format!("{which}: no panel name"))?;
        let edge = v
            .get("edge")
            .and_then(Value::as_u64)
            .with_context(|| format!("{which}: no edge index"))?;
        Ok((panel.to_string(), edge as usize))
    };
    let right_wrong = match items.get(2) {
        None => false,
        Some(f) if f.as_str() == Some("right_wrong") => true,
        Some(f) => bail!("third item {f}: only \"right_wrong\" is known"),
    };
    Ok(GcStitch {
        a: side(&items[0], "first edge")?,
        b: side(&items[1], "second edge")?,
        right_wrong,
    })
}

fn parse_panel(name: &str, p: &Value, unit: f64) -> Result<GcPanel> {
    let verts: Vec<[f64; 2]> = p
        .get("vertices")
        .and_then(Value::as_array)
        .context("vertices: missing")?
        .iter()
        .enumerate()
        .map(|(k, v)| pair(v, &format!("vertices[{k}]")).map(|q| [q[0] * unit, q[1] * unit]))
        .collect::<Result<_>>()?;
    let edges = p
        .get("edges")
        .and_then(Value::as_array)
        .context("edges: missing")?;
    if edges.len() < 2 {
        bail!("edges: {} edges cannot close a panel", edges.len());
    }
    let mut sampled = Vec::new();
    let mut prev_end: Option<usize> = None;
    let mut first_start = 0;
    for (k, e) in edges.iter().enumerate() {
        let ends = e
            .get("endpoints")
            .and_then(Value::as_array)
            .filter(|a| a.len() == 2)
            .with_context(|| format!("edges[{k}].endpoints: missing or not two indices"))?;
        let mut ij = [0usize; 2];
        for (q, x) in ends.iter().enumerate() {
            let i = x
                .as_u64()
                .with_context(|| format!("edges[{k}].endpoints[{q}] = {x}: not an index"))?
                as usize;
            if i >= verts.len() {
                bail!(
                    "edges[{k}].endpoints[{q}] = {i}: the panel has {} vertices",
                    verts.len()
                );
            }
            ij[q] = i;
        }
        if let Some(pe) = prev_end {
            if pe != ij[0] {
                bail!(
                    "edges[{k}] starts at vertex {} but edges[{}] ends at vertex {pe}: the edges \
                     must form one loop in order",
                    ij[0],
                    k - 1
                );
            }
        } else {
            first_start = ij[0];
        }
        prev_end = Some(ij[1]);
        let (s, t) = (verts[ij[0]], verts[ij[1]]);
        let pts = sample_edge(s, t, e.get("curvature"), unit)
            .with_context(|| format!("edges[{k}].curvature"))?;
        sampled.push(pts);
    }
    if prev_end != Some(first_start) {
        bail!("the last edge does not end where the first starts: the outline is not closed");
    }
    let rot = triple(p.get("rotation"), "rotation")?;
    let tr = triple(p.get("translation"), "translation")?;
    let r = |axis: Vector3<f64>, deg: f64| {
        Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians())
    };
    let rotation =
        (r(Vector3::z(), rot[2]) * r(Vector3::y(), rot[1]) * r(Vector3::x(), rot[0])).into_inner();
    Ok(GcPanel {
        name: name.to_string(),
        edges: sampled,
        rotation,
        translation: Vector3::from(tr) * unit,
    })
}

/// Samples the edge from `s` to `t` (m) with its curvature (see the module).
pub fn sample_edge(
    s: [f64; 2],
    t: [f64; 2],
    curvature: Option<&Value>,
    unit: f64,
) -> Result<Vec<[f64; 2]>> {
    let d = [t[0] - s[0], t[1] - s[1]];
    let n = [-d[1], d[0]];
    let chord = (d[0] * d[0] + d[1] * d[1]).sqrt();
    let rel = |q: [f64; 2]| {
        [
            s[0] + q[0] * d[0] + q[1] * n[0],
            s[1] + q[0] * d[1] + q[1] * n[1],
        ]
    };
    let Some(c) = curvature else {
        return Ok(vec![s, t]);
    };
    // legacy form: a bare control point
    if c.is_array() {
        let q = pair(c, "curvature")?;
        return Ok(bezier(&[s, rel(q), t]));
    }
    let kind = c.get("type").and_then(Value::as_str).context("no type")?;
    let params = c.get("params").context("no params")?;
    match kind {
        "quadratic" => {
            let q = pair(
                params.get(0).context("params: needs one control point")?,
                "params[0]",
            )?;
            Ok(bezier(&[s, rel(q), t]))
        }
        "cubic" => {
            let q0 = pair(
                params.get(0).context("params: needs two control points")?,
                "params[0]",
            )?;
            let q1 = pair(
                params.get(1).context("params: needs two control points")?,
                "params[1]",
            )?;
            Ok(bezier(&[s, rel(q0), rel(q1), t]))
        }
        "circle" => {
            let a = params
                .as_array()
                .filter(|a| a.len() == 3)
                .context("params: needs [radius, large_arc, right]")?;
            let r = num(&a[0], "radius")? * unit;
            let flag = |v: &Value, what: &str| -> Result<bool> {
                match v.as_f64().or_else(|| v.as_bool().map(|b| b as u8 as f64)) {
                    Some(x) if x == 0.0 || x == 1.0 => Ok(x == 1.0),
                    _ => bail!("{what} = {v}: must be 0 or 1"),
                }
            };
            let large = flag(&a[1], "large_arc")?;
            let right = flag(&a[2], "right")?;
            if r.is_nan() || r <= 0.0 || chord == 0.0 {
                bail!("circle of radius {r} m over a chord of {chord} m");
            }
            let r = r.max(chord / 2.0);
            let h = (r * r - chord * chord / 4.0).max(0.0).sqrt();
            let sign = if right != large { 1.0 } else { -1.0 };
            let c = [
                s[0] + d[0] / 2.0 + sign * h * n[0] / chord,
                s[1] + d[1] / 2.0 + sign * h * n[1] / chord,
            ];
            let a0 = (s[1] - c[1]).atan2(s[0] - c[0]);
            let a1 = (t[1] - c[1]).atan2(t[0] - c[0]);
            let tau = std::f64::consts::TAU;
            // right: counter-clockwise from s to t
            let mut sweep = if right {
                (a1 - a0).rem_euclid(tau)
            } else {
                -(a0 - a1).rem_euclid(tau)
            };
            if sweep == 0.0 {
                sweep = if right { tau } else { -tau };
            }
            let len = r * sweep.abs();
            let m = ((len / CURVE_STEP).ceil() as usize).max(CURVE_MIN_SEGMENTS);
            let mut pts: Vec<[f64; 2]> = (0..=m)
                .map(|k| {
                    let a = a0 + sweep * k as f64 / m as f64;
                    [c[0] + r * a.cos(), c[1] + r * a.sin()]
                })
                .collect();
            pts[0] = s;
            pts[m] = t;
            Ok(pts)
        }
        other => bail!("type {other:?}: known are quadratic, cubic and circle"),
    }
}

/// A Bézier curve through its control points, sampled finely.
fn bezier(ctrl: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let at = |u: f64| -> [f64; 2] {
        let mut p = ctrl.to_vec();
        for level in (1..p.len()).rev() {
            for i in 0..level {
                p[i] = [
                    p[i][0] + u * (p[i + 1][0] - p[i][0]),
                    p[i][1] + u * (p[i + 1][1] - p[i][1]),
                ];
            }
        }
        p[0]
    };
    let poly_len: f64 = ctrl
        .windows(2)
        .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
        .sum();
    let m = ((poly_len / CURVE_STEP).ceil() as usize).max(CURVE_MIN_SEGMENTS);
    let mut pts: Vec<[f64; 2]> = (0..=m).map(|k| at(k as f64 / m as f64)).collect();
    pts[0] = ctrl[0];
    pts[m] = ctrl[ctrl.len() - 1];
    pts
}

#[cfg(test)]
mod tests {
    use super::*;

    fn len(p: &[[f64; 2]]) -> f64 {
        garment_core::garment::polyline_length(p)
    }

    #[test]
    fn arcs_follow_svg_semantics() {
        // half circle of radius 1 over the chord (0,0)–(2,0)
        let j = serde_json::json!({"type": "circle", "params": [100.0, 0, 1]});
        let p = sample_edge([0.0, 0.0], [2.0, 0.0], Some(&j), 0.01).unwrap();
        assert!((len(&p) - std::f64::consts::PI).abs() < 1e-4, "{}", len(&p));
        // right = 1 bulges to the right of s→t: below the x axis
        assert!(p[p.len() / 2][1] < -0.99);
        let j = serde_json::json!({"type": "circle", "params": [100.0, 0, 0]});
        let p = sample_edge([0.0, 0.0], [2.0, 0.0], Some(&j), 0.01).unwrap();
        assert!(p[p.len() / 2][1] > 0.99);
        // a small arc of radius 2 over a chord of 2: 2·(π/3); the large one 2·(5π/3)
        let j = serde_json::json!({"type": "circle", "params": [200.0, 0, 1]});
        let p = sample_edge([0.0, 0.0], [2.0, 0.0], Some(&j), 0.01).unwrap();
        assert!((len(&p) - 2.0 * std::f64::consts::FRAC_PI_3).abs() < 1e-4);
        let j = serde_json::json!({"type": "circle", "params": [200.0, 1, 1]});
        let p = sample_edge([0.0, 0.0], [2.0, 0.0], Some(&j), 0.01).unwrap();
        assert!((len(&p) - 10.0 * std::f64::consts::PI / 3.0).abs() < 1e-3);
        assert!(p[p.len() / 2][1] < -3.0);
    }

    #[test]
    fn bezier_control_points_are_relative_to_the_edge() {
        // quadratic with control (0.5, 0.5): apex at half the control's offset,
        // to the left of s→t
        let j = serde_json::json!({"type": "quadratic", "params": [[0.5, 0.5]]});
        let p = sample_edge([0.0, 0.0], [1.0, 0.0], Some(&j), 0.01).unwrap();
        let apex = p.iter().map(|q| q[1]).fold(f64::MIN, f64::max);
        assert!((apex - 0.25).abs() < 1e-9, "{apex}");
        assert_eq!(p[0], [0.0, 0.0]);
        assert_eq!(*p.last().unwrap(), [1.0, 0.0]);
    }
}
