//! `garment_sim identify`: a fabric's damping from a motion capture of a
//! free fall (thesis ch. 5).

use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct IdentifyArgs {
    /// Capture file: C3D, or CSV (frame,time,<label>_x,_y,_z,...; metres).
    pub capture: PathBuf,
    /// Fabric file whose laws give the spring forces.
    #[arg(long)]
    pub fabric: PathBuf,
    /// Capture of a falling ball (first marker) giving the vertical.
    #[arg(long)]
    pub vertical: Option<PathBuf>,
    /// Upward direction in the capture's coordinates, e.g. 0,0,1 or 0,1,0
    /// (instead of --vertical; default: the capture's +z is up).
    #[arg(long, allow_hyphen_values = true)]
    pub up: Option<String>,
    /// Viscous window in frames, e.g. 40..100 (default: from the mean-speed curve).
    #[arg(long)]
    pub window: Option<String>,
    /// Marker grid, e.g. 11x11.
    #[arg(long, default_value = "11x11")]
    pub grid: String,
    /// Marker spacing, m.
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true)]
    pub spacing: f64,
    /// Markers are stored warp-major (index i*ny + j) instead of grid order (j*nx + i).
    #[arg(long)]
    pub warp_major: bool,
    /// Output directory (report.json, fabric with the measured damping).
    #[arg(long, default_value = "out/identify")]
    pub out: PathBuf,
}

/// Runs `identify`.
pub fn identify(a: IdentifyArgs) -> Result<()> {
    let IdentifyArgs {
        capture,
        fabric,
        vertical,
        up,
        window,
        grid,
        spacing,
        warp_major,
        out,
    } = a;
    use garment_sim::lab::identify::{identify_file, IdentifyOptions, MarkerGrid};
    let (nx, ny) = grid
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .filter(|&(a, b)| a >= 2 && b >= 2)
        .with_context(|| format!("--grid {grid:?}: expected NXxNY, e.g. 11x11"))?;
    if !(spacing.is_finite() && spacing > 0.0) {
        anyhow::bail!("--spacing {spacing}: must be > 0 m");
    }
    let window = match window {
        Some(w) => Some(
            w.split_once("..")
                .and_then(|(a, b)| {
                    Some((
                        a.trim().parse::<usize>().ok()?,
                        b.trim().parse::<usize>().ok()?,
                    ))
                })
                .with_context(|| format!("--window {w:?}: expected START..END in frames"))?,
        ),
        None => None,
    };
    let fab = garment_sim::io::load_fabric(&fabric)?;
    let opts = IdentifyOptions {
        grid: MarkerGrid {
            nx,
            ny,
            spacing: [spacing, spacing],
        },
        window,
        up: match up {
            None => None,
            Some(text) => {
                let v: Vec<f64> = text
                    .split(',')
                    .map(|c| c.trim().parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| anyhow::anyhow!("--up {text:?}: expected three numbers x,y,z"))?;
                if v.len() != 3 {
                    anyhow::bail!("--up {text:?}: expected three numbers x,y,z");
                }
                Some(nalgebra::Vector3::new(v[0], v[1], v[2]))
            }
        },
        ..Default::default()
    };
    let rep = identify_file(&capture, vertical.as_deref(), &fab, &opts, warp_major)?;
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    std::fs::write(out.join("report.json"), serde_json::to_string_pretty(&rep)?)?;
    let r = &rep.result;
    let mut file = fab.file.clone();
    // the joint fit is the answer (exact on exact data); the ordered fits are
    // the thesis' tables, biased where the dissipations are correlated
    let m = r.measured;
    if !r.resolved[0] {
        anyhow::bail!("the capture does not determine alpha (singular fit): check the window and the marker grid");
    }
    file.damping.alpha = m[0];
    if r.resolved[1] {
        file.damping.beta_bend = m[1];
    }
    if r.resolved[2] {
        file.damping.beta_shear = m[2];
    }
    if r.resolved[3] {
        file.damping.beta_tension = m[3];
    }
    file.notes = format!(
        "{}\nDamping measured by `garment_sim identify {}` (window {}..{} of {} frames at {} Hz).",
        file.notes.trim_end(),
        capture.display(),
        r.window.0,
        r.window.1,
        rep.frames,
        rep.rate_hz
    );
    let fab_out = out.join("fabric_measured.yaml");
    std::fs::write(&fab_out, serde_yaml::to_string(&file)?)?;
    let plots = garment_sim::lab::identify::write_plots(r, &out)?;
    println!(
        "capture          {} ({} frames, {} markers at {} Hz)",
        rep.capture, rep.frames, rep.markers, rep.rate_hz
    );
    println!(
        "gaps filled      {} marker positions in {} sweeps (thesis Algorithm 1)",
        rep.missing_markers_filled, rep.gap_fill_sweeps
    );
    if let Some(v) = rep.vertical_from_ball {
        println!(
            "vertical         ({:.5}, {:.5}, {:.5}) from the ball drop",
            v[0], v[1], v[2]
        );
    }
    println!(
        "viscous window   frames {}..{}{}",
        r.window.0,
        r.window.1,
        if r.window_chosen_automatically {
            " (from the mean-speed curve)"
        } else {
            ""
        }
    );
    println!("measured (± one standard error):");
    for (k, (name, unit)) in [
        ("alpha", "1/s"),
        ("beta_f", "s"),
        ("beta_c", "s"),
        ("beta_t", "s"),
    ]
    .iter()
    .enumerate()
    {
        if r.resolved[k] && r.measured_se[k].is_finite() {
            println!(
                "  {name:<8} {:>12.4e} ± {:.1e} {unit}",
                m[k], r.measured_se[k]
            );
        } else if r.resolved[k] {
            println!("  {name:<8} {:>12.4e} {unit} (trajectory fit)", m[k]);
        } else {
            println!("  {name:<8} not resolved by this capture (the fabric's own value is kept)");
        }
    }
    if let Some(t) = &r.trajectory {
        println!(
            "trajectory fit, frames {}..{} ({} simulations): {:.4e}, {:.4e}, {:.4e}, {:.4e}; rms {:.2e} m; \
             markers moved by a 15 % change: {:.1e}, {:.1e}, {:.1e}, {:.1e} m; resolved {:?}",
            t.frames.0,
            t.frames.1,
            t.simulations,
            t.theta[0],
            t.theta[1],
            t.theta[2],
            t.theta[3],
            t.rms_m,
            t.effect_15pc_m[0],
            t.effect_15pc_m[1],
            t.effect_15pc_m[2],
            t.effect_15pc_m[3],
            t.resolved
        );
    }
    println!(
        "all four jointly: {:.4e}, {:.4e}, {:.4e}, {:.4e} (condition number {:.2e})",
        r.global[0], r.global[1], r.global[2], r.global[3], r.global_condition_number
    );
    println!("ordered fits (thesis §5.4.3, Tables 5.1 and 5.2):");
    println!(
        "{:<14} {:>12} {:>12} {:>16}",
        "parameter", "mean", "std", "error decrease"
    );
    for e in [&r.alpha, &r.beta_bend, &r.beta_shear, &r.beta_tension] {
        println!(
            "{:<14} {:>12.4e} {:>12.4e} {:>15.2}%",
            e.name,
            e.mean,
            e.std,
            100.0 * e.error_decrease
        );
    }
    println!(
        "wrote            {}/report.json, {}",
        out.display(),
        fab_out.display()
    );
    for p in plots {
        println!("plot             {}", p.display());
    }
    Ok(())
}
