//! Test systems shared by the linear solvers' tests: random SPD block
//! matrices on a grid of vertices, as the assembly makes them.

use super::linear::Filter;
use super::sparse::BlockMatrix;
use nalgebra::{Matrix3, Vector3};

/// The springs of an `nx` × `ny` grid: each vertex to its right, upper
/// and diagonal neighbour.
pub(super) fn grid_edges(nx: usize, ny: usize) -> Vec<[usize; 2]> {
    let id = |i: usize, j: usize| j * nx + i;
    let mut edges = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            for (di, dj) in [(1, 0), (0, 1), (1, 1)] {
                if i + di < nx && j + dj < ny {
                    edges.push([id(i, j), id(i + di, j + dj)]);
                }
            }
        }
    }
    edges
}

/// An `nx` × `ny` grid of vertices with random PSD springs (xorshift from
/// `seed`) to their right, upper and diagonal neighbours plus a mass on the
/// diagonal: SPD, symmetric bit for bit; the matrix and the masses.
pub(super) fn spd_grid_sized(nx: usize, ny: usize, seed: u64) -> (BlockMatrix, Vec<f64>) {
    let edges = grid_edges(nx, ny);
    let n = nx * ny;
    let mut a = BlockMatrix::from_cliques(n, edges.iter().map(|e| e.as_slice()));
    let mut state = seed;
    let mut rnd = || {
        // xorshift, in [-1, 1)
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    };
    let mass: Vec<f64> = (0..n).map(|_| 1.0 + 0.5 * rnd()).collect();
    for i in 0..n {
        let d = a.diag[i];
        a.val[d] = Matrix3::identity() * mass[i];
    }
    for e in &edges {
        let b = Matrix3::from_fn(|_, _| rnd());
        let k = b * b.transpose() * 30.0;
        let k = (k + k.transpose()) * 0.5;
        let (ii, jj, ij, ji) = (
            a.diag[e[0]],
            a.diag[e[1]],
            a.index(e[0], e[1]),
            a.index(e[1], e[0]),
        );
        a.val[ii] += k;
        a.val[jj] += k;
        a.val[ij] -= k;
        a.val[ji] -= k.transpose();
    }
    (a, mass)
}

/// Every tenth vertex in contact along one normal, every tenth in a crease
/// (free along one axis only), every fifth pinned, the rest free; a
/// right-hand side, and prescribed parts z only in the constrained
/// directions.
#[allow(clippy::type_complexity)]
pub(super) fn mixed_constraints(n: usize) -> (Vec<Filter>, Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let nrm = Vector3::new(0.3, -0.2, 0.9).normalize();
    let axis = Vector3::new(-0.5, 0.8, 0.1).normalize();
    let filter: Vec<Filter> = (0..n)
        .map(|i| match i % 10 {
            1 => Filter::Normal(nrm),
            6 => Filter::Crease(axis),
            3 | 8 => Filter::Fixed,
            _ => Filter::Free,
        })
        .collect();
    let b: Vec<Vector3<f64>> = (0..n)
        .map(|i| Vector3::new((i as f64).sin(), (i as f64 * 0.7).cos(), 0.3))
        .collect();
    let z: Vec<Vector3<f64>> = (0..n)
        .map(|i| match filter[i] {
            Filter::Normal(m) => m * 0.05,
            Filter::Crease(a) => Vector3::new(0.02, 0.01, -0.04).cross(&a),
            Filter::Fixed => Vector3::new(0.01, -0.02, 0.03),
            Filter::Free => Vector3::zeros(),
        })
        .collect();
    (filter, b, z)
}
