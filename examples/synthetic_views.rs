//! Writes a synthetic VIEWS.yaml for `garment_sim reconstruct`: a drape
//! (the "real" one) seen by the ten cameras of
//! `lab::reconstruct::example_rig`, marks every 5 cm of the cloth and the
//! board's eight corners as known points, with Gaussian pixel noise and a
//! fraction of the marks hidden in each view.
//!
//! ```text
//! cargo run --release --example synthetic_views -- TRUE.ply SCENE.yaml OUT.yaml [NOISE_PX HIDDEN SEED]
//! ```
//!
//! TRUE.ply is a drape with material coordinates (`garment_sim drape` writes
//! one as final.ply); SCENE.yaml gives the board (its first obstacle).
//! `docs/reconstruct.md` has the command that made
//! `config/reconstruct/table_drape_views.yaml`.

use anyhow::{Context, Result};
use garment_sim::lab::compare::Shape;
use garment_sim::lab::reconstruct::{
    example_rig, obstacle_corners, synthetic_views, SyntheticSettings,
};
use garment_sim::scene::{Overrides, Scene};
use std::path::PathBuf;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 3 && args.len() != 6 {
        anyhow::bail!("usage: synthetic_views TRUE.ply SCENE.yaml OUT.yaml [NOISE_PX HIDDEN SEED]");
    }
    let truth = Shape::read(&PathBuf::from(&args[0]))?;
    let scene = Scene::load(&PathBuf::from(&args[1]))?;
    let sim = scene.build(&Overrides {
        spacing: Some(0.05),
        ..Default::default()
    })?;
    let board = sim
        .obstacles()
        .first()
        .context("the scene has no obstacle")?;
    let (noise_px, hidden, seed) = if args.len() == 6 {
        (args[3].parse()?, args[4].parse()?, args[5].parse()?)
    } else {
        (0.0, 0.0, 1)
    };
    let (k, size, poses) = example_rig();
    let file = synthetic_views(
        &truth,
        &obstacle_corners(board),
        &poses,
        &SyntheticSettings {
            intrinsics: k,
            image_size: size,
            mark_spacing: 0.05,
            noise_px,
            hidden,
            seed,
        },
    )?;
    let head = format!(
        "# Synthetic views for `garment_sim reconstruct` (docs/reconstruct.md): {} seen by ten\n\
         # cameras, marks every 5 cm (grid [i, j] at (0.05 i, 0.05 j) m), the board's corners\n\
         # as known points, pixel noise {noise_px} px, {:.0} % of the marks hidden per view, seed {seed}.\n",
        args[0],
        100.0 * hidden
    );
    std::fs::write(&args[2], head + &file.to_yaml())
        .with_context(|| format!("cannot write {}", args[2]))?;
    Ok(())
}
