//! A bounding-volume hierarchy of axis-aligned boxes over triangles (the
//! cloth's, for its contacts with itself; a deforming body's): its tree is
//! built once from the starting shape (median splits along the longest axis
//! of the centroids), and only its boxes are refitted every step (the
//! connectivity never changes, so a tree of neighbouring triangles stays one
//! of neighbouring triangles; Bridson, Fedkiw & Anderson 2002 §6 and ARCSim
//! refit theirs the same way).

use nalgebra::Vector3;

/// Axis-aligned box (min, max corners).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lowest corner.
    pub lo: Vector3<f64>,
    /// Highest corner.
    pub hi: Vector3<f64>,
}

impl Aabb {
    /// The empty box (adding a point makes it that point).
    pub fn empty() -> Aabb {
        Aabb {
            lo: Vector3::repeat(f64::INFINITY),
            hi: Vector3::repeat(f64::NEG_INFINITY),
        }
    }

    /// Grows the box to hold `p`.
    pub fn add(&mut self, p: &Vector3<f64>) {
        self.lo = self.lo.inf(p);
        self.hi = self.hi.sup(p);
    }

    /// The smallest box holding both.
    pub fn merge(&self, o: &Aabb) -> Aabb {
        Aabb {
            lo: self.lo.inf(&o.lo),
            hi: self.hi.sup(&o.hi),
        }
    }

    /// Grows the box by `r` on every side.
    pub fn grow(&mut self, r: f64) {
        self.lo.add_scalar_mut(-r);
        self.hi.add_scalar_mut(r);
    }

    #[inline]
    /// Whether the two boxes share a point.
    pub fn overlaps(&self, o: &Aabb) -> bool {
        (0..3).all(|k| self.lo[k] <= o.hi[k] && o.lo[k] <= self.hi[k])
    }

    /// The widest gap between the two boxes along an axis (negative or 0
    /// when they overlap): a lower bound of the distance between any point
    /// of one and any point of the other.
    #[inline]
    pub fn gap(&self, o: &Aabb) -> f64 {
        (0..3)
            .map(|k| (o.lo[k] - self.hi[k]).max(self.lo[k] - o.hi[k]))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// Squared distance from `p` to the box (0 inside).
    pub fn distance2(&self, p: &Vector3<f64>) -> f64 {
        let mut d = 0.0;
        for k in 0..3 {
            let e = (self.lo[k] - p[k]).max(p[k] - self.hi[k]).max(0.0);
            d += e * e;
        }
        d
    }
}

#[derive(Debug, Clone, Copy)]
struct Node {
    b: Aabb,
    /// Children (inner node), or `LEAF` and the triangle.
    left: u32,
    right: u32,
    /// Leaves under it.
    leaves: u32,
}

const LEAF: u32 = u32::MAX;

/// The tree; nodes in pre-order (a parent before its children), so a
/// refit walks them backwards.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
}

impl Bvh {
    /// The tree over `tris` at positions `x` (one leaf per triangle).
    pub fn build(tris: &[[usize; 3]], x: &[Vector3<f64>]) -> Bvh {
        Bvh::build_with(tris.len(), |t| {
            let [a, b, c] = tris[t];
            (x[a] + x[b] + x[c]) / 3.0
        })
    }

    /// The tree over `n` leaves whose centroids `centroid(t)` gives.
    pub fn build_with(n: usize, centroid: impl Fn(usize) -> Vector3<f64>) -> Bvh {
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * n),
        };
        if n == 0 {
            return bvh;
        }
        let mut order: Vec<(u32, Vector3<f64>)> = (0..n).map(|t| (t as u32, centroid(t))).collect();
        bvh.split(&mut order);
        bvh
    }

    fn split(&mut self, items: &mut [(u32, Vector3<f64>)]) -> u32 {
        let me = self.nodes.len() as u32;
        self.nodes.push(Node {
            b: Aabb::empty(),
            left: LEAF,
            right: 0,
            leaves: items.len() as u32,
        });
        if items.len() == 1 {
            self.nodes[me as usize].right = items[0].0;
            return me;
        }
        let mut b = Aabb::empty();
        for (_, c) in items.iter() {
            b.add(c);
        }
        let ext = b.hi - b.lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        // total order (centroid, then index): the same tree on every run
        items.select_nth_unstable_by(mid, |p, q| {
            p.1[axis].total_cmp(&q.1[axis]).then(p.0.cmp(&q.0))
        });
        let (l, r) = items.split_at_mut(mid);
        let left = self.split(l);
        let right = self.split(r);
        self.nodes[me as usize].left = left;
        self.nodes[me as usize].right = right;
        me
    }

    /// New boxes from the leaves' (`leaf(t)`: triangle t's box).
    pub fn refit(&mut self, leaf: impl Fn(usize) -> Aabb) {
        for k in (0..self.nodes.len()).rev() {
            let n = self.nodes[k];
            self.nodes[k].b = if n.left == LEAF {
                leaf(n.right as usize)
            } else {
                self.nodes[n.left as usize]
                    .b
                    .merge(&self.nodes[n.right as usize].b)
            };
        }
    }

    /// The box of the whole tree.
    pub fn root(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::empty(), |n| n.b)
    }

    /// Calls `f(t)` for each leaf whose box meets `q`.
    pub fn overlapping(&self, q: &Aabb, mut f: impl FnMut(usize)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let n = self.nodes[stack[top] as usize];
            if !n.b.overlaps(q) {
                continue;
            }
            if n.left == LEAF {
                f(n.right as usize);
            } else {
                stack[top] = n.left;
                stack[top + 1] = n.right;
                top += 2;
            }
        }
    }

    /// The leaf nearest `p` by `dist2(t)` (squared distance to leaf t's
    /// triangle), branch and bound on the boxes, nearer child first; ties go
    /// to the lower index, the same answer whatever the order of the walk.
    pub fn nearest(
        &self,
        p: &Vector3<f64>,
        mut dist2: impl FnMut(usize) -> f64,
    ) -> Option<(usize, f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best: Option<(usize, f64)> = None;
        let mut stack = [(0u32, 0.0f64); 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (k, d) = stack[top];
            if best.is_some_and(|(_, b)| d > b) {
                continue;
            }
            let n = self.nodes[k as usize];
            if n.left == LEAF {
                let d = dist2(n.right as usize);
                if best.is_none_or(|(t, b)| d < b || (d == b && (n.right as usize) < t)) {
                    best = Some((n.right as usize, d));
                }
                continue;
            }
            let dl = self.nodes[n.left as usize].b.distance2(p);
            let dr = self.nodes[n.right as usize].b.distance2(p);
            // push the farther first so the nearer is taken next
            if dl <= dr {
                stack[top] = (n.right, dr);
                stack[top + 1] = (n.left, dl);
            } else {
                stack[top] = (n.left, dl);
                stack[top + 1] = (n.right, dr);
            }
            top += 2;
        }
        best
    }

    /// Calls `f(s, t)` for every pair of distinct leaves whose boxes
    /// overlap, in an order fixed by the tree alone: which node of a pair is
    /// opened depends on the tree, not on the boxes, so the pairs of boxes
    /// that lie inside larger ones come in the order the larger ones' pairs
    /// do (a candidate list built with grown boxes, then sifted, keeps the
    /// order of a search with the boxes themselves).
    pub fn self_pairs(&self, stack: &mut Vec<(u32, u32)>, mut f: impl FnMut(usize, usize)) {
        stack.clear();
        if self.nodes.is_empty() {
            return;
        }
        // (a, a): pairs within a subtree; (a, b), a ≠ b: pairs across two
        stack.push((0, 0));
        while let Some((a, b)) = stack.pop() {
            let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
            if a == b {
                if na.left != LEAF {
                    stack.push((na.left, na.right));
                    stack.push((na.right, na.right));
                    stack.push((na.left, na.left));
                }
                continue;
            }
            if !na.b.overlaps(&nb.b) {
                continue;
            }
            match (na.left == LEAF, nb.left == LEAF) {
                (true, true) => f(na.right as usize, nb.right as usize),
                (false, true) => {
                    stack.push((na.right, b));
                    stack.push((na.left, b));
                }
                (true, false) => {
                    stack.push((a, nb.right));
                    stack.push((a, nb.left));
                }
                (false, false) => {
                    // the node with more leaves (the first on a tie)
                    if na.leaves >= nb.leaves {
                        stack.push((na.right, b));
                        stack.push((na.left, b));
                    } else {
                        stack.push((a, nb.right));
                        stack.push((a, nb.left));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tree finds exactly the overlapping pairs a brute-force loop finds.
    #[test]
    fn pairs_match_brute_force() {
        let mut x = Vec::new();
        let mut s = 7u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut tris = Vec::new();
        for t in 0..200 {
            let c = Vector3::new(rnd(), rnd(), rnd());
            for _ in 0..3 {
                x.push(c + Vector3::new(rnd(), rnd(), rnd()) * 0.25);
            }
            tris.push([3 * t, 3 * t + 1, 3 * t + 2]);
        }
        let boxes: Vec<Aabb> = tris
            .iter()
            .map(|t| {
                let mut b = Aabb::empty();
                t.iter().for_each(|&v| b.add(&x[v]));
                b
            })
            .collect();
        let mut bvh = Bvh::build(&tris, &x);
        bvh.refit(|t| boxes[t]);
        let mut found = Vec::new();
        bvh.self_pairs(&mut Vec::new(), |a, b| found.push((a.min(b), a.max(b))));
        found.sort();
        let mut brute = Vec::new();
        for a in 0..tris.len() {
            for b in a + 1..tris.len() {
                if boxes[a].overlaps(&boxes[b]) {
                    brute.push((a, b));
                }
            }
        }
        assert!(brute.len() > 100, "{} pairs", brute.len());
        assert_eq!(found, brute);
    }
}
