//! Identification of a fabric's dissipation from a motion capture of a free
//! fall (thesis ch. 5, docs/identify.md).
//!
//! Markers form an `nx × ny` grid (grid order: index `j·nx + i`, warp index
//! `i`), the same grid the model is built on, so every marker is a mass.
//! Velocities and accelerations come from forward differences (eq. 5.6–5.7),
//! `V_i = (P_{i+1} − P_i)/dt`, `A_i = (V_{i+1} − V_i)/dt`. `A_i` is centred on
//! frame `i + 1`, so the model is evaluated there: positions `P_{i+1}` and
//! velocity `(V_i + V_{i+1})/2` (the same forward differences, averaged; using
//! `V_i` itself would lag the acceleration by one frame, a bias of about
//! `|α|·dt` ≈ 6 % on α at 120 Hz).
//!
//! The spring forces and the per-family stiffness matrices `K̃` (PSD, the
//! ones the solver's Rayleigh damping uses) are those of the fabric's laws on
//! the captured shapes, with the hysteresis memory replayed along the captured
//! path from the first frame.
//!
//! Fits, with `F_err = M A − M g − (elastic forces of the families in the
//! model so far)`:
//! - global least squares of `(α, β_f, β_c, β_t)` (eq. 5.10–5.12), with the
//!   condition number of its normal matrix (the thesis finds ≈ 4e13);
//! - the thesis' ordered one-parameter fits (§5.4.3): α on `MA − Mg`; then the
//!   bending springs join the model and β_f is fitted on what is left; then
//!   shear and β_c; then tension and β_t. Each per frame
//!   (`β = F_err·K̃V / ‖K̃V‖²`), averaged over the viscous window.

use crate::cloth::{Cloth, GridSpec};
use crate::fabric::Fabric;
use crate::solver::family::Family;
use crate::solver::{Params, Simulation};
use anyhow::{bail, Result};
use nalgebra::{Isometry3, Matrix4, Vector3, Vector4};
use serde::Serialize;

/// The marker grid.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct MarkerGrid {
    pub nx: usize,
    pub ny: usize,
    /// Marker spacing along warp and weft, m (thesis: 5 cm).
    pub spacing: [f64; 2],
}

impl MarkerGrid {
    /// The model's grid on the markers (every marker a mass), flat, in its own frame.
    pub fn spec(&self) -> GridSpec {
        GridSpec {
            size: [
                (self.nx - 1) as f64 * self.spacing[0],
                (self.ny - 1) as f64 * self.spacing[1],
            ],
            spacing: self.spacing,
            pose: Isometry3::identity(),
        }
    }
}

impl Default for MarkerGrid {
    fn default() -> Self {
        MarkerGrid {
            nx: 11,
            ny: 11,
            spacing: [0.05, 0.05],
        }
    }
}

#[derive(Debug, Clone)]
pub struct IdentifyOptions {
    pub grid: MarkerGrid,
    /// Frames (inclusive start, exclusive end) of the viscous window, in
    /// evaluation frames; chosen from the mean-speed curve when `None`.
    pub window: Option<(usize, usize)>,
    /// Gravity in the capture's (rotated) frame, m/s².
    pub gravity: Vector3<f64>,
    /// The upward direction in the capture's coordinates, when known
    /// (instead of a ball drop): the capture is rotated so that it is +z.
    pub up: Option<Vector3<f64>>,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        IdentifyOptions {
            grid: MarkerGrid::default(),
            window: None,
            gravity: Vector3::new(0.0, 0.0, -9.81),
            up: None,
        }
    }
}

/// One parameter of the thesis' ordered fit (Tables 5.1, 5.2).
#[derive(Debug, Clone, Serialize)]
pub struct Estimate {
    pub name: String,
    /// Mean over the window (thesis sign convention: ≤ 0 dissipates).
    pub mean: f64,
    pub std: f64,
    /// Mean relative decrease of the residual force this parameter brings.
    pub error_decrease: f64,
    /// (evaluation frame, value) for every frame of the capture.
    pub per_frame: Vec<(usize, f64)>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Identification {
    pub rate_hz: f64,
    /// Evaluation frame k is capture frame k + 1.
    pub window: (usize, usize),
    pub window_chosen_automatically: bool,
    /// Mean marker speed per evaluation frame, m/s.
    pub mean_speed: Vec<f64>,
    pub alpha: Estimate,
    pub beta_bend: Estimate,
    pub beta_shear: Estimate,
    pub beta_tension: Estimate,
    /// Joint least squares (α, β_f, β_c, β_t) over the window (thesis eq.
    /// 5.10–5.12, instrumented): the measured values.
    pub global: [f64; 4],
    /// Condition number of the joint fit's (column-scaled) normal matrix.
    pub global_condition_number: f64,
    /// The measured (α, β_f, β_c, β_t): the joint fit when the capture
    /// resolves every β (dissipative, beyond twice its standard error, α
    /// consistent with the ordered α), else the ordered α and NaN β's.
    pub measured: [f64; 4],
    /// Standard errors of `measured` (one cluster per frame).
    pub measured_se: [f64; 4],
    pub resolved: [bool; 4],
    /// Where the joint fit leaves β's unresolved: the trajectory fit.
    pub trajectory: Option<TrajectoryFit>,
}

/// Output-error fit: the damping parameters whose simulated trajectory,
/// started from the captured state at the window's first frame, stays
/// closest to the captured one over the window (Levenberg–Marquardt on the
/// four parameters, finite-difference sensitivities).
///
/// Why: the equation-error fits above put the spring forces computed on
/// captured shapes into every equation, and the stiff tension springs turn
/// a tiny position error into a large force error (float32 C3D files at
/// 3 m: 0.2 µm steps, force errors beyond the β's). A simulated trajectory
/// integrates the dissipation instead: on the thesis' free fall a 15 %
/// change of β_f or β_c moves the markers by 3–5 µm rms over the window,
/// far above float32 steps, while a 15 % change of β_t moves them by about
/// 3 nm, which no capture resolves.
#[derive(Debug, Clone, Serialize)]
pub struct TrajectoryFit {
    /// (α, β_f, β_c, β_t); an unresolved parameter is held at 0.
    pub theta: [f64; 4],
    /// Resolved: dissipative, and a 15 % change of it (of the fabric's own
    /// value if that is larger) moves the simulated markers by at least 3 ×
    /// the fit's rms residual.
    pub resolved: [bool; 4],
    /// RMS distance between simulated and captured markers, m.
    pub rms_m: f64,
    /// RMS displacement of the markers caused by a 15 % change of each parameter, m.
    pub effect_15pc_m: [f64; 4],
    /// Gauss–Newton standard errors (residual rms × (JᵀJ)^-½): they assume
    /// independent residuals and understate the error (on the synthetic
    /// float32 capture: 0.01 % stated, 0.8 % real).
    pub se: [f64; 4],
    /// Capture frames simulated (first, last).
    pub frames: (usize, usize),
    pub simulations: usize,
}

/// Per evaluation frame k: `M A − M g` (A = (vel[k] − vel[k−1]) / h), `M V`
/// (V = vel[k]), each family's force in the implicit step `f(x[k]) − h K̃s V`
/// and its `K̃ V`.
///
/// The least-squares products use instruments `zm = M Vc`, `zk = K̃ Vc` with
/// the central velocity Vc = (vel[k−1] + vel[k]) / 2 in place of the
/// regressors themselves: marker noise enters `A` and `V` together (both
/// hold x[k+1]) and would bias a plain fit (errors in variables), while it
/// is uncorrelated between `A` and `Vc`. On exact data both give the same.
struct Frame {
    r0: Vec<Vector3<f64>>,
    mv: Vec<Vector3<f64>>,
    f: [Vec<Vector3<f64>>; 3],
    kv: [Vec<Vector3<f64>>; 3],
    zm: Vec<Vector3<f64>>,
    zk: [Vec<Vector3<f64>>; 3],
}

const FAMILIES: [Family; 3] = [Family::Bending, Family::Shear, Family::Tension];

fn dot(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

/// Chooses the viscous window from the mean-speed curve (thesis Fig. 5.11):
/// from the first frame where the speed has reached 60 % of its maximum, to
/// the last frame before it drops below that again (or the end).
pub fn viscous_window(speed: &[f64]) -> (usize, usize) {
    let max = speed.iter().cloned().fold(0.0, f64::max);
    let thr = 0.6 * max;
    let start = speed.iter().position(|&s| s >= thr).unwrap_or(0);
    let end = speed[start..]
        .iter()
        .position(|&s| s < thr)
        .map(|k| start + k)
        .unwrap_or(speed.len());
    (start, end)
}

/// Runs the identification on gap-free marker positions `frames[f][marker]`.
/// Joint instrumented least squares of the parameters in `set` (0: α,
/// 1..3: β_f, β_c, β_t) over the frames `win`, with the others at zero.
/// Returns the estimates and their standard errors (sandwich estimate with
/// one cluster per frame), or None if the system is singular.
fn joint_fit(
    evals: &[Frame],
    win: std::ops::Range<usize>,
    set: &[usize],
) -> Option<(Vec<f64>, Vec<f64>)> {
    use nalgebra::{DMatrix, DVector};
    let m = set.len();
    fn col(fr: &Frame, p: usize) -> &[Vector3<f64>] {
        if p == 0 {
            &fr.mv
        } else {
            &fr.kv[p - 1]
        }
    }
    fn ins(fr: &Frame, p: usize) -> &[Vector3<f64>] {
        if p == 0 {
            &fr.zm
        } else {
            &fr.zk[p - 1]
        }
    }
    let full = |fr: &Frame| -> Vec<Vector3<f64>> {
        (0..fr.r0.len())
            .map(|k| fr.r0[k] - fr.f[0][k] - fr.f[1][k] - fr.f[2][k])
            .collect()
    };
    let mut nm = DMatrix::<f64>::zeros(m, m);
    let mut rhs = DVector::<f64>::zeros(m);
    for fr in &evals[win.clone()] {
        let r = full(fr);
        for (a, &pa) in set.iter().enumerate() {
            rhs[a] += dot(ins(fr, pa), &r);
            for (b, &pb) in set.iter().enumerate() {
                nm[(a, b)] += dot(ins(fr, pa), col(fr, pb));
            }
        }
    }
    let inv = nm.clone().try_inverse()?;
    let theta = &inv * &rhs;
    let mut meat = DMatrix::<f64>::zeros(m, m);
    for fr in &evals[win.clone()] {
        let mut e = full(fr);
        for (a, &pa) in set.iter().enumerate() {
            for (x, c) in e.iter_mut().zip(col(fr, pa)) {
                *x -= c * theta[a];
            }
        }
        let g = DVector::from_iterator(m, set.iter().map(|&pa| dot(ins(fr, pa), &e)));
        meat += &g * g.transpose();
    }
    let cov = &inv * meat * inv.transpose();
    let se = (0..m).map(|a| cov[(a, a)].max(0.0).sqrt()).collect();
    Some((theta.iter().copied().collect(), se))
}

/// Slowest peak of the markers' mean speed a capture may have, m/s: a
/// damping force is proportional to velocity, so a capture of a still cloth
/// (or one frame copied, or markers jittering by noise) holds no damping to
/// measure, and its fit would write α = 0 or NaN into a fabric file. A
/// free fall reaches metres per second; 1 cm/s is ten times the speed of
/// 0.1 mm of marker noise at 100 Hz.
pub const MIN_CAPTURE_SPEED: f64 = 0.01;

/// Refuses a capture that cannot be identified: a rate not above zero,
/// fewer than 4 frames, frames with other than the grid's marker count, or
/// markers not finite or beyond `MAX_CAPTURE_DISTANCE`.
fn check_capture(frames: &[Vec<Vector3<f64>>], rate_hz: f64, g: &MarkerGrid) -> Result<()> {
    let n = g.nx * g.ny;
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        bail!("capture rate {rate_hz} Hz: must be > 0");
    }
    if frames.len() < 4 {
        bail!(
            "a capture of {} frames is too short: at least 4 are needed",
            frames.len()
        );
    }
    for (k, f) in frames.iter().enumerate() {
        if f.len() != n {
            bail!(
                "frame {k} has {} markers; the {} × {} grid needs {n}",
                f.len(),
                g.nx,
                g.ny
            );
        }
        if let Some(m) = f.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            bail!("frame {k}, marker {m}: not a finite position (fill gaps first)");
        }
        for (m, p) in f.iter().enumerate() {
            crate::limits::check_capture_position(&format!("frame {k}, marker {m}"), p)?;
        }
    }
    Ok(())
}

/// The equation of every inner capture frame (see `Frame`) and the markers'
/// mean speed there. The equation written on frame k is the simulator's
/// own implicit Euler step from x[k] to x[k+1]:
///   M (vel[k] − vel[k−1]) / h − M g
///     = Σ_fam (f_fam(x[k]) − h K̃s_fam(x[k]) vel[k]) + α M vel[k] + Σ β_fam K̃_fam(x[k]) vel[k]
/// with the springs' memory replayed along the captured path up to x[k].
fn frame_equations(
    frames: &[Vec<Vector3<f64>>],
    dt: f64,
    fabric: &Fabric,
    opts: &IdentifyOptions,
) -> Result<(Vec<Frame>, Vec<f64>)> {
    let g = opts.grid;
    let n = g.nx * g.ny;
    let cloth = Cloth::grid(&g.spec(), fabric.areal_mass)?;
    let mut sim = Simulation::new(
        cloth,
        fabric.clone(),
        Params {
            threads: 1,
            ..Params::default()
        },
    )?;
    let mass = sim.cloth.mass.clone();
    // forward-difference velocities (eq. 5.6): vel[k] = (x[k+1] − x[k]) / h
    let vel: Vec<Vec<Vector3<f64>>> = frames
        .windows(2)
        .map(|w| w[1].iter().zip(&w[0]).map(|(b, a)| (b - a) / dt).collect())
        .collect();
    sim.cloth.set_positions(&frames[0])?;
    sim.commit();
    let mut evals = Vec::with_capacity(frames.len() - 2);
    let mut speed = Vec::with_capacity(frames.len() - 2);
    for i in 0..frames.len() - 2 {
        let k = i + 1;
        sim.cloth.set_positions(&frames[k])?;
        sim.commit();
        let v1 = &vel[k];
        let r0: Vec<Vector3<f64>> = (0..n)
            .map(|j| (vel[k][j] - vel[k - 1][j]) / dt * mass[j] - opts.gravity * mass[j])
            .collect();
        let mv: Vec<Vector3<f64>> = (0..n).map(|j| v1[j] * mass[j]).collect();
        let f = FAMILIES.map(|fam| {
            let mut fe = sim.family_forces(fam);
            let js = sim.family_step_jacobian(fam);
            let mut jv = vec![Vector3::zeros(); n];
            js.mul(v1, &mut jv);
            // − h K̃s v = + h (∂f/∂x) v
            for (a, b) in fe.iter_mut().zip(&jv) {
                *a += b * dt;
            }
            fe
        });
        let vc: Vec<Vector3<f64>> = (0..n).map(|j| (vel[k - 1][j] + v1[j]) / 2.0).collect();
        let jd = FAMILIES.map(|fam| sim.family_jacobian(fam, true));
        // K̃ = −∂f/∂x (projected)
        let kmul = |j: &crate::solver::sparse::BlockMatrix, v: &[Vector3<f64>]| {
            let mut out = vec![Vector3::zeros(); n];
            j.mul(v, &mut out);
            out.iter_mut().for_each(|x| *x = -*x);
            out
        };
        let kv = [kmul(&jd[0], v1), kmul(&jd[1], v1), kmul(&jd[2], v1)];
        let zk = [kmul(&jd[0], &vc), kmul(&jd[1], &vc), kmul(&jd[2], &vc)];
        let zm: Vec<Vector3<f64>> = (0..n).map(|j| vc[j] * mass[j]).collect();
        speed.push(v1.iter().map(|v| v.norm()).sum::<f64>() / n as f64);
        evals.push(Frame {
            r0,
            mv,
            f,
            kv,
            zm,
            zk,
        });
    }
    Ok((evals, speed))
}

/// The viscous window: the one given, checked against the `count`
/// evaluation frames, or one chosen from the mean-speed curve (then `true`);
/// refused with fewer than 2 frames.
fn choose_window(
    given: Option<(usize, usize)>,
    speed: &[f64],
    count: usize,
) -> Result<((usize, usize), bool)> {
    let (window, auto) = match given {
        Some((a, b)) => {
            if a >= b || b > count {
                bail!("window {a}..{b} is outside the {count} evaluation frames");
            }
            ((a, b), false)
        }
        None => (viscous_window(speed), true),
    };
    if window.1 - window.0 < 2 {
        if auto {
            let peak = speed.iter().cloned().fold(0.0, f64::max);
            bail!(
                "the viscous window {}..{} chosen from the mean-speed curve (the frames at \
                 60 % or more of its peak, {peak:.3e} m/s) has fewer than 2 frames: the \
                 speed peaks in one frame (a marker jump?); give the window (--window)",
                window.0,
                window.1
            );
        }
        bail!(
            "the viscous window {}..{} has fewer than 2 frames",
            window.0,
            window.1
        );
    }
    Ok((window, auto))
}

/// Global least squares over the window, r_full ≈ α MV + Σ β K̃V: the four
/// parameters (NaN if singular) and the condition number of the normal
/// matrix with its columns scaled to unit norm.
fn global_fit(evals: &[Frame], win: std::ops::Range<usize>, n: usize) -> ([f64; 4], f64) {
    let mut nm: Matrix4<f64> = Matrix4::zeros();
    let mut rhs = Vector4::zeros();
    for fr in &evals[win] {
        let r: Vec<Vector3<f64>> = (0..n)
            .map(|k| fr.r0[k] - fr.f[0][k] - fr.f[1][k] - fr.f[2][k])
            .collect();
        let cols = [&fr.mv, &fr.kv[0], &fr.kv[1], &fr.kv[2]];
        let inst = [&fr.zm, &fr.zk[0], &fr.zk[1], &fr.zk[2]];
        for a in 0..4 {
            rhs[a] += dot(inst[a], &r);
            for b in 0..4 {
                nm[(a, b)] += dot(inst[a], cols[b]);
            }
        }
    }
    // columns scaled to unit norm so the condition number measures how
    // independent the four dissipations are, not their units
    let scale: Vector4<f64> = Vector4::from_fn(|a, _| 1.0 / nm[(a, a)].abs().sqrt().max(1e-300));
    let scaled: Matrix4<f64> = Matrix4::from_fn(|a, b| nm[(a, b)] * scale[a] * scale[b]);
    let sv = scaled.singular_values();
    let cond = sv.max() / sv.min();
    let global = nm
        .lu()
        .solve(&rhs)
        .map(|x| [x[0], x[1], x[2], x[3]])
        .unwrap_or([f64::NAN; 4]);
    (global, cond)
}

/// The thesis' ordered fits: α, then each family's β with its springs
/// joined to the model, each from the residual the previous fits left.
fn ordered_fits(evals: &[Frame], win: std::ops::Range<usize>) -> Vec<Estimate> {
    let mut resid: Vec<Vec<Vector3<f64>>> = evals.iter().map(|fr| fr.r0.clone()).collect();
    let names = ["alpha", "beta_bend", "beta_shear", "beta_tension"];
    let mut est: Vec<Estimate> = Vec::with_capacity(4);
    for (p, name) in names.iter().enumerate() {
        // the family's springs join the model (their elastic forces are known)
        if p > 0 {
            for (r, fr) in resid.iter_mut().zip(evals) {
                for (x, y) in r.iter_mut().zip(&fr.f[p - 1]) {
                    *x -= y;
                }
            }
        }
        let col = |fr: &Frame| -> Vec<Vector3<f64>> {
            if p == 0 {
                fr.mv.clone()
            } else {
                fr.kv[p - 1].clone()
            }
        };
        let ins = |fr: &Frame| -> Vec<Vector3<f64>> {
            if p == 0 {
                fr.zm.clone()
            } else {
                fr.zk[p - 1].clone()
            }
        };
        let mut per_frame = Vec::with_capacity(evals.len());
        for (k, (r, fr)) in resid.iter().zip(evals).enumerate() {
            let (c, z) = (col(fr), ins(fr));
            let zc = dot(&z, &c);
            per_frame.push((k, if zc != 0.0 { dot(r, &z) / zc } else { 0.0 }));
        }
        let vals: Vec<f64> = per_frame[win.clone()]
            .iter()
            .map(|x| x.1)
            .filter(|x| x.is_finite())
            .collect();
        let mean = vals.iter().sum::<f64>() / vals.len().max(1) as f64;
        let std = (vals.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / vals.len().max(1) as f64)
            .sqrt();
        // subtract the fitted dissipation and measure what it removed
        let mut dec = 0.0;
        for (r, fr) in resid[win.clone()].iter_mut().zip(&evals[win.clone()]) {
            let before = dot(r, r).sqrt();
            let c = col(fr);
            for (x, y) in r.iter_mut().zip(&c) {
                *x -= y * mean;
            }
            let after = dot(r, r).sqrt();
            if before > 0.0 {
                dec += (before - after) / before;
            }
        }
        for (k, (r, fr)) in resid.iter_mut().zip(evals).enumerate() {
            if !win.contains(&k) {
                let c = col(fr);
                for (x, y) in r.iter_mut().zip(&c) {
                    *x -= y * mean;
                }
            }
        }
        est.push(Estimate {
            name: name.to_string(),
            mean,
            std,
            error_decrease: dec / win.len() as f64,
            per_frame,
        });
    }
    est
}

/// What the capture resolves: the measured values, their standard errors
/// and which are resolved. The joint fit of all four writes the simulator's
/// own step on the captured shapes, so it is exact on exact data; but
/// marker noise makes the spring forces on captured shapes (stiff tension
/// springs: 0.5 mm on 5 cm is 1 % strain) far larger than the dissipation.
/// It is taken when every β comes out dissipative and beyond twice its
/// standard error and its α agrees with the ordered α (which needs no
/// spring forces) within 10 %; otherwise only α is measured, by the ordered
/// fit, and the β's are reported unresolved.
fn resolved_fit(
    evals: &[Frame],
    win: std::ops::Range<usize>,
    est: &[Estimate],
) -> ([f64; 4], [f64; 4], [bool; 4]) {
    let ordered_alpha = est[0].mean;
    let joint = joint_fit(evals, win.clone(), &[0, 1, 2, 3]);
    let accept = joint.as_ref().is_some_and(|(th, se)| {
        (1..4).all(|p| th[p] < 0.0 && th[p].abs() > 2.0 * se[p])
            && (th[0] / ordered_alpha - 1.0).abs() < 0.1
    });
    match (&joint, accept) {
        (Some((th, se)), true) => (
            [th[0], th[1], th[2], th[3]],
            [se[0], se[1], se[2], se[3]],
            [true; 4],
        ),
        _ => {
            let cnt = win.len() as f64;
            (
                [ordered_alpha, f64::NAN, f64::NAN, f64::NAN],
                [est[0].std / cnt.sqrt(), f64::NAN, f64::NAN, f64::NAN],
                [true, false, false, false],
            )
        }
    }
}

/// The capture frames the trajectory fit runs over: from the start of the
/// fall (after the slowest frame before the viscous window, the first frame
/// whose mean marker acceleration along gravity exceeds g/2: the release)
/// to the window's end; the first frames of the fall, where the cloth
/// shears and bends most, carry most of what the markers tell of β_f and
/// β_c.
fn fall_frames(
    frames: &[Vec<Vector3<f64>>],
    rate_hz: f64,
    gravity: &Vector3<f64>,
    speed: &[f64],
    window: (usize, usize),
) -> (usize, usize) {
    let n = frames[0].len();
    let down = gravity.normalize();
    let g = gravity.norm();
    let accel = |k: usize| {
        frames[k + 1]
            .iter()
            .zip(&frames[k])
            .zip(&frames[k - 1])
            .map(|((a, b), c)| (a - 2.0 * b + c).dot(&down))
            .sum::<f64>()
            * rate_hz
            * rate_hz
            / n as f64
    };
    // evaluation frame k is capture frame k + 1
    let slowest = (0..=window.0)
        .min_by(|&a, &b| speed[a].total_cmp(&speed[b]))
        .map_or(1, |k| k + 1);
    let release = (slowest.max(1)..(window.1 + 1).min(frames.len() - 1))
        .find(|&k| accel(k) > 0.5 * g)
        .unwrap_or(slowest.max(1));
    let first = release + 2;
    let last = (window.1 + 1).min(frames.len() - 1);
    (first, last)
}

/// Identifies the damping of `fabric` from gap-free marker positions
/// `frames[f][marker]` captured at `rate_hz`.
pub fn identify(
    frames: &[Vec<Vector3<f64>>],
    rate_hz: f64,
    fabric: &Fabric,
    opts: &IdentifyOptions,
) -> Result<Identification> {
    let n = opts.grid.nx * opts.grid.ny;
    check_capture(frames, rate_hz, &opts.grid)?;
    let dt = 1.0 / rate_hz;
    let (evals, speed) = frame_equations(frames, dt, fabric, opts)?;
    let fastest = speed.iter().cloned().fold(0.0, f64::max);
    if fastest.is_nan() || fastest < MIN_CAPTURE_SPEED {
        bail!(
            "the capture shows no motion: the markers' mean speed is at most {fastest:.2e} m/s \
             over its {} frames, below {MIN_CAPTURE_SPEED} m/s (MIN_CAPTURE_SPEED); damping \
             is measured on a moving cloth (a free fall reaches metres per second)",
            frames.len()
        );
    }
    let (window, auto) = choose_window(opts.window, &speed, evals.len())?;
    let win = window.0..window.1;
    let (global, cond) = global_fit(&evals, win.clone(), n);
    let est = ordered_fits(&evals, win.clone());
    let (mut measured, mut measured_se, mut resolved) = resolved_fit(&evals, win, &est);
    let trajectory = if resolved.iter().all(|&r| r) {
        None
    } else {
        let (first, last) = fall_frames(frames, rate_hz, &opts.gravity, &speed, window);
        let t = trajectory_fit(frames, rate_hz, fabric, opts, (first, last), measured[0])?;
        for p in 1..4 {
            if !resolved[p] && t.resolved[p] {
                measured[p] = t.theta[p];
                // no standard error: the trajectory residual is not white
                // noise (it is mostly the start velocity's error carried
                // along), so the Gauss–Newton one would understate it
                measured_se[p] = f64::NAN;
                resolved[p] = true;
            }
        }
        Some(t)
    };
    let mut it = est.into_iter();
    let alpha = it.next().expect("4 estimates");
    let beta_bend = it.next().expect("4 estimates");
    let beta_shear = it.next().expect("4 estimates");
    let beta_tension = it.next().expect("4 estimates");
    Ok(Identification {
        rate_hz,
        window,
        window_chosen_automatically: auto,
        mean_speed: speed,
        measured,
        measured_se,
        resolved,
        alpha,
        beta_bend,
        beta_shear,
        beta_tension,
        global,
        global_condition_number: cond,
        trajectory,
    })
}

/// Marker differences (or sensitivities) over a window, frame after frame.
type Markers = Vec<Vector3<f64>>;

/// Smallest finite-difference steps of (α, β_f, β_c, β_t).
const FD_FLOOR: [f64; 4] = [0.05, 1e-4, 1e-5, 1e-7];

/// The model on the markers at capture frame `first`: positions, velocity
/// `(x[first] − x[first−1])/h`, hysteresis memory replayed along the capture
/// up to it (done once; every simulation of the fit starts from a copy).
fn start_state(
    frames: &[Vec<Vector3<f64>>],
    fabric: &Fabric,
    params: &Params,
    grid: &MarkerGrid,
    first: usize,
) -> Result<Cloth> {
    let cloth = Cloth::grid(&grid.spec(), fabric.areal_mass)?;
    let mut sim = Simulation::new(cloth, fabric.clone(), params.clone())?;
    for f in &frames[..=first] {
        sim.cloth.set_positions(f)?;
        sim.commit();
    }
    let v: Vec<Vector3<f64>> = (frames[first].iter().zip(&frames[first - 1]))
        .map(|(a, b)| (a - b) / params.dt)
        .collect();
    sim.cloth.set_velocities(&v)?;
    Ok(sim.cloth)
}

/// Simulates the fall from `start` (see [`start_state`]) over the capture
/// frames `first + 1..=last` with damping `theta`; the differences to the
/// captured markers, or `None` if the simulation fails.
fn simulate_window(
    start: &Cloth,
    frames: &[Vec<Vector3<f64>>],
    fabric: &Fabric,
    params: &Params,
    (first, last): (usize, usize),
    theta: &[f64; 4],
) -> Option<Vec<Vector3<f64>>> {
    let mut fab = fabric.clone();
    fab.damping.alpha = theta[0];
    fab.damping.beta_bend = theta[1];
    fab.damping.beta_shear = theta[2];
    fab.damping.beta_tension = theta[3];
    let mut sim = Simulation::new(start.clone(), fab, params.clone()).ok()?;
    let mut r = Vec::with_capacity((last - first) * frames[0].len());
    for f in &frames[first + 1..=last] {
        sim.step().ok()?;
        r.extend(sim.cloth.positions().iter().zip(f).map(|(a, b)| a - b));
    }
    r.iter()
        .all(|d| d.iter().all(|c| c.is_finite()))
        .then_some(r)
}

fn sum_sq(r: &[Vector3<f64>]) -> f64 {
    r.iter().map(|d| d.norm_squared()).sum()
}

/// The trajectory fit (see [`TrajectoryFit`]) over capture frames
/// `first..=last`, starting from α = `alpha0` and no β.
pub fn trajectory_fit(
    frames: &[Vec<Vector3<f64>>],
    rate_hz: f64,
    fabric: &Fabric,
    opts: &IdentifyOptions,
    (first, last): (usize, usize),
    alpha0: f64,
) -> Result<TrajectoryFit> {
    if first < 1 || last <= first || last >= frames.len() {
        bail!(
            "trajectory fit: frames {first}..{last} do not fit in a capture of {} frames",
            frames.len()
        );
    }
    let params = Params {
        dt: 1.0 / rate_hz,
        gravity: opts.gravity,
        linear_solver: crate::solver::LinearSolverKind::Cholesky,
        threads: 1,
        ..Params::default()
    };
    let start_cloth = start_state(frames, fabric, &params, &opts.grid, first)?;
    let simulate =
        |th: &[f64; 4]| simulate_window(&start_cloth, frames, fabric, &params, (first, last), th);
    let sims = std::cell::Cell::new(0usize);
    let run = |th: &[f64; 4]| {
        sims.set(sims.get() + 1);
        simulate(th)
    };
    let mut theta = [alpha0, 0.0, 0.0, 0.0];
    let r0 = run(&theta).ok_or_else(|| {
        anyhow::anyhow!(
            "trajectory fit: the simulation from frame {first} fails at α = {}",
            theta[0]
        )
    })?;
    let n_res = (r0.len() * 3) as f64;
    let rms_of = |r: &[Vector3<f64>]| (sum_sq(r) / n_res).sqrt();
    // all four together (β's kept dissipative); then those the capture does
    // not resolve are held at 0 and the rest fitted again. Resolved: a 15 %
    // change of the parameter moves the markers by at least 3 × what the fit
    // leaves unexplained.
    // (a 15 % change of the fitted value, or of the fabric's own value if
    // larger: a parameter fitted to 0 is judged on the scale it should have)
    let d = fabric.damping;
    let prior = [d.alpha, d.beta_bend, d.beta_shear, d.beta_tension];
    let effect_of = |th: &[f64; 4], jac: &[Option<Vec<Vector3<f64>>>], p: usize| {
        jac[p].as_ref().map_or(0.0, |jp| {
            0.15 * th[p].abs().max(prior[p].abs()) * (sum_sq(jp) / n_res).sqrt()
        })
    };
    let mut free = [true; 4];
    let (mut r, mut jac) = (r0, Vec::new());
    let mut effect = [0.0; 4];
    for _ in 0..4 {
        let out = levenberg_marquardt(&simulate, &sims, theta, r, free);
        theta = out.0;
        r = out.1;
        jac = out.2;
        let rms = rms_of(&r);
        let mut keep = free;
        for p in (0..4).filter(|&p| free[p]) {
            effect[p] = effect_of(&theta, &jac, p);
            keep[p] = free[p] && (p == 0 || theta[p] < 0.0) && effect[p] >= 3.0 * rms;
        }
        if keep == free {
            break;
        }
        free = keep;
        for p in 0..4 {
            if !free[p] {
                theta[p] = 0.0;
            }
        }
        r = run(&theta)
            .ok_or_else(|| anyhow::anyhow!("trajectory fit: the simulation fails at {theta:?}"))?;
    }
    let resolved = free;
    // standard errors from the Gauss–Newton covariance rms² (JᵀJ)⁻¹
    let rms = rms_of(&r);
    let se = gauss_newton_se(&jac, free, rms);
    Ok(TrajectoryFit {
        theta,
        resolved,
        rms_m: rms,
        effect_15pc_m: effect,
        se,
        frames: (first, last),
        simulations: sims.get(),
    })
}

/// Levenberg–Marquardt on the parameters in `free` (β's kept dissipative)
/// from `theta` and its residual `r`, with sensitivities by forward
/// differences simulated side by side: the parameters, their residual and
/// the last sensitivities (`None` for parameters held). `sims` counts the
/// simulations run.
fn levenberg_marquardt<S>(
    simulate: &S,
    sims: &std::cell::Cell<usize>,
    mut theta: [f64; 4],
    mut r: Markers,
    free: [bool; 4],
) -> ([f64; 4], Markers, Vec<Option<Markers>>)
where
    S: Fn(&[f64; 4]) -> Option<Markers> + Sync,
{
    let run = |th: &[f64; 4]| {
        sims.set(sims.get() + 1);
        simulate(th)
    };
    let mut lambda = 1e-3;
    let mut jac: Vec<Option<Vec<Vector3<f64>>>> = vec![None; 4];
    for _ in 0..15 {
        // sensitivities: forward differences, simulated side by side
        let h: [f64; 4] = std::array::from_fn(|p| -(0.05 * theta[p].abs()).max(FD_FLOOR[p]));
        let cols: Vec<Option<Vec<Vector3<f64>>>> = std::thread::scope(|sc| {
            let hs: Vec<_> = (0..4)
                .map(|p| {
                    let mut th = theta;
                    th[p] += h[p];
                    let go = free[p];
                    sc.spawn(move || go.then(|| simulate(&th)).flatten())
                })
                .collect();
            hs.into_iter().map(|t| t.join().ok().flatten()).collect()
        });
        sims.set(sims.get() + free.iter().filter(|&&f| f).count());
        for p in 0..4 {
            jac[p] = cols[p]
                .as_ref()
                .map(|c| c.iter().zip(&r).map(|(a, b)| (a - b) / h[p]).collect());
        }
        let idx: Vec<usize> = (0..4).filter(|&p| jac[p].is_some()).collect();
        let m = idx.len();
        if m == 0 {
            break;
        }
        let col = |p: usize| jac[p].as_deref().expect("free column");
        let a = nalgebra::DMatrix::<f64>::from_fn(m, m, |i, k| dot(col(idx[i]), col(idx[k])));
        let g = nalgebra::DVector::<f64>::from_fn(m, |i, _| dot(col(idx[i]), &r));
        let cost = sum_sq(&r);
        let mut improved = false;
        for _ in 0..8 {
            let mut damped = a.clone();
            for i in 0..m {
                damped[(i, i)] += lambda * a[(i, i)].max(1e-300);
            }
            let Some(delta) = damped.cholesky().map(|c| c.solve(&(-&g))) else {
                lambda *= 10.0;
                continue;
            };
            let mut th = theta;
            for (i, &p) in idx.iter().enumerate() {
                th[p] += delta[i];
                if p > 0 {
                    th[p] = th[p].min(0.0);
                }
            }
            match run(&th) {
                Some(rn) if sum_sq(&rn) < cost => {
                    theta = th;
                    r = rn;
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = true;
                    break;
                }
                _ => lambda *= 4.0,
            }
        }
        if !improved || (cost - sum_sq(&r)) < 1e-6 * cost {
            break;
        }
    }
    (theta, r, jac)
}

/// Standard errors of the parameters in `free` from the Gauss–Newton
/// covariance rms² (JᵀJ)⁻¹ (NaN for the others, or if JᵀJ is singular).
fn gauss_newton_se(jac: &[Option<Markers>], free: [bool; 4], rms: f64) -> [f64; 4] {
    let idx: Vec<usize> = (0..4).filter(|&p| free[p] && jac[p].is_some()).collect();
    let mut se = [f64::NAN; 4];
    if !idx.is_empty() {
        let m = idx.len();
        let a = nalgebra::DMatrix::<f64>::from_fn(m, m, |i, k| {
            dot(
                jac[idx[i]].as_ref().expect("column"),
                jac[idx[k]].as_ref().expect("column"),
            )
        });
        if let Some(inv) = a.try_inverse() {
            for (i, &p) in idx.iter().enumerate() {
                se[p] = rms * inv[(i, i)].max(0.0).sqrt();
            }
        }
    }
    se
}

/// Simulates a built free fall and samples every vertex at `rate_hz`
/// (the simulation's step must divide the sampling period).
pub fn sample_capture(
    sim: &mut Simulation,
    rate_hz: f64,
    duration: f64,
) -> Result<Vec<Vec<Vector3<f64>>>> {
    let per = 1.0 / (rate_hz * sim.params().dt);
    let every = per.round() as u64;
    if every == 0 || (per - every as f64).abs() > 1e-6 {
        bail!(
            "the time step {} s does not divide the sampling period 1/{rate_hz} s",
            sim.params().dt
        );
    }
    let frames = (duration * rate_hz).round() as usize;
    let mut out = Vec::with_capacity(frames + 1);
    out.push(sim.cloth.positions().to_vec());
    for _ in 0..frames {
        for _ in 0..every {
            sim.step()?;
        }
        out.push(sim.cloth.positions().to_vec());
    }
    Ok(out)
}

/// Everything `garment_sim identify` reports (`report.json`).
#[derive(Debug, Clone, Serialize)]
pub struct IdentifyReport {
    pub capture: String,
    pub fabric: String,
    pub markers: usize,
    pub frames: usize,
    pub rate_hz: f64,
    pub missing_markers_filled: usize,
    pub gap_fill_sweeps: usize,
    /// Unit vector of the vertical (up) in the capture's frame, if found from a ball drop.
    pub vertical_from_ball: Option<[f64; 3]>,
    pub result: Identification,
}

/// Reads a capture (C3D or CSV by extension), finds the vertical from an
/// optional ball-drop capture, fills gaps (thesis Algorithm 1) and runs
/// [`identify`]. Markers are taken in grid order (index `j·nx + i`, warp
/// index `i` fastest) unless `warp_major` (index `i·ny + j`).
pub fn identify_file(
    capture: &std::path::Path,
    ball: Option<&std::path::Path>,
    fabric: &Fabric,
    opts: &IdentifyOptions,
    warp_major: bool,
) -> Result<IdentifyReport> {
    use crate::capture::{
        fill_gaps, read_c3d, read_capture_csv, rotate_capture, rotation_to_z, vertical_from_ball,
        GridMap,
    };
    use anyhow::Context;
    let read = |p: &std::path::Path| -> Result<crate::capture::Capture> {
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let c = if ext == "csv" {
            read_capture_csv(p)
        } else {
            read_c3d(p)
        };
        c.and_then(|c| c.check_positions().map(|()| c))
            .with_context(|| format!("capture {}", p.display()))
    };
    let mut cap = read(capture)?;
    let g = opts.grid;
    let n = g.nx * g.ny;
    if cap.n_markers() != n {
        bail!(
            "capture {} has {} markers; the {} × {} marker grid needs {n}",
            capture.display(),
            cap.n_markers(),
            g.nx,
            g.ny
        );
    }
    let mut up = None;
    if let Some(u) = opts.up {
        if ball.is_some() {
            bail!("give the vertical either by a ball capture or as a direction, not both");
        }
        if !(u.iter().all(|c| c.is_finite()) && u.norm() > 0.0) {
            bail!(
                "up direction ({}, {}, {}): must be a non-zero finite vector",
                u.x,
                u.y,
                u.z
            );
        }
        rotate_capture(&mut cap, &rotation_to_z(&u.normalize()));
        up = Some([u.x, u.y, u.z]);
    }
    if let Some(b) = ball {
        let bc = read(b)?;
        let track: Vec<Vector3<f64>> = bc
            .frames
            .iter()
            .filter_map(|f| f.first().copied().flatten())
            .collect();
        let v = vertical_from_ball(&track)
            .with_context(|| format!("vertical from ball capture {}", b.display()))?;
        rotate_capture(&mut cap, &rotation_to_z(&v));
        up = Some([v.x, v.y, v.z]);
    }
    // GridMap: node (i, j) -> marker index[i * ny + j]
    let map = GridMap {
        nx: g.nx,
        ny: g.ny,
        index: (0..g.nx)
            .flat_map(|i| {
                (0..g.ny).map(move |j| {
                    if warp_major {
                        i * g.ny + j
                    } else {
                        j * g.nx + i
                    }
                })
            })
            .collect(),
    };
    let fill = fill_gaps(&mut cap, &map)
        .with_context(|| format!("filling gaps of {}", capture.display()))?;
    let frames: Vec<Vec<Vector3<f64>>> = cap
        .frames
        .iter()
        .map(|f| {
            (0..n)
                .map(|v| {
                    let (i, j) = (v % g.nx, v / g.nx);
                    f[map.index[i * g.ny + j]].unwrap_or_else(|| Vector3::repeat(f64::NAN))
                })
                .collect()
        })
        .collect();
    let result = identify(&frames, cap.rate_hz, fabric, opts)?;
    Ok(IdentifyReport {
        capture: capture.display().to_string(),
        fabric: fabric.name.clone(),
        markers: n,
        frames: frames.len(),
        rate_hz: cap.rate_hz,
        missing_markers_filled: fill.filled,
        gap_fill_sweeps: fill.sweeps,
        vertical_from_ball: up,
        result,
    })
}

/// The thesis' identification figures as PNG files in `out`:
/// `mean_speed.png` (Fig. 5.11: mean marker speed, viscous window marked) and
/// one per parameter, `alpha.png`, `beta_bend.png`, `beta_shear.png`,
/// `beta_tension.png` (Fig. 5.12–5.15: per-frame value over the window, with
/// the mean and ± one standard deviation). Returns the files written.
pub fn write_plots(rep: &Identification, out: &std::path::Path) -> Result<Vec<std::path::PathBuf>> {
    use crate::pictures::plot::{LinePlot, Style};
    let mut files = Vec::new();
    let t = |k: usize| k as f64 / rep.rate_hz;
    let mut p = LinePlot::new(
        "Mean marker speed (thesis Fig. 5.11)",
        "time (s)",
        "mean speed (m/s)",
    );
    p.add(
        "mean speed",
        rep.mean_speed
            .iter()
            .enumerate()
            .map(|(k, v)| (t(k), *v))
            .collect(),
        Style::Line,
    );
    let top = rep.mean_speed.iter().cloned().fold(0.0, f64::max);
    for (k, label) in [(rep.window.0, "window start"), (rep.window.1, "window end")] {
        p.add(label, vec![(t(k), 0.0), (t(k), top)], Style::Dashed);
    }
    let f = out.join("mean_speed.png");
    p.save_png(&f)?;
    files.push(f);
    let (wa, wb) = (t(rep.window.0), t(rep.window.1));
    for (e, file, unit, fig) in [
        (&rep.alpha, "alpha.png", "alpha (1/s)", "5.12"),
        (&rep.beta_bend, "beta_bend.png", "beta_f (s)", "5.13"),
        (&rep.beta_shear, "beta_shear.png", "beta_c (s)", "5.14"),
        (&rep.beta_tension, "beta_tension.png", "beta_t (s)", "5.15"),
    ] {
        let mut p = LinePlot::new(
            &format!("{}, per frame (thesis Fig. {fig})", e.name),
            "time (s)",
            unit,
        );
        let pts: Vec<(f64, f64)> = e
            .per_frame
            .iter()
            .filter(|(_, v)| v.is_finite())
            .map(|(k, v)| (t(*k), *v))
            .collect();
        if pts.is_empty() {
            continue;
        }
        // y range from the values inside the viscous window (those outside,
        // in the free fall's first frames, can be orders of magnitude off)
        let inside: Vec<f64> = pts
            .iter()
            .filter(|(x, _)| *x >= wa && *x <= wb)
            .map(|p| p.1)
            .collect();
        if !inside.is_empty() {
            let lo = inside.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = inside.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            let pad = 0.25 * (hi - lo).max(1e-12 * hi.abs().max(1e-300));
            p.y_range = Some((lo - pad, hi + pad));
        }
        p.add("per frame", pts, Style::Points);
        p.add(
            &format!("mean {:.4e} over the window", e.mean),
            vec![(wa, e.mean), (wb, e.mean)],
            Style::Line,
        );
        p.add(
            &format!("mean +/- std ({:.2e})", e.std),
            vec![
                (wa, e.mean + e.std),
                (wb, e.mean + e.std),
                (wb, e.mean - e.std),
                (wa, e.mean - e.std),
                (wa, e.mean + e.std),
            ],
            Style::Dashed,
        );
        let f = out.join(file);
        p.save_png(&f)?;
        files.push(f);
    }
    Ok(files)
}
