//! A trial as a binary glTF 2.0 file (`trial.glb`): the body at the end
//! as a grey mesh and the garment as one mesh coloured by its stretch at
//! the end (`COLOR_0`, the strain pictures' colour map from 0 to a fixed
//! full scale), animated over the run with morph targets: the garment's
//! positions are the first frame's, target k holds frame k's displacement
//! from them, and the animation channel on the garment's `weights` gives
//! target k the weight 1 at frame k's time (linear in between, so the
//! positions are interpolated between frames). The data stay Z-up, in m;
//! a root node turns them Y-up as glTF wants (−90° about x).

use super::render::colour_map;
use anyhow::{bail, ensure, Result};
use serde_json::{json, Value};
use std::path::Path;

/// What `trial.glb` shows.
pub struct GlbScene<'a> {
    /// The body at the end (static mesh), m.
    pub body_vertices: &'a [[f64; 3]],
    pub body_triangles: &'a [[u32; 3]],
    pub garment_triangles: &'a [[usize; 3]],
    /// (time s, positions) of the garment, in time order, at least one frame; all the same length.
    pub frames: &'a [(f64, Vec<[f32; 3]>)],
    /// Per-vertex stretch of the garment at the last frame (fraction, 0.05 = 5 %), coloured with a
    /// fixed scale `stretch_full` (colour saturates there).
    pub stretch: &'a [f64],
    pub stretch_full: f64,
    pub name: &'a str,
}

/// Most morph targets (frames after the first) a file holds.
pub const MAX_TARGETS: usize = 255;

const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// The binary chunk and the buffer views and accessors that describe it.
#[derive(Default)]
struct Bin {
    data: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    /// Appends `bytes` as a buffer view (4-byte aligned) for one accessor;
    /// the accessor's index.
    fn push(&mut self, bytes: &[u8], target: Option<u32>, mut accessor: Value) -> usize {
        let mut view = json!({
            "buffer": 0,
            "byteOffset": self.data.len(),
            "byteLength": bytes.len(),
        });
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.data.extend_from_slice(bytes);
        self.data.resize(self.data.len().next_multiple_of(4), 0);
        accessor["bufferView"] = json!(self.views.len());
        self.views.push(view);
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// VEC3 floats, with their min and max when `bounds` (positions need them).
    fn vec3(&mut self, v: &[[f32; 3]], bounds: bool) -> usize {
        let bytes: Vec<u8> = v.iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
        let mut acc = json!({ "componentType": FLOAT, "count": v.len(), "type": "VEC3" });
        if bounds {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for p in v {
                for c in 0..3 {
                    lo[c] = lo[c].min(p[c]);
                    hi[c] = hi[c].max(p[c]);
                }
            }
            // as f64, so that the JSON number is the float's exact value
            acc["min"] = json!(lo.map(f64::from));
            acc["max"] = json!(hi.map(f64::from));
        }
        self.push(&bytes, Some(ARRAY_BUFFER), acc)
    }

    /// Triangle indices.
    fn indices(&mut self, t: &[[u32; 3]]) -> usize {
        let bytes: Vec<u8> = t.iter().flatten().flat_map(|i| i.to_le_bytes()).collect();
        let acc = json!({ "componentType": UNSIGNED_INT, "count": 3 * t.len(), "type": "SCALAR" });
        self.push(&bytes, Some(ELEMENT_ARRAY_BUFFER), acc)
    }

    /// Scalar floats (animation times with their bounds, weights without).
    fn scalars(&mut self, v: &[f32], bounds: bool) -> usize {
        let bytes: Vec<u8> = v.iter().flat_map(|c| c.to_le_bytes()).collect();
        let mut acc = json!({ "componentType": FLOAT, "count": v.len(), "type": "SCALAR" });
        if bounds {
            let lo = v.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            acc["min"] = json!([f64::from(lo)]);
            acc["max"] = json!([f64::from(hi)]);
        }
        self.push(&bytes, None, acc)
    }
}

/// An sRGB colour (0–255) as the linear values glTF colours are.
fn linear(c: [u8; 3]) -> [f32; 3] {
    c.map(|v| {
        let s = v as f64 / 255.0;
        let l = if s <= 0.04045 {
            s / 12.92
        } else {
            ((s + 0.055) / 1.055).powf(2.4)
        };
        l as f32
    })
}

/// Refuses a scene glTF cannot hold or whose numbers are not finite.
fn check(s: &GlbScene) -> Result<()> {
    let Some((_, first)) = s.frames.first() else {
        bail!(
            "glTF scene {:?}: no garment frame (at least one is needed)",
            s.name
        );
    };
    let n = first.len();
    ensure!(
        n > 0,
        "glTF scene {:?}: the garment has no vertices",
        s.name
    );
    ensure!(
        n <= u32::MAX as usize,
        "glTF scene {:?}: {n} garment vertices, more than 32-bit indices address",
        s.name
    );
    ensure!(
        s.frames.len() - 1 <= MAX_TARGETS,
        "glTF scene {:?}: {} garment frames, at most {} (the first and one morph target per later \
         frame, {MAX_TARGETS} targets at most)",
        s.name,
        s.frames.len(),
        MAX_TARGETS + 1
    );
    let mut last_t = f32::NEG_INFINITY;
    for (k, (t, x)) in s.frames.iter().enumerate() {
        ensure!(
            t.is_finite() && *t >= 0.0,
            "glTF scene {:?}: garment frame {k} at time {t} s (must be finite, ≥ 0 s)",
            s.name
        );
        ensure!(
            (*t as f32) > last_t,
            "glTF scene {:?}: garment frame {k} at {t} s is not after frame {} (times must increase \
             by more than a 32-bit float's step)",
            s.name,
            k.saturating_sub(1)
        );
        last_t = *t as f32;
        ensure!(
            x.len() == n,
            "glTF scene {:?}: garment frame {k} (t = {t} s) has {} vertices, frame 0 has {n}",
            s.name,
            x.len()
        );
        if let Some(i) = x.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            bail!(
                "glTF scene {:?}: garment frame {k} (t = {t} s), vertex {i}: position {:?} m is \
                 not finite",
                s.name,
                x[i]
            );
        }
    }
    ensure!(
        !s.garment_triangles.is_empty(),
        "glTF scene {:?}: the garment has no triangles",
        s.name
    );
    if let Some(j) = s
        .garment_triangles
        .iter()
        .position(|t| t.iter().any(|&i| i >= n))
    {
        bail!(
            "glTF scene {:?}: garment triangle {j} {:?} indexes past the garment's {n} vertices",
            s.name,
            s.garment_triangles[j]
        );
    }
    ensure!(
        s.stretch.len() == n,
        "glTF scene {:?}: {} stretch values for {n} garment vertices",
        s.name,
        s.stretch.len()
    );
    if let Some(i) = s.stretch.iter().position(|e| !e.is_finite()) {
        bail!(
            "glTF scene {:?}: stretch of garment vertex {i} is {} (not finite)",
            s.name,
            s.stretch[i]
        );
    }
    ensure!(
        s.stretch_full.is_finite() && s.stretch_full > 0.0,
        "glTF scene {:?}: stretch full scale {} (must be finite and > 0)",
        s.name,
        s.stretch_full
    );
    let nb = s.body_vertices.len();
    ensure!(
        (nb == 0) == s.body_triangles.is_empty(),
        "glTF scene {:?}: the body has {nb} vertices and {} triangles (both or neither needed)",
        s.name,
        s.body_triangles.len()
    );
    if let Some(i) = s
        .body_vertices
        .iter()
        .position(|p| p.iter().any(|c| !c.is_finite()))
    {
        bail!(
            "glTF scene {:?}: body vertex {i} at {:?} m is not finite",
            s.name,
            s.body_vertices[i]
        );
    }
    if let Some(j) = s
        .body_triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= nb))
    {
        bail!(
            "glTF scene {:?}: body triangle {j} {:?} indexes past the body's {nb} vertices",
            s.name,
            s.body_triangles[j]
        );
    }
    Ok(())
}

/// The file's bytes: the GLB header, the JSON chunk and the binary chunk.
fn glb_bytes(s: &GlbScene) -> Result<Vec<u8>> {
    check(s)?;
    let mut bin = Bin::default();
    let mut meshes = Vec::new();
    let mut nodes = vec![json!({
        "name": s.name,
        // −90° about x: the data's +z (up) is glTF's +y
        "rotation": [-std::f64::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f64::consts::FRAC_1_SQRT_2],
        "children": [],
    })];
    let child = |nodes: &mut Vec<Value>, node: Value| {
        nodes.push(node);
        let i = nodes.len() - 1;
        nodes[0]["children"]
            .as_array_mut()
            .expect("children")
            .push(json!(i));
        i
    };

    if !s.body_vertices.is_empty() {
        let v: Vec<[f32; 3]> = s
            .body_vertices
            .iter()
            .map(|p| p.map(|c| c as f32))
            .collect();
        let pos = bin.vec3(&v, true);
        let idx = bin.indices(s.body_triangles);
        meshes.push(json!({
            "name": "body",
            "primitives": [{ "attributes": { "POSITION": pos }, "indices": idx, "material": 0 }],
        }));
        child(
            &mut nodes,
            json!({ "name": "body", "mesh": meshes.len() - 1 }),
        );
    }

    let base = &s.frames[0].1;
    let pos = bin.vec3(base, true);
    let colours: Vec<[f32; 3]> = s
        .stretch
        .iter()
        .map(|&e| linear(colour_map(e / s.stretch_full)))
        .collect();
    let col = bin.vec3(&colours, false);
    let tris: Vec<[u32; 3]> = s
        .garment_triangles
        .iter()
        .map(|t| t.map(|i| i as u32))
        .collect();
    let idx = bin.indices(&tris);
    let targets: Vec<Value> = s.frames[1..]
        .iter()
        .map(|(_, x)| {
            let d: Vec<[f32; 3]> = x
                .iter()
                .zip(base)
                .map(|(p, b)| [p[0] - b[0], p[1] - b[1], p[2] - b[2]])
                .collect();
            json!({ "POSITION": bin.vec3(&d, true) })
        })
        .collect();
    let m = targets.len();
    let mut primitive = json!({
        "attributes": { "POSITION": pos, "COLOR_0": col },
        "indices": idx,
        "material": 1,
    });
    let mut mesh = json!({ "name": "garment" });
    if m > 0 {
        primitive["targets"] = json!(targets);
        mesh["weights"] = json!(vec![0.0; m]);
    }
    mesh["primitives"] = json!([primitive]);
    meshes.push(mesh);
    let garment = child(
        &mut nodes,
        json!({
            "name": "garment",
            "mesh": meshes.len() - 1,
            "extras": { "stretch_full": s.stretch_full, "colour_map": "viridis, 0 to stretch_full" },
        }),
    );

    let mut root = json!({
        "asset": { "version": "2.0", "generator": "garment_sim" },
        "scene": 0,
        "scenes": [{ "name": s.name, "nodes": [0] }],
        "nodes": nodes,
        "meshes": meshes,
        "materials": [
            {
                "name": "body",
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.4, 0.4, 0.38, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.8,
                },
            },
            {
                "name": "garment (colour: stretch)",
                "pbrMetallicRoughness": { "metallicFactor": 0.0, "roughnessFactor": 0.9 },
                "doubleSided": true,
            },
        ],
    });
    if m > 0 {
        // key k: target k (frame k's displacement) weighs 1, the others 0
        let times: Vec<f32> = s.frames.iter().map(|(t, _)| *t as f32).collect();
        let mut weights = vec![0f32; times.len() * m];
        for k in 1..times.len() {
            weights[k * m + k - 1] = 1.0;
        }
        let input = bin.scalars(&times, true);
        let output = bin.scalars(&weights, false);
        root["animations"] = json!([{
            "name": "drape",
            "samplers": [{ "input": input, "output": output, "interpolation": "LINEAR" }],
            "channels": [{ "sampler": 0, "target": { "node": garment, "path": "weights" } }],
        }]);
    }
    root["buffers"] = json!([{ "byteLength": bin.data.len() }]);
    root["bufferViews"] = json!(bin.views);
    root["accessors"] = json!(bin.accessors);

    let mut text = serde_json::to_vec(&root)?;
    text.resize(text.len().next_multiple_of(4), b' ');
    let total = 12 + 8 + text.len() + 8 + bin.data.len();
    ensure!(
        total <= u32::MAX as usize,
        "glTF scene {:?}: {total} bytes, more than a GLB file holds (4 GiB)",
        s.name
    );
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.data.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin.data);
    Ok(out)
}

/// Writes the scene to `path` as binary glTF 2.0 (atomically).
pub fn write_glb(scene: &GlbScene, path: &Path) -> Result<()> {
    let bytes =
        glb_bytes(scene).map_err(|e| e.context(format!("cannot write {}", path.display())))?;
    crate::io::write_atomic(path, |w| w.write_all(&bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square of two triangles, over `frames` frames 0.1 s apart,
    /// moving up 1 cm a frame, on a one-triangle body.
    fn frames(n: usize) -> Vec<(f64, Vec<[f32; 3]>)> {
        (0..n)
            .map(|k| {
                let z = 0.01 * k as f32;
                (
                    0.1 * k as f64,
                    vec![[0.0, 0.0, z], [1.0, 0.0, z], [1.0, 1.0, z], [0.0, 1.0, z]],
                )
            })
            .collect()
    }

    const BODY: [[f64; 3]; 3] = [[0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 1.0, -1.0]];
    const BODY_T: [[u32; 3]; 1] = [[0, 1, 2]];
    const GARMENT_T: [[usize; 3]; 2] = [[0, 1, 2], [0, 2, 3]];
    const STRETCH: [f64; 4] = [0.0, 0.01, 0.02, 0.1];

    fn scene<'a>(f: &'a [(f64, Vec<[f32; 3]>)]) -> GlbScene<'a> {
        GlbScene {
            body_vertices: &BODY,
            body_triangles: &BODY_T,
            garment_triangles: &GARMENT_T,
            frames: f,
            stretch: &STRETCH,
            stretch_full: 0.05,
            name: "square",
        }
    }

    fn error(s: &GlbScene) -> String {
        format!("{:#}", glb_bytes(s).expect_err("refused"))
    }

    #[test]
    fn a_good_scene_is_a_glb_of_the_length_it_says() {
        let f = frames(3);
        let b = glb_bytes(&scene(&f)).unwrap();
        assert_eq!(&b[0..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(b[8..12].try_into().unwrap()) as usize,
            b.len()
        );
        assert_eq!(b.len() % 4, 0);
        let json_len = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        let root: Value = serde_json::from_slice(&b[20..20 + json_len]).unwrap();
        // two targets, three keys of two weights
        assert_eq!(
            root["meshes"][1]["primitives"][0]["targets"]
                .as_array()
                .unwrap()
                .len(),
            2
        );
        let out = root["animations"][0]["samplers"][0]["output"]
            .as_u64()
            .unwrap() as usize;
        assert_eq!(root["accessors"][out]["count"], 6);
        // one frame: no targets, no animation
        let f1 = frames(1);
        let b = glb_bytes(&scene(&f1)).unwrap();
        let json_len = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        let root: Value = serde_json::from_slice(&b[20..20 + json_len]).unwrap();
        assert!(root.get("animations").is_none());
        assert!(root["meshes"][1]["primitives"][0].get("targets").is_none());
    }

    #[test]
    fn refuses_no_frames_and_too_many() {
        assert!(error(&scene(&[])).contains("no garment frame"));
        let f = frames(MAX_TARGETS + 2);
        let e = error(&scene(&f));
        assert!(e.contains("257 garment frames, at most 256"), "{e}");
        let f = frames(MAX_TARGETS + 1);
        glb_bytes(&scene(&f)).unwrap();
    }

    #[test]
    fn refuses_mismatched_lengths() {
        let mut f = frames(3);
        f[2].1.pop();
        let e = error(&scene(&f));
        assert!(
            e.contains("frame 2 (t = 0.2 s) has 3 vertices, frame 0 has 4"),
            "{e}"
        );
        let f = frames(2);
        let mut s = scene(&f);
        s.stretch = &STRETCH[..3];
        assert!(error(&s).contains("3 stretch values for 4 garment vertices"));
    }

    #[test]
    fn refuses_nan_naming_it() {
        let mut f = frames(3);
        f[1].1[2][1] = f32::NAN;
        let e = error(&scene(&f));
        assert!(
            e.contains("garment frame 1 (t = 0.1 s), vertex 2") && e.contains("NaN"),
            "{e}"
        );
        let f = frames(2);
        let mut s = scene(&f);
        let st = [0.0, f64::NAN, 0.0, 0.0];
        s.stretch = &st;
        assert!(error(&s).contains("stretch of garment vertex 1 is NaN"));
        let body = [[0.0, 0.0, 0.0], [1.0, f64::INFINITY, 0.0], [0.0, 1.0, 0.0]];
        s.stretch = &STRETCH;
        s.body_vertices = &body;
        assert!(error(&s).contains("body vertex 1"));
        let mut f = frames(2);
        f[1].0 = f64::NAN;
        assert!(error(&scene(&f)).contains("garment frame 1 at time NaN s"));
    }

    #[test]
    fn refuses_out_of_range_indices_and_unordered_times() {
        let f = frames(2);
        let mut s = scene(&f);
        let t = [[0usize, 1, 4]];
        s.garment_triangles = &t;
        assert!(error(&s).contains("garment triangle 0 [0, 1, 4] indexes past the garment's 4"));
        let mut s = scene(&f);
        let bt = [[0u32, 3, 1]];
        s.body_triangles = &bt;
        assert!(error(&s).contains("body triangle 0 [0, 3, 1] indexes past the body's 3"));
        let mut f = frames(3);
        f[2].0 = 0.1;
        assert!(error(&scene(&f)).contains("frame 2 at 0.1 s is not after frame 1"));
        let f = frames(2);
        let mut s = scene(&f);
        s.stretch_full = 0.0;
        assert!(error(&s).contains("stretch full scale 0"));
    }
}
