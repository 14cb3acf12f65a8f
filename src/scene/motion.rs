//! Body motions read from files (docs/bodies.md): a sequence of meshes of
//! one topology (OBJ or ASCII PLY, one file per frame, at a frame rate) and
//! glTF 2.0 skinned animations, skinned by linear blend skinning. Either
//! gives the triangles and a [`Motion`] for
//! [`crate::collision::Obstacle::with_motion`].

use crate::deforming::{Keyframes, Motion};
use anyhow::{bail, Context, Result};
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3, Vector4};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

type V = Vector3<f64>;

/// A glTF vertex's bind position and skinning (slot, weight), as bits.
type WeldKey = ([u64; 3], [(u32, u64); 4]);

/// A motion and the triangles of the mesh it moves.
#[derive(Debug, Clone)]
pub struct LoadedMotion {
    pub triangles: Vec<[u32; 3]>,
    pub motion: Arc<dyn Motion>,
}

/// The files a pattern with one `*` in its file name names (`walk/f_*.obj`),
/// in the order of the number the `*` stands for when every match has one
/// (`f_2` before `f_10`), else in the order of their names.
pub fn expand_pattern(pattern: &Path) -> Result<Vec<PathBuf>> {
    let name = pattern
        .file_name()
        .and_then(|n| n.to_str())
        .with_context(|| format!("frame pattern {}: no file name", pattern.display()))?;
    let Some((head, tail)) = name.split_once('*') else {
        bail!(
            "frame pattern {}: put one '*' in the file name where the frame number goes",
            pattern.display()
        );
    };
    if tail.contains('*') {
        bail!("frame pattern {}: only one '*' is read", pattern.display());
    }
    let dir = match pattern.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found: Vec<(String, PathBuf)> = Vec::new();
    for e in std::fs::read_dir(&dir).with_context(|| {
        format!(
            "frame pattern {}: cannot list {}",
            pattern.display(),
            dir.display()
        )
    })? {
        let e = e?;
        let n = e.file_name().to_string_lossy().to_string();
        if n.len() >= head.len() + tail.len() && n.starts_with(head) && n.ends_with(tail) {
            let mid = n[head.len()..n.len() - tail.len()].to_string();
            found.push((mid, e.path()));
        }
    }
    if found.is_empty() {
        bail!("frame pattern {}: no file matches", pattern.display());
    }
    let numbers: Option<Vec<u64>> = found.iter().map(|(m, _)| m.parse().ok()).collect();
    match numbers {
        Some(nums) => {
            let mut idx: Vec<usize> = (0..found.len()).collect();
            idx.sort_by_key(|&k| (nums[k], found[k].0.clone()));
            Ok(idx.into_iter().map(|k| found[k].1.clone()).collect())
        }
        None => {
            found.sort();
            Ok(found.into_iter().map(|(_, p)| p).collect())
        }
    }
}

/// Frames from meshes of one topology (OBJ, or ASCII PLY as `garment_sim`
/// writes it), `1 / fps` apart, scaled by `scale` (m per file unit).
/// Refuses, naming the file, a frame whose vertex count or faces differ
/// from the first frame's, or that has a non-finite coordinate.
pub fn load_frames(files: &[PathBuf], fps: f64, scale: f64) -> Result<LoadedMotion> {
    if files.is_empty() {
        bail!("a mesh sequence needs at least one frame file");
    }
    if !(scale.is_finite() && scale > 0.0) {
        bail!("scale {scale}: must be > 0 (metres per file unit)");
    }
    let mut frames = Vec::with_capacity(files.len());
    let mut tris: Vec<[usize; 3]> = Vec::new();
    for (k, f) in files.iter().enumerate() {
        let s = super::shape::Shape::read(f)
            .with_context(|| format!("frame {k} of the mesh sequence"))?;
        if let Some(i) = s
            .vertices
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            bail!(
                "frame file {}: vertex {i} is not finite: {:?}",
                f.display(),
                s.vertices[i]
            );
        }
        if k == 0 {
            tris = s.triangles.clone();
        } else {
            let n0 = frames.first().map_or(0, |v: &Vec<V>| v.len());
            if s.vertices.len() != n0 {
                bail!(
                    "frame file {}: {} vertices where the first frame ({}) has {n0}: every frame \
                     must be the same mesh",
                    f.display(),
                    s.vertices.len(),
                    files[0].display()
                );
            }
            if s.triangles != tris {
                let at = s
                    .triangles
                    .iter()
                    .zip(&tris)
                    .position(|(a, b)| a != b)
                    .unwrap_or(tris.len().min(s.triangles.len()));
                bail!(
                    "frame file {}: its faces differ from the first frame's ({}), from triangle \
                     {at} on ({} and {} triangles): every frame must have one topology",
                    f.display(),
                    files[0].display(),
                    s.triangles.len(),
                    tris.len()
                );
            }
        }
        frames.push(s.vertices.iter().map(|p| p * scale).collect());
    }
    let n = frames[0].len();
    let triangles = tris.iter().map(|t| t.map(|i| i as u32)).collect::<Vec<_>>();
    if let Some(t) = triangles
        .iter()
        .find(|t| t.iter().any(|&i| i as usize >= n))
    {
        bail!("{}: face {t:?} beyond its {n} vertices", files[0].display());
    }
    let k = Keyframes::at_rate(fps, frames).context("mesh sequence")?;
    Ok(LoadedMotion {
        triangles,
        motion: Arc::new(k),
    })
}

/// Interpolation of an animation channel.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Interp {
    Linear,
    Step,
}

/// What a channel animates.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Prop {
    Translation,
    Rotation,
    Scale,
}

#[derive(Debug, Clone)]
struct Channel {
    node: usize,
    prop: Prop,
    interp: Interp,
    times: Vec<f64>,
    /// One value per time: xyz (translation, scale) or xyzw (rotation).
    values: Vec<[f64; 4]>,
}

impl Channel {
    fn sample(&self, t: f64) -> [f64; 4] {
        let n = self.times.len();
        let k = self.times.partition_point(|&s| s <= t);
        if k == 0 {
            return self.values[0];
        }
        if k >= n || self.interp == Interp::Step {
            return self.values[k - 1];
        }
        let (t0, t1) = (self.times[k - 1], self.times[k]);
        let w = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
        let (a, b) = (self.values[k - 1], self.values[k]);
        if self.prop == Prop::Rotation {
            slerp(a, b, w)
        } else {
            std::array::from_fn(|i| a[i] + (b[i] - a[i]) * w)
        }
    }
}

/// Spherical linear interpolation of unit quaternions (xyzw) along the
/// shorter arc.
fn slerp(a: [f64; 4], b: [f64; 4], w: f64) -> [f64; 4] {
    let (qa, mut qb) = (Vector4::from(a), Vector4::from(b));
    let mut d = qa.dot(&qb);
    if d < 0.0 {
        qb = -qb;
        d = -d;
    }
    let q = if d > 1.0 - 1e-12 {
        (qa + (qb - qa) * w).normalize()
    } else {
        let th = d.min(1.0).acos();
        let s = th.sin();
        qa * (((1.0 - w) * th).sin() / s) + qb * ((w * th).sin() / s)
    };
    [q[0], q[1], q[2], q[3]]
}

#[derive(Debug, Clone)]
struct NodeRest {
    parent: Option<usize>,
    t: [f64; 3],
    r: [f64; 4],
    s: [f64; 3],
}

/// A glTF 2.0 scene's meshes moved by one of its animations: skinned
/// meshes by linear blend skinning (each vertex Σ wⱼ Jⱼ v, with joint
/// matrix Jⱼ = the joint node's animated world transform × its inverse bind
/// matrix), other meshes by their node's animated world transform. Positions
/// come out Z up (glTF's +Y up turned to +Z: (x, y, z) → (x, −z, y), as
/// Blender's importer does), scaled by `scale`.
#[derive(Debug, Clone)]
pub struct Skinned {
    nodes: Vec<NodeRest>,
    /// Nodes with parents before children.
    order: Vec<usize>,
    channels: Vec<Channel>,
    duration: f64,
    /// Matrix slots: (node, matrix applied after its world transform).
    slots: Vec<(usize, Matrix4<f64>)>,
    /// Per output vertex: its bind position and up to four (slot, weight).
    bind: Vec<V>,
    influences: Vec<[(u32, f64); 4]>,
    scale: f64,
}

impl Skinned {
    fn world(&self, t: f64) -> Vec<Matrix4<f64>> {
        let mut trs: Vec<([f64; 3], [f64; 4], [f64; 3])> =
            self.nodes.iter().map(|n| (n.t, n.r, n.s)).collect();
        for c in &self.channels {
            let v = c.sample(t);
            let e = &mut trs[c.node];
            match c.prop {
                Prop::Translation => e.0 = [v[0], v[1], v[2]],
                Prop::Rotation => e.1 = v,
                Prop::Scale => e.2 = [v[0], v[1], v[2]],
            }
        }
        let mut world = vec![Matrix4::identity(); self.nodes.len()];
        for &k in &self.order {
            let (t, r, s) = trs[k];
            let q = UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2]));
            let local = Matrix4::new_translation(&V::from(t))
                * q.to_homogeneous()
                * Matrix4::new_nonuniform_scaling(&V::from(s));
            world[k] = match self.nodes[k].parent {
                Some(p) => world[p] * local,
                None => local,
            };
        }
        world
    }

    /// The joint (or node) matrices at time `t`, one per slot.
    fn slot_matrices(&self, t: f64) -> Vec<Matrix4<f64>> {
        let world = self.world(t);
        self.slots.iter().map(|(n, m)| world[*n] * m).collect()
    }

    /// Positions in glTF's own axes (Y up, file units) at time `t`.
    pub fn positions_y_up(&self, t: f64) -> Vec<V> {
        let mats = self.slot_matrices(t);
        self.bind
            .iter()
            .zip(&self.influences)
            .map(|(p, inf)| {
                let h = p.push(1.0);
                let mut o = Vector4::zeros();
                for &(s, w) in inf {
                    if w != 0.0 {
                        o += (mats[s as usize] * h) * w;
                    }
                }
                o.xyz()
            })
            .collect()
    }
}

impl Motion for Skinned {
    fn vertex_count(&self) -> usize {
        self.bind.len()
    }

    fn duration(&self) -> f64 {
        self.duration
    }

    fn positions(&self, t: f64, out: &mut [V]) {
        for (o, p) in out.iter_mut().zip(self.positions_y_up(t)) {
            *o = V::new(p.x, -p.z, p.y) * self.scale;
        }
    }
}

/// The buffers of a glTF file: a GLB's binary chunk, base64 `data:` URIs,
/// or files beside it.
fn buffers(doc: &gltf::Gltf, path: &Path) -> Result<Vec<Vec<u8>>> {
    use base64::Engine;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for b in doc.buffers() {
        let data = match b.source() {
            gltf::buffer::Source::Bin => doc
                .blob
                .clone()
                .with_context(|| format!("buffer {}: the file has no binary chunk", b.index()))?,
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let (_, payload) = rest.split_once(";base64,").with_context(|| {
                        format!("buffer {}: a data URI that is not base64", b.index())
                    })?;
                    base64::engine::general_purpose::STANDARD
                        .decode(payload)
                        .with_context(|| format!("buffer {}: bad base64", b.index()))?
                } else {
                    let p = dir.join(uri);
                    std::fs::read(&p).with_context(|| {
                        format!("buffer {}: cannot read {}", b.index(), p.display())
                    })?
                }
            }
        };
        if data.len() < b.length() {
            bail!(
                "buffer {}: {} bytes, the file declares {}",
                b.index(),
                data.len(),
                b.length()
            );
        }
        out.push(data);
    }
    Ok(out)
}

/// The nodes' rest transforms and parents, and an order with parents first.
fn node_hierarchy(doc: &gltf::Gltf) -> Result<(Vec<NodeRest>, Vec<usize>)> {
    let n = doc.nodes().count();
    let mut parent = vec![None; n];
    for node in doc.nodes() {
        for c in node.children() {
            parent[c.index()] = Some(node.index());
        }
    }
    let nodes: Vec<NodeRest> = doc
        .nodes()
        .map(|node| {
            let (t, r, s) = node.transform().decomposed();
            NodeRest {
                parent: parent[node.index()],
                t: t.map(f64::from),
                r: r.map(f64::from),
                s: s.map(f64::from),
            }
        })
        .collect();
    let mut order = Vec::with_capacity(n);
    let mut stack: Vec<usize> = (0..n).filter(|&k| parent[k].is_none()).collect();
    while let Some(k) = stack.pop() {
        order.push(k);
        stack.extend(
            doc.nodes()
                .nth(k)
                .expect("node")
                .children()
                .map(|c| c.index()),
        );
    }
    if order.len() != n {
        bail!("its node hierarchy has a cycle");
    }
    Ok((nodes, order))
}

/// The animation named `animation` (its name, or its index as a number;
/// the first if `None`).
fn find_animation<'a>(
    doc: &'a gltf::Gltf,
    animation: Option<&str>,
) -> Result<Option<gltf::Animation<'a>>> {
    Ok(match animation {
        None => doc.animations().next(),
        Some(a) => Some(
            doc.animations()
                .find(|x| x.name() == Some(a) || a.parse::<usize>().ok() == Some(x.index()))
                .with_context(|| {
                    let names: Vec<String> = doc
                        .animations()
                        .map(|x| x.name().map_or(format!("#{}", x.index()), str::to_string))
                        .collect();
                    format!("no animation {a:?}; it has {names:?}")
                })?,
        ),
    })
}

/// One channel of an animation, checked (`None`: morph target weights,
/// which are not read).
fn read_channel(
    anim: &gltf::Animation,
    ch: &gltf::animation::Channel,
    bufs: &[Vec<u8>],
) -> Result<Option<Channel>> {
    let get = |b: gltf::Buffer| bufs.get(b.index()).map(|v| v.as_slice());
    let what = || format!("animation {}, channel {}", anim.index(), ch.index());
    let prop = match ch.target().property() {
        gltf::animation::Property::Translation => Prop::Translation,
        gltf::animation::Property::Rotation => Prop::Rotation,
        gltf::animation::Property::Scale => Prop::Scale,
        // morph targets are not read
        gltf::animation::Property::MorphTargetWeights => return Ok(None),
    };
    let interp = match ch.sampler().interpolation() {
        gltf::animation::Interpolation::Linear => Interp::Linear,
        gltf::animation::Interpolation::Step => Interp::Step,
        gltf::animation::Interpolation::CubicSpline => bail!(
            "{}: CUBICSPLINE interpolation is not read; export with LINEAR (e.g. \
             Blender: bake the animation) or STEP",
            what()
        ),
    };
    let r = ch.reader(get);
    let times: Vec<f64> = r
        .read_inputs()
        .with_context(|| format!("{}: no input times", what()))?
        .map(f64::from)
        .collect();
    let values: Vec<[f64; 4]> = match r
        .read_outputs()
        .with_context(|| format!("{}: no output values", what()))?
    {
        gltf::animation::util::ReadOutputs::Translations(it)
        | gltf::animation::util::ReadOutputs::Scales(it) => it
            .map(|v| [v[0].into(), v[1].into(), v[2].into(), 0.0])
            .collect(),
        gltf::animation::util::ReadOutputs::Rotations(it) => {
            it.into_f32().map(|v| v.map(f64::from)).collect()
        }
        gltf::animation::util::ReadOutputs::MorphTargetWeights(_) => return Ok(None),
    };
    if times.is_empty() || values.len() != times.len() {
        bail!(
            "{}: {} times for {} values",
            what(),
            times.len(),
            values.len()
        );
    }
    if times.windows(2).any(|w| w[1] <= w[0]) || !times.iter().all(|t| t.is_finite()) {
        bail!("{}: its times must be finite and increase", what());
    }
    if values.iter().any(|v| !v.iter().all(|c| c.is_finite())) {
        bail!("{}: a non-finite value", what());
    }
    Ok(Some(Channel {
        node: ch.target().node().index(),
        prop,
        interp,
        times,
        values,
    }))
}

/// The glTF nodes of `scene` and their descendants, by index.
fn scene_nodes(scene: &gltf::Scene) -> Vec<usize> {
    let mut in_scene = Vec::new();
    let mut stack: Vec<gltf::Node> = scene.nodes().collect();
    while let Some(node) = stack.pop() {
        in_scene.push(node.index());
        stack.extend(node.children());
    }
    in_scene.sort();
    in_scene
}

/// The skinned mesh as it is read: matrix slots, welded vertices (bind
/// position and skinning) and triangles.
#[derive(Default)]
struct MeshReader {
    slots: Vec<(usize, Matrix4<f64>)>,
    bind: Vec<V>,
    influences: Vec<[(u32, f64); 4]>,
    weld: HashMap<WeldKey, u32>,
    triangles: Vec<[u32; 3]>,
}

impl MeshReader {
    /// Adds node `k`'s matrix slots (one per joint of its skin, or one for
    /// the node itself) and reads its mesh's primitives.
    fn add_node(&mut self, node: &gltf::Node, mesh: &gltf::Mesh, bufs: &[Vec<u8>]) -> Result<()> {
        let get = |b: gltf::Buffer| bufs.get(b.index()).map(|v| v.as_slice());
        let k = node.index();
        // the matrix slots of this node's vertices
        let skin_slots: Option<Vec<u32>> = match node.skin() {
            Some(skin) => {
                let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
                let ibm: Vec<Matrix4<f64>> = match skin.reader(get).read_inverse_bind_matrices() {
                    Some(it) => it
                        .map(|m| Matrix4::from_fn(|r, c| f64::from(m[c][r])))
                        .collect(),
                    None => vec![Matrix4::identity(); joints.len()],
                };
                if ibm.len() != joints.len() {
                    bail!(
                        "skin {}: {} inverse bind matrices for {} joints",
                        skin.index(),
                        ibm.len(),
                        joints.len()
                    );
                }
                Some(
                    joints
                        .iter()
                        .zip(ibm)
                        .map(|(&j, m)| {
                            self.slots.push((j, m));
                            (self.slots.len() - 1) as u32
                        })
                        .collect(),
                )
            }
            None => None,
        };
        let rigid_slot = if skin_slots.is_none() {
            self.slots.push((k, Matrix4::identity()));
            Some((self.slots.len() - 1) as u32)
        } else {
            None
        };
        for prim in mesh.primitives() {
            self.add_primitive(mesh, &prim, skin_slots.as_deref(), rigid_slot, bufs)?;
        }
        Ok(())
    }

    /// Reads a triangle primitive: its vertices welded by bind position and
    /// skinning, and its triangles (degenerate ones dropped).
    fn add_primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        skin_slots: Option<&[u32]>,
        rigid_slot: Option<u32>,
        bufs: &[Vec<u8>],
    ) -> Result<()> {
        let get = |b: gltf::Buffer| bufs.get(b.index()).map(|v| v.as_slice());
        let what = || format!("mesh {}, primitive {}", mesh.index(), prim.index());
        if prim.mode() != gltf::mesh::Mode::Triangles {
            bail!(
                "{}: mode {:?}; only triangles are read",
                what(),
                prim.mode()
            );
        }
        let r = prim.reader(get);
        let pos: Vec<[f32; 3]> = r
            .read_positions()
            .with_context(|| format!("{}: no POSITION", what()))?
            .collect();
        let inf: Vec<[(u32, f64); 4]> = match skin_slots {
            Some(ss) => skin_influences(&r, ss, pos.len(), &what)?,
            None => {
                let s = rigid_slot.expect("rigid");
                vec![[(s, 1.0), (s, 0.0), (s, 0.0), (s, 0.0)]; pos.len()]
            }
        };
        let idx: Vec<u32> = match r.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..pos.len() as u32).collect(),
        };
        if !idx.len().is_multiple_of(3) {
            bail!("{}: {} indices, not whole triangles", what(), idx.len());
        }
        let mut map = Vec::with_capacity(pos.len());
        for (i, p) in pos.iter().enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                bail!("{}: vertex {i} is not finite: {p:?}", what());
            }
            let key = (
                p.map(|c| f64::from(c).to_bits()),
                inf[i].map(|(s, w)| (s, w.to_bits())),
            );
            let next = self.bind.len() as u32;
            let id = *self.weld.entry(key).or_insert(next);
            if id == next {
                self.bind
                    .push(V::new(p[0].into(), p[1].into(), p[2].into()));
                self.influences.push(inf[i]);
            }
            map.push(id);
        }
        for t in idx.chunks(3) {
            let v = [t[0], t[1], t[2]].map(|i| map.get(i as usize).copied());
            let [Some(a), Some(b), Some(c)] = v else {
                bail!(
                    "{}: a triangle uses a vertex beyond its {}",
                    what(),
                    pos.len()
                );
            };
            if a != b && b != c && a != c {
                self.triangles.push([a, b, c]);
            }
        }
        Ok(())
    }
}

/// A skinned primitive's vertices' (slot, weight) from JOINTS_0 and
/// WEIGHTS_0, the weights normalised to sum 1.
fn skin_influences<'a, 's, F>(
    r: &gltf::mesh::Reader<'a, 's, F>,
    ss: &[u32],
    count: usize,
    what: &dyn Fn() -> String,
) -> Result<Vec<[(u32, f64); 4]>>
where
    F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    let j: Vec<[u16; 4]> = r
        .read_joints(0)
        .with_context(|| format!("{}: skinned but no JOINTS_0", what()))?
        .into_u16()
        .collect();
    let w: Vec<[f32; 4]> = r
        .read_weights(0)
        .with_context(|| format!("{}: skinned but no WEIGHTS_0", what()))?
        .into_f32()
        .collect();
    if j.len() != count || w.len() != count {
        bail!("{}: JOINTS_0 or WEIGHTS_0 not one per vertex", what());
    }
    let mut out = Vec::with_capacity(count);
    for (i, (j, w)) in j.iter().zip(&w).enumerate() {
        let sum: f64 = w.iter().map(|&x| f64::from(x)).sum();
        if !(sum.is_finite() && sum > 0.0) || w.iter().any(|&x| x < 0.0) {
            bail!("{}: vertex {i} has skin weights {w:?}", what());
        }
        let mut e = [(0u32, 0.0); 4];
        for q in 0..4 {
            let slot = *ss.get(j[q] as usize).with_context(|| {
                format!("{}: vertex {i} uses joint {} of {}", what(), j[q], ss.len())
            })?;
            e[q] = (slot, f64::from(w[q]) / sum);
        }
        out.push(e);
    }
    Ok(out)
}

/// Reads a glTF 2.0 file (`.gltf` with its buffers, or `.glb`): the meshes
/// of its default scene (or first scene) moved by the animation named
/// `animation` (its name, or its index as a number; the first if `None`;
/// none: the meshes stand still). Vertices with the same bind position and
/// the same skinning are one vertex (glTF splits them at texture seams), so
/// a closed body stays closed. Only triangle primitives are read; an
/// interpolation other than LINEAR or STEP is refused.
pub fn load_gltf(
    path: &Path,
    animation: Option<&str>,
    scale: f64,
) -> Result<(Vec<[u32; 3]>, Skinned)> {
    let ctx = || format!("glTF file {}", path.display());
    (|| -> Result<(Vec<[u32; 3]>, Skinned)> {
        if !(scale.is_finite() && scale > 0.0) {
            bail!("scale {scale}: must be > 0 (metres per file unit)");
        }
        let bytes = std::fs::read(path).context("cannot read it")?;
        let doc = gltf::Gltf::from_slice(&bytes).context("not valid glTF 2.0")?;
        let bufs = buffers(&doc, path)?;
        // nodes, their parents and an order with parents first
        let n = doc.nodes().count();
        let (nodes, order) = node_hierarchy(&doc)?;
        // the animation
        let anim = find_animation(&doc, animation)?;
        let mut channels = Vec::new();
        let mut duration: f64 = 0.0;
        if let Some(anim) = &anim {
            for ch in anim.channels() {
                let Some(c) = read_channel(anim, &ch, &bufs)? else {
                    continue;
                };
                duration = duration.max(*c.times.last().expect("non-empty"));
                channels.push(c);
            }
        }
        // the meshes of the scene
        let scene = doc
            .default_scene()
            .or_else(|| doc.scenes().next())
            .context("it has no scene")?;
        let mut mesh = MeshReader::default();
        for k in scene_nodes(&scene) {
            let node = doc.nodes().nth(k).expect("node");
            let Some(m) = node.mesh() else { continue };
            mesh.add_node(&node, &m, &bufs)?;
        }
        if mesh.triangles.is_empty() {
            bail!("its scene has no triangle mesh");
        }
        for c in &channels {
            if c.node >= n {
                bail!("a channel animates node {} of {n}", c.node);
            }
        }
        let skinned = Skinned {
            nodes,
            order,
            channels,
            duration,
            slots: mesh.slots,
            bind: mesh.bind,
            influences: mesh.influences,
            scale,
        };
        Ok((mesh.triangles, skinned))
    })()
    .with_context(ctx)
}
