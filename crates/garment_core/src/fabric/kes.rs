//! Kawabata (KES-FB) data: unit conversion (one place), summary values, raw
//! curves, and the construction of curves from summary values (thesis §2.3.1).

use serde::{Deserialize, Serialize};

/// 1 gf in newtons.
pub const GF: f64 = 9.80665e-3;
/// 1 gf/cm (tensile or shear force per width) in N/m.
pub const GF_PER_CM: f64 = 0.980665;
/// 1 gf·cm/cm (bending moment per width) in N·m/m.
pub const GF_CM_PER_CM: f64 = 9.80665e-3;
/// 1 gf·cm²/cm (bending rigidity B) in N·m.
pub const GF_CM2_PER_CM: f64 = 9.80665e-5;
/// 1 gf·cm/cm² (tensile energy WT) in J/m².
pub const GF_CM_PER_CM2: f64 = 0.980665;
/// 1 mg/cm² (areal mass W) in kg/m².
pub const MG_PER_CM2: f64 = 0.01;
/// 1 degree in radians.
pub const DEG: f64 = std::f64::consts::PI / 180.0;
/// 1 /cm (curvature) in 1/m.
pub const PER_CM: f64 = 100.0;

/// KES-FB1 tensile summary values (KES units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TensileSummary {
    /// Linearity of the load–extension curve (WT / (Fm·EMT/2)), dimensionless.
    #[serde(rename = "LT")]
    pub lt: f64,
    /// Tensile energy per area, gf·cm/cm².
    #[serde(rename = "WT")]
    pub wt: f64,
    /// Tensile resilience (recovered / spent energy), %.
    #[serde(rename = "RT")]
    pub rt: f64,
    /// Extension at the maximum load Fm, %.
    #[serde(rename = "EMT")]
    pub emt: f64,
}

/// KES-FB1 shear summary values (KES units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShearSummary {
    /// Shear rigidity, gf/(cm·deg): mean slope between 0.5° and 5°.
    #[serde(rename = "G")]
    pub g: f64,
    /// Hysteresis width at ±0.5°, gf/cm.
    #[serde(rename = "2HG")]
    pub hg: f64,
    /// Hysteresis width at ±5°, gf/cm.
    #[serde(rename = "2HG5")]
    pub hg5: f64,
}

/// KES-FB2 bending summary values (KES units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BendingSummary {
    /// Bending rigidity, gf·cm²/cm: mean slope between 0.5 and 1.5 cm⁻¹.
    #[serde(rename = "B")]
    pub b: f64,
    /// Hysteresis width of the moment at ±1 cm⁻¹, gf·cm/cm.
    #[serde(rename = "2HB")]
    pub hb: f64,
}

/// A measured (or constructed) KES loop, in SI: `x` is the deformation
/// (strain, rad, 1/m), `y` the force per width (N/m) or moment per width (N).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct KesCurve {
    /// Loading branch, x increasing.
    pub load: Vec<(f64, f64)>,
    /// Recovery branch, x decreasing.
    pub recover: Vec<(f64, f64)>,
}

/// The KES tensile protocol's maximum load, 500 gf/cm.
pub const TENSILE_FM_DEFAULT_GF_CM: f64 = 500.0;
/// KES shear range ±8°.
pub const SHEAR_MAX_DEG: f64 = 8.0;
/// KES pure-bending range ±2.5 cm⁻¹.
pub const BENDING_MAX_PER_CM: f64 = 2.5;

const SAMPLES: usize = 161;

/// Tensile curve from summary values (the documented construction, docs/fabrics.md):
/// loading `F(ε) = Fm (ε/εm)^n` with `n = 2/LT − 1` (so that its energy is
/// `LT·Fm·εm/2`), and recovery `F(ε) − 2 h2 ε²` with `h2 = 1.5 (1 − RT) WT / εm³`
/// so that the energy given back is `RT·WT` (the recovery curve is clipped at 0).
pub fn tensile_curve(s: &TensileSummary, fm_gf_cm: f64) -> KesCurve {
    let fm = fm_gf_cm * GF_PER_CM;
    let em = s.emt / 100.0;
    let n = 2.0 / s.lt - 1.0;
    let wt = s.lt * fm * em / 2.0;
    let h2 = 1.5 * (1.0 - s.rt / 100.0) * wt / em.powi(3);
    let load: Vec<_> = (0..SAMPLES)
        .map(|k| {
            let e = em * k as f64 / (SAMPLES - 1) as f64;
            (e, fm * (e / em).powf(n))
        })
        .collect();
    let recover = load
        .iter()
        .rev()
        .map(|&(e, f)| (e, (f - 2.0 * h2 * e * e).max(0.0)))
        .collect();
    KesCurve { load, recover }
}

/// Shear curve from summary values: elastic `G·θ`, loop half-width
/// `h(θ) = h0 + h1|θ|` through `2HG/2` at 0.5° and `2HG5/2` at 5°
/// (h0 ≥ 0); loading branch `Gθ + h`, recovery `Gθ − h`, over ±8°, turning
/// over as described at `symmetric_loop` (memory length `memory`, rad).
pub fn shear_curve(s: &ShearSummary, memory: f64) -> KesCurve {
    let g = s.g * GF_PER_CM / DEG;
    let (h0, h1) = shear_half_width(s);
    let th = SHEAR_MAX_DEG * DEG;
    symmetric_loop(th, |t| g * t, |t| h0 + h1 * t.abs(), memory)
}

/// `(h0, h1)` of the shear loop half-width in SI (N/m, N/m per rad).
pub fn shear_half_width(s: &ShearSummary) -> (f64, f64) {
    let a = s.hg * GF_PER_CM / 2.0;
    let b = s.hg5 * GF_PER_CM / 2.0;
    let mut h1 = (b - a) / (4.5 * DEG);
    let mut h0 = a - h1 * 0.5 * DEG;
    if h0 < 0.0 {
        h0 = 0.0;
        h1 = b / (5.0 * DEG);
    }
    if h1 < 0.0 {
        h1 = 0.0;
        h0 = a;
    }
    (h0, h1)
}

/// Bending curve from summary values: elastic `Bκ`, loop half-width `2HB/2`,
/// over ±2.5 cm⁻¹, turning over as described at `symmetric_loop`.
pub fn bending_curve(s: &BendingSummary, memory: f64) -> KesCurve {
    let b = s.b * GF_CM2_PER_CM;
    let h = s.hb * GF_CM_PER_CM / 2.0;
    symmetric_loop(BENDING_MAX_PER_CM * PER_CM, |k| b * k, |_| h, memory)
}

/// Samples of the symmetric (shear, bending) loops: fine enough that linear
/// interpolation follows a turn-over of one memory length (≥ 12 samples each).
const LOOP_SAMPLES: usize = 641;

/// The KES loop of elastic part `el` and half-width `h` over ±`xmax`.
///
/// Summary values fix the branches where they are read (2HG at ±0.5°, G and
/// 2HG5 up to ±5°, B and 2HB within ±1.5 cm⁻¹), not how the force turns over
/// at the ends of the range; a KES instrument reverses its clamp there and the
/// force falls from one branch to the other over a small, finite travel, as
/// KES plots show. The construction's branches are `el ± h` and its turn-overs
/// those of the law's rate-independent memory ([`crate::fabric::Hysteresis`],
/// memory length `memory`) taken in one stretch from the reversal at `xr`:
/// `σp = s h(x) + (s h(xr) + s h(x))·(−1)·exp(−|x − xr|/memory)` along a path of
/// direction `s`, i.e. the jump `h(xr) + h(x)` between the branches decays over
/// a few memory lengths. [`SATURATED_MEMORY_LENGTHS`] memory lengths past a
/// reversal the branches are `el ± h` to within 0.03 % of the jump, and the
/// summary values are the fabric's (2HG5 and G, read 3° = 12 memory lengths
/// from a turn-over, to 6·10⁻⁶ of the jump; the others to rounding).
fn symmetric_loop(
    xmax: f64,
    el: impl Fn(f64) -> f64,
    h: impl Fn(f64) -> f64,
    memory: f64,
) -> KesCurve {
    assert!(memory > 0.0, "memory length {memory}");
    let xs: Vec<f64> = (0..LOOP_SAMPLES)
        .map(|k| -xmax + 2.0 * xmax * k as f64 / (LOOP_SAMPLES - 1) as f64)
        .collect();
    let branch = |s: f64, x: f64| {
        let xr = -s * xmax;
        let jump = h(xr) + h(x);
        (
            x,
            el(x) + s * (h(x) - jump * (-(x - xr).abs() / memory).exp()),
        )
    };
    let load = xs.iter().map(|&x| branch(1.0, x)).collect();
    let recover = xs.iter().rev().map(|&x| branch(-1.0, x)).collect();
    KesCurve { load, recover }
}

/// Travel after a reversal, in memory lengths, beyond which a loop built by
/// `symmetric_loop` is on its saturated branch (e⁻⁸ = 0.03 % of the jump).
pub const SATURATED_MEMORY_LENGTHS: f64 = 8.0;

/// Linear interpolation of a branch (sorted or reverse-sorted in x) at `x`;
/// `None` outside its range.
pub fn interp(branch: &[(f64, f64)], x: f64) -> Option<f64> {
    if branch.len() < 2 {
        return None;
    }
    let inc = branch[branch.len() - 1].0 >= branch[0].0;
    let at = |k: usize| {
        if inc {
            branch[k]
        } else {
            branch[branch.len() - 1 - k]
        }
    };
    let (lo, hi) = (at(0).0, at(branch.len() - 1).0);
    if x < lo - 1e-15 || x > hi + 1e-15 {
        return None;
    }
    let mut a = 0;
    let mut b = branch.len() - 1;
    while b - a > 1 {
        let m = (a + b) / 2;
        if at(m).0 <= x {
            a = m
        } else {
            b = m
        }
    }
    let (x0, y0) = at(a);
    let (x1, y1) = at(b);
    if (x1 - x0).abs() < 1e-300 {
        return Some(y0);
    }
    Some(y0 + (y1 - y0) * (x - x0) / (x1 - x0))
}

/// Parses a raw KES curve in CSV; `source` (the file's path) names it in
/// errors. The header names the columns; accepted forms:
/// `strain_pct,force_gf_cm,branch` (tensile), `angle_deg,force_gf_cm,branch`
/// (shear), `curvature_per_cm,moment_gf_cm_cm,branch` (bending); `branch` is
/// `load` or `recover`. Values are converted to SI here.
pub fn parse_curve_csv(text: &str, source: &str) -> crate::Result<KesCurve> {
    use crate::error::fail;
    use crate::Error;
    let mut lines = text.lines().enumerate().filter(|(_, l)| {
        let t = l.trim();
        !t.is_empty() && !t.starts_with('#')
    });
    let (_, header) = lines
        .next()
        .ok_or_else(|| Error::fabric(format!("{}: empty curve file", source)))?;
    let cols: Vec<&str> = header.split(',').map(|s| s.trim()).collect();
    let (sx, sy) = match (cols.first().copied(), cols.get(1).copied()) {
        (Some("strain_pct"), Some("force_gf_cm")) => (0.01, GF_PER_CM),
        (Some("strain"), Some("force_n_m")) => (1.0, 1.0),
        (Some("angle_deg"), Some("force_gf_cm")) => (DEG, GF_PER_CM),
        (Some("curvature_per_cm"), Some("moment_gf_cm_cm")) => (PER_CM, GF_CM_PER_CM),
        _ => fail!(
            fabric,
            "{}: line 1: unknown header {header:?}; expected strain_pct,force_gf_cm,branch \
             or angle_deg,force_gf_cm,branch or curvature_per_cm,moment_gf_cm_cm,branch",
            source
        ),
    };
    if cols.get(2).copied() != Some("branch") {
        fail!(fabric, "{}: line 1: third column must be `branch`", source);
    }
    let mut c = KesCurve::default();
    for (ln, l) in lines {
        let f: Vec<&str> = l.split(',').map(|s| s.trim()).collect();
        if f.len() < 3 {
            fail!(fabric, "{}: line {}: expected 3 columns", source, ln + 1);
        }
        let x: f64 = f[0].parse().map_err(|e| {
            Error::external(
                format!("{}: line {}: bad number {:?}", source, ln + 1, f[0]),
                e,
            )
        })?;
        let y: f64 = f[1].parse().map_err(|e| {
            Error::external(
                format!("{}: line {}: bad number {:?}", source, ln + 1, f[1]),
                e,
            )
        })?;
        if !x.is_finite() || !y.is_finite() {
            fail!(fabric, "{}: line {}: non-finite value", source, ln + 1);
        }
        match f[2] {
            "load" => c.load.push((x * sx, y * sy)),
            "recover" => c.recover.push((x * sx, y * sy)),
            other => fail!(
                fabric,
                "{}: line {}: branch must be load or recover, got {other:?}",
                source,
                ln + 1
            ),
        }
    }
    if c.load.len() < 4 || c.recover.len() < 4 {
        fail!(
            fabric,
            "{}: need at least 4 points on each branch (load {}, recover {})",
            source,
            c.load.len(),
            c.recover.len()
        );
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_table_of_model_md() {
        // 1 gf/(cm·deg) = 56.19 N/m per rad
        assert!((GF_PER_CM / DEG - 56.19).abs() < 0.01);
        assert!((21.3 * MG_PER_CM2 - 0.213).abs() < 1e-12);
        assert!((GF_CM2_PER_CM - 9.80665e-5).abs() < 1e-18);
    }

    #[test]
    fn tensile_construction_energies() {
        let s = TensileSummary {
            lt: 0.65,
            wt: 8.68,
            rt: 62.0,
            emt: 5.34,
        };
        let c = tensile_curve(&s, 500.0);
        let wt = trapz(&c.load);
        let fm = 500.0 * GF_PER_CM;
        assert!((wt / (0.65 * fm * 0.0534 / 2.0) - 1.0).abs() < 1e-3, "{wt}");
        let wr = -trapz(&c.recover);
        assert!((wr / wt - 0.62).abs() < 0.01, "{}", wr / wt);
        // 1 % strain: 500 (1/5.34)^(2/0.65-1) gf/cm ≈ 15.3 gf/cm (thesis §6.4.2.1)
        let f1 = interp(&c.load, 0.01).unwrap() / GF_PER_CM;
        assert!((f1 - 15.3).abs() < 0.5, "{f1}");
    }

    fn trapz(b: &[(f64, f64)]) -> f64 {
        b.windows(2)
            .map(|w| (w[1].0 - w[0].0) * (w[0].1 + w[1].1) / 2.0)
            .sum()
    }

    #[test]
    fn shear_half_width_hand_values() {
        let s = ShearSummary {
            g: 1.0,
            hg: 1.0,
            hg5: 1.9,
        };
        let (h0, h1) = shear_half_width(&s);
        // h(0.5°) = 0.5 gf/cm, h(5°) = 0.95 gf/cm
        assert!(((h0 + h1 * 0.5 * DEG) / GF_PER_CM - 0.5).abs() < 1e-12);
        assert!(((h0 + h1 * 5.0 * DEG) / GF_PER_CM - 0.95).abs() < 1e-12);
    }
}
