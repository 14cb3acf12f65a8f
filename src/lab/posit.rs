//! The calibrated camera of thesis eq. 6.1 (§6.3.1) and what the
//! reconstruction does with it: the pose of a camera from marks of known
//! position (POSIT, then least squares on the reprojection error) and the
//! position of a mark seen by posed cameras (triangulation).
//!
//! - [`posit`]: DeMenthon & Davis 1995, "Model-based object pose in 25 lines
//!   of code" (IJCV 15) for marks that are not coplanar, and its coplanar
//!   variant, Oberkampf, DeMenthon & Davis 1996, "Iterative pose estimation
//!   using coplanar feature points" (CVIU 63), for marks on a plane, which
//!   also tries the closed-form pose of the plane's homography (Zhang 2000).
//! - [`refine_pose`]: Levenberg–Marquardt on the pixel reprojection error
//!   with the full intrinsic model (focal length, pixel scales, principal
//!   point, skew).
//! - [`triangulate`]: the linear (DLT) triangulation (Hartley & Zisserman,
//!   "Multiple View Geometry", §12.2), then Levenberg–Marquardt on the pixel
//!   reprojection error.

use anyhow::{bail, Result};
use nalgebra::{DMatrix, Matrix3, Matrix6, Rotation3, SMatrix, SVector, Vector3, Vector6};
use serde::{Deserialize, Serialize};

type V3 = Vector3<f64>;

/// The intrinsic parameters of thesis eq. 6.1: a pinhole of focal length
/// `focal` (m) whose sensor has `ku` × `kv` pixels per metre, principal
/// point (`cu`, `cv`) in pixels and skew `skew` (pixels per metre; 0 for
/// square-cornered cells). A point (x, y, z) in the camera's frame (z along
/// the optical axis, y down the image) falls on pixel
/// u = (f ku x + f s_uv y) / z + cu, v = f kv y / z + cv.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    pub focal: f64,
    pub ku: f64,
    pub kv: f64,
    pub cu: f64,
    pub cv: f64,
    #[serde(default)]
    pub skew: f64,
}

impl Intrinsics {
    /// Refuses non-finite values and a focal length or pixel scale ≤ 0.
    pub fn check(&self) -> Result<()> {
        let all = [
            ("focal", self.focal),
            ("ku", self.ku),
            ("kv", self.kv),
            ("cu", self.cu),
            ("cv", self.cv),
            ("skew", self.skew),
        ];
        for (name, v) in all {
            if !v.is_finite() {
                bail!("intrinsics: {name} = {v} is not a finite number");
            }
        }
        for (name, v) in &all[..3] {
            if *v <= 0.0 {
                bail!("intrinsics: {name} = {v} must be > 0");
            }
        }
        Ok(())
    }

    /// The 3 × 3 matrix of eq. 6.1 (pixel scales times focal length).
    pub fn matrix(&self) -> Matrix3<f64> {
        let f = self.focal;
        Matrix3::new(
            f * self.ku,
            f * self.skew,
            self.cu,
            0.0,
            f * self.kv,
            self.cv,
            0.0,
            0.0,
            1.0,
        )
    }

    /// Pixel of a point of normalised image coordinates (x/z, y/z).
    pub fn pixel(&self, n: [f64; 2]) -> [f64; 2] {
        let f = self.focal;
        [
            f * self.ku * n[0] + f * self.skew * n[1] + self.cu,
            f * self.kv * n[1] + self.cv,
        ]
    }

    /// Normalised image coordinates (x/z, y/z) of a pixel.
    pub fn normalise(&self, px: [f64; 2]) -> [f64; 2] {
        let f = self.focal;
        let y = (px[1] - self.cv) / (f * self.kv);
        let x = (px[0] - self.cu - f * self.skew * y) / (f * self.ku);
        [x, y]
    }

    /// Pixels per unit of normalised coordinate (the mean of the two scales).
    pub fn focal_px(&self) -> f64 {
        0.5 * self.focal * (self.ku + self.kv)
    }
}

/// Where a camera is: a point p of the world is at `rotation` p +
/// `translation` in the camera's frame (eq. 6.1's [R | t]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub rotation: Rotation3<f64>,
    pub translation: V3,
}

impl Pose {
    /// A point of the world in the camera's frame.
    pub fn to_camera(&self, p: &V3) -> V3 {
        self.rotation * p + self.translation
    }

    /// The optical centre in the world.
    pub fn centre(&self) -> V3 {
        -(self.rotation.inverse() * self.translation)
    }

    /// A camera at `eye` looking at `target`, image x along `forward × up`
    /// (so that world `up` is up in the image, which has y down).
    pub fn looking_at(eye: V3, target: V3, up: V3) -> Pose {
        let z = (target - eye).normalize();
        let x = z.cross(&up).normalize();
        let y = z.cross(&x);
        let r = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
            x.transpose(),
            y.transpose(),
            z.transpose(),
        ]));
        Pose {
            rotation: r,
            translation: -(r * eye),
        }
    }

    /// Rotation angle between two poses, rad.
    pub fn angle_to(&self, other: &Pose) -> f64 {
        // atan2 of the sine and cosine halves of R = R1 R2ᵀ: accurate near 0
        let r = (self.rotation * other.rotation.inverse()).into_inner();
        let s = V3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        );
        (0.5 * s.norm()).atan2(0.5 * (r.trace() - 1.0))
    }
}

/// Pixel of a world point seen by a posed camera; `None` behind the camera.
pub fn project(k: &Intrinsics, pose: &Pose, p: &V3) -> Option<[f64; 2]> {
    let c = pose.to_camera(p);
    (c.z > 1e-9).then(|| k.pixel([c.x / c.z, c.y / c.z]))
}

/// How far points are from a line and from a plane, relative to their
/// spread: the singular values σ2/σ1 and σ3/σ1 of the centred points.
pub fn flatness(points: &[V3]) -> (f64, f64) {
    let n = points.len().max(1) as f64;
    let c = points.iter().sum::<V3>() / n;
    let mut m = Matrix3::zeros();
    for p in points {
        let d = p - c;
        m += d * d.transpose();
    }
    let mut s: Vec<f64> = m
        .symmetric_eigenvalues()
        .iter()
        .map(|e| e.max(0.0).sqrt())
        .collect();
    s.sort_by(|a, b| b.total_cmp(a));
    if s[0] <= 0.0 {
        return (0.0, 0.0);
    }
    (s[1] / s[0], s[2] / s[0])
}

/// Below this σ2/σ1 the marks of a view are taken as collinear: no pose.
pub const COLLINEAR: f64 = 1e-4;
/// Below this σ3/σ1 the marks are taken as coplanar (Oberkampf's variant).
pub const COPLANAR: f64 = 1e-3;

/// Refuses marks POSIT cannot pose: counts that differ or are under 4,
/// non-finite coordinates, marks collinear in the world or in the image.
/// Returns the marks' σ3/σ1 (their flatness).
fn check_marks(object: &[V3], image: &[[f64; 2]]) -> Result<f64> {
    if object.len() != image.len() {
        bail!("{} points but {} image points", object.len(), image.len());
    }
    if object.len() < 4 {
        bail!("{} marks: a pose needs at least 4", object.len());
    }
    if image.iter().flatten().any(|x| !x.is_finite())
        || object.iter().any(|p| !p.iter().all(|c| c.is_finite()))
    {
        bail!("non-finite coordinates");
    }
    let (line, plane) = flatness(object);
    if line < COLLINEAR {
        bail!("the marks are collinear (σ2/σ1 = {line:.1e}): no pose");
    }
    let img3: Vec<V3> = image.iter().map(|q| V3::new(q[0], q[1], 0.0)).collect();
    if flatness(&img3).0 < COLLINEAR {
        bail!("the marks are collinear in the image: no pose");
    }
    Ok(plane)
}

/// The state of a POSIT iteration: the marks, the reference mark M0, the
/// others and their offsets from it, the pseudo-inverse B of those offsets
/// and, for coplanar marks, the plane's normal.
struct Posit<'a> {
    object: &'a [V3],
    image: &'a [[f64; 2]],
    r0: usize,
    others: Vec<usize>,
    rel: Vec<V3>,
    b: DMatrix<f64>,
    normal: V3,
    x0: [f64; 2],
}

/// The best pose found so far, by its reprojection error.
type Best = Option<(f64, Pose)>;

impl<'a> Posit<'a> {
    /// Sets up the iteration; also returns the directions of the marks'
    /// best-fit plane (the offsets' two strongest singular directions).
    fn new(object: &'a [V3], image: &'a [[f64; 2]], coplanar: bool) -> (Posit<'a>, V3, V3) {
        // reference point M0: the mark nearest the centroid
        let c = object.iter().sum::<V3>() / object.len() as f64;
        let r0 = (0..object.len())
            .min_by(|&a, &b| (object[a] - c).norm().total_cmp(&(object[b] - c).norm()))
            .unwrap_or(0);
        let others: Vec<usize> = (0..object.len()).filter(|&i| i != r0).collect();
        let a = DMatrix::from_fn(others.len(), 3, |r, k| object[others[r]][k] - object[r0][k]);
        let svd = a.clone().svd(true, true);
        let v_t = svd.v_t.as_ref().expect("asked for V");
        let sv = &svd.singular_values;
        let smax = sv.max();
        // pseudo-inverse B (3 × n−1), dropping the null direction when coplanar
        let u = svd.u.as_ref().expect("asked for U");
        let mut b: DMatrix<f64> = DMatrix::zeros(3, others.len());
        let mut normal = V3::zeros();
        for k in 0..3 {
            let vk = V3::new(v_t[(k, 0)], v_t[(k, 1)], v_t[(k, 2)]);
            if coplanar && sv[k] < COPLANAR * smax {
                normal = vk;
                continue;
            }
            for r in 0..others.len() {
                for d in 0..3 {
                    b[(d, r)] += vk[d] * u[(r, k)] / sv[k];
                }
            }
        }
        let rel: Vec<V3> = others.iter().map(|&i| object[i] - object[r0]).collect();
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| sv[b].total_cmp(&sv[a]));
        let row = |k: usize| V3::new(v_t[(k, 0)], v_t[(k, 1)], v_t[(k, 2)]);
        let (e1, e2) = (row(order[0]), row(order[1]));
        let posit = Posit {
            object,
            image,
            r0,
            others,
            rel,
            b,
            normal,
            x0: image[r0],
        };
        (posit, e1, e2)
    }

    /// The scaled vectors I, J from the image corrected by the perspective
    /// terms `eps`.
    fn step(&self, eps: &[f64]) -> (V3, V3) {
        let (others, image, x0) = (&self.others, self.image, self.x0);
        let xp = nalgebra::DVector::from_iterator(
            others.len(),
            others
                .iter()
                .enumerate()
                .map(|(r, &i)| image[i][0] * (1.0 + eps[r]) - x0[0]),
        );
        let yp = nalgebra::DVector::from_iterator(
            others.len(),
            others
                .iter()
                .enumerate()
                .map(|(r, &i)| image[i][1] * (1.0 + eps[r]) - x0[1]),
        );
        let i = &self.b * xp;
        let j = &self.b * yp;
        (V3::new(i[0], i[1], i[2]), V3::new(j[0], j[1], j[2]))
    }

    /// A pose from the scaled vectors I = s i, J = s j of the object's
    /// first two rows.
    fn pose_of(&self, i: V3, j: V3) -> Option<Pose> {
        let x0 = self.x0;
        let (ni, nj) = (i.norm(), j.norm());
        if !(ni > 0.0 && nj > 0.0) {
            return None;
        }
        let s = 0.5 * (ni + nj);
        let iu = i / ni;
        let k = iu.cross(&(j / nj)).try_normalize(1e-12)?;
        let ju = k.cross(&iu);
        let z0 = 1.0 / s;
        let r = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
            iu.transpose(),
            ju.transpose(),
            k.transpose(),
        ]));
        let t0 = V3::new(x0[0] * z0, x0[1] * z0, z0);
        Some(Pose {
            rotation: r,
            translation: t0 - r * self.object[self.r0],
        })
    }

    /// The perspective corrections ε_i of pose `p`.
    fn eps_of(&self, p: &Pose) -> Vec<f64> {
        let z0 = p.to_camera(&self.object[self.r0]).z;
        let k = p.rotation.matrix().row(2).transpose();
        self.rel.iter().map(|m| m.dot(&k) / z0).collect()
    }

    /// Normalised-image reprojection error, infinite when a mark is behind
    /// the camera.
    fn err(&self, p: &Pose) -> f64 {
        let mut e = 0.0;
        for (o, q) in self.object.iter().zip(self.image) {
            let c = p.to_camera(o);
            if c.z <= 0.0 {
                return f64::INFINITY;
            }
            e += (c.x / c.z - q[0]).powi(2) + (c.y / c.z - q[1]).powi(2);
        }
        e
    }

    /// Keeps `p` if it reprojects better than the best so far.
    fn offer(&self, best: &mut Best, p: Pose) {
        let e = self.err(&p);
        if e.is_finite() && best.as_ref().is_none_or(|b| e < b.0) {
            *best = Some((e, p));
        }
    }

    /// POSIT for marks spanning a volume, offering each iteration's pose.
    fn iterate(&self, best: &mut Best) {
        let mut eps = vec![0.0; self.others.len()];
        for _ in 0..200 {
            let (i, j) = self.step(&eps);
            let Some(p) = self.pose_of(i, j) else {
                break;
            };
            let new = self.eps_of(&p);
            let change = new
                .iter()
                .zip(&eps)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            eps = new;
            if change < 1e-12 || !change.is_finite() {
                self.offer(best, p);
                break;
            }
            self.offer(best, p);
        }
    }

    /// Coplanar: I = I0 + λ n, J = J0 + μ n with |I| = |J| and I·J = 0, that
    /// is (λ + iμ)² = |J0|² − |I0|² − 2i I0·J0: two solutions ±(λ, μ).
    fn two(&self, eps: &[f64]) -> Vec<Pose> {
        let normal = self.normal;
        let (i0, j0) = self.step(eps);
        let q = nalgebra::Complex::new(j0.norm_squared() - i0.norm_squared(), -2.0 * i0.dot(&j0));
        let root = q.sqrt();
        [1.0, -1.0]
            .iter()
            .filter_map(|sg| {
                self.pose_of(i0 + normal * (sg * root.re), j0 + normal * (sg * root.im))
            })
            .collect()
    }

    /// Oberkampf et al.: both solutions of the first iteration start a
    /// branch; each later iteration keeps, per branch, the better of its two
    /// poses; each branch's last pose is offered.
    fn iterate_coplanar(&self, best: &mut Best) {
        for start in self.two(&vec![0.0; self.others.len()]) {
            let mut pose = start;
            let mut eps = self.eps_of(&pose);
            for _ in 0..200 {
                let cand = self.two(&eps);
                let Some(p) = cand
                    .into_iter()
                    .min_by(|a, b| self.err(a).total_cmp(&self.err(b)))
                else {
                    break;
                };
                let new = self.eps_of(&p);
                let change = new
                    .iter()
                    .zip(&eps)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                eps = new;
                pose = p;
                if change < 1e-12 {
                    break;
                }
            }
            self.offer(best, pose);
        }
    }
}

/// A first pose from at least four marks whose world positions `object`
/// are seen at normalised image coordinates `image` (see
/// [`Intrinsics::normalise`]): POSIT (DeMenthon & Davis 1995) when the
/// marks span a volume, its coplanar variant (Oberkampf et al. 1996) when
/// they lie on a plane, each iterated until the perspective corrections ε_i
/// change by less than 1e-12 (at most 200 iterations); and the pose from the
/// homography of the marks' best-fit plane ([`homography_pose`]): exact for
/// coplanar marks, a start for nearly coplanar ones, where POSIT may not
/// converge. Returns the candidate that reprojects best with every mark in
/// front of the camera. Collinear marks have no pose: an error.
pub fn posit(object: &[V3], image: &[[f64; 2]]) -> Result<Pose> {
    let plane = check_marks(object, image)?;
    let coplanar = plane < COPLANAR;
    let (solver, e1, e2) = Posit::new(object, image, coplanar);
    let mut best: Best = None;
    // the plane's homography gives a closed-form pose for coplanar marks and a
    // fair start for nearly coplanar ones, where POSIT may not converge;
    // near-frontal planes close to the camera, where both of Oberkampf's
    // branches may settle on a wrong pose, need it too
    if let Some(h) = homography_pose(object, image, object[solver.r0], e1, e2) {
        solver.offer(&mut best, h);
    }
    if !coplanar {
        solver.iterate(&mut best);
        return best.map(|b| b.1).ok_or_else(|| {
            anyhow::anyhow!("POSIT found no pose with every mark in front of the camera")
        });
    }
    solver.iterate_coplanar(&mut best);
    best.map(|b| b.1)
        .ok_or_else(|| anyhow::anyhow!("coplanar POSIT found no pose"))
}

/// The pose of a camera seeing coplanar marks from the homography between
/// the plane (origin `o`, orthonormal axes `e1`, `e2`) and the normalised
/// image (Zhang 2000, "A flexible new technique for camera calibration",
/// PAMI 22, §2.3, with the intrinsics known): H = λ [r1 r2 t], the rotation
/// completed by r1 × r2 and made orthonormal by SVD.
pub fn homography_pose(object: &[V3], image: &[[f64; 2]], o: V3, e1: V3, e2: V3) -> Option<Pose> {
    let n = object.len();
    if n < 4 {
        return None;
    }
    let plane: Vec<[f64; 2]> = object
        .iter()
        .map(|p| [(p - o).dot(&e1), (p - o).dot(&e2)])
        .collect();
    let mut a = DMatrix::<f64>::zeros(2 * n, 9);
    for (k, (q, x)) in plane.iter().zip(image).enumerate() {
        let r0 = [
            q[0],
            q[1],
            1.0,
            0.0,
            0.0,
            0.0,
            -x[0] * q[0],
            -x[0] * q[1],
            -x[0],
        ];
        let r1 = [
            0.0,
            0.0,
            0.0,
            q[0],
            q[1],
            1.0,
            -x[1] * q[0],
            -x[1] * q[1],
            -x[1],
        ];
        for c in 0..9 {
            a[(2 * k, c)] = r0[c];
            a[(2 * k + 1, c)] = r1[c];
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t?;
    let h = v_t.row(svd.singular_values.imin());
    let c1 = V3::new(h[0], h[3], h[6]);
    let c2 = V3::new(h[1], h[4], h[7]);
    let c3 = V3::new(h[2], h[5], h[8]);
    let mut l = 2.0 / (c1.norm() + c2.norm());
    if !l.is_finite() {
        return None;
    }
    if c3.z * l < 0.0 {
        l = -l;
    }
    let (r1, r2, t) = (c1 * l, c2 * l, c3 * l);
    let m = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut rp = u * v_t;
    if rp.determinant() < 0.0 {
        let mut u2 = u;
        u2.column_mut(2).neg_mut();
        rp = u2 * v_t;
    }
    // world → plane axes → camera
    let b = Matrix3::from_columns(&[e1, e2, e1.cross(&e2)]);
    let r = rp * b.transpose();
    let rotation = Rotation3::from_matrix_unchecked(r);
    Some(Pose {
        rotation,
        translation: t - rotation * o,
    })
}

/// Derivatives of a pixel with respect to the point in the camera's frame.
fn pixel_jacobian(k: &Intrinsics, c: &V3) -> [V3; 2] {
    let f = k.focal;
    let (z, x, y) = (c.z, c.x, c.y);
    let dxn = V3::new(1.0 / z, 0.0, -x / (z * z));
    let dyn_ = V3::new(0.0, 1.0 / z, -y / (z * z));
    [dxn * (f * k.ku) + dyn_ * (f * k.skew), dyn_ * (f * k.kv)]
}

/// Sum of squared pixel errors of marks seen from a pose (∞ when one is
/// behind the camera).
pub fn pose_cost(k: &Intrinsics, pose: &Pose, object: &[V3], pixels: &[[f64; 2]]) -> f64 {
    let mut s = 0.0;
    for (o, q) in object.iter().zip(pixels) {
        match project(k, pose, o) {
            Some(p) => s += (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2),
            None => return f64::INFINITY,
        }
    }
    s
}

/// Levenberg–Marquardt on the sum of squared pixel errors over the pose
/// (rotation as a small rotation vector applied on the left, translation),
/// from `start`; stops when a step changes the cost by less than a 1e-15
/// fraction or after 100 steps.
pub fn refine_pose(k: &Intrinsics, start: Pose, object: &[V3], pixels: &[[f64; 2]]) -> Pose {
    let mut pose = start;
    let mut cost = pose_cost(k, &pose, object, pixels);
    let mut lambda = 1e-3;
    for _ in 0..100 {
        let mut h = Matrix6::<f64>::zeros();
        let mut g = Vector6::<f64>::zeros();
        for (o, q) in object.iter().zip(pixels) {
            let rp = pose.rotation * o;
            let c = rp + pose.translation;
            let Some(p) = project(k, &pose, o) else {
                return pose;
            };
            let jp = pixel_jacobian(k, &c);
            let res = [p[0] - q[0], p[1] - q[1]];
            for a in 0..2 {
                // d c / d δ = −[R p]×, d c / d t = I
                let jr = rp.cross(&jp[a]);
                let row = Vector6::new(jr.x, jr.y, jr.z, jp[a].x, jp[a].y, jp[a].z);
                h += row * row.transpose();
                g += row * res[a];
            }
        }
        match damped_step(&h, &g, &mut lambda, 1e-12, cost, |step| {
            let cand = Pose {
                rotation: Rotation3::new(V3::new(step[0], step[1], step[2])) * pose.rotation,
                translation: pose.translation + V3::new(step[3], step[4], step[5]),
            };
            let c = pose_cost(k, &cand, object, pixels);
            (cand, c)
        }) {
            Some((cand, c, done)) => {
                pose = cand;
                cost = c;
                if done {
                    break;
                }
            }
            None => break,
        }
    }
    pose
}

/// One Levenberg–Marquardt update of the normal equations `h δ = −g`:
/// tries the steps damped by `λ · max(diag h, floor)` (λ tenfold after a
/// failed try, at most 20 tries) until `eval(δ)` gives a cost below `cost`;
/// then lowers λ (× 0.3, at least 1e-12) and returns the candidate, its cost
/// and whether the cost fell by less than a 1e-15 fraction (converged).
/// `None` when no try lowered the cost.
fn damped_step<const D: usize, T>(
    h: &SMatrix<f64, D, D>,
    g: &SVector<f64, D>,
    lambda: &mut f64,
    floor: f64,
    cost: f64,
    eval: impl Fn(&SVector<f64, D>) -> (T, f64),
) -> Option<(T, f64, bool)> {
    for _ in 0..20 {
        let mut hl = *h;
        for d in 0..D {
            hl[(d, d)] += *lambda * h[(d, d)].max(floor);
        }
        let Some(step) = hl.cholesky().map(|ch| ch.solve(&(-g))) else {
            *lambda *= 10.0;
            continue;
        };
        let (cand, c) = eval(&step);
        if c < cost {
            *lambda = (*lambda * 0.3).max(1e-12);
            return Some((cand, c, cost - c <= 1e-15 * cost));
        }
        *lambda *= 10.0;
    }
    None
}

/// The point seen at `pixels` by the posed cameras (at least two): the
/// linear (DLT) solution on normalised coordinates, then Levenberg–Marquardt
/// on the pixel error. `None` when the views are degenerate (the rays are
/// parallel) or the point falls behind a camera.
pub fn triangulate(k: &Intrinsics, poses: &[Pose], pixels: &[[f64; 2]]) -> Option<V3> {
    if poses.len() < 2 || poses.len() != pixels.len() {
        return None;
    }
    let mut a = DMatrix::zeros(2 * poses.len(), 4);
    for (r, (p, q)) in poses.iter().zip(pixels).enumerate() {
        let n = k.normalise(*q);
        let m = p.rotation.matrix();
        let t = p.translation;
        for col in 0..4 {
            let row = |i: usize| if col < 3 { m[(i, col)] } else { t[i] };
            a[(2 * r, col)] = n[0] * row(2) - row(0);
            a[(2 * r + 1, col)] = n[1] * row(2) - row(1);
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t?;
    let imin = svd.singular_values.imin();
    let h = v_t.row(imin);
    if h[3].abs() < 1e-300 {
        return None;
    }
    let mut x = V3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]);
    if !x.iter().all(|c| c.is_finite()) {
        return None;
    }
    let cost = |x: &V3| -> f64 {
        poses
            .iter()
            .zip(pixels)
            .map(|(p, q)| match project(k, p, x) {
                Some(u) => (u[0] - q[0]).powi(2) + (u[1] - q[1]).powi(2),
                None => f64::INFINITY,
            })
            .sum()
    };
    let mut c0 = cost(&x);
    if !c0.is_finite() {
        return None;
    }
    let mut lambda = 1e-3;
    for _ in 0..50 {
        let mut h = Matrix3::zeros();
        let mut g = V3::zeros();
        for (p, q) in poses.iter().zip(pixels) {
            let c = p.to_camera(&x);
            let u = k.pixel([c.x / c.z, c.y / c.z]);
            let jp = pixel_jacobian(k, &c);
            let res = [u[0] - q[0], u[1] - q[1]];
            for d in 0..2 {
                let row = p.rotation.inverse() * jp[d];
                h += row * row.transpose();
                g += row * res[d];
            }
        }
        match damped_step(&h, &g, &mut lambda, 1e-18, c0, |step| {
            let cand = x + step;
            let c = cost(&cand);
            (cand, c)
        }) {
            Some((cand, c, done)) => {
                x = cand;
                c0 = c;
                if done {
                    break;
                }
            }
            None => break,
        }
    }
    Some(x)
}

/// Root mean square of pixel errors (per mark: the norm of the 2D error).
pub fn rms(errors: &[f64]) -> f64 {
    if errors.is_empty() {
        return 0.0;
    }
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_and_normalise_are_inverse_and_match_eq_6_1() {
        let k = Intrinsics {
            focal: 0.02,
            ku: 80_000.0,
            kv: 82_000.0,
            cu: 1000.0,
            cv: 700.0,
            skew: 300.0,
        };
        let n = [0.13, -0.21];
        let p = k.pixel(n);
        let m = k.matrix() * V3::new(n[0], n[1], 1.0);
        assert!((p[0] - m.x).abs() < 1e-9 && (p[1] - m.y).abs() < 1e-9);
        let back = k.normalise(p);
        assert!((back[0] - n[0]).abs() < 1e-15 && (back[1] - n[1]).abs() < 1e-15);
    }
}
