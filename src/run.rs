//! The run interface. Every run of the library steps its simulation through
//! a [`Run`]: a scene's drape ([`crate::scene::run`]), a garment trial and
//! each of its phases, the dressing among them ([`crate::trial::run`]),
//! `bench`, and the ROS 2 node. A [`Run`] keeps the run's costs ([`Spent`])
//! and names a step that fails ([`StepFailed`]); a run that goes on by itself
//! shows each step to one observer ([`Observe`]) that can stop it.

use crate::solver::{Simulation, SolvedBy, StepStats};
use anyhow::Result;
use serde::Serialize;
use std::time::Instant;

/// The phases a run goes through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// A trial's first phase: gravity off, the seams pull the panels
    /// together on the body.
    Sewing,
    /// Gravity on until the cloth settles: a trial's drape after sewing
    /// (until `settle.max_time`), or a scene's whole run (its `duration`).
    Drape,
    /// A trial's body with a `motion` plays it.
    Motion,
    /// A trial's gripper pulls a sleeve over the arm.
    Dressing,
}

impl Phase {
    /// The phase's name as the progress lines and `fit.json` say it.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Sewing => "sewing",
            Phase::Drape => "drape",
            Phase::Motion => "motion",
            Phase::Dressing => "dressing",
        }
    }
}

/// What an observer sees: the state as it is, the phase, and how far the
/// phase has gone (`done` of `of`, simulated seconds; `of` is the phase's
/// longest duration).
pub struct Step<'a> {
    pub sim: &'a Simulation,
    pub phase: Phase,
    pub done: f64,
    pub of: f64,
}

/// What an observer tells the run to do next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    Continue,
    /// End the run before the next step (its outcome covers the steps
    /// taken).
    Stop,
}

/// Called after each step of a run, in every phase (a scene's drape also
/// shows it the state before its first step, for a recording's first
/// frame); [`Control::Stop`] ends the run. An observer's error (a recording
/// that cannot be written) ends the run as an error.
pub type Observe<'a> = &'a mut dyn FnMut(&Step) -> Result<Control>;

/// An observer that lets the run go to its end.
pub fn run_on(_: &Step) -> Result<Control> {
    Ok(Control::Continue)
}

/// A step that failed: the run's step number (from 1), the simulated time
/// it started from (a failed step changes nothing) and the solver's error.
#[derive(Debug, Clone, PartialEq)]
pub struct StepFailed {
    pub step: u64,
    pub time: f64,
    pub error: String,
}

impl std::fmt::Display for StepFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "step {} (t = {:.4} s): {}",
            self.step, self.time, self.error
        )
    }
}

impl std::error::Error for StepFailed {}

/// Wall-clock time of the step's parts, s (summed) or ms per step.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct TimeSplit {
    pub assemble: f64,
    pub solve: f64,
    pub collide: f64,
}

/// Steps by the linear solve that gave their answer.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct SolvedSteps {
    /// The block-Jacobi PCG.
    pub pcg: u64,
    /// The PCG preconditioned by symmetric block Gauss–Seidel (`sgs`).
    pub sgs: u64,
    /// The multigrid PCG.
    pub amg: u64,
    /// The Cholesky factor.
    pub cholesky: u64,
}

impl SolvedSteps {
    fn count(&mut self, by: SolvedBy) {
        match by {
            SolvedBy::Pcg => self.pcg += 1,
            SolvedBy::Sgs => self.sgs += 1,
            SolvedBy::Amg => self.amg += 1,
            SolvedBy::Cholesky => self.cholesky += 1,
        }
    }
}

/// What the steps of a run cost, summed over them.
#[derive(Debug, Clone, Copy, Default)]
pub struct Spent {
    /// The steps' parts, s.
    pub split: TimeSplit,
    /// The whole steps, s (the step's own timer).
    pub total_s: f64,
    /// Linear-solver iterations, and the most in one step.
    pub iterations: usize,
    pub max_iterations: usize,
    pub solved_by: SolvedSteps,
    /// The self-collision pass: its time (s), its contacts summed over the
    /// steps and the most in one step, the collisions and impact zones.
    pub self_s: f64,
    pub self_contacts: usize,
    pub self_max_contacts: usize,
    pub self_collisions: usize,
    pub self_zones: usize,
}

impl Spent {
    fn add(&mut self, st: &StepStats) {
        self.split.assemble += st.assemble_s;
        self.split.solve += st.solve_s;
        self.split.collide += st.collide_s;
        self.total_s += st.total_s;
        self.iterations += st.iterations;
        self.max_iterations = self.max_iterations.max(st.iterations);
        self.solved_by.count(st.solved_by);
        self.self_s += st.self_s;
        self.self_contacts += st.self_contacts;
        self.self_max_contacts = self.self_max_contacts.max(st.self_contacts);
        self.self_collisions += st.self_collisions;
        self.self_zones += st.self_zones;
    }

    /// What was spent after `before` (`max_iterations` is the run's).
    pub fn since(&self, before: &Spent) -> Spent {
        let s = &before.solved_by;
        Spent {
            split: TimeSplit {
                assemble: self.split.assemble - before.split.assemble,
                solve: self.split.solve - before.split.solve,
                collide: self.split.collide - before.split.collide,
            },
            total_s: self.total_s - before.total_s,
            iterations: self.iterations - before.iterations,
            max_iterations: self.max_iterations,
            solved_by: SolvedSteps {
                pcg: self.solved_by.pcg - s.pcg,
                sgs: self.solved_by.sgs - s.sgs,
                amg: self.solved_by.amg - s.amg,
                cholesky: self.solved_by.cholesky - s.cholesky,
            },
            self_s: self.self_s - before.self_s,
            self_contacts: self.self_contacts - before.self_contacts,
            self_max_contacts: self.self_max_contacts,
            self_collisions: self.self_collisions - before.self_collisions,
            self_zones: self.self_zones - before.self_zones,
        }
    }

    /// The split in ms per step over `steps` steps.
    pub fn split_ms_per_step(&self, steps: u64) -> TimeSplit {
        let n = steps.max(1) as f64;
        TimeSplit {
            assemble: 1e3 * self.split.assemble / n,
            solve: 1e3 * self.split.solve / n,
            collide: 1e3 * self.split.collide / n,
        }
    }
}

/// A run's steps: each one taken through [`Run::step`], which adds its cost
/// to [`Run::spent`] and counts it.
#[derive(Debug, Clone)]
pub struct Run {
    start: Instant,
    /// The steps that succeeded.
    pub steps: u64,
    pub spent: Spent,
}

impl Default for Run {
    fn default() -> Run {
        Run::new()
    }
}

impl Run {
    /// A run starting now (its wall clock too).
    pub fn new() -> Run {
        Run {
            start: Instant::now(),
            steps: 0,
            spent: Spent::default(),
        }
    }

    /// One step of `sim`. A step that fails changes nothing and is named
    /// with the run's step number and time.
    pub fn step(&mut self, sim: &mut Simulation) -> Result<StepStats, StepFailed> {
        match sim.step() {
            Ok(st) => {
                self.steps += 1;
                self.spent.add(&st);
                Ok(st)
            }
            Err(e) => Err(StepFailed {
                step: self.steps + 1,
                time: sim.time,
                error: format!("{e:#}"),
            }),
        }
    }

    /// Wall-clock seconds since the run started.
    pub fn wall_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Overrides, Scene};

    /// The shipped free fall at 5 cm.
    fn square() -> Simulation {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenes/free_fall.yaml");
        let ov = Overrides {
            spacing: Some(0.05),
            threads: Some(1),
            ..Overrides::default()
        };
        Scene::load(path.as_ref()).unwrap().build(&ov).unwrap()
    }

    #[test]
    fn a_run_counts_its_steps_and_sums_their_own_costs() {
        let mut sim = square();
        let mut run = Run::new();
        let mut total = 0.0;
        let mut iters = 0;
        for k in 1..=3 {
            let st = run.step(&mut sim).unwrap();
            total += st.total_s;
            iters += st.iterations;
            assert_eq!(run.steps, k);
        }
        assert_eq!(run.spent.total_s, total);
        assert_eq!(run.spent.iterations, iters);
        let by = run.spent.solved_by;
        assert_eq!(by.pcg + by.sgs + by.amg + by.cholesky, 3);
        let later = run.spent;
        run.step(&mut sim).unwrap();
        let last = run.spent.since(&later);
        assert!(last.total_s > 0.0 && last.total_s < run.spent.total_s);
    }

    #[test]
    fn a_failed_step_is_named_with_its_number_and_time_and_changes_nothing() {
        let mut sim = square();
        let mut run = Run::new();
        run.step(&mut sim).unwrap();
        let (t, x) = (sim.time, sim.cloth.positions().to_vec());
        // a velocity that overflows the first position it moves
        let mut v = sim.cloth.velocities().to_vec();
        v[3].z = 1e308;
        sim.cloth.set_velocities(&v).unwrap();
        let e = run.step(&mut sim).unwrap_err();
        assert_eq!((e.step, e.time), (2, t));
        assert!(e
            .to_string()
            .starts_with(&format!("step 2 (t = {t:.4} s): ")));
        assert_eq!(run.steps, 1);
        assert_eq!(sim.time, t);
        assert_eq!(sim.cloth.positions(), &x[..]);
    }
}
