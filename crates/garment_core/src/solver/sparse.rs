//! Block-sparse symmetric matrix with 3 × 3 blocks, pattern built once from the
//! springs and hinges and reused every step (faer's habit: symbolic once,
//! numeric every time).

use nalgebra::{Matrix3, Vector3};

/// Block compressed rows, both triangles stored (for fast products).
#[derive(Debug, Clone)]
pub struct BlockMatrix {
    /// Block rows (vertices).
    pub n: usize,
    /// Row i's blocks are `row_ptr[i]..row_ptr[i + 1]`.
    pub row_ptr: Vec<usize>,
    /// Column of each block (32-bit: the products read 4 bytes less per
    /// 72-byte block than with `usize`).
    pub col: Vec<u32>,
    /// The blocks.
    pub val: Vec<Matrix3<f64>>,
    /// Index of the diagonal block of each row.
    pub diag: Vec<usize>,
    /// The pattern's two triangles ([`BlockMatrix::triangles`]), made the
    /// first time they are asked for (the pattern does not change after
    /// construction).
    pub(super) triangles: std::sync::OnceLock<Triangles>,
}

/// Where the blocks below and above the diagonal of each row go in compact
/// copies of the two triangles, and their columns: row i's lower blocks at
/// `lptr[i]..lptr[i + 1]`, its upper ones at `uptr[i]..uptr[i + 1]`.
#[derive(Debug, Clone)]
pub(crate) struct Triangles {
    pub lptr: Vec<u32>,
    pub uptr: Vec<u32>,
    pub lcol: Vec<u32>,
    pub ucol: Vec<u32>,
}

impl BlockMatrix {
    /// Pattern from a list of vertex sets that interact (each set is fully coupled).
    pub fn from_cliques<'a>(n: usize, cliques: impl Iterator<Item = &'a [usize]>) -> BlockMatrix {
        // the cloth builder refuses grids above `cloth::MAX_VERTICES`
        assert!(u32::try_from(n).is_ok(), "{n} vertices: columns are 32-bit");
        let mut adj: Vec<Vec<usize>> = (0..n).map(|i| vec![i]).collect();
        for c in cliques {
            for &a in c {
                for &b in c {
                    adj[a].push(b);
                }
            }
        }
        let mut row_ptr = Vec::with_capacity(n + 1);
        let mut col = Vec::new();
        let mut diag = Vec::with_capacity(n);
        row_ptr.push(0);
        for (i, a) in adj.iter_mut().enumerate() {
            a.sort_unstable();
            a.dedup();
            for &j in a.iter() {
                if j == i {
                    diag.push(col.len());
                }
                col.push(j as u32);
            }
            row_ptr.push(col.len());
        }
        let nnz = col.len();
        BlockMatrix {
            n,
            row_ptr,
            col,
            val: vec![Matrix3::zeros(); nnz],
            diag,
            triangles: Default::default(),
        }
    }

    /// The pattern's lower and upper triangles, row by row ([`Triangles`]),
    /// built once.
    pub(crate) fn triangles(&self) -> &Triangles {
        self.triangles.get_or_init(|| {
            let (rp, diag) = (&self.row_ptr, &self.diag);
            let mut t = Triangles {
                lptr: Vec::with_capacity(self.n + 1),
                uptr: Vec::with_capacity(self.n + 1),
                lcol: Vec::new(),
                ucol: Vec::new(),
            };
            for i in 0..self.n {
                t.lptr.push(t.lcol.len() as u32);
                t.uptr.push(t.ucol.len() as u32);
                t.lcol.extend_from_slice(&self.col[rp[i]..diag[i]]);
                t.ucol.extend_from_slice(&self.col[diag[i] + 1..rp[i + 1]]);
            }
            t.lptr.push(t.lcol.len() as u32);
            t.uptr.push(t.ucol.len() as u32);
            t
        })
    }

    /// Position of block (i, j); panics if not in the pattern (a bug).
    pub fn index(&self, i: usize, j: usize) -> usize {
        let r = &self.col[self.row_ptr[i]..self.row_ptr[i + 1]];
        self.row_ptr[i]
            + r.binary_search(&(j as u32))
                .unwrap_or_else(|_| panic!("block ({i},{j}) not in pattern"))
    }

    /// Sets every block to zero (the pattern kept).
    pub fn clear(&mut self) {
        for v in self.val.iter_mut() {
            *v = Matrix3::zeros();
        }
    }

    /// y = A x
    pub fn mul(&self, x: &[Vector3<f64>], y: &mut [Vector3<f64>]) {
        for (i, yi) in y.iter_mut().enumerate() {
            let mut s = Vector3::zeros();
            for k in self.row_ptr[i]..self.row_ptr[i + 1] {
                s += self.val[k] * x[self.col[k] as usize];
            }
            *yi = s;
        }
    }

    /// The blocks' values as one flat array (each block column-major).
    pub fn flat(&self) -> &[f64] {
        const _: () = assert!(std::mem::size_of::<Matrix3<f64>>() == 9 * 8);
        // SAFETY: Matrix3<f64> is nine contiguous f64 (nalgebra's
        // column-major ArrayStorage, repr(C)), so the Vec is 9·len of them
        unsafe { std::slice::from_raw_parts(self.val.as_ptr() as *const f64, 9 * self.val.len()) }
    }

    /// Number of stored blocks.
    pub fn nnz_blocks(&self) -> usize {
        self.col.len()
    }
}

/// Scalar lower-triangular CSC structure of a [`BlockMatrix`], with the map
/// from each block entry to its CSC position: filled every step without
/// reallocation.
#[derive(Debug, Clone)]
pub(crate) struct LowerCsc {
    pub dim: usize,
    pub col_ptr: Vec<usize>,
    pub row_idx: Vec<usize>,
    pub values: Vec<f64>,
    /// The blocks with entries in the lower triangle (storage order), and
    /// for each the positions of its nine entries (column-major) among the
    /// values; an entry not in the lower triangle points at the spare value
    /// after the last (`values` has one more than the pattern), so the fill
    /// writes all nine without a test.
    pub stored: Vec<u32>,
    pub entries: Vec<[u32; 9]>,
}

impl LowerCsc {
    /// The lower triangle of `Pᵀ A P` for the vertex ordering `perm` (new
    /// vertex → old vertex), each vertex's three unknowns kept together.
    ///
    /// Fails when the matrix has more entries than 32-bit positions address
    /// (about 4.7e8 blocks).
    pub fn new_permuted(a: &BlockMatrix, perm: &[usize]) -> crate::Result<LowerCsc> {
        let dim = 3 * a.n;
        if 9 * a.val.len() + 1 >= u32::MAX as usize {
            return Err(crate::Error::factorization(format!(
                "the system matrix has {} blocks: too many for the direct solver (at most {})",
                a.val.len(),
                u32::MAX / 9
            )));
        }
        let mut inv = vec![0; a.n];
        for (new, &old) in perm.iter().enumerate() {
            inv[old] = new;
        }
        let mut col_ptr = Vec::with_capacity(dim + 1);
        let mut row_idx = Vec::new();
        let mut entries = vec![[u32::MAX; 9]; a.val.len()];
        let mut stored = Vec::new();
        col_ptr.push(0);
        let mut below: Vec<(usize, usize)> = Vec::new();
        // A is symmetric: column j of the lower triangle = row j entries with i ≥ j.
        for (nj, &j) in perm.iter().enumerate() {
            below.clear();
            for k in a.row_ptr[j]..a.row_ptr[j + 1] {
                let i = a.col[k] as usize;
                if inv[i] >= nj {
                    below.push((inv[i], a.index(i, j)));
                }
            }
            below.sort_unstable();
            for q in 0..3 {
                for &(ni, blk) in &below {
                    for p in 0..3 {
                        let r = 3 * ni + p;
                        if r >= 3 * nj + q {
                            entries[blk][3 * q + p] = row_idx.len() as u32;
                            row_idx.push(r);
                        }
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        let nnz = row_idx.len();
        for (blk, e) in entries.iter_mut().enumerate() {
            if e.iter().any(|&k| k != u32::MAX) {
                stored.push(blk as u32);
            }
            for k in e.iter_mut().filter(|k| **k == u32::MAX) {
                *k = nnz as u32;
            }
        }
        Ok(LowerCsc {
            dim,
            col_ptr,
            row_idx,
            values: vec![0.0; nnz + 1],
            stored,
            entries,
        })
    }

    /// Column pointers and row indices of the transpose (the upper triangle).
    pub fn transposed_pattern(&self) -> (Vec<usize>, Vec<usize>) {
        let mut count = vec![0usize; self.dim + 1];
        for &r in &self.row_idx {
            count[r + 1] += 1;
        }
        for k in 0..self.dim {
            count[k + 1] += count[k];
        }
        let col_ptr = count.clone();
        let mut row_idx = vec![0; self.row_idx.len()];
        for j in 0..self.dim {
            for k in self.col_ptr[j]..self.col_ptr[j + 1] {
                let r = self.row_idx[k];
                row_idx[count[r]] = j;
                count[r] += 1;
            }
        }
        (col_ptr, row_idx)
    }
}

/// Approximate-minimum-degree ordering of the vertices (new → old), from
/// the block pattern: each vertex's three unknowns stay together, so the
/// factor can be built directly in that order (no permutation of the matrix
/// at every factorisation).
pub(crate) fn amd_vertex_order(a: &BlockMatrix) -> Vec<usize> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::sparse::linalg::amd;
    use faer::sparse::SymbolicSparseColMatRef;
    let nnz = a.col.len();
    let mut perm = vec![0usize; a.n];
    let mut inv = vec![0usize; a.n];
    let mut mem = MemBuffer::new(amd::order_scratch::<usize>(a.n, nnz));
    let col: Vec<usize> = a.col.iter().map(|&j| j as usize).collect();
    let pattern = SymbolicSparseColMatRef::new_checked(a.n, a.n, &a.row_ptr, None, &col);
    match amd::order(
        &mut perm,
        &mut inv,
        pattern,
        Default::default(),
        MemStack::new(&mut mem),
    ) {
        Ok(_) => perm,
        Err(_) => (0..a.n).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pattern_and_product() {
        let cl: Vec<Vec<usize>> = vec![vec![0, 1], vec![1, 2]];
        let mut a = BlockMatrix::from_cliques(3, cl.iter().map(|c| c.as_slice()));
        assert_eq!(a.nnz_blocks(), 7);
        let i01 = a.index(0, 1);
        a.val[i01] = Matrix3::identity() * 2.0;
        let d = a.diag[2];
        a.val[d] = Matrix3::identity();
        let x = vec![
            Vector3::new(1.0, 2.0, 3.0),
            Vector3::new(1.0, 1.0, 1.0),
            Vector3::new(0.0, 0.0, 5.0),
        ];
        let mut y = vec![Vector3::zeros(); 3];
        a.mul(&x, &mut y);
        assert_eq!(y[0], Vector3::new(2.0, 2.0, 2.0));
        assert_eq!(y[2], Vector3::new(0.0, 0.0, 5.0));
        let csc = LowerCsc::new_permuted(&a, &[0, 1, 2]).unwrap();
        // lower triangle of a 9×9 with 7 blocks: 3 diag blocks (6 each) + 2 off (9 each)
        assert_eq!(csc.row_idx.len(), 3 * 6 + 2 * 9);
    }
}
