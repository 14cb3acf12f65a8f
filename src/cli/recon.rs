//! `garment_sim reconstruct` (the 3D shape of a drape from marked photos,
//! thesis §6.3) and `garment_sim compare` (the distance of eq. 6.2 between
//! two shapes of a cloth).

use anyhow::{Context, Result};
use garment_sim::lab::compare::{self, Shape};
use garment_sim::lab::reconstruct::{self, LoopSettings, Problem, ViewsFile};
use garment_sim::scene::{Overrides, Scene};
use serde_json::json;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct ReconstructArgs {
    /// The views: intrinsics, known points, marks seen per view (docs/reconstruct.md).
    pub views: PathBuf,
    /// The generic model: a cloth shape as PLY with material coordinates (x y z u v,
    /// as `drape` writes final.ply). Default: the table drape
    /// (--scene) at 1 cm, dt 1/120 s, 3 s.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Scene drapes for the default model.
    #[arg(long, default_value = "config/scenes/table_drape.yaml")]
    pub scene: PathBuf,
    /// Largest number of calibration–reconstruction rounds.
    #[arg(long, default_value_t = LoopSettings::default().max_rounds)]
    pub max_rounds: usize,
    /// Kernel of the radial basis functions that deform the model (thin-plate r² ln r,
    /// biharmonic in 2D; r, biharmonic in 3D; r³).
    #[arg(long, value_enum, default_value = "thin-plate")]
    pub rbf_kernel: reconstruct::RbfKernel,
    /// Where the radial basis functions live: world (3D positions on the model) or
    /// material (the flat cloth's u, v).
    #[arg(long, value_enum, default_value = "material")]
    pub rbf_space: reconstruct::RbfSpace,
    /// Output directory (reconstructed.ply, report.json, view_NAME.png).
    #[arg(long, default_value = "out/reconstruct")]
    pub out: PathBuf,
}

/// The default generic model: the table drape at 1 cm, dt = 1/120 s, 3 s,
/// on one thread, so that it is the same model on every machine (another
/// thread count sums in another order, and the drape's folds amplify that
/// round-off to about 1 mm).
fn default_model(scene: &Path) -> Result<Shape> {
    let sc = Scene::load(scene).with_context(|| {
        "the default model drapes this scene; give another with --scene or a mesh with --model"
    })?;
    let ov = Overrides {
        spacing: Some(0.01),
        dt: Some(1.0 / 120.0),
        duration: Some(3.0),
        threads: Some(1),
        ..Default::default()
    };
    let mut sim = sc.build(&ov)?;
    let mut pr =
        crate::PhaseProgress::new(Some(format!("model: drape {} at 1 cm", scene.display())));
    garment_sim::scene::run::run(&mut sim, 3.0, 30.0, sc.file.settle_speed, &mut |s| {
        pr.show(s);
        Ok(garment_sim::run::Control::Continue)
    })?;
    pr.finish();
    Ok(Shape::from_cloth(&sim.cloth))
}

pub fn reconstruct(a: ReconstructArgs) -> Result<()> {
    if a.max_rounds == 0 {
        anyhow::bail!("--max-rounds 0: the loop needs at least one round");
    }
    let file = ViewsFile::load(&a.views)?;
    let model = match &a.model {
        Some(m) => Shape::read(m)?,
        None => default_model(&a.scene)?,
    };
    let base = a.views.parent().map(Path::to_path_buf).unwrap_or_default();
    let problem = Problem::new(&file, &model, &base)
        .with_context(|| format!("views file {}", a.views.display()))?;
    let settings = LoopSettings {
        max_rounds: a.max_rounds,
        deformation: reconstruct::Deformation {
            space: a.rbf_space,
            kernel: a.rbf_kernel,
        },
        ..Default::default()
    };
    let rec = reconstruct::reconstruct(&problem, &model, &settings, &mut |_, _| {})
        .with_context(|| format!("views file {}", a.views.display()))?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    if a.model.is_none() {
        model.write_ply(
            &a.out.join("model.ply"),
            "garment_sim generic model: table drape at 1 cm",
        )?;
    }
    rec.shape.write_ply(
        &a.out.join("reconstructed.ply"),
        "garment_sim reconstruct: the model deformed through the reconstructed marks, metres",
    )?;
    let k = &problem.intrinsics;
    let views: Vec<_> = problem
        .views
        .iter()
        .zip(&rec.poses)
        .zip(&rec.fits)
        .map(|((v, pose), f)| {
            let r = pose.rotation.matrix();
            json!({
                "name": v.name,
                "photo": v.photo.as_ref().map(|p| p.display().to_string()),
                "marks": v.seen.len(),
                "rotation": [[r[(0,0)], r[(0,1)], r[(0,2)]], [r[(1,0)], r[(1,1)], r[(1,2)]], [r[(2,0)], r[(2,1)], r[(2,2)]]],
                "translation_m": [pose.translation.x, pose.translation.y, pose.translation.z],
                "centre_m": [pose.centre().x, pose.centre().y, pose.centre().z],
                "rms_px": f.rms,
                "max_px": f.max,
                "errors_px": v.seen.iter().zip(&f.errors).map(|((i, _), e)| json!({
                    "mark": problem.marks[*i].label, "error_px": e })).collect::<Vec<_>>(),
            })
        })
        .collect();
    let mut views_of = vec![0usize; problem.marks.len()];
    for v in &problem.views {
        for (i, _) in &v.seen {
            views_of[*i] += 1;
        }
    }
    let marks: Vec<_> = problem
        .marks
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let (kind, uv) = match m.kind {
                reconstruct::MarkKind::Cloth { uv } => ("cloth", Some(uv)),
                reconstruct::MarkKind::Known { .. } => ("known", None),
            };
            let x = rec.marks[i];
            let x0 = problem.model_marks[i];
            json!({
                "mark": m.label,
                "kind": kind,
                "uv_m": uv,
                "views": views_of[i],
                "triangulated": rec.triangulated[i],
                "model_m": [x0.x, x0.y, x0.z],
                "position_m": [x.x, x.y, x.z],
                "moved_m": (x - x0).norm(),
                "rms_px": rec.mark_rms[i],
            })
        })
        .collect();
    let all: Vec<f64> = rec
        .fits
        .iter()
        .flat_map(|f| f.errors.iter().copied())
        .collect();
    let report = json!({
        "views_file": a.views.display().to_string(),
        "model": a.model.as_ref().map(|m| m.display().to_string())
            .unwrap_or_else(|| format!("{} at 1 cm, dt 1/120 s, 3 s", a.scene.display())),
        "intrinsics": k,
        "deformation": format!("radial basis functions, kernel {:?}, in {:?} space",
            a.rbf_kernel, a.rbf_space).to_lowercase(),
        "rounds": rec.history.len() - 1,
        "rms_px_history": rec.history,
        "rms_px": garment_sim::lab::posit::rms(&all),
        "max_px": all.iter().cloned().fold(0.0, f64::max),
        "marks_triangulated": rec.triangulated.iter().filter(|t| **t).count(),
        "views": views,
        "marks": marks,
    });
    let rp = a.out.join("report.json");
    let js = serde_json::to_string_pretty(&report)?;
    garment_sim::io::write_atomic(&rp, |w| w.write_all(js.as_bytes()))?;
    let mut pictures = Vec::new();
    for (i, v) in problem.views.iter().enumerate() {
        let name = format!("view_{}.png", sanitize(&v.name));
        reconstruct::view_picture(&problem, &rec, i)?.save_png(&a.out.join(&name))?;
        pictures.push(name);
    }
    println!(
        "views            {} ({} marks, {} triangulated, {} known points)",
        problem.views.len(),
        problem.marks.len(),
        rec.triangulated.iter().filter(|t| **t).count(),
        problem
            .marks
            .iter()
            .filter(|m| matches!(m.kind, reconstruct::MarkKind::Known { .. }))
            .count()
    );
    println!(
        "rounds           {} (rms reprojection error {:.4} px after the first poses, {:.4} px at the end)",
        rec.history.len() - 1,
        rec.history[0],
        rec.history.last().copied().unwrap_or(f64::NAN)
    );
    for (v, f) in problem.views.iter().zip(&rec.fits) {
        println!(
            "  {:<14} rms {:.3} px, largest {:.3} px",
            v.name, f.rms, f.max
        );
    }
    println!(
        "wrote            {}/reconstructed.ply, report.json, {}{}",
        a.out.display(),
        pictures.join(", "),
        if a.model.is_none() { ", model.ply" } else { "" }
    );
    Ok(())
}

fn sanitize(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[derive(clap::Args)]
pub struct CompareArgs {
    /// First shape (PLY with or without u v, or OBJ).
    pub a: PathBuf,
    /// Second shape.
    pub b: PathBuf,
    /// Pair each point with the nearest point of the other surface even when both
    /// shapes carry material coordinates.
    #[arg(long)]
    pub nearest: bool,
    /// Output directory (compare.json, distance.png).
    #[arg(long, default_value = "out/compare")]
    pub out: PathBuf,
}

pub fn compare(a: CompareArgs) -> Result<()> {
    let sa = Shape::read(&a.a)?;
    let sb = Shape::read(&a.b)?;
    let c = compare::compare(&sa, &sb, a.nearest)
        .with_context(|| format!("comparing A = {} with B = {}", a.a.display(), a.b.display()))?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let report = json!({
        "a": a.a.display().to_string(),
        "b": a.b.display().to_string(),
        "vertices_a": sa.vertices.len(),
        "vertices_b": sb.vertices.len(),
        "correspondence": c.correspondence,
        "from": c.from,
        "points": c.points,
        "mean_m": c.mean,
        "max_m": c.max,
        "rms_m": c.rms,
    });
    let js = serde_json::to_string_pretty(&report)?;
    garment_sim::io::write_atomic(&a.out.join("compare.json"), |w| w.write_all(js.as_bytes()))?;
    let from = if c.from == "A" { &sa } else { &sb };
    compare::distance_picture(from, &c, "distance (eq. 6.2)")
        .save_png(&a.out.join("distance.png"))?;
    println!(
        "A                {} ({} vertices)",
        a.a.display(),
        sa.vertices.len()
    );
    println!(
        "B                {} ({} vertices)",
        a.b.display(),
        sb.vertices.len()
    );
    println!(
        "homologues       {} ({} points of {})",
        c.correspondence, c.points, c.from
    );
    println!("mean distance    {:.3} mm (eq. 6.2)", c.mean * 1e3);
    println!("largest          {:.3} mm", c.max * 1e3);
    println!(
        "wrote            {}/compare.json, distance.png",
        a.out.display()
    );
    Ok(())
}
