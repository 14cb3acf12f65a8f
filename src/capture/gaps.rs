//! Gap filling: the missing markers of the fabric's grid (thesis §5.3, Algorithm 1).

use super::{Capture, CaptureError};
use nalgebra::Vector3;

/// Layout of the fabric's marker grid: grid node (i, j), `i` along the warp
/// (0..nx) and `j` along the weft (0..ny), is marker `index[i * ny + j]` of the capture.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GridMap {
    pub nx: usize,
    pub ny: usize,
    pub index: Vec<usize>,
}

impl GridMap {
    /// Marker index = i * ny + j.
    pub fn row_major(nx: usize, ny: usize) -> Self {
        GridMap {
            nx,
            ny,
            index: (0..nx * ny).collect(),
        }
    }

    /// Checks the map against a capture with `n_markers` markers: `index` has nx × ny
    /// distinct entries, all valid marker indices.
    pub fn check(&self, n_markers: usize) -> Result<(), CaptureError> {
        let cells = self.nx.checked_mul(self.ny).ok_or_else(|| {
            CaptureError::Invalid(format!("grid {} × {} overflows", self.nx, self.ny))
        })?;
        if self.index.len() != cells {
            return Err(CaptureError::Invalid(format!(
                "grid {} × {} needs {cells} marker indices, got {}",
                self.nx,
                self.ny,
                self.index.len()
            )));
        }
        let mut seen = vec![false; n_markers];
        for (g, &m) in self.index.iter().enumerate() {
            let s = seen.get_mut(m).ok_or_else(|| {
                CaptureError::Invalid(format!(
                    "grid node ({}, {}) maps to marker {m} but the capture has {n_markers} markers",
                    g / self.ny,
                    g % self.ny
                ))
            })?;
            if *s {
                return Err(CaptureError::Invalid(format!(
                    "marker {m} appears twice in the grid map"
                )));
            }
            *s = true;
        }
        Ok(())
    }
}

/// Outcome of [`fill_gaps`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FillReport {
    /// Marker positions filled (over all frames).
    pub filled: usize,
    /// Sweeps of Algorithm 1 performed (0 when nothing was missing).
    pub sweeps: usize,
}

/// Fills the missing grid markers of a capture, thesis §5.3 / Algorithm 1.
///
/// Each missing marker P(i, j) in frame f is set to the mean of every estimate that
/// applies (each estimate counts once, as in Algorithm 1):
///
/// 1. **neighbours** (fig. 5.6): the barycentre of the warp pair P(i±1, j) and/or the
///    weft pair P(i, j±1) — a pair is used only when both of its points are present;
/// 2. **symmetry** (fig. 5.8): for each diagonal neighbour D = P(i+a, j+b) (a, b = ±1)
///    whose two sides A = P(i+a, j) and B = P(i, j+b) are present, the image of D
///    through the midpoint of AB, i.e. A + B − D (parallelogram rule); the estimate is
///    the mean of the available images;
/// 3. **frames** (fig. 5.9): the midpoint of the same marker in frames f−1 and f+1, when
///    both are present;
/// 4. **corner extrapolation** (fig. 5.7), for the four corners: the image of the second
///    neighbour along the warp (and/or weft) through the first, 2 P₁ − P₂; the mean of
///    the available directions.
///
/// Repeated sweeps fill the markers that had no estimate in earlier sweeps. Two
/// documented departures from the thesis' pseudo-code:
/// * estimates in a sweep use only the positions known at the start of that sweep
///   (Jacobi-style), so the result does not depend on the order of the markers; the
///   thesis writes each filled value immediately;
/// * a non-corner marker with no estimate at all (e.g. an edge marker whose edge
///   neighbour is missing too and which is missing in adjacent frames) falls back to
///   the extrapolation 2 P₁ − P₂ along any grid direction where it is possible, so
///   that the sweeps do not stall on such cases.
///
/// Markers that are not in the grid are left untouched. Returns an error if a sweep
/// fills nothing while grid markers are still missing (e.g. a whole frame missing at
/// the start or end of the capture).
pub fn fill_gaps(cap: &mut Capture, grid: &GridMap) -> Result<FillReport, CaptureError> {
    let nm = cap.labels.len();
    grid.check(nm)?;
    if let Some((f, fr)) = cap.frames.iter().enumerate().find(|(_, fr)| fr.len() != nm) {
        return Err(CaptureError::Invalid(format!(
            "frame index {f} has {} markers but there are {nm} labels",
            fr.len()
        )));
    }
    let (nx, ny) = (grid.nx as isize, grid.ny as isize);
    let mut report = FillReport {
        filled: 0,
        sweeps: 0,
    };
    loop {
        let missing: Vec<(usize, usize)> = (0..cap.frames.len())
            .flat_map(|f| (0..grid.index.len()).map(move |g| (f, g)))
            .filter(|&(f, g)| cap.frames[f][grid.index[g]].is_none())
            .collect();
        if missing.is_empty() {
            return Ok(report);
        }
        report.sweeps += 1;
        let frames = &cap.frames;
        let get = |f: usize, i: isize, j: isize| -> Option<Vector3<f64>> {
            if i < 0 || j < 0 || i >= nx || j >= ny {
                return None;
            }
            frames
                .get(f)
                .and_then(|fr| fr[grid.index[(i * ny + j) as usize]])
        };
        let mut updates = Vec::new();
        for &(f, g) in &missing {
            let (i, j) = ((g / grid.ny) as isize, (g % grid.ny) as isize);
            let mut acc = (Vector3::zeros(), 0usize);
            let add = |acc: &mut (Vector3<f64>, usize), est: Option<Vector3<f64>>| {
                if let Some(e) = est {
                    acc.0 += e;
                    acc.1 += 1;
                }
            };
            // 1. Barycentre of the complete warp / weft neighbour pairs.
            let mut nb = Vec::with_capacity(4);
            for (a, b) in [((i - 1, j), (i + 1, j)), ((i, j - 1), (i, j + 1))] {
                if let (Some(p), Some(q)) = (get(f, a.0, a.1), get(f, b.0, b.1)) {
                    nb.push(p);
                    nb.push(q);
                }
            }
            add(&mut acc, mean(&nb));
            // 2. Symmetric images of the diagonal neighbours.
            let mut sym = Vec::with_capacity(4);
            for (a, b) in [(-1, -1), (-1, 1), (1, -1), (1, 1)] {
                if let (Some(d), Some(pa), Some(pb)) =
                    (get(f, i + a, j + b), get(f, i + a, j), get(f, i, j + b))
                {
                    sym.push(pa + pb - d);
                }
            }
            add(&mut acc, mean(&sym));
            // 3. Same marker in the previous and next frames.
            if f > 0 {
                if let (Some(p), Some(q)) = (get(f - 1, i, j), get(f + 1, i, j)) {
                    add(&mut acc, Some((p + q) * 0.5));
                }
            }
            // 4. Corner extrapolation (fallback for other markers with no estimate).
            let corner = (i == 0 || i == nx - 1) && (j == 0 || j == ny - 1);
            if corner || acc.1 == 0 {
                let mut ext = Vec::with_capacity(4);
                for (a, b) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
                    if let (Some(p1), Some(p2)) =
                        (get(f, i + a, j + b), get(f, i + 2 * a, j + 2 * b))
                    {
                        ext.push(2.0 * p1 - p2);
                    }
                }
                add(&mut acc, mean(&ext));
            }
            if acc.1 > 0 {
                updates.push((f, grid.index[g], acc.0 / acc.1 as f64));
            }
        }
        if updates.is_empty() {
            let (f, g) = missing[0];
            return Err(CaptureError::GapFill(format!(
                "sweep {}: none of the {} missing grid markers has an applicable estimate \
                 (first: frame {} (index {f}), marker '{}' at grid node ({}, {}))",
                report.sweeps,
                missing.len(),
                u64::from(cap.first_frame) + f as u64,
                cap.labels[grid.index[g]],
                g / grid.ny,
                g % grid.ny
            )));
        }
        report.filled += updates.len();
        for (f, m, p) in updates {
            cap.frames[f][m] = Some(p);
        }
    }
}

fn mean(v: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    (!v.is_empty()).then(|| v.iter().sum::<Vector3<f64>>() / v.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::test_support::Lcg;
    use nalgebra::Matrix3;

    /// Smooth falling, deforming sheet on an 11 × 11 grid at 5 cm (the thesis sample).
    fn sheet(nframes: usize) -> Capture {
        let (nx, ny, h) = (11usize, 11usize, 0.05);
        let dt = 1.0 / 120.0;
        let frames = (0..nframes)
            .map(|f| {
                let t = f as f64 * dt;
                let amp = 0.05 * (1.0 + 2.0 * t);
                (0..nx * ny)
                    .map(|g| {
                        let (x, y) = ((g / ny) as f64 * h, (g % ny) as f64 * h);
                        Some(Vector3::new(
                            x + 0.3 * t,
                            y - 0.1 * t,
                            1.5 + amp * (x / 0.2).sin() * (y / 0.3).cos() - 0.5 * 9.81 * t * t,
                        ))
                    })
                    .collect()
            })
            .collect();
        Capture {
            labels: (0..nx * ny).map(|g| format!("M{g}")).collect(),
            rate_hz: 120.0,
            units: "m".into(),
            first_frame: 1,
            frames,
        }
    }

    /// Algorithm 1 on the sheet z = A(t) sin(x/0.2) cos(y/0.3) (A = 5 cm × (1 + 2 t/s),
    /// falling under gravity and drifting sideways), 11 × 11 markers at 5 cm, 8 frames
    /// at 120 Hz, about 10 % of the markers removed at random plus all four corners in
    /// one frame, a 3 × 3 hole, and a marker missing in three consecutive frames.
    ///
    /// Measured: 105 positions removed, filled in 2 sweeps, RMS error 0.48 mm, max
    /// 2.23 mm (a marker on the rim of the 3 × 3 hole that also lacks a neighbouring
    /// frame, so its first-sweep estimate is an extrapolation); only 3 errors exceed
    /// 1 mm. Asserted: RMS < 1 mm and max < 3 mm.
    #[test]
    fn gap_fill_smooth_sheet() {
        let truth = sheet(8);
        let mut cap = truth.clone();
        let mut rng = Lcg(2024);
        let mut removed = Vec::new();
        for f in 0..8 {
            for g in 0..121 {
                if rng.below(10) == 0 {
                    removed.push((f, g));
                }
            }
        }
        for g in [0, 10, 110, 120] {
            removed.push((3, g)); // all corners in one frame
        }
        for i in 4..7 {
            for j in 4..7 {
                removed.push((5, i * 11 + j)); // 3 × 3 hole
            }
        }
        for f in 1..4 {
            removed.push((f, 2 * 11 + 7)); // same marker in three consecutive frames
        }
        removed.sort();
        removed.dedup();
        for &(f, g) in &removed {
            cap.frames[f][g] = None;
        }
        let rep = fill_gaps(&mut cap, &GridMap::row_major(11, 11)).unwrap();
        assert_eq!(rep.filled, removed.len());
        assert!(rep.sweeps >= 2);
        assert_eq!(cap.n_missing(), 0);
        let errs: Vec<f64> = removed
            .iter()
            .map(|&(f, g)| (cap.frames[f][g].unwrap() - truth.frames[f][g].unwrap()).norm())
            .collect();
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
        let max = errs.iter().cloned().fold(0.0, f64::max);
        eprintln!(
            "gap fill: {} removed, {} sweeps, RMS {:.3} mm, max {:.3} mm",
            removed.len(),
            rep.sweeps,
            rms * 1e3,
            max * 1e3
        );
        assert!(removed.len() > 90);
        assert!(rms < 1.0e-3, "RMS {rms}");
        assert!(max < 3.0e-3, "max {max}");
    }

    /// On an affinely deformed, uniformly moving grid every estimate is exact.
    #[test]
    fn gap_fill_exact_on_affine_grid() {
        let (nx, ny) = (4usize, 6usize);
        // Non-row-major map: node (i, j) is marker j * nx + i.
        let index: Vec<usize> = (0..nx * ny).map(|g| (g % ny) * nx + g / ny).collect();
        let grid = GridMap { nx, ny, index };
        let a = Matrix3::new(0.9, 0.2, 0.0, -0.1, 1.1, 0.0, 0.3, -0.2, 1.0);
        let mk = |f: usize, m: usize| {
            let (i, j) = ((m % nx) as f64, (m / nx) as f64);
            a * Vector3::new(0.05 * i, 0.05 * j, 0.0) + Vector3::new(0.0, 0.0, 0.01 * f as f64)
        };
        let truth: Vec<Vec<Option<Vector3<f64>>>> = (0..3)
            .map(|f| (0..nx * ny).map(|m| Some(mk(f, m))).collect())
            .collect();
        let mut cap = Capture {
            labels: (0..nx * ny).map(|m| m.to_string()).collect(),
            rate_hz: 100.0,
            units: "m".into(),
            first_frame: 1,
            frames: truth.clone(),
        };
        for m in [0, 3, 5, 10, 23, 20] {
            cap.frames[1][m] = None;
        }
        cap.frames[0][7] = None;
        let rep = fill_gaps(&mut cap, &grid).unwrap();
        assert_eq!(rep.filled, 7);
        for (fa, fb) in cap.frames.iter().zip(&truth) {
            for (p, q) in fa.iter().zip(fb) {
                assert!((p.unwrap() - q.unwrap()).norm() < 1e-14);
            }
        }
    }

    #[test]
    fn gap_fill_stalls_with_error() {
        let mut cap = sheet(2);
        for p in cap.frames[0].iter_mut() {
            *p = None;
        }
        let e = fill_gaps(&mut cap, &GridMap::row_major(11, 11)).unwrap_err();
        assert!(e.to_string().contains("121 missing"), "{e}");
        let e = fill_gaps(&mut cap, &GridMap::row_major(11, 12)).unwrap_err();
        assert!(matches!(e, CaptureError::Invalid(_)));
    }
}
