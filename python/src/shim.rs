//! TEMPORARY stand-in for `garment_sim::trial::run_trial` (issue 58) until
//! main has it: the same API, over today's library functions.
use anyhow::Result;
use garment_sim::body_forces::BodyPressure;
use garment_sim::garment::Garment;
use garment_sim::run::Control;
use garment_sim::solver::Simulation;
use garment_sim::trial::{self, Fit, Trial, TrialOverrides, VertexFit};
use std::path::Path;

#[derive(Debug, Clone, Copy)]
pub enum Phase {
    Sewing,
    Drape,
    Motion,
}
impl Phase {
    pub fn name(&self) -> &'static str {
        match self {
            Phase::Sewing => "sewing",
            Phase::Drape => "drape",
            Phase::Motion => "motion",
        }
    }
}
pub struct Step<'a> {
    #[allow(dead_code)]
    pub sim: &'a Simulation,
    pub phase: Phase,
    pub done: f64,
    pub of: f64,
}
pub struct TrialOutcome {
    pub fit: Fit,
    pub sim: Simulation,
    pub garment: Garment,
    vf: VertexFit,
    on_body: Option<BodyPressure>,
}
impl TrialOutcome {
    pub fn positions(&self) -> Vec<[f64; 3]> {
        self.sim.cloth.x.iter().map(|p| [p.x, p.y, p.z]).collect()
    }
    pub fn triangles(&self) -> Vec<[usize; 3]> {
        self.sim.cloth.triangles.clone()
    }
    pub fn error(&self) -> Option<anyhow::Error> {
        self.fit
            .run
            .failure
            .as_ref()
            .map(|f| anyhow::anyhow!("{f}"))
    }
    pub fn write(&self, t: &Trial, out: &Path) -> Result<()> {
        use garment_sim::render::{full_scale, FieldPicture, Surface};
        let (sim, fit, vf) = (&self.sim, &self.fit, &self.vf);
        std::fs::create_dir_all(out)?;
        trial::write_trace(&fit.run, &out.join("trial.csv"))?;
        trial::write_wrench(&fit.run, &out.join("body_wrench.csv"))?;
        if let Some(p) = &self.on_body {
            trial::write_body_ply(p, &out.join("body_pressure.ply"))?;
        }
        trial::write_obj(sim, &self.garment, &out.join("garment.obj"))?;
        trial::write_ply(sim, vf, &out.join("garment.ply"))?;
        let json = serde_json::to_string_pretty(fit)?;
        garment_sim::io::write_atomic(&out.join("fit.json"), |w| w.write_all(json.as_bytes()))?;
        let cloth = Surface {
            vertices: self.positions(),
            triangles: sim.cloth.triangles.clone(),
        };
        let body = vec![Surface::from_obstacle(trial::body_now(sim, t))];
        let info = vec![format!("fabric {}", sim.fabric.name)];
        FieldPicture {
            title: format!("{}: stretch", t.garment.name),
            info: info.clone(),
            cloth: cloth.clone(),
            full: full_scale(&vf.stretch, 0.001),
            field: vf.stretch.clone(),
            label: ("stretch (warp, weft, bias)".into(), "%".into()),
            label_scale: 100.0,
            obstacles: body.clone(),
            size: (1500, 800),
        }
        .save_png(&out.join("fit_strain.png"))?;
        FieldPicture {
            title: format!("{}: pressure on the body", t.garment.name),
            info,
            cloth,
            full: full_scale(&vf.pressure, 1.0),
            field: vf.pressure.clone(),
            label: ("pressure".into(), "Pa".into()),
            label_scale: 1.0,
            obstacles: body,
            size: (1500, 800),
        }
        .save_png(&out.join("fit_pressure.png"))?;
        Ok(())
    }
}
pub fn run_trial(
    t: &Trial,
    ov: &TrialOverrides,
    observe: &mut dyn FnMut(&Step) -> Control,
) -> Result<TrialOutcome> {
    anyhow::ensure!(t.file.dressing.is_none(), "dressing: not yet from Python");
    let (mut sim, g) = t.build(ov)?;
    let body = trial::body_handle(&sim);
    let stop = std::cell::Cell::new(false);
    let stats = trial::run_to_failure(
        &mut sim,
        body,
        &t.file.sewing,
        &t.file.settle,
        ov.max_time,
        &mut |s, phase, done, of| {
            let phase = match phase {
                "sewing" => Phase::Sewing,
                "motion" => Phase::Motion,
                _ => Phase::Drape,
            };
            if observe(&Step {
                sim: s,
                phase,
                done,
                of,
            }) == Control::Stop
            {
                stop.set(true);
            }
        },
        &|| stop.get(),
    )?;
    let (fit, vf, on_body) = trial::fit(&sim, &g, t, stats);
    Ok(TrialOutcome {
        fit,
        sim,
        garment: g,
        vf,
        on_body,
    })
}
