//! The settings of a run: written once, flattened into the command line's
//! `drape` and `trial` arguments and into the scene and trial files (their
//! top-level `dt`, `solver`, `self_collision`, …: [`read_file`]), read from
//! a dict (serde) and built from the node's parameters; the command line's
//! over the file's ([`Overrides::or`]), applied to the step's [`Params`] in
//! one place ([`Overrides::apply`]). SI units: m, s.

use super::HingesFile;
use crate::limits;
use crate::solver::{LinearSolverKind, Params};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// What a run takes in place of its file's values (each `None`: the file's).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Overrides {
    /// Grid spacing, m (default: the file's).
    #[arg(long, allow_negative_numbers = true)]
    pub spacing: Option<f64>,
    /// Fixed time step, s (default: the file's).
    #[arg(long, allow_negative_numbers = true)]
    pub dt: Option<f64>,
    /// A scene's simulated duration, s (default: the scene's `duration`).
    #[arg(long, allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// Linear solver: auto (default: the block-Jacobi PCG while it converges in fewer
    /// iterations than the break-even count, else a single-precision Cholesky factor as
    /// the PCG's preconditioner), pcg (block-Jacobi), sgs (PCG with symmetric block
    /// Gauss–Seidel), amg (PCG with smoothed-aggregation multigrid) or cholesky (exact,
    /// double precision) (default: the file's, auto when absent).
    #[arg(long)]
    #[serde(alias = "linear_solver")]
    pub solver: Option<LinearSolverKind>,
    /// Turn the hysteretic parts of the laws off (`--no-hysteresis`).
    #[arg(
        long = "no-hysteresis",
        num_args = 0,
        default_missing_value = "false",
        action = clap::ArgAction::Set
    )]
    pub hysteresis: Option<bool>,
    /// Relative tolerance of the PCG, in (0, 1) (default: the file's, 1e-6 when absent).
    #[arg(long, allow_negative_numbers = true)]
    pub cg_tolerance: Option<f64>,
    /// Threads of the assembly, the PCG and the contacts (default: the file's, else one
    /// per core from 500 vertices; 1 for one core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Keep the cloth from passing through itself, true or false (default: the file's
    /// `self_collision`, off when absent).
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub self_collision: Option<bool>,
    /// The triangle-mesh obstacles' vertices and edges meet the cloth's triangles and
    /// edges too, true or false (default: the file's `obstacle_edges`, off when absent;
    /// docs/self_collision.md).
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacle_edges: Option<bool>,
    /// Each cell's shear from both its diagonals, with the egg-crate guards, true or
    /// false (default: the file's `cell_shear`, off when absent; docs/lab.md).
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell_shear: Option<bool>,
    /// A scene's bending hinges: skewed (one per grid edge) or mirror_symmetric (pairs
    /// that bend alike in every direction) (default: the scene's `cloth.hinges`, skewed
    /// when absent; docs/drape.md).
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hinges: Option<HingesFile>,
    /// A trial's longest drape after sewing, or its dressing's longest run, s
    /// (default: the trial's `settle.max_time`; the whole dressing).
    #[arg(long, allow_negative_numbers = true)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_time: Option<f64>,
}

impl Overrides {
    /// The keys a file's settings take (the fields' names; `solver` is also
    /// read as `linear_solver`).
    pub const KEYS: [&'static str; 13] = [
        "spacing",
        "dt",
        "duration",
        "solver",
        "linear_solver",
        "hysteresis",
        "cg_tolerance",
        "threads",
        "self_collision",
        "obstacle_edges",
        "cell_shear",
        "hinges",
        "max_time",
    ];

    /// Each value given here, else `file`'s (the command line's over the
    /// file's).
    pub fn or(&self, file: &Overrides) -> Overrides {
        Overrides {
            spacing: self.spacing.or(file.spacing),
            dt: self.dt.or(file.dt),
            duration: self.duration.or(file.duration),
            solver: self.solver.or(file.solver),
            hysteresis: self.hysteresis.or(file.hysteresis),
            cg_tolerance: self.cg_tolerance.or(file.cg_tolerance),
            threads: self.threads.or(file.threads),
            self_collision: self.self_collision.or(file.self_collision),
            obstacle_edges: self.obstacle_edges.or(file.obstacle_edges),
            cell_shear: self.cell_shear.or(file.cell_shear),
            hinges: self.hinges.or(file.hinges),
            max_time: self.max_time.or(file.max_time),
        }
    }

    /// Each value checked as the file's field it replaces (the command
    /// line's `--spacing`, `--dt`, `--duration`, `--cg-tolerance`; a
    /// trial's `--max-time` is checked as its `settle.max_time`).
    pub fn check(&self) -> Result<()> {
        if let Some(s) = self.spacing {
            limits::check_positive("--spacing", s, "m")?;
        }
        if let Some(dt) = self.dt {
            limits::check_dt("--dt", dt)?;
        }
        if let Some(d) = self.duration {
            limits::check_duration("--duration", d)?;
        }
        if let Some(t) = self.cg_tolerance {
            limits::check_cg_tolerance("--cg-tolerance", t)?;
        }
        Ok(())
    }

    /// The step's parameters: `base` (the file's) with each value given
    /// here in place of the file's.
    pub fn apply(&self, base: Params) -> Params {
        Params {
            dt: self.dt.unwrap_or(base.dt),
            linear_solver: self.solver.unwrap_or(base.linear_solver),
            hysteresis: self.hysteresis.unwrap_or(base.hysteresis),
            cg_tolerance: self.cg_tolerance.unwrap_or(base.cg_tolerance),
            threads: self.threads.unwrap_or(base.threads),
            self_collision: self.self_collision.unwrap_or(base.self_collision),
            obstacle_edges: self.obstacle_edges.unwrap_or(base.obstacle_edges),
            cell_shear: self.cell_shear.unwrap_or(base.cell_shear),
            ..base
        }
    }

    /// Refuses what a scene's drape cannot honour, naming the flag.
    pub fn check_for_scene(&self) -> Result<()> {
        if self.max_time.is_some() {
            bail!("--max-time: not for a scene (a scene runs for --duration)");
        }
        Ok(())
    }

    /// Refuses what a garment trial cannot honour, naming the flag.
    pub fn check_for_trial(&self) -> Result<()> {
        if self.duration.is_some() {
            bail!(
                "--duration: not for a trial (a trial drapes until it settles or for \
                 --max-time after sewing)"
            );
        }
        if self.hinges.is_some() {
            bail!("--hinges: not for a trial (its panels' hinges are the garment file's `hinges`)");
        }
        Ok(())
    }
}

/// Reads a scene or trial file (`what`, for the errors) whose settings are
/// an [`Overrides`] at its top level: each top-level key must be one of the
/// file's own (`own`) or a setting not `elsewhere` (a setting the file
/// takes in another place or not at all, with where it goes), so a
/// misspelt key is refused as serde's `deny_unknown_fields` would. Returns
/// the file's own fields (`T`, which skips its settings) and its settings,
/// each read from the text itself so that an error names its key, line and
/// column.
pub fn read_file<T: serde::de::DeserializeOwned>(
    text: &str,
    what: &str,
    own: &[&str],
    elsewhere: &[(&str, &str)],
) -> Result<(T, Overrides)> {
    use anyhow::Context;
    crate::io::check_yaml_shape(text).with_context(|| what.to_string())?;
    let doc: serde_yaml::Value =
        serde_yaml::from_str(text).with_context(|| format!("{what}: invalid YAML"))?;
    if let serde_yaml::Value::Mapping(m) = &doc {
        for k in m.keys() {
            let key = match k {
                serde_yaml::Value::String(s) => s.as_str(),
                other => bail!("{what}: key {other:?}: keys are names"),
            };
            if let Some((_, why)) = elsewhere.iter().find(|(e, _)| *e == key) {
                bail!("{what}: `{key}`: {why}");
            }
            if !own.contains(&key) && !Overrides::KEYS.contains(&key) {
                let mut known: Vec<&str> = own.to_vec();
                known.extend(
                    (Overrides::KEYS.iter()).filter(|k| !elsewhere.iter().any(|(e, _)| e == *k)),
                );
                let known: Vec<String> = known.iter().map(|k| format!("`{k}`")).collect();
                bail!(
                    "{what}: unknown field `{key}`, expected one of {}",
                    known.join(", ")
                );
            }
        }
    }
    let file: T = serde_yaml::from_str(text).with_context(|| format!("{what}: invalid field"))?;
    let settings: Overrides =
        serde_yaml::from_str(text).with_context(|| format!("{what}: invalid setting"))?;
    Ok((file, settings))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file with no fields of its own.
    #[derive(Debug, Deserialize)]
    struct Nothing {}

    #[test]
    fn a_bad_setting_is_named_with_its_line() {
        let e = read_file::<Nothing>("dt: 0.01\nthreads: many\n", "f.yaml", &[], &[]).unwrap_err();
        let m = format!("{e:#}");
        assert!(
            m.starts_with("f.yaml: invalid setting: threads: invalid"),
            "{m}"
        );
        assert!(m.contains("line 2"), "{m}");
    }

    /// `KEYS` names every field an `Overrides` reads: a file with all of
    /// them set reads back whole.
    #[test]
    fn the_keys_are_the_fields() {
        let all = Overrides {
            spacing: Some(0.01),
            dt: Some(0.002),
            duration: Some(1.0),
            solver: Some(LinearSolverKind::Pcg),
            hysteresis: Some(false),
            cg_tolerance: Some(1e-7),
            threads: Some(2),
            self_collision: Some(true),
            obstacle_edges: Some(true),
            cell_shear: Some(true),
            hinges: Some(HingesFile::MirrorSymmetric),
            max_time: Some(3.0),
        };
        let v = serde_yaml::to_value(&all).unwrap();
        let keys: Vec<String> = v
            .as_mapping()
            .unwrap()
            .keys()
            .map(|k| k.as_str().unwrap().to_string())
            .collect();
        assert_eq!(keys.len(), 12);
        for k in &keys {
            assert!(Overrides::KEYS.contains(&k.as_str()), "{k}");
        }
        let (_, back) =
            read_file::<Nothing>(&serde_yaml::to_string(&all).unwrap(), "f", &[], &[]).unwrap();
        assert_eq!(back, all);
        let (_, alias) = read_file::<Nothing>("linear_solver: sgs\n", "f", &[], &[]).unwrap();
        assert_eq!(alias.solver, Some(LinearSolverKind::Sgs));
    }

    #[test]
    fn a_file_key_is_its_own_a_setting_or_refused_by_name() {
        let e = read_file::<Nothing>("dt: 0.01\ncolour: red\n", "f.yaml", &[], &[]).unwrap_err();
        assert!(
            format!("{e:#}").contains("f.yaml: unknown field `colour`"),
            "{e:#}"
        );
        let e = read_file::<Nothing>(
            "max_time: 3\n",
            "f.yaml",
            &[],
            &[("max_time", "give settle.max_time")],
        )
        .unwrap_err();
        assert_eq!(format!("{e:#}"), "f.yaml: `max_time`: give settle.max_time");
        let cli = Overrides {
            dt: Some(0.001),
            ..Overrides::default()
        };
        let (_, file) = read_file::<Nothing>("dt: 0.01\nthreads: 2\n", "f", &[], &[]).unwrap();
        let both = cli.or(&file);
        assert_eq!(
            (both.dt, both.threads, both.spacing),
            (Some(0.001), Some(2), None)
        );
    }

    fn shipped(rel: &str) -> String {
        std::fs::read_to_string(format!("{}/{rel}", env!("CARGO_MANIFEST_DIR"))).unwrap()
    }

    /// The shipped files' settings are read as the command line's are, and
    /// a setting a file takes elsewhere is refused saying where.
    #[test]
    fn scene_and_trial_files_take_their_settings_as_overrides() {
        use crate::scene::{Scene, SceneFile};
        use crate::trial::TrialFile;
        let text = shipped("config/scenes/free_fall.yaml") + "threads: 1\nsolver: sgs\n";
        let f = SceneFile::parse(&text, "free_fall").unwrap();
        assert_eq!(
            (f.run.threads, f.run.solver),
            (Some(1), Some(LinearSolverKind::Sgs))
        );
        assert!(f.dt() > 0.0 && f.duration() > 0.0);
        let path = format!(
            "{}/config/scenes/free_fall.yaml",
            env!("CARGO_MANIFEST_DIR")
        );
        let sc = Scene::from_file(f, path.as_ref()).unwrap();
        let cli = Overrides {
            solver: Some(LinearSolverKind::Pcg),
            ..Overrides::default()
        };
        let sim = sc.build(&cli).unwrap();
        assert_eq!(sim.params().threads, 1);
        assert_eq!(sim.params().linear_solver, LinearSolverKind::Pcg);
        let e = SceneFile::parse(
            &(shipped("config/scenes/free_fall.yaml") + "spacing: 0.01\n"),
            "s",
        )
        .unwrap_err();
        assert_eq!(
            format!("{e:#}"),
            "s: `spacing`: a scene's grid spacing is `cloth.spacing`"
        );
        let no_dt: String = (shipped("config/scenes/free_fall.yaml").lines())
            .filter(|l| !l.starts_with("dt:"))
            .map(|l| format!("{l}\n"))
            .collect();
        let e = SceneFile::parse(&no_dt, "s").unwrap_err();
        assert_eq!(format!("{e:#}"), "s: dt: missing (the fixed time step, s)");
        let skirt = shipped("config/trials/skirt_on_anny.yaml");
        let t = TrialFile::parse(&(skirt.clone() + "linear_solver: sgs\n"), "t").unwrap();
        assert_eq!(t.run.solver, Some(LinearSolverKind::Sgs));
        assert_eq!(t.settings(&cli).solver, Some(LinearSolverKind::Pcg));
        for (key, says) in [
            ("max_time: 3", "`settle.max_time`"),
            ("duration: 3", "not for a trial"),
            ("hinges: skewed", "not for a trial"),
        ] {
            let e = TrialFile::parse(&format!("{skirt}{key}\n"), "t").unwrap_err();
            let m = format!("{e:#}");
            assert!(
                m.starts_with(&format!("t: `{}`", key.split(':').next().unwrap())),
                "{m}"
            );
            assert!(m.contains(says), "{m}");
        }
    }
}
