//! Command-line front ends of the lab subcommands (`kes`, `fit-kes`,
//! `drapemeter`, `cantilever`): argument structs and one function each; the work is in
//! [`garment_sim::lab`].

use anyhow::{bail, Context, Result};
use garment_sim::lab::cantilever::CantileverOptions;
use garment_sim::lab::kes_lab::{self, Direction, KesTest, LabOptions, LabReport};
use std::path::PathBuf;

/// `garment_sim kes`: virtual KES-FB tests on a simulated specimen.
#[derive(clap::Args)]
pub struct KesArgs {
    /// Fabric file, e.g. config/fabrics/acrylic.yaml
    pub fabric: PathBuf,
    /// Test to run (tensile, shear or bending).
    #[arg(long, required_unless_present = "all")]
    pub test: Option<KesTest>,
    /// Thread direction along the gauge.
    #[arg(long, default_value = "warp")]
    pub dir: Direction,
    /// Run every test in both directions and write one report.
    #[arg(long, conflicts_with = "test")]
    pub all: bool,
    /// Output directory (CSV curves, PNG plots, report.json).
    #[arg(long, default_value = "out/kes")]
    pub out: PathBuf,
    /// Grid spacing along the 5 cm gauge of the tensile and shear specimens, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = LabOptions::default().fb1_spacing)]
    pub spacing: f64,
    /// Grid spacing along the 1 cm gauge of the bending specimen, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = LabOptions::default().fb2_spacing)]
    pub bending_spacing: f64,
    /// Grid spacing along the 20 cm clamps, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = LabOptions::default().width_spacing)]
    pub width_spacing: f64,
    /// Fixed time step, s.
    #[arg(long, allow_negative_numbers = true, default_value_t = LabOptions::default().dt)]
    pub dt: f64,
}

pub fn kes(a: KesArgs) -> Result<()> {
    let fabric = garment_sim::io::load_fabric(&a.fabric)?;
    let opt = LabOptions {
        fb1_spacing: a.spacing,
        fb2_spacing: a.bending_spacing,
        width_spacing: a.width_spacing,
        dt: a.dt,
    };
    let jobs: Vec<(KesTest, Direction)> = if a.all {
        KesTest::ALL
            .iter()
            .flat_map(|&t| Direction::ALL.iter().map(move |&d| (t, d)))
            .collect()
    } else {
        vec![(a.test.context("--test or --all is required")?, a.dir)]
    };
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let mut runs = Vec::new();
    for (t, d) in jobs {
        let label = format!("kes {} {}", t.name(), d.name());
        let mut pr = crate::progress_printer(label);
        let dur = kes_lab::protocol_duration(&fabric, t, d);
        let run = kes_lab::run_test(&fabric, t, d, &opt, &mut |f| pr(f * dur, dur)).with_context(
            || {
                format!(
                    "{}: the virtual KES {} {} test",
                    a.fabric.display(),
                    t.name(),
                    d.name()
                )
            },
        )?;
        kes_lab::write_outputs(&run, &a.out)?;
        print!("{}", kes_lab::format_run(&run));
        runs.push(run);
    }
    let curves = a.out.join("curves.csv");
    std::fs::write(&curves, kes_lab::curves_csv(&runs))
        .with_context(|| format!("cannot write {}", curves.display()))?;
    let report = LabReport {
        fabric: fabric.name.clone(),
        options: opt,
        runs,
    };
    let rp = a.out.join("report.json");
    std::fs::write(&rp, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", rp.display()))?;
    println!(
        "wrote            {}/report.json, curves.csv, <test>_<dir>.csv and .png",
        a.out.display()
    );
    if report.runs.is_empty() {
        bail!("no test ran");
    }
    Ok(())
}

/// `garment_sim drapemeter`: drape coefficient and nodes of a circular specimen.
#[derive(clap::Args)]
pub struct DrapemeterArgs {
    /// Fabric file, e.g. config/fabrics/wool_tropical.yaml
    pub fabric: PathBuf,
    /// Specimen diameter, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.30)]
    pub diameter: f64,
    /// Support disk diameter, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.18)]
    pub disk: f64,
    /// Grid spacing, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.01)]
    pub spacing: f64,
    /// Fixed time step, s.
    #[arg(long, allow_negative_numbers = true, default_value_t = 1e-3)]
    pub dt: f64,
    /// Longest simulated time (the run stops earlier once settled), s.
    #[arg(long, allow_negative_numbers = true, value_parser = seconds, default_value_t = 4.0)]
    pub duration: f64,
    /// Seed of the initial out-of-plane perturbation.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Specimens to drape, with seeds seed, seed + 1, …: each is written to
    /// OUT/specimen_<seed>/ and OUT/specimens.json gives their mean drape
    /// coefficient, its standard deviation and standard error, and the nodes.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub specimens: u64,
    /// Keep the grid's staircase border instead of moving border nodes onto the circle.
    #[arg(long)]
    pub staircase_border: bool,
    /// Keep the specimen's folds from passing through each other.
    #[arg(long)]
    pub self_collision: bool,
    /// Each cell's shear from both its diagonals, with the egg-crate guards
    /// (docs/lab.md); default: each diagonal alone (thesis eq. 4.34).
    #[arg(long)]
    pub cell_shear: bool,
    /// Clamp out to the radius whose pinned region's hull has the disks' area
    /// (default: the vertices within the disks).
    #[arg(long)]
    pub clamp_area_matched: bool,
    /// Clamp out to half a spacing beyond the disks' rim, the cantilever's
    /// discrete clamp (docs/lab.md).
    #[arg(long, conflicts_with = "clamp_area_matched")]
    pub clamp_half_spacing_out: bool,
    /// The laws' elastic parts alone (the middle of each KES loop): the
    /// fabric's hysteresis off.
    #[arg(long)]
    pub no_hysteresis: bool,
    /// Output directory (report.json, top_view.png; with several specimens
    /// specimens.json and a directory per specimen).
    #[arg(long, default_value = "out/drapemeter")]
    pub out: PathBuf,
}

pub fn drapemeter(a: DrapemeterArgs) -> Result<()> {
    use garment_sim::lab::drapemeter::{self, ClampEdge, DrapeOptions};
    let fabric = garment_sim::io::load_fabric(&a.fabric)?;
    let opt = DrapeOptions {
        diameter: a.diameter,
        disk: a.disk,
        spacing: a.spacing,
        dt: a.dt,
        max_duration: a.duration,
        seed: a.seed,
        border_on_outline: !a.staircase_border,
        self_collision: a.self_collision,
        cell_shear: a.cell_shear,
        clamp: match (a.clamp_area_matched, a.clamp_half_spacing_out) {
            (true, _) => ClampEdge::AreaMatched,
            (_, true) => ClampEdge::HalfSpacingOut,
            _ => ClampEdge::Rim,
        },
        hysteresis: !a.no_hysteresis,
        ..Default::default()
    };
    let seeds: Vec<u64> = (0..a.specimens)
        .map(|k| a.seed.checked_add(k))
        .collect::<Option<_>>()
        .with_context(|| {
            format!(
                "--seed {} with --specimens {}: the last seed is beyond {}",
                a.seed,
                a.specimens,
                u64::MAX
            )
        })?;
    if seeds.len() == 1 {
        return drape_specimen(&a, &fabric, &opt, &a.out).map(|_| ());
    }
    let mut reports = Vec::with_capacity(seeds.len());
    for &seed in &seeds {
        let out = a.out.join(format!("specimen_{seed}"));
        println!("== specimen seed {seed}");
        reports.push(drape_specimen(
            &a,
            &fabric,
            &DrapeOptions {
                seed,
                ..opt.clone()
            },
            &out,
        )?);
    }
    let sp = drapemeter::Specimens::of(&reports)?;
    let path = a.out.join("specimens.json");
    std::fs::write(&path, serde_json::to_string_pretty(&sp)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let each: Vec<String> = sp
        .drape_coefficients
        .iter()
        .zip(&sp.nodes)
        .map(|(d, n)| format!("{:.2} ({n})", 100.0 * d))
        .collect();
    println!(
        "== {} specimens, seeds {} … {}",
        seeds.len(),
        seeds[0],
        seeds[seeds.len() - 1]
    );
    println!("drape coefficients {} %", each.join(", "));
    println!(
        "mean               {:.2} %, standard deviation {:.2} points, standard error {:.2} points",
        100.0 * sp.mean_drape_coefficient,
        100.0 * sp.sd_drape_coefficient,
        100.0 * sp.standard_error
    );
    println!(
        "nodes              mean {:.1}, {} … {}",
        sp.mean_nodes, sp.nodes_range[0], sp.nodes_range[1]
    );
    if sp.unsettled > 0 {
        println!(
            "not settled        {} of {} specimens (see their report.json)",
            sp.unsettled,
            seeds.len()
        );
    }
    println!("wrote              {}", path.display());
    Ok(())
}

/// Drapes one specimen, writes its report and top view to `out` and prints it.
fn drape_specimen(
    a: &DrapemeterArgs,
    fabric: &garment_sim::fabric::Fabric,
    opt: &garment_sim::lab::drapemeter::DrapeOptions,
    out: &std::path::Path,
) -> Result<garment_sim::lab::drapemeter::DrapeReport> {
    use garment_sim::lab::drapemeter;
    let mut pr = crate::progress_printer(format!("drapemeter {}", a.fabric.display()));
    let (rep, _, shadow) = drapemeter::run(fabric, opt, &mut pr)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let rp = out.join("report.json");
    std::fs::write(&rp, serde_json::to_string_pretty(&rep)?)
        .with_context(|| format!("cannot write {}", rp.display()))?;
    drapemeter::top_view(&shadow, &rep).save_png(&out.join("top_view.png"))?;
    println!("fabric             {}", rep.fabric);
    println!(
        "specimen           {} m on a {} m disk, grid {} m ({} vertices), dt {} s, clamped out to {:.2} cm, hysteresis {}",
        rep.diameter_m,
        rep.disk_m,
        rep.spacing_m,
        rep.vertices,
        rep.dt_s,
        100.0 * rep.pin_radius_m,
        if rep.hysteresis { "on" } else { "off" }
    );
    match rep.settled_at_s {
        Some(t) => println!(
            "settled            at {t:.3} s (simulated {:.3} s)",
            rep.simulated_s
        ),
        None => println!(
            "settled            no (rms speed still ≥ {} m/s at {:.3} s)",
            drapemeter::SETTLE_SPEED,
            rep.simulated_s
        ),
    }
    println!(
        "drape coefficient  {:.2} % of the annulus ({:.2} % of the flat discrete specimen, which covers {:.1} % of the annulus)",
        100.0 * rep.drape_coefficient,
        100.0 * rep.drape_coefficient_flat_normalised,
        100.0 * rep.flat_specimen_fraction
    );
    let angles: Vec<String> = rep
        .node_angles_deg
        .iter()
        .map(|a| format!("{a:.0}°"))
        .collect();
    println!("nodes              {} at {}", rep.nodes, angles.join(", "));
    println!(
        "shadow radius      {:.1} … {:.1} cm; lowest point {:.1} cm below the disk",
        100.0 * rep.shadow_radius_m[0],
        100.0 * rep.shadow_radius_m[1],
        100.0 * rep.drop_m
    );
    println!(
        "wrote              {}/report.json, top_view.png",
        out.display()
    );
    Ok(rep)
}

/// `garment_sim cantilever`: Peirce's cantilever bending test on a strip.
#[derive(clap::Args)]
pub struct CantileverArgs {
    /// Fabric file, e.g. config/fabrics/wool_tropical.yaml
    pub fabric: PathBuf,
    /// Thread direction along the strip.
    #[arg(long, default_value = "warp")]
    pub dir: Direction,
    /// Grid spacing along the strip (across it at most this), m.
    #[arg(long, allow_negative_numbers = true, default_value_t = CantileverOptions::default().spacing)]
    pub spacing: f64,
    /// Strip width, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = CantileverOptions::default().width)]
    pub width: f64,
    /// Strip length, m.
    #[arg(long, allow_negative_numbers = true, default_value_t = CantileverOptions::default().length)]
    pub length: f64,
    /// Fixed time step, s.
    #[arg(long, allow_negative_numbers = true, default_value_t = CantileverOptions::default().dt)]
    pub dt: f64,
    /// Slide speed while a row moves onto the edge, m/s.
    #[arg(long, allow_negative_numbers = true, default_value_t = CantileverOptions::default().slide_speed)]
    pub speed: f64,
    /// Leave out the hysteretic parts of the laws (a linearly elastic strip for a linear B).
    #[arg(long)]
    pub no_hysteresis: bool,
    /// The grid's single skewed hinge per edge instead of mirror-symmetric pairs.
    #[arg(long)]
    pub single_hinges: bool,
    /// Keep the fabric's own bending damping: each row's release then swings the
    /// overhang, the swings wear the hysteretic memories down, and the reading
    /// depends on the step and the damping (by default the bending damping is
    /// raised to damp the overhang critically, a quasi-static slide).
    #[arg(long)]
    pub fabric_damping: bool,
    /// Output directory (report.json, strip.png, readings.png).
    #[arg(long, default_value = "out/cantilever")]
    pub out: PathBuf,
}

pub fn cantilever(a: CantileverArgs) -> Result<()> {
    use garment_sim::lab::cantilever;
    let fabric = garment_sim::io::load_fabric(&a.fabric)?;
    let opt = CantileverOptions {
        width: a.width,
        length: a.length,
        spacing: a.spacing,
        dt: a.dt,
        slide_speed: a.speed,
        hysteresis: !a.no_hysteresis,
        symmetric_hinges: !a.single_hinges,
        quasi_static: !a.fabric_damping,
        ..Default::default()
    };
    let mut pr = crate::progress_printer(format!(
        "cantilever {} {}",
        a.fabric.display(),
        a.dir.name()
    ));
    let rep = cantilever::run(&fabric, a.dir, &opt, &mut pr)?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let rp = a.out.join("report.json");
    std::fs::write(&rp, serde_json::to_string_pretty(&rep)?)
        .with_context(|| format!("cannot write {}", rp.display()))?;
    cantilever::side_view(&rep).save_png(&a.out.join("strip.png"))?;
    cantilever::readings_plot(&rep).save_png(&a.out.join("readings.png"))?;
    println!("fabric             {}", rep.fabric);
    println!(
        "strip              {} × {} m along {}, grid {:.4} × {:.4} m ({} vertices), dt {} s, hysteresis {}",
        opt.length,
        opt.width,
        a.dir.name(),
        rep.spacing_m[0],
        rep.spacing_m[1],
        rep.vertices,
        opt.dt,
        if opt.hysteresis { "on" } else { "off" }
    );
    println!(
        "slide              {} m/s, bending damping {:.3} s ({})",
        opt.slide_speed,
        rep.beta_bend_s,
        if opt.quasi_static && rep.beta_bend_s != fabric.damping.beta_bend {
            "quasi-static: the overhang's lowest mode critically damped"
        } else {
            "the fabric's"
        }
    );
    println!("readings at rest   overhang (cm)  tip angle (°)  elastica c (cm)  Peirce c (cm)");
    for r in &rep.readings {
        println!(
            "                   {:>13.3}  {:>13.2}  {:>15.3}  {:>13.3}",
            100.0 * r.overhang_m,
            r.tip_angle_deg,
            100.0 * r.bending_length_m,
            100.0 * r.peirce_bending_length_m
        );
    }
    println!(
        "bending length     c = {:.3} cm (overhang {:.3} cm at {}°); the fabric's B gives {:.3} cm",
        100.0 * rep.bending_length_m,
        100.0 * rep.overhang_m,
        cantilever::PEIRCE_ANGLE_DEG,
        100.0 * rep.fabric_bending_length_m
    );
    println!(
        "flexural rigidity  B = w c³ = {:.4} gf·cm²/cm; fabric B {:.4} gf·cm²/cm (2HB {:.4} gf·cm/cm): {:+.1} %",
        rep.flexural_rigidity_gf_cm2_cm,
        rep.fabric_b_gf_cm2_cm,
        rep.fabric_2hb_gf_cm_cm,
        100.0 * rep.relative_error
    );
    println!(
        "wrote              {}/report.json, strip.png, readings.png",
        a.out.display()
    );
    Ok(())
}

/// `garment_sim fit-kes`: fit the laws to raw KES curves and write a fabric file.
#[derive(clap::Args)]
pub struct FitKesArgs {
    /// Curves CSV: direction,test,x,y,branch in KES units (as `kes --all` writes curves.csv).
    pub curves: PathBuf,
    /// Fabric file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Fabric file giving the name, areal mass, thickness and damping.
    #[arg(long)]
    pub base: Option<PathBuf>,
    /// Areal mass W, mg/cm² (required without --base).
    #[arg(long, allow_negative_numbers = true)]
    pub areal_mass: Option<f64>,
    /// Fabric name.
    #[arg(long)]
    pub name: Option<String>,
}

pub fn fit_kes(a: FitKesArgs) -> Result<()> {
    use garment_sim::fabric::{Damping, FabricFile};
    use garment_sim::lab::fit_kes::{fit_fabric, read_curves_csv, FitMeta};
    let curves = read_curves_csv(&a.curves)?;
    let base: Option<FabricFile> = match &a.base {
        Some(p) => Some(garment_sim::io::load_fabric(p)?.file),
        None => None,
    };
    let areal = match (a.areal_mass, &base) {
        (Some(w), _) => w,
        (None, Some(b)) => b.areal_mass_mg_per_cm2,
        (None, None) => bail!("give --areal-mass (mg/cm²) or --base FABRIC.yaml"),
    };
    let meta = FitMeta {
        name: a.name.clone().unwrap_or_else(|| match &base {
            Some(b) => format!("{} (fitted to {})", b.name, a.curves.display()),
            None => format!("fitted to {}", a.curves.display()),
        }),
        source: format!("KES curves {}", a.curves.display()),
        areal_mass_mg_per_cm2: areal,
        thickness_mm: base.as_ref().and_then(|b| b.thickness_mm),
        // without a base: the thesis' measured damping (Table 5.1, row 1)
        damping: base.as_ref().map(|b| b.damping).unwrap_or(Damping {
            alpha: -7.0,
            beta_bend: -6.8e-3,
            beta_shear: -3.1e-4,
            beta_tension: -3.9e-6,
        }),
    };
    let (file, fits) = fit_fabric(&curves, &meta)?;
    // the file must load
    garment_sim::io::fabric_from_file(file.clone(), std::path::Path::new("."))
        .context("the fitted fabric does not load")?;
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(&a.out, serde_yaml::to_string(&file)?)
        .with_context(|| format!("cannot write {}", a.out.display()))?;
    println!(
        "{:<6} {:<8} {:>14} {:>10} {:>16} {:>6}",
        "dir", "test", "residual", "of peak", "linear start", "iters"
    );
    for f in &fits {
        println!(
            "{:<6} {:<8} {:>14.4} {:>9.2}% {:>16.4} {:>6}",
            f.direction,
            f.test,
            f.residual,
            100.0 * f.residual_relative,
            f.residual_linear_start,
            f.iterations
        );
    }
    println!("(residuals: RMS force error of the fitted law driven along each curve, KES units)");
    println!("wrote            {}", a.out.display());
    Ok(())
}

/// A finite number of seconds ≥ 0 (a command-line value parser).
pub fn seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|e| format!("{s:?}: {e}"))?;
    garment_sim::limits::check_duration("value", v).map_err(|e| e.to_string())?;
    Ok(v)
}

/// A count ≥ 1 (a command-line value parser).
pub fn at_least_one(s: &str) -> Result<usize, String> {
    let v: usize = s.trim().parse().map_err(|e| format!("{s:?}: {e}"))?;
    if v == 0 {
        return Err("0: must be ≥ 1".into());
    }
    Ok(v)
}

/// Output into a pipe that closes early (`garment_sim bag info … | head`)
/// ends the program quietly, as for any command-line tool, instead of a
/// panic in `println!`: SIGPIPE is restored to its default action.
pub fn quiet_broken_pipe() {
    // SAFETY: resetting a signal to its default action before any thread
    // starts has no memory effect.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
