//! How a trial ended, in one word and its reasons (`fit.json`'s `outcome`,
//! and stderr): settled only at rest with every seam closed, no panel
//! stretched past what its fabric's KES tensile curve reaches and no cloth
//! inside the body; otherwise the reasons, each naming where.

use super::{Fit, Trial, VertexFit};
use crate::garment::Garment;
use crate::solver::Simulation;
use serde::Serialize;

/// A seam open wider than this is a seam that did not close, m.
pub const SEAM_CLOSED: f64 = 2e-3;

/// The word for how a trial ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// At rest, seams closed, every panel within its fabric's measured
    /// range, no cloth inside the body.
    Settled,
    /// The run went its course but the garment is not a settled fit: the
    /// reasons say why and where.
    NotSettled,
    /// A dressing ran its course with no fault (a dressing does not settle).
    Dressed,
    /// A step failed; the outputs are of the steps before it.
    Failed,
    /// Stopped before its end (a signal, an observer).
    Stopped,
}

impl Status {
    /// As `fit.json` says it.
    pub fn name(self) -> &'static str {
        match self {
            Status::Settled => "settled",
            Status::NotSettled => "not_settled",
            Status::Dressed => "dressed",
            Status::Failed => "failed",
            Status::Stopped => "stopped",
        }
    }
}

/// How a trial ended, with every reason it is not a settled fit.
#[derive(Debug, Clone, Serialize)]
pub struct Outcome {
    pub status: Status,
    /// Each reason names what and where: the step that failed, the seam
    /// that did not close, the panel stretched past its fabric's range
    /// (a pattern too small for the body where the garment rests, cloth
    /// caught in a crease where it still moves), cloth inside the body, the
    /// garment still moving and where fastest.
    pub reasons: Vec<String>,
}

impl Outcome {
    /// One line for stderr.
    pub fn line(&self) -> String {
        match self.reasons.is_empty() {
            true => format!("outcome: {}", self.status.name()),
            false => format!(
                "outcome: {}: {}",
                self.status.name(),
                self.reasons.join("; ")
            ),
        }
    }
}

/// A panel is stretched past its fabric's range when more than this share
/// of its vertices are (a lone stitch corner past it is not).
pub const STRETCHED_SHARE: f64 = 0.02;

/// The largest strain each fabric's KES tests reached: warp and weft
/// tensile (the end of their loading curves) and bias (the diagonal's
/// stretch at the end of the shear curves, `sqrt(1 + sin θ) − 1`); fractions.
fn reach(t: &Trial, panel: usize) -> [f64; 3] {
    let f = &t.fabrics[t.fabric_of[panel] as usize];
    let end = |c: &crate::fabric::kes::KesCurve| c.load.last().map_or(f64::INFINITY, |p| p.0);
    let shear = end(&f.warp.shear_curve).max(end(&f.weft.shear_curve));
    [
        end(&f.warp.tensile_curve),
        end(&f.weft.tensile_curve),
        (1.0 + shear.sin()).sqrt() - 1.0,
    ]
}

/// How the trial ended: the fit `fit` of garment `g` as `sim` ended it.
pub fn outcome(t: &Trial, sim: &Simulation, g: &Garment, vf: &VertexFit, fit: &Fit) -> Outcome {
    let run = &fit.run;
    if let Some(f) = &run.failure {
        return Outcome {
            status: Status::Failed,
            reasons: vec![format!("a step failed: {f}")],
        };
    }
    if run.stopped {
        return Outcome {
            status: Status::Stopped,
            reasons: vec![format!("stopped at t = {:.3} s", run.simulated_s)],
        };
    }
    let dressing = fit.dressing.is_some();
    let at_rest = run.settle_time_s.is_some();
    let x = sim.cloth.positions();
    let near = |i: usize| format!("near ({:.3}, {:.3}, {:.3}) m", x[i].x, x[i].y, x[i].z);
    let mut reasons = Vec::new();
    if fit.largest_seam_gap_mm > 1e3 * SEAM_CLOSED {
        reasons.push(format!(
            "seam {} did not close: open by {:.1} mm",
            fit.largest_seam_gap_at.as_deref().unwrap_or("?"),
            fit.largest_seam_gap_mm
        ));
    }
    // a girth where the garment's section is shorter than the body's: the
    // pattern is too small for the body there, whatever else holds it
    let tight: Vec<String> = (fit.girths.iter())
        .filter_map(|(name, gf)| {
            let (e, b, g) = (gf.ease_cm?, gf.body_cm?, gf.garment_cm?);
            (e < 0.0).then(|| format!("{name} ({g:.1} cm round a {b:.1} cm body)"))
        })
        .collect();
    if !tight.is_empty() {
        reasons.push(format!(
            "the pattern is too small for the body at the {}",
            tight.join(", the ")
        ));
    }
    for (k, p) in g.panels.iter().enumerate() {
        let limits = reach(t, k);
        let range = p.first..p.first + p.count;
        let worst = [("warp", &vf.warp), ("weft", &vf.weft), ("bias", &vf.bias)]
            .into_iter()
            .zip(limits)
            .map(|((along, e), limit)| {
                let past = range.clone().filter(|&i| e[i] > limit).count();
                let i = (range.clone())
                    .max_by(|&a, &b| e[a].total_cmp(&e[b]))
                    .unwrap_or(p.first);
                (along, past as f64 / p.count.max(1) as f64, e[i], i, limit)
            })
            .filter(|q| q.1 > STRETCHED_SHARE)
            .max_by(|a, b| a.1.total_cmp(&b.1));
        let Some((along, share, strain, i, limit)) = worst else {
            continue;
        };
        let why = if at_rest || dressing || !tight.is_empty() {
            "the pattern is too small for the body there"
        } else {
            "cloth caught in a crease of the body"
        };
        reasons.push(format!(
            "{why}: {:.0} % of panel {:?} stretched along {along} past the {:.1} % its \
             fabric's KES test reached, up to {:.0} % {}",
            100.0 * share,
            p.name,
            100.0 * limit,
            100.0 * strain,
            near(i)
        ));
    }
    if fit.body_penetrations > 0 {
        reasons.push(format!(
            "{} vertices inside the body (deepest {:.1} mm)",
            fit.body_penetrations,
            10.0 * fit.deepest_penetration_cm
        ));
    }
    if !at_rest && !dressing {
        let v = sim.cloth.velocities();
        let i = (0..v.len())
            .max_by(|&a, &b| v[a].norm().total_cmp(&v[b].norm()))
            .unwrap_or(0);
        let panel = g
            .panels
            .iter()
            .find(|p| (p.first..p.first + p.count).contains(&i))
            .map_or("?", |p| p.name.as_str());
        reasons.push(format!(
            "did not come to rest (rms speed {:.3} m/s {:.2} s after sewing): moving fastest \
             ({:.3} m/s) on panel {panel:?} {}",
            run.final_rms_speed_m_s,
            run.simulated_s - run.sewing_s,
            v[i].norm(),
            near(i)
        ));
    }
    let status = match (reasons.is_empty(), dressing) {
        (true, true) => Status::Dressed,
        (true, false) => Status::Settled,
        (false, _) => Status::NotSettled,
    };
    Outcome { status, reasons }
}
