//! One step's linear system written for solvers outside this program
//! (`garment_sim drape --write-system STEP`): the matrix and right-hand side
//! in Matrix Market (read by SciPy's `scipy.io.mmread`, MATLAB, Julia), the
//! constraint filter, first guess, answer, positions and masses per vertex
//! in CSV, and the step's figures in JSON. docs/benchmarks.md uses it to
//! measure other multigrid solvers on the drapes' own systems.

use crate::io::write_atomic;
use crate::solver::{Filter, LinearSystem, Simulation};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// `--write-system` of `drape` and `trial`: writes the systems a simulation
/// kept ([`Simulation::capture_systems`] with the same steps) into
/// `OUT/system-STEP/` after their steps. A system that cannot be written (a
/// full disk) is reported at once and fails the command at the end, after
/// the run and its own outputs.
pub struct SystemWriter {
    out: PathBuf,
    steps: Vec<u64>,
    written: Result<()>,
}

impl SystemWriter {
    /// For the steps `steps` (indices from 0), into `out`.
    pub fn new(out: &Path, steps: &[u64]) -> SystemWriter {
        SystemWriter {
            out: out.to_path_buf(),
            steps: steps.to_vec(),
            written: Ok(()),
        }
    }

    /// After each step: writes its system if it was one asked for (none
    /// after a failure).
    pub fn observe(&mut self, sim: &Simulation) {
        let Some(sys) = sim.captured_system() else {
            return;
        };
        if self.written.is_err() {
            return;
        }
        let dir = self.out.join(format!("system-{}", sys.step));
        self.written = write_system(&dir, sys);
        match &self.written {
            Ok(()) => eprintln!(
                "wrote system     {}/ (step {}, {} iterations)",
                dir.display(),
                sys.step,
                sys.iterations
            ),
            Err(e) => eprintln!("--write-system: {e:#}; the run goes on"),
        }
    }

    /// After a run of `taken` steps: names the steps it did not reach;
    /// the write's error, if one failed.
    pub fn finish(self, taken: u64) -> Result<()> {
        for k in self.steps.iter().filter(|&&k| k >= taken) {
            eprintln!("--write-system: step {k} not reached (the run took {taken} steps, from 0)");
        }
        self.written
    }
}

/// Writes `s` into the directory `dir` (created if missing): `A.mtx`,
/// `b.mtx`, `vertices.csv` and `system.json` (see the module's text). Row
/// and column `3i + c` of the matrix are vertex i's coordinate c (x, y, z).
pub fn write_system(dir: &Path, s: &LinearSystem) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create directory {}", dir.display()))?;
    let n = s.a.n;
    let dim = 3 * n;
    // the matrix: every entry of every stored block (zeros too: the pattern)
    write_atomic(&dir.join("A.mtx"), |w| {
        writeln!(w, "%%MatrixMarket matrix coordinate real general")?;
        writeln!(
            w,
            "% garment_sim: the implicit step's matrix A (kg) of step {} (t = {} s, dt = {} s)",
            s.step, s.time, s.dt
        )?;
        writeln!(w, "{dim} {dim} {}", 9 * s.a.col.len())?;
        for i in 0..n {
            for q in s.a.row_ptr[i]..s.a.row_ptr[i + 1] {
                let j = s.a.col[q] as usize;
                let blk = &s.a.val[q];
                for r in 0..3 {
                    for c in 0..3 {
                        writeln!(w, "{} {} {:e}", 3 * i + r + 1, 3 * j + c + 1, blk[(r, c)])?;
                    }
                }
            }
        }
        Ok(())
    })?;
    write_atomic(&dir.join("b.mtx"), |w| {
        writeln!(w, "%%MatrixMarket matrix array real general")?;
        writeln!(
            w,
            "% garment_sim: the implicit step's right-hand side b (N s) of step {}",
            s.step
        )?;
        writeln!(w, "{dim} 1")?;
        for v in &s.b {
            for c in 0..3 {
                writeln!(w, "{:e}", v[c])?;
            }
        }
        Ok(())
    })?;
    write_atomic(&dir.join("vertices.csv"), |w| {
        writeln!(
            w,
            "vertex,filter,normal_x,normal_y,normal_z,z_x,z_y,z_z,guess_x,guess_y,guess_z,\
             dv_x,dv_y,dv_z,x,y,z,mass_kg"
        )?;
        for i in 0..n {
            let (kind, nrm) = match s.filter[i] {
                Filter::Free => ("free", [0.0; 3]),
                Filter::Normal(m) => ("normal", [m.x, m.y, m.z]),
                Filter::Crease(a) => ("crease", [a.x, a.y, a.z]),
                Filter::Fixed => ("fixed", [0.0; 3]),
            };
            write!(w, "{i},{kind}")?;
            for v in [
                nrm,
                s.z[i].into(),
                s.guess[i].into(),
                s.dv[i].into(),
                s.x[i].into(),
            ] {
                for c in v {
                    write!(w, ",{c:e}")?;
                }
            }
            writeln!(w, ",{:e}", s.mass[i])?;
        }
        Ok(())
    })?;
    let meta = serde_json::json!({
        "step": s.step,
        "time_s": s.time,
        "dt_s": s.dt,
        "gravity_m_s2": [s.gravity.x, s.gravity.y, s.gravity.z],
        "tolerance": s.tolerance,
        "solved_by": s.solved_by,
        "iterations": s.iterations,
        "vertices": n,
        "blocks": s.a.col.len(),
        "files": {
            "A.mtx": "the system matrix A (kg), 3n x 3n; row and column 3i + c are vertex i's coordinate c",
            "b.mtx": "the right-hand side b (N s)",
            "vertices.csv": "per vertex: the filter (free; normal: the velocity change along normal is prescribed; crease: all of it but along the crease's axis, given in the normal columns; fixed: all of it), z the prescribed part (m/s), the solve's first guess and answer dv (m/s), position (m), mass (kg)",
        },
        "system": "A dv = b for the free directions (S (A dv - b) = 0), dv = S dv + z; S is I (free), I - n n^T (normal), a a^T (crease, a its axis) or 0 (fixed)",
        "stopping_test": "the filtered residual r = S (b - A dv) in the norm of the inverse 3x3 diagonal blocks D of A: r^T D^-1 r <= tolerance^2 max((S b)^T D^-1 (S b), (S w)^T D^-1 (S w)), w_i = m_i g dt",
    });
    let text = serde_json::to_string_pretty(&meta)? + "\n";
    write_atomic(&dir.join("system.json"), |w| w.write_all(text.as_bytes()))?;
    Ok(())
}
