//! Assembly of the implicit step's matrix and right-hand side, on the
//! simulation's team of threads ([`super::team::Team`]) without locks: the
//! vertices are cut into contiguous chunks, each element of a
//! [`Stage::Tiles`] set whose vertices all lie in one chunk is assembled by
//! that chunk's thread into its own rows, and the few that straddle two
//! chunks are assembled afterwards on one thread; the [`Stage::Last`] sets
//! follow on that thread. Elements are stored grouped that way (the order of
//! springs changes nothing else), so every thread also owns a contiguous
//! slice of each set's memories.

use super::energy::Fabrics;
use super::sets::{self, memory_mut, Element, Stage, StepIn, StepOut, Visit, VisitMut, SETS};
use super::sparse::BlockMatrix;
use super::team::Team;
use crate::cloth::Cloth;
use crate::fabric::{Fabric, LawState};
use nalgebra::{Matrix3, Vector3};
use std::ops::Range;

/// Element groups of each set: `ranges[s][t]` for chunk t, the last entry
/// for the straddling ones (all empty for a [`Stage::Last`] set).
#[derive(Debug, Clone, Default)]
pub struct Partition {
    /// Vertex chunk boundaries: chunk t owns vertices `bounds[t]..bounds[t + 1]`.
    pub bounds: Vec<usize>,
    pub ranges: [Vec<Range<usize>>; SETS],
    /// Largest vertex-index distance within one element.
    pub span: usize,
}

/// Reorders the elements of the [`Stage::Tiles`] sets (with their memories)
/// into per-chunk groups and returns the groups.
pub fn partition(cloth: &mut Cloth, threads: usize) -> Partition {
    let n = cloth.len();
    let t = threads.max(1);
    let bounds: Vec<usize> = (0..=t).map(|k| k * n / t).collect();
    struct Regroup<'a> {
        bounds: &'a [usize],
        t: usize,
        part: [Vec<Range<usize>>; SETS],
        span: usize,
    }
    impl Regroup<'_> {
        fn chunk(&self, v: usize) -> usize {
            self.bounds.partition_point(|&b| b <= v) - 1
        }
        fn group(&self, vs: &[usize]) -> usize {
            let c0 = self.chunk(vs[0]);
            if vs.iter().all(|&v| self.chunk(v) == c0) {
                c0
            } else {
                self.t
            }
        }
    }
    impl VisitMut for Regroup<'_> {
        fn set<E: Element>(&mut self, i: usize, els: &mut Vec<E>, st: &mut Vec<LawState>) {
            let groups = self.t;
            if E::STAGE != Stage::Tiles {
                self.part[i] = vec![0..0; groups + 1];
                return;
            }
            let key = |e: &E| self.group(e.clique().as_ref());
            let mut idx: Vec<usize> = (0..els.len()).collect();
            // by group, then by lowest vertex: [`elements`] walks the sets in
            // step through vertex tiles, so the blocks they add into stay in
            // cache
            idx.sort_by_key(|&k| (key(&els[k]), els[k].lowest()));
            *els = idx.iter().map(|&k| els[k]).collect();
            if E::MEMORY {
                *st = idx.iter().map(|&k| st[k]).collect();
            }
            let mut r = Vec::with_capacity(groups + 1);
            let mut start = 0;
            for g in 0..=groups {
                let end = start + els[start..].iter().take_while(|e| key(e) == g).count();
                r.push(start..end);
                start = end;
            }
            self.part[i] = r;
            for e in els.iter() {
                let c = e.clique();
                let c = c.as_ref();
                let (lo, hi) = (c.iter().min().unwrap_or(&0), c.iter().max().unwrap_or(&0));
                self.span = self.span.max(hi - lo);
            }
        }
    }
    let mut g = Regroup {
        bounds: &bounds,
        t,
        part: Default::default(),
        span: 0,
    };
    sets::each_mut(cloth, &mut g);
    let (ranges, span) = (g.part, g.span);
    Partition {
        bounds,
        ranges,
        span,
    }
}

/// Block positions of each element in the system matrix: for set `s`,
/// element `k`'s block `(p, q)` of its clique at `of[s][N² k + N p + q]`.
#[derive(Debug, Clone)]
pub struct Slots {
    pub of: [Vec<usize>; SETS],
}

impl Slots {
    pub fn new(a: &BlockMatrix, c: &Cloth) -> Slots {
        struct Make<'a>(&'a BlockMatrix, [Vec<usize>; SETS]);
        impl Visit for Make<'_> {
            fn set<E: Element>(&mut self, i: usize, els: &[E], _: &[LawState]) {
                let out = &mut self.1[i];
                out.reserve(els.len() * E::N * E::N);
                for e in els {
                    let c = e.clique();
                    for &p in c.as_ref() {
                        for &q in c.as_ref() {
                            out.push(self.0.index(p, q));
                        }
                    }
                }
            }
        }
        let mut m = Make(a, Default::default());
        sets::each(c, &mut m);
        Slots { of: m.1 }
    }
}

/// What every thread reads.
struct Ctx<'a> {
    step: StepIn<'a>,
    /// The elements (their memories are in [`Out`]).
    cloth: &'a Cloth,
    slots: &'a Slots,
    gravity: Vector3<f64>,
    mass: &'a [f64],
    row_ptr: &'a [usize],
    diag: &'a [usize],
    span: usize,
}

/// What one thread writes: rows `voff..` of the matrix blocks (starting at
/// block `boff`), forces and right-hand sides; memories of its element ranges.
struct Out<'a, 'm> {
    acc: StepOut<'a>,
    mem: [&'m mut [LawState]; SETS],
}

/// Starts rows `rows` of the step: mass and Rayleigh-α terms on the
/// diagonal, zero elsewhere; gravity and α damping in the force.
#[inline(always)]
fn init_rows(ctx: &Ctx, o: &mut StepOut, rows: Range<usize>) {
    let h = ctx.step.h;
    for i in rows {
        let al = ctx.step.fabrics.at(i).damping.alpha;
        let m = ctx.mass[i];
        let v = ctx.step.v[i];
        o.force[i - o.voff] = ctx.gravity * m + v * (al * m);
        o.power += al * m * v.norm_squared();
        o.rhs[i - o.voff] = Vector3::zeros();
        for b in &mut o.val[ctx.row_ptr[i] - o.boff..ctx.row_ptr[i + 1] - o.boff] {
            *b = Matrix3::zeros();
        }
        o.val[ctx.diag[i] - o.boff] = Matrix3::identity() * ((1.0 - h * al) * m);
    }
}

/// Assembles the given element ranges of the [`Stage::Tiles`] sets into
/// `o`; with `init`, `o`'s rows are started (see [`init_rows`]) just ahead
/// of the tiles that add to them, so the matrix is walked once. The same
/// code compiled for AVX2 where the CPU has it (no FMA: the same roundings,
/// the same results).
fn elements(ctx: &Ctx, r: &[Range<usize>; SETS], o: &mut Out, init: bool) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        unsafe { elements_avx2(ctx, r, o, init) };
        return;
    }
    elements_impl(ctx, r, o, init)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn elements_avx2(ctx: &Ctx, r: &[Range<usize>; SETS], o: &mut Out, init: bool) {
    elements_impl(ctx, r, o, init)
}

#[inline(always)]
fn elements_impl(ctx: &Ctx, r: &[Range<usize>; SETS], o: &mut Out, init: bool) {
    // the sets advance together through tiles of vertices (the elements of
    // each group are sorted by lowest vertex), so each tile's matrix rows
    // are loaded into cache once instead of once per set
    let mut at: [usize; SETS] = std::array::from_fn(|s| r[s].start);
    let vend = o.acc.voff + o.acc.force.len();
    let mut started = o.acc.voff;
    let mut bound = 0;
    while (0..SETS).any(|s| at[s] < r[s].end) {
        bound += TILE;
        if init {
            // this tile's elements reach rows below bound + span
            let upto = (bound + ctx.span).min(vend);
            if upto > started {
                init_rows(ctx, &mut o.acc, started..upto);
                started = upto;
            }
        }
        sets::each(
            ctx.cloth,
            &mut Tile {
                ctx,
                r,
                at: &mut at,
                bound,
                o,
            },
        );
    }
    if init && started < vend {
        init_rows(ctx, &mut o.acc, started..vend);
    }
}

/// Vertices per assembly tile (a few grid rows: their blocks fit in L2).
const TILE: usize = 256;

/// One tile of [`elements_impl`]: each set's elements from `at` whose
/// lowest vertex is below `bound`.
struct Tile<'c, 'o, 'a, 'm> {
    ctx: &'c Ctx<'c>,
    r: &'c [Range<usize>; SETS],
    at: &'c mut [usize; SETS],
    bound: usize,
    o: &'o mut Out<'a, 'm>,
}

impl Visit for Tile<'_, '_, '_, '_> {
    #[inline(always)]
    fn set<E: Element>(&mut self, s: usize, els: &[E], _: &[LawState]) {
        if E::STAGE != Stage::Tiles {
            return;
        }
        let (r, k0) = (&self.r[s], self.at[s]);
        let k1 = k0 + els[k0..r.end].partition_point(|e| e.lowest() < self.bound);
        let m = E::N * E::N;
        let slots = &self.ctx.slots.of[s];
        let Out { acc, mem } = &mut *self.o;
        let mem = &mut mem[s];
        let mut fresh = LawState::at(0.0);
        for k in k0..k1 {
            let st = memory_mut::<E>(mem, k - r.start, &mut fresh);
            els[k].step(st, &slots[m * k..m * (k + 1)], &self.ctx.step, acc);
        }
        self.at[s] = k1;
    }
}

/// Adds the elements of the [`Stage::Last`] sets, in storage order.
struct Last<'c, 'o, 'a> {
    ctx: &'c Ctx<'c>,
    mem: &'c mut [Vec<LawState>; SETS],
    o: &'o mut StepOut<'a>,
}

impl Visit for Last<'_, '_, '_> {
    fn set<E: Element>(&mut self, s: usize, els: &[E], _: &[LawState]) {
        if E::STAGE != Stage::Last {
            return;
        }
        let m = E::N * E::N;
        let slots = &self.ctx.slots.of[s];
        let mut fresh = LawState::at(0.0);
        for (k, e) in els.iter().enumerate() {
            let st = memory_mut::<E>(&mut self.mem[s], k, &mut fresh);
            e.step(st, &slots[m * k..m * (k + 1)], &self.ctx.step, self.o);
        }
    }
}

/// Builds `A`, the right-hand side `rhs` and the total force `force` of the
/// step (see [`super::Simulation`] for the formulas), advancing every
/// element's hysteresis memory to the current shape in the same pass.
/// Returns the damping power `vᵀ C v` (≤ 0).
#[allow(clippy::too_many_arguments)]
pub fn assemble(
    h: f64,
    gravity: Vector3<f64>,
    fabric: &Fabric,
    other_fabrics: &[Fabric],
    cloth: &mut Cloth,
    y: &[Vector3<f64>],
    slots: &Slots,
    part: &Partition,
    a: &mut BlockMatrix,
    force: &mut [Vector3<f64>],
    rhs: &mut [Vector3<f64>],
    team: &mut Team,
) -> f64 {
    let mut power = 0.0;
    let mut mem = sets::take_memories(cloth);
    let c: &Cloth = cloth;
    let ctx = Ctx {
        step: StepIn {
            h,
            fabrics: Fabrics {
                first: fabric,
                others: other_fabrics,
                of: &c.vertex_fabric,
            },
            x: &c.x,
            v: &c.v,
            y,
        },
        cloth: c,
        slots,
        gravity,
        mass: &c.mass,
        row_ptr: &a.row_ptr,
        diag: &a.diag,
        span: part.span,
    };
    let nt = part.bounds.len() - 1;
    let ranges =
        |t: usize| -> [Range<usize>; SETS] { std::array::from_fn(|s| part.ranges[s][t].clone()) };
    // split every output into per-chunk slices
    let mut outs: Vec<Out> = Vec::with_capacity(nt);
    {
        let mut val: &mut [Matrix3<f64>] = &mut a.val;
        let mut fo: &mut [Vector3<f64>] = force;
        let mut rh: &mut [Vector3<f64>] = rhs;
        let mut ms: [&mut [LawState]; SETS] = mem.each_mut().map(|m| m.as_mut_slice());
        let mut moff = [0; SETS];
        let mut boff = 0;
        for t in 0..nt {
            let (v0, v1) = (part.bounds[t], part.bounds[t + 1]);
            let bend = a.row_ptr[v1];
            let (vh, vt) = std::mem::take(&mut val).split_at_mut(bend - boff);
            let (fh, ft) = std::mem::take(&mut fo).split_at_mut(v1 - v0);
            let (rhh, rht) = std::mem::take(&mut rh).split_at_mut(v1 - v0);
            let mh: [&mut [LawState]; SETS] = std::array::from_fn(|s| {
                let end = if ms[s].is_empty() {
                    0
                } else {
                    part.ranges[s][t].end - moff[s]
                };
                let (head, tail) = std::mem::take(&mut ms[s]).split_at_mut(end);
                ms[s] = tail;
                moff[s] += end;
                head
            });
            outs.push(Out {
                acc: StepOut {
                    val: vh,
                    boff,
                    force: fh,
                    rhs: rhh,
                    voff: v0,
                    power: 0.0,
                },
                mem: mh,
            });
            val = vt;
            fo = ft;
            rh = rht;
            boff = bend;
        }
        debug_assert!(val.is_empty() && fo.is_empty());
    }
    // chunk t on the team's thread t (the team has one thread per chunk)
    debug_assert_eq!(team.size(), nt);
    team.run_each(&mut outs, |t, o| elements(&ctx, &ranges(t), o, true));
    power += outs.iter().map(|o| o.acc.power).sum::<f64>();
    drop(outs);
    // the straddling elements, on this thread, with whole-matrix slices
    let straddle = ranges(nt);
    let mut o = Out {
        acc: StepOut {
            val: &mut a.val,
            boff: 0,
            force,
            rhs,
            voff: 0,
            power: 0.0,
        },
        mem: {
            let mut ms = mem.iter_mut();
            std::array::from_fn(|s| {
                let m = ms.next().expect("one memory per set");
                if m.is_empty() {
                    &mut m[..]
                } else {
                    &mut m[straddle[s].clone()]
                }
            })
        },
    };
    elements(&ctx, &straddle, &mut o, false);
    power += o.acc.power;
    let StepOut {
        val, force, rhs, ..
    } = o.acc;
    for i in 0..force.len() {
        rhs[i] = (force[i] + rhs[i]) * h;
    }
    // the sets added last, into the finished right-hand side
    let mut last = StepOut {
        val,
        boff: 0,
        force,
        rhs,
        voff: 0,
        power: 0.0,
    };
    sets::each(
        c,
        &mut Last {
            ctx: &ctx,
            mem: &mut mem,
            o: &mut last,
        },
    );
    power += last.power;
    sets::put_memories(cloth, mem);
    power
}
