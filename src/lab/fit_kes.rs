//! Fitting the spring laws to raw KES curves (thesis §3.4.2: "tous les
//! paramètres des deux polynômes sont obtenus par optimisation globale
//! minimisant l'erreur entre les courbes du KES et les modèles").
//!
//! Per curve, the start is [`fit_law`]'s linear least squares (elastic
//! polynomial on the mean of the branches, loop half-width on half their
//! difference). The global fit then adjusts all coefficients together
//! (elastic polynomial and half-width, all ≥ 0) so that the law, driven with
//! its hysteresis memory along the measured path (loading branch, then
//! recovery), reproduces every measured point: projected Levenberg–Marquardt
//! on the sum of squared force errors. The memory length stays the family's
//! ([`Family::memory_length`]). The residual reported is the RMS force error
//! of the driven law, in KES units and relative to the curve's peak.
//!
//! Input: one CSV with every curve, `direction,test,x,y,branch` (the file
//! `garment_sim kes --all` writes as `curves.csv`), KES units: tensile strain %
//! and gf/cm, shear degrees and gf/cm, bending 1/cm and gf·cm/cm; `#` starts
//! a comment line. Tensile and bending are needed in both directions; shear in
//! at least one (the model uses one shear curve, thesis eq. 4.50; a missing
//! direction takes the other's).

use super::kes_lab::{summarise, KesRun, KesTest};
use crate::fabric::kes::*;
use crate::fabric::{
    fit_law, BehaviourSpec, Damping, DirectionSpec, FabricFile, Family, Law, LawState,
};
use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// Curves keyed by (direction, test), SI.
pub type CurveSet = BTreeMap<(&'static str, &'static str), KesCurve>;

/// Reads the combined curves CSV (see the module doc). Errors name the line.
pub fn read_curves_csv(path: &Path) -> Result<CurveSet> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read KES curves file {}", path.display()))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let (hl, header) = lines
        .next()
        .with_context(|| format!("{}: no header line", path.display()))?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    if cols != ["direction", "test", "x", "y", "branch"] {
        bail!(
            "{}: line {}: header {header:?}; expected direction,test,x,y,branch",
            path.display(),
            hl + 1
        );
    }
    let mut set = CurveSet::new();
    for (ln, l) in lines {
        let at = || format!("{}: line {}", path.display(), ln + 1);
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        if f.len() != 5 {
            bail!("{}: expected 5 columns, got {}", at(), f.len());
        }
        let dir = match f[0] {
            "warp" => "warp",
            "weft" => "weft",
            o => bail!("{}: direction must be warp or weft, got {o:?}", at()),
        };
        let test = match f[1] {
            "tensile" => KesTest::Tensile,
            "shear" => KesTest::Shear,
            "bending" => KesTest::Bending,
            o => bail!(
                "{}: test must be tensile, shear or bending, got {o:?}",
                at()
            ),
        };
        let num = |s: &str| -> Result<f64> {
            let v: f64 = s
                .parse()
                .with_context(|| format!("{}: bad number {s:?}", at()))?;
            if !v.is_finite() {
                bail!("{}: non-finite value {s:?}", at());
            }
            Ok(v)
        };
        let (_, _, sx, sy) = test.units();
        let p = (num(f[2])? / sx, num(f[3])? / sy);
        let c = set.entry((dir, test.name())).or_default();
        match f[4] {
            "load" => c.load.push(p),
            "recover" => c.recover.push(p),
            o => bail!("{}: branch must be load or recover, got {o:?}", at()),
        }
    }
    for ((d, t), c) in &set {
        if c.load.len() < 4 || c.recover.len() < 4 {
            bail!(
                "{}: {d} {t}: need at least 4 points on each branch (load {}, recover {})",
                path.display(),
                c.load.len(),
                c.recover.len()
            );
        }
    }
    for d in ["warp", "weft"] {
        for t in ["tensile", "bending"] {
            if !set.contains_key(&(d, t)) {
                bail!("{}: no {d} {t} curve", path.display());
            }
        }
    }
    if !set.contains_key(&("warp", "shear")) && !set.contains_key(&("weft", "shear")) {
        bail!("{}: no shear curve", path.display());
    }
    for d in ["warp", "weft"] {
        check_tensile_reaches_fm(d, &set[&(d, "tensile")])
            .with_context(|| path.display().to_string())?;
    }
    Ok(set)
}

/// Refuses a tensile curve whose loading branch does not reach the KES-FB1
/// maximum load, 500 gf/cm ([`TENSILE_FM_DEFAULT_GF_CM`]): the test turns
/// there, and EMT, LT, WT and RT are read up to it. The error names the
/// curve, the largest force it does reach, and, when the curve is too
/// sparse to hold its top (the last loading step is longer than the force
/// the branch lacks, or the recovery branch starts above the loading
/// branch's largest force: the turn fell between two samples), says so.
pub fn check_tensile_reaches_fm(direction: &str, c: &KesCurve) -> Result<()> {
    let fm = TENSILE_FM_DEFAULT_GF_CM;
    let (_, _, sx, sy) = KesTest::Tensile.units();
    let kes = |p: &(f64, f64)| (p.0 * sx, p.1 * sy);
    let top = |b: &[(f64, f64)]| {
        b.iter().map(kes).fold(
            (f64::NAN, f64::NEG_INFINITY),
            |a, p| if p.1 > a.1 { p } else { a },
        )
    };
    let (x_top, f_top) = top(&c.load);
    if f_top >= fm {
        return Ok(());
    }
    let what = format!(
        "{direction} tensile curve: its loading branch ({} points) reaches at most \
         {f_top:.1} gf/cm (at {x_top:.3} %), not the {fm} gf/cm the KES-FB1 test loads to \
         (EMT, LT, WT and RT are read up to it)",
        c.load.len()
    );
    let (_, f_rec) = top(&c.recover);
    let lacks = fm - f_top;
    let last_step = match c.load.len() {
        n if n >= 2 => kes(&c.load[n - 1]).1 - kes(&c.load[n - 2]).1,
        _ => 0.0,
    };
    let mut sparse = Vec::new();
    if last_step >= lacks {
        sparse.push(format!(
            "its last loading step, {last_step:.1} gf/cm, is more than the {lacks:.1} gf/cm \
             it lacks"
        ));
    }
    if f_rec > f_top {
        sparse.push(format!(
            "its recovery branch starts higher, at {f_rec:.1} gf/cm"
        ));
    }
    if !sparse.is_empty() {
        bail!(
            "{what}; the curve is too sparse to hold its top ({}): the turn at {fm} gf/cm fell \
             between two samples (when thinning a curve, keep the loading branch's last point)",
            sparse.join(", and ")
        );
    }
    bail!(
        "{what}; its largest force, on either branch, is {:.1} gf/cm: the test stopped short \
         of {fm} gf/cm",
        f_top.max(f_rec)
    );
}

/// The curves of a set of virtual KES runs (what `kes --all` writes).
pub fn curve_set(runs: &[KesRun]) -> CurveSet {
    runs.iter()
        .map(|r| ((r.direction.name(), r.test.name()), r.curve.clone()))
        .collect()
}

/// The law driven along the measured path: (x, measured y, law y) per point.
fn drive(law: &Law, family: Family, c: &KesCurve) -> Vec<(f64, f64, f64)> {
    let x0 = c.load.first().map_or(0.0, |p| p.0);
    let mut st = LawState::at(x0);
    if family != Family::Tensile {
        // a symmetric loop's loading branch starts from the saturated recovery
        st.sp = -law.hysteresis.half_width(x0).0;
        st.dir = -1.0;
    }
    let mut out = Vec::with_capacity(c.load.len() + c.recover.len());
    for &(x, y) in c.load.iter().chain(&c.recover) {
        out.push((x, y, law.eval(&st, x).0));
        law.commit(&mut st, x);
    }
    out
}

fn params_of(family: Family, l: &Law) -> Vec<f64> {
    let e = l.elastic.c;
    let h = [l.hysteresis.h0, l.hysteresis.h1, l.hysteresis.h2];
    match family {
        Family::Tensile => vec![e[0], e[1], e[2], e[3], h[0], h[1], h[2]],
        Family::Shear => vec![e[0], e[2], h[0], h[1], h[2]],
        Family::Bending => vec![e[0], e[1], h[0], h[1], h[2]],
    }
}

fn law_of(family: Family, p: &[f64], xs: f64) -> Law {
    let mut l = Law::elastic_only(Default::default());
    match family {
        Family::Tensile => l.elastic.c.copy_from_slice(&p[0..4]),
        Family::Shear => {
            l.elastic.c[0] = p[0];
            l.elastic.c[2] = p[1];
        }
        Family::Bending => {
            l.elastic.c[0] = p[0];
            l.elastic.c[1] = p[1];
        }
    }
    let k = p.len() - 3;
    l.hysteresis = crate::fabric::Hysteresis {
        h0: p[k],
        h1: p[k + 1],
        h2: p[k + 2],
        xs,
    };
    l
}

/// Fit of one curve.
#[derive(Debug, Clone, Serialize)]
pub struct CurveFit {
    pub direction: String,
    pub test: String,
    /// RMS force error of the driven law, KES units.
    pub residual: f64,
    /// Same relative to the curve's peak |force|.
    pub residual_relative: f64,
    /// RMS error of the linear start (same measure), KES units.
    pub residual_linear_start: f64,
    pub iterations: usize,
}

/// Global least-squares fit of a law to a KES loop (see the module doc).
/// Returns the law, the RMS residual (SI), the start's residual and the
/// number of iterations.
pub fn fit_law_global(family: Family, c: &KesCurve) -> (Law, f64, f64, usize) {
    let (start, _) = fit_law(family, c);
    let xmax = c
        .load
        .iter()
        .chain(&c.recover)
        .fold(0.0f64, |m, p| m.max(p.0.abs()));
    let xs = if start.hysteresis.is_none() {
        family.memory_length(xmax)
    } else {
        start.hysteresis.xs
    };
    let cost = |p: &[f64]| -> f64 {
        let r = drive(&law_of(family, p, xs), family, c);
        r.iter().map(|(_, y, m)| (m - y) * (m - y)).sum::<f64>() / r.len().max(1) as f64
    };
    let mut p = params_of(family, &start);
    let m = p.len();
    // parameter scales: a coefficient's contribution at the curve's extent
    let yscale = c
        .load
        .iter()
        .chain(&c.recover)
        .fold(0.0f64, |a, q| a.max(q.1.abs()))
        .max(1e-300);
    let scale: Vec<f64> = (0..m)
        .map(|k| {
            let mut e = vec![0.0; m];
            e[k] = 1.0;
            let l = law_of(family, &e, xs);
            let v = l.elastic.eval(xmax).0.abs() + l.hysteresis.half_width(xmax).0.abs();
            yscale / v.max(1e-300)
        })
        .collect();
    let c0 = cost(&p);
    let mut best = c0;
    let mut lambda = 1e-3;
    let mut iters = 0;
    for it in 0..60 {
        iters = it + 1;
        // residual vector and Jacobian (central differences, scaled parameters)
        let res = |q: &[f64]| -> Vec<f64> {
            drive(&law_of(family, q, xs), family, c)
                .iter()
                .map(|(_, y, mm)| mm - y)
                .collect()
        };
        let r0 = res(&p);
        let n = r0.len();
        let mut jac = nalgebra::DMatrix::<f64>::zeros(n, m);
        for k in 0..m {
            let h = 1e-6 * scale[k];
            let mut a = p.clone();
            let mut b = p.clone();
            a[k] += h;
            b[k] = (b[k] - h).max(0.0);
            let (ra, rb) = (res(&a), res(&b));
            let d = a[k] - b[k];
            for i in 0..n {
                jac[(i, k)] = (ra[i] - rb[i]) / d * scale[k];
            }
        }
        let r = nalgebra::DVector::from_vec(r0);
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * r;
        let mut improved = false;
        for _ in 0..10 {
            let mut a = jtj.clone();
            for k in 0..m {
                a[(k, k)] += lambda * (jtj[(k, k)] + 1e-12);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&g)) else {
                lambda *= 10.0;
                continue;
            };
            let q: Vec<f64> = (0..m)
                .map(|k| (p[k] - step[k] * scale[k]).max(0.0))
                .collect();
            let cq = cost(&q);
            if cq < best {
                p = q;
                best = cq;
                lambda = (lambda / 3.0).max(1e-9);
                improved = true;
                break;
            }
            lambda *= 10.0;
        }
        if !improved || best < 1e-30 {
            break;
        }
    }
    (law_of(family, &p, xs), best.sqrt(), c0.sqrt(), iters)
}

/// Name, areal mass and damping of the fabric a fit writes.
#[derive(Debug, Clone)]
pub struct FitMeta {
    pub name: String,
    pub source: String,
    pub areal_mass_mg_per_cm2: f64,
    pub thickness_mm: Option<f64>,
    pub damping: Damping,
}

/// Fits every curve and builds the fabric file: per behaviour the KES summary
/// values read from the curve and the fitted law (which the loader uses as
/// is).
pub fn fit_fabric(curves: &CurveSet, meta: &FitMeta) -> Result<(FabricFile, Vec<CurveFit>)> {
    let mut fits = Vec::new();
    let mut spec = |d: &'static str| -> Result<DirectionSpec> {
        let other = if d == "warp" { "weft" } else { "warp" };
        let mut ds = DirectionSpec {
            tensile: BehaviourSpec::default(),
            shear: BehaviourSpec::default(),
            bending: BehaviourSpec::default(),
        };
        for test in KesTest::ALL {
            let c = match curves.get(&(d, test.name())) {
                Some(c) => c,
                None if test == KesTest::Shear => &curves[&(other, "shear")],
                None => bail!("no {d} {} curve", test.name()),
            };
            let family = match test {
                KesTest::Tensile => Family::Tensile,
                KesTest::Shear => Family::Shear,
                KesTest::Bending => Family::Bending,
            };
            let (law, res, res0, iterations) = fit_law_global(family, c);
            let (_, _, _, sy) = test.units();
            let peak = c
                .load
                .iter()
                .chain(&c.recover)
                .fold(0.0f64, |a, q| a.max(q.1.abs()));
            fits.push(CurveFit {
                direction: d.to_string(),
                test: test.name().to_string(),
                residual: res * sy,
                residual_relative: res / peak.max(1e-300),
                residual_linear_start: res0 * sy,
                iterations,
            });
            if test == KesTest::Tensile {
                check_tensile_reaches_fm(d, c)?;
            }
            let s = summarise(test, c).with_context(|| format!("{d} {} curve", test.name()))?;
            let b = match test {
                KesTest::Tensile => {
                    let fm = c.load.iter().fold(0.0f64, |a, q| a.max(q.1)) / GF_PER_CM;
                    BehaviourSpec {
                        lt: Some(s[0]),
                        wt: Some(s[1]),
                        rt: Some(s[2]),
                        emt: Some(s[3]),
                        fm_gf_per_cm: if (fm - TENSILE_FM_DEFAULT_GF_CM).abs()
                            > 0.02 * TENSILE_FM_DEFAULT_GF_CM
                        {
                            Some(fm)
                        } else {
                            None
                        },
                        law: Some(law),
                        ..Default::default()
                    }
                }
                KesTest::Shear => BehaviourSpec {
                    g: Some(s[0]),
                    hg: Some(s[1]),
                    hg5: Some(s[2]),
                    law: Some(law),
                    ..Default::default()
                },
                KesTest::Bending => BehaviourSpec {
                    b: Some(s[0]),
                    hb: Some(s[1]),
                    law: Some(law),
                    ..Default::default()
                },
            };
            match test {
                KesTest::Tensile => ds.tensile = b,
                KesTest::Shear => ds.shear = b,
                KesTest::Bending => ds.bending = b,
            }
        }
        Ok(ds)
    };
    let warp = spec("warp")?;
    let weft = spec("weft")?;
    let file = FabricFile {
        name: meta.name.clone(),
        source: meta.source.clone(),
        notes: "Written by `garment_sim fit-kes`: the summary values are read from the curves \
                (KES definitions); `law` holds the globally fitted laws in SI (thesis §3.4.2), \
                which the loader uses as they are."
            .to_string(),
        areal_mass_mg_per_cm2: meta.areal_mass_mg_per_cm2,
        thickness_mm: meta.thickness_mm,
        cloth_friction: None,
        warp,
        weft,
        damping: meta.damping,
    };
    Ok((file, fits))
}
