//! The settings a run takes from outside its file: written once, flattened
//! into the command line's `drape` and `trial` arguments, read from a file
//! or a dict (serde) and built from the node's parameters; applied to the
//! step's [`Params`] in one place ([`Overrides::apply`]). SI units: m, s.

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
