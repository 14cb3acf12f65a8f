//! Cantilever bending test (Peirce 1930; ASTM D1388, ISO 9073-7).
//!
//! A strip (default 2.5 cm × 20 cm, its length along the tested thread
//! direction) lies on a horizontal platform and is slid over the platform's
//! edge until the line from the edge to the strip's tip falls 41.5° below the
//! horizontal. With `l` the overhang at that moment, the bending length is
//! `c = l/2` and the flexural rigidity per width `B = w c³`, `w` the fabric's
//! weight per area (the elastica of a clamped strip under its own weight
//! puts the tip line of an overhang `2c` at 41.5°).
//!
//! In the simulation the strip is a warp/weft grid ([`Cloth::grid`], hinges
//! rebuilt as mirror-symmetric pairs, see below) and the platform is its
//! supported part: the vertices on the platform are pinned to its plane and
//! move with the slide, so the last two pinned rows hold the strip's tangent
//! horizontal (the clamp of Peirce's elastica; the instrument's weighted
//! slide keeps the strip flat on the platform). The grid's rows leave the platform
//! one at a time, so the overhang of the discrete strip changes by whole row
//! spacings, and it is read only when a row has just reached the edge:
//!
//! 1. the row on the edge is released and the slide moves the strip on by one
//!    spacing at the slide speed (default 2 mm/s), until the next row is on
//!    the edge;
//! 2. the slide holds still until the overhang is at rest (RMS speed of the
//!    free vertices below [`CantileverOptions::rest_speed`], default
//!    0.01 mm/s, i.e. within a few µm of its equilibrium) — this is what makes
//!    the reading quasi-static: the shape read does not depend on the slide
//!    speed or the damping, only on the path of the (hysteretic) laws. Each
//!    release is a step load, an artefact of the grid (the instrument's slide
//!    is continuous): with the fabric's own damping the overhang would
//!    overshoot its rest shape and swing back, and every swing reverses the
//!    hysteretic memories along it (a small cycle of amplitude δ shrinks the
//!    Dahl operator's σp by about `2δ/xs`), so the reading would depend on the
//!    step, the damping and the slide speed (wool tropical at 1 cm: B +20.6 %
//!    at dt = 2 ms, +45.6 % at 10 ms). The test is therefore run
//!    **quasi-statically** ([`CantileverOptions::quasi_static`], the default):
//!    the bending hinges' stiffness-proportional damping is raised to at least
//!    [`quasi_static_bend_damping`], which damps critically the lowest mode of
//!    the overhang at 41.5°, so that no release overshoots and every point of
//!    the strip follows the monotone path of a continuous slide; the reading
//!    at rest is then the same for any step, slide speed and air damping
//!    (tested), and without hysteresis it is unchanged (the damping force
//!    vanishes at rest);
//! 3. the tip angle θ (the line from the edge to the middle of the tip row) is
//!    read at overhang `(n + ½)·h` (see the clamp below); the slide goes on
//!    until θ ≥ 41.5°.
//!
//! The overhang at which θ = 41.5° lies between the last two readings. Each
//! reading gives the bending length of the linearly elastic strip (the
//! elastica of [`elastica_tip_angle`]) whose tip line falls at its angle,
//! `c_n = l_n / λ(θ_n)`, and `c` is interpolated linearly in θ between the two
//! to 41.5°, where `λ = 2` (the elastica puts the tip line of an overhang 2c
//! at 41.49°: the instrument's `c = l/2`). Peirce's closed form
//! `c = l (cos(θ/2) / (8 tan θ))^(1/3)` is an approximation of the same
//! relation, 1.9 % high in c at 41.5° (0.509 l) and exact as θ → 0; it is
//! reported beside each reading.
//!
//! The discrete clamp: the hinge of the edge row (wings on the row behind,
//! pinned, and the row ahead, free) carries the strip's curvature over half a
//! spacing either side of its row. On the platform the strip is flat, so
//! that half spacing must lie beyond the edge: the pinned rows end half a
//! spacing beyond the platform's edge, and the overhang with `n` free rows is
//! `(n + ½) h`. With the edge on the last pinned row instead, the first
//! hinge reads half the clamp's curvature and the strip droops by a first
//! order error (B −12 % at 0.25 cm, −49 % at 1 cm, without hysteresis). The
//! hinges are mirror-symmetric pairs ([`HingeLayout::MirrorSymmetric`]):
//! the grid's single skewed hinge lets the strip twist into the diagonal
//! fold that costs no bending, and its tip deflects more than 1.5 times the
//! elastica's (tested; B −40 % at 0.25 cm without hysteresis).

use crate::cloth::{Cloth, HingeLayout};
use crate::fabric::kes::{GF_CM2_PER_CM, PER_CM};
use crate::fabric::Fabric;
use crate::lab::kes_lab::{self, Direction, KesTest};
use crate::pictures::plot::{LinePlot, Style};
use crate::solver::{LinearSolverKind, Params, Pin, PinPath, Simulation};
use anyhow::{bail, Context, Result};
use nalgebra::Vector3;
use serde::Serialize;

/// The instrument's angle, degrees (ASTM D1388: 41.5°).
pub const PEIRCE_ANGLE_DEG: f64 = 41.5;

#[derive(Debug, Clone, Serialize)]
pub struct CantileverOptions {
    /// Strip width, m.
    pub width: f64,
    /// Strip length, m.
    pub length: f64,
    /// Grid spacing along the strip, m (the grid rounds it so that it divides
    /// the length); across the strip the spacing is at most this.
    pub spacing: f64,
    /// Fixed time step, s.
    pub dt: f64,
    /// Slide speed while a row moves onto the edge, m/s.
    pub slide_speed: f64,
    /// The overhang is read once the RMS speed of its vertices is below this, m/s.
    pub rest_speed: f64,
    /// Longest hold for the overhang to come to rest, s.
    pub max_hold: f64,
    /// Include the hysteretic parts of the laws (the fabric's KES loops).
    pub hysteresis: bool,
    /// Mirror-symmetric hinge pairs ([`HingeLayout::MirrorSymmetric`]);
    /// false: the grid's single skewed hinge per edge.
    pub symmetric_hinges: bool,
    /// Raise the bending damping to [`quasi_static_bend_damping`] so that no
    /// row's release overshoots (see the module doc); false: the fabric's own
    /// damping, whose swings wear the hysteretic memories down.
    pub quasi_static: bool,
}

impl Default for CantileverOptions {
    fn default() -> Self {
        CantileverOptions {
            width: 0.025,
            length: 0.20,
            spacing: 0.01,
            dt: 2e-3,
            slide_speed: 2e-3,
            rest_speed: 1e-5,
            max_hold: 30.0,
            hysteresis: true,
            symmetric_hinges: true,
            quasi_static: true,
        }
    }
}

/// Bending damping (stiffness-proportional, s) that damps critically the
/// lowest mode of an overhang of two bending lengths `c`: a clamped strip of
/// length L has `ω₁ = 1.8751² √(B / (m L⁴))` (Euler–Bernoulli), and with
/// `B = w c³`, `m = w/g` and `L = 2c`, `ω₁ = (1.8751²/4) √(g/c)`; the
/// damping `β K` gives that mode the ratio `β ω₁ / 2`, 1 at `β = 2/ω₁`.
/// Higher modes are damped more. (Wool tropical, c = 1.60 cm: 0.092 s.)
pub fn quasi_static_bend_damping(c: f64, g: f64) -> f64 {
    let omega1 = 1.875_104_068_711_961f64.powi(2) / 4.0 * (g / c).sqrt();
    2.0 / omega1
}

/// The strip at rest with one row on the edge.
#[derive(Debug, Clone, Serialize)]
pub struct Reading {
    /// Overhang beyond the edge, m.
    pub overhang_m: f64,
    /// Angle of the line from the edge to the tip below the horizontal, degrees.
    pub tip_angle_deg: f64,
    /// Bending length of the elastica whose tip line falls at this angle, m.
    pub bending_length_m: f64,
    /// Peirce's closed form at this angle, m.
    pub peirce_bending_length_m: f64,
    /// Tip (middle of the tip row) relative to the edge: horizontal, vertical (m).
    pub tip_m: [f64; 2],
    /// Simulated time at the reading, s.
    pub time_s: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct CantileverReport {
    pub fabric: String,
    pub direction: Direction,
    pub options: CantileverOptions,
    /// Spacing along and across the strip, m.
    pub spacing_m: [f64; 2],
    pub vertices: usize,
    /// Weight per area w, N/m².
    pub weight_per_area_n_m2: f64,
    pub readings: Vec<Reading>,
    /// Overhang at 41.5°, m (2c).
    pub overhang_m: f64,
    /// Bending length c, m.
    pub bending_length_m: f64,
    /// Flexural rigidity per width B = w c³, gf·cm²/cm.
    pub flexural_rigidity_gf_cm2_cm: f64,
    /// The same, N·m.
    pub flexural_rigidity_n_m: f64,
    /// The fabric's KES B of this direction, gf·cm²/cm.
    pub fabric_b_gf_cm2_cm: f64,
    /// The fabric's KES 2HB of this direction, gf·cm/cm.
    pub fabric_2hb_gf_cm_cm: f64,
    /// (simulated B − fabric B) / fabric B.
    pub relative_error: f64,
    /// Bending length the fabric's B gives, (B/w)^(1/3), m.
    pub fabric_bending_length_m: f64,
    /// Largest RMS speed of the overhang at a reading, m/s.
    pub largest_rest_speed_m_s: f64,
    /// Bending damping of the run, s (thesis sign, ≤ 0): the fabric's, or
    /// [`quasi_static_bend_damping`] when that is larger.
    pub beta_bend_s: f64,
    pub simulated_s: f64,
    /// Strip centreline at the last reading (horizontal, vertical from the
    /// edge, m), edge row first.
    pub profile_m: Vec<[f64; 2]>,
}

/// Peirce's bending length of an overhang `l` whose tip line falls `theta`
/// (rad) below the horizontal: `l (cos(θ/2) / (8 tan θ))^(1/3)`.
pub fn peirce_bending_length(l: f64, theta: f64) -> f64 {
    l * ((theta / 2.0).cos() / (8.0 * theta.tan())).cbrt()
}

/// Tip-line angle (rad below the horizontal) of the elastica of a clamped,
/// inextensible, linearly elastic strip under its own weight whose overhang
/// is `lambda` bending lengths: `θ'' = −(λ − s) cos θ` over `s ∈ [0, λ]` in
/// units of c, `θ(0) = 0`, `θ'(λ) = 0`; RK4 over 400 steps, the clamp
/// curvature found by bisection.
pub fn elastica_tip_angle(lambda: f64) -> f64 {
    let n = 400;
    let ds = lambda / n as f64;
    let shoot = |m0: f64| -> [f64; 4] {
        let f = |s: f64, y: [f64; 4]| [y[1], -(lambda - s) * y[0].cos(), y[0].cos(), -y[0].sin()];
        let add = |a: [f64; 4], b: [f64; 4], h: f64| {
            [
                a[0] + h * b[0],
                a[1] + h * b[1],
                a[2] + h * b[2],
                a[3] + h * b[3],
            ]
        };
        let mut y = [0.0, m0, 0.0, 0.0];
        for k in 0..n {
            let s = k as f64 * ds;
            let k1 = f(s, y);
            let k2 = f(s + ds / 2.0, add(y, k1, ds / 2.0));
            let k3 = f(s + ds / 2.0, add(y, k2, ds / 2.0));
            let k4 = f(s + ds, add(y, k3, ds));
            for c in 0..4 {
                y[c] += ds / 6.0 * (k1[c] + 2.0 * k2[c] + 2.0 * k3[c] + k4[c]);
            }
        }
        y
    };
    // θ'(λ) grows with the clamp curvature, which lies in [0, λ²/2]
    let (mut lo, mut hi) = (0.0, lambda * lambda / 2.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if shoot(mid)[1] < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let y = shoot(0.5 * (lo + hi));
    (-y[3]).atan2(y[2])
}

/// The overhang, in bending lengths, whose elastica tip line falls at
/// `theta` (rad, in (0, 80°]).
pub fn elastica_overhang(theta: f64) -> f64 {
    let (mut lo, mut hi) = (1e-3, 8.0);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if elastica_tip_angle(mid) < theta {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The fabric's KES bending summary (B gf·cm²/cm, 2HB gf·cm/cm) of a direction.
pub fn fabric_bending(fabric: &Fabric, dir: Direction) -> Result<(f64, f64)> {
    let s = kes_lab::input_summary(
        fabric,
        KesTest::Bending,
        dir,
        &fabric.dir(dir.is_weft()).bending_curve,
    )?;
    Ok((s[0], s[1]))
}

fn params(opt: &CantileverOptions) -> Params {
    Params {
        dt: opt.dt,
        linear_solver: LinearSolverKind::Cholesky,
        threads: 1,
        hysteresis: opt.hysteresis,
        ..Default::default()
    }
}

/// A strip of the given length, its length along +X from x = 0, flat at z = 0.
/// Returns the cloth, each vertex's row (0 at x = 0) and the row spacing.
fn strip(
    fabric: &Fabric,
    dir: Direction,
    length: f64,
    opt: &CantileverOptions,
) -> Result<(Cloth, Vec<usize>, f64)> {
    for (n, v) in [
        ("width", opt.width),
        ("length", length),
        ("spacing", opt.spacing),
        ("dt", opt.dt),
        ("slide speed", opt.slide_speed),
        ("rest speed", opt.rest_speed),
        ("max hold", opt.max_hold),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!("cantilever {n} = {v}: must be > 0");
        }
    }
    let rows = (length / opt.spacing).round().max(1.0) as usize;
    let h = length / rows as f64;
    let across = (opt.width / opt.spacing).ceil().max(1.0) as usize;
    let (cloth, gw) = kes_lab::specimen(
        fabric,
        dir,
        length,
        opt.width,
        h,
        opt.width / across as f64,
        if opt.symmetric_hinges {
            HingeLayout::MirrorSymmetric
        } else {
            HingeLayout::Skewed
        },
    )?;
    let row = gw.iter().map(|g| (g[0] / h).round() as usize).collect();
    Ok((cloth, row, h))
}

/// Mean position of the vertices of row `r`.
fn row_mean(x: &[Vector3<f64>], row: &[usize], r: usize) -> Vector3<f64> {
    let (s, n) = x
        .iter()
        .zip(row)
        .filter(|(_, &q)| q == r)
        .fold((Vector3::zeros(), 0usize), |(s, n), (p, _)| (s + p, n + 1));
    s / n.max(1) as f64
}

/// Steps until the free vertices' RMS speed is below `opt.rest_speed`
/// (at least 0.1 s); returns that speed.
fn settle(sim: &mut Simulation, opt: &CantileverOptions, what: &str) -> Result<f64> {
    let t0 = sim.time;
    loop {
        sim.step()
            .with_context(|| format!("{what}, t = {:.3} s", sim.time))?;
        let v = sim.rms_speed();
        if sim.time - t0 >= 0.1 && v < opt.rest_speed {
            return Ok(v);
        }
        if sim.time - t0 > opt.max_hold {
            bail!(
                "{what}: the overhang is still moving ({v:.2e} m/s RMS) after {} s",
                opt.max_hold
            );
        }
    }
}

/// Runs the cantilever test.
pub fn run(
    fabric: &Fabric,
    dir: Direction,
    opt: &CantileverOptions,
    progress: &mut dyn FnMut(f64, f64),
) -> Result<CantileverReport> {
    let (mut cloth, row, h) = strip(fabric, dir, opt.length, opt)?;
    let (spacing_across, n_rows) = {
        let n = row.iter().copied().max().unwrap_or(0);
        let w = if dir.is_weft() { cloth.lc } else { cloth.lt };
        (w, n)
    };
    // pinned rows up to row k, which sits half a spacing beyond the edge
    // (x = 0); row n_rows (the tip) starts there
    let edge_at =
        |i: usize, k: usize, y: f64| Vector3::new((row[i] as f64 - k as f64 + 0.5) * h, y, 0.0);
    let ys: Vec<f64> = cloth.positions().iter().map(|p| p.y).collect();
    let placed: Vec<Vector3<f64>> = (0..cloth.len())
        .map(|i| edge_at(i, n_rows, ys[i]))
        .collect();
    cloth.set_positions(&placed)?;
    let (b_fabric, hb_fabric) = fabric_bending(fabric, dir)?;
    let g = params(opt).gravity.norm();
    let weight = fabric.areal_mass * g;
    let c_fabric = (b_fabric * GF_CM2_PER_CM / weight).cbrt();
    let mut run_fabric = fabric.clone();
    if opt.quasi_static {
        let beta = -quasi_static_bend_damping(c_fabric, g);
        run_fabric.damping.beta_bend = run_fabric.damping.beta_bend.min(beta);
    }
    let beta_bend_s = run_fabric.damping.beta_bend;
    let mut sim = Simulation::new(cloth, run_fabric, params(opt))?;
    let pins_for = |k: usize, path: &dyn Fn(usize) -> PinPath| -> Vec<Pin> {
        (0..row.len())
            .filter(|&i| row[i] <= k)
            .map(|i| Pin::new(i, path(i)))
            .collect()
    };
    let steps_per_row = (h / (opt.slide_speed * opt.dt)).ceil().max(1.0) as u64;
    let v = h / (steps_per_row as f64 * opt.dt);
    let target = PEIRCE_ANGLE_DEG.to_radians();
    let mut readings: Vec<Reading> = Vec::new();
    let mut largest_rest = 0.0f64;
    let mut k = n_rows;
    // a rough length of the run for progress reports: the overhang 2c
    let expect_rows = (2.0 * c_fabric / h).ceil().max(1.0);
    loop {
        if k < 2 {
            bail!(
                "cantilever: the strip ({} m) ran out before its tip line reached {PEIRCE_ANGLE_DEG}° (last reading {:.1}° at {:.3} m)",
                opt.length,
                readings.last().map_or(0.0, |r| r.tip_angle_deg),
                readings.last().map_or(0.0, |r| r.overhang_m)
            );
        }
        // release the row on the edge; slide the next one onto it
        k -= 1;
        let start: Vec<Vector3<f64>> = (0..row.len()).map(|i| edge_at(i, k + 1, ys[i])).collect();
        let t0 = sim.time;
        sim.set_pins(pins_for(k, &|i| PinPath::Velocity {
            start: start[i],
            velocity: Vector3::x() * v,
            t0,
        }))?;
        for _ in 0..steps_per_row {
            sim.step()
                .with_context(|| format!("cantilever slide, t = {:.3} s", sim.time))?;
        }
        sim.set_pins(pins_for(k, &|i| PinPath::Fixed(edge_at(i, k, ys[i]))))?;
        let rest = settle(&mut sim, opt, "cantilever hold")?;
        largest_rest = largest_rest.max(rest);
        let tip = row_mean(sim.cloth.positions(), &row, n_rows);
        let theta = (-tip.z).atan2(tip.x);
        let l = (n_rows - k) as f64 * h + 0.5 * h;
        readings.push(Reading {
            overhang_m: l,
            tip_angle_deg: theta.to_degrees(),
            bending_length_m: if theta > 0.0 {
                l / elastica_overhang(theta)
            } else {
                f64::INFINITY
            },
            peirce_bending_length_m: if theta > 0.0 {
                peirce_bending_length(l, theta)
            } else {
                f64::INFINITY
            },
            tip_m: [tip.x, tip.z],
            time_s: sim.time,
        });
        progress(
            (n_rows - k) as f64,
            expect_rows.max((n_rows - k) as f64 + 1.0),
        );
        if theta >= target {
            break;
        }
    }
    let last = readings.len() - 1;
    let c = if last == 0 || !readings[last - 1].bending_length_m.is_finite() {
        readings[last].bending_length_m
    } else {
        let (a, b) = (&readings[last - 1], &readings[last]);
        let f = (PEIRCE_ANGLE_DEG - a.tip_angle_deg) / (b.tip_angle_deg - a.tip_angle_deg);
        a.bending_length_m + f * (b.bending_length_m - a.bending_length_m)
    };
    let b_n_m = weight * c.powi(3);
    let b_kes = b_n_m / GF_CM2_PER_CM;
    let profile = (k..=n_rows)
        .map(|r| {
            let p = row_mean(sim.cloth.positions(), &row, r);
            [p.x, p.z]
        })
        .collect();
    Ok(CantileverReport {
        fabric: fabric.name.clone(),
        direction: dir,
        options: opt.clone(),
        spacing_m: [h, spacing_across],
        vertices: sim.cloth.len(),
        weight_per_area_n_m2: weight,
        readings,
        overhang_m: 2.0 * c,
        bending_length_m: c,
        flexural_rigidity_gf_cm2_cm: b_kes,
        flexural_rigidity_n_m: b_n_m,
        fabric_b_gf_cm2_cm: b_fabric,
        fabric_2hb_gf_cm_cm: hb_fabric,
        relative_error: (b_kes - b_fabric) / b_fabric,
        fabric_bending_length_m: c_fabric,
        largest_rest_speed_m_s: largest_rest,
        beta_bend_s,
        simulated_s: sim.time,
        profile_m: profile,
    })
}

/// A strip clamped at one end with a given overhang, at rest under its own
/// weight: rows 0 and 1 pinned, row 1 half a spacing beyond the edge at
/// x = 0 (the discrete clamp of [`run`]), `n` free rows beyond, the spacing
/// `overhang / (n + ½)` nearest the requested one. Returns the centreline
/// (horizontal, vertical from the edge, m; the last pinned row first) and
/// the overhang.
pub fn clamped_strip(
    fabric: &Fabric,
    dir: Direction,
    overhang: f64,
    opt: &CantileverOptions,
) -> Result<(Vec<[f64; 2]>, f64)> {
    let n = (overhang / opt.spacing - 0.5).round().max(1.0) as usize;
    let h = overhang / (n as f64 + 0.5);
    let length = (n + 1) as f64 * h;
    let o = CantileverOptions {
        spacing: h,
        ..opt.clone()
    };
    let (mut cloth, row, _) = strip(fabric, dir, length, &o)?;
    let mut x0 = cloth.positions().to_vec();
    for p in x0.iter_mut() {
        p.x -= 0.5 * h;
        p.z = 0.0;
    }
    cloth.set_positions(&x0)?;
    let mut sim = Simulation::new(cloth, fabric.clone(), params(&o))?;
    sim.set_pins(
        (0..row.len())
            .filter(|&i| row[i] <= 1)
            .map(|i| Pin::new(i, PinPath::Fixed(x0[i])))
            .collect(),
    )?;
    settle(&mut sim, &o, "clamped strip")?;
    let profile = (1..=n + 1)
        .map(|r| {
            let p = row_mean(sim.cloth.positions(), &row, r);
            [p.x, p.z]
        })
        .collect();
    Ok((profile, overhang))
}

/// Side view of the strip at the last reading: the platform, the strip, the
/// 41.5° line from the edge.
pub fn side_view(rep: &CantileverReport) -> LinePlot {
    let mut p = LinePlot::new(
        &format!(
            "cantilever, {}: c {:.2} cm, B {:.4}",
            rep.direction.name(),
            rep.bending_length_m * PER_CM,
            rep.flexural_rigidity_gf_cm2_cm,
        ),
        "horizontal from the edge (cm)",
        "height (cm)",
    );
    let l = rep.readings.last().map_or(0.05, |r| r.overhang_m) * PER_CM;
    let span = l.max(1.0);
    p.add_colored(
        "platform",
        vec![(-0.3 * span, 0.0), (0.0, 0.0), (0.0, -0.15 * span)],
        Style::Line,
        [150, 150, 160],
    );
    // the strip on the platform, then the overhang
    let mut strip = vec![(-0.3 * span, 0.0)];
    strip.extend(rep.profile_m.iter().map(|q| (q[0] * PER_CM, q[1] * PER_CM)));
    p.add(
        &format!(
            "strip, overhang {l:.2} cm (fabric B {:.4} gf·cm²/cm)",
            rep.fabric_b_gf_cm2_cm
        ),
        strip,
        Style::Line,
    );
    let t = PEIRCE_ANGLE_DEG.to_radians();
    p.add(
        "41.5° below the edge",
        vec![(0.0, 0.0), (span * t.cos(), -span * t.sin())],
        Style::Dashed,
    );
    // about equal scales on both axes (the plot is 900 × 600 pixels)
    p.x_range = Some((-0.3 * span, 1.1 * span));
    p.y_range = Some((-0.8 * span, 0.13 * span));
    p
}

/// Angles and overhangs of the readings, as a plot of the tip angle.
pub fn readings_plot(rep: &CantileverReport) -> LinePlot {
    let mut p = LinePlot::new(
        "cantilever: tip angle against overhang",
        "overhang (cm)",
        "tip angle (°)",
    );
    p.add(
        "readings at rest",
        rep.readings
            .iter()
            .map(|r| (r.overhang_m * PER_CM, r.tip_angle_deg))
            .collect(),
        Style::Points,
    );
    p.add(
        "41.5°",
        vec![
            (0.0, PEIRCE_ANGLE_DEG),
            (
                rep.readings.last().map_or(1.0, |r| r.overhang_m) * PER_CM,
                PEIRCE_ANGLE_DEG,
            ),
        ],
        Style::Dashed,
    );
    p
}
