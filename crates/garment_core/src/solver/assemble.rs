//! Assembly of the implicit step's matrix and right-hand side, on the
//! simulation's team of threads ([`super::team::Team`]) without locks: the
//! vertices are cut into contiguous chunks, each spring or hinge whose
//! vertices all lie in one chunk is assembled by that chunk's thread into its
//! own rows, and the few that straddle two chunks are
//! assembled afterwards on one thread. Elements are stored grouped that way
//! (the order of springs changes nothing else), so every thread also owns a
//! contiguous slice of the hysteresis memories.

use super::elements::*;
use super::sparse::BlockMatrix;
use super::team::Team;
use super::Fabrics;
use crate::cloth::Cloth;
use crate::fabric::{Fabric, LawState};
use nalgebra::{Matrix3, Vector3};
use std::ops::Range;

/// Element groups: `ranges[t]` for chunk t, the last entry for the straddling ones.
#[derive(Debug, Clone, Default)]
pub struct Partition {
    /// Vertex chunk boundaries: chunk t owns vertices `bounds[t]..bounds[t + 1]`.
    pub bounds: Vec<usize>,
    pub tension: Vec<Range<usize>>,
    pub shear: Vec<Range<usize>>,
    pub hinge: Vec<Range<usize>>,
    /// Largest vertex-index distance within one element.
    pub span: usize,
}

/// Reorders the cloth's springs and hinges (with their memories) into
/// per-chunk groups and returns the groups.
pub fn partition(cloth: &mut Cloth, threads: usize) -> Partition {
    let n = cloth.len();
    let t = threads.max(1);
    let bounds: Vec<usize> = (0..=t).map(|k| k * n / t).collect();
    let chunk = |v: usize| bounds.partition_point(|&b| b <= v) - 1;
    let group = |vs: &[usize]| -> usize {
        let c0 = chunk(vs[0]);
        if vs.iter().all(|&v| chunk(v) == c0) {
            c0
        } else {
            t
        }
    };
    fn regroup<E: Copy>(
        els: &mut Vec<E>,
        st: &mut Vec<LawState>,
        key: impl Fn(&E) -> usize,
        low: impl Fn(&E) -> usize,
        groups: usize,
    ) -> Vec<Range<usize>> {
        let mut idx: Vec<usize> = (0..els.len()).collect();
        // by group, then by lowest vertex: [`elements`] walks the three
        // families in step through vertex tiles, so the blocks they add into
        // stay in cache
        idx.sort_by_key(|&k| (key(&els[k]), low(&els[k])));
        *els = idx.iter().map(|&k| els[k]).collect();
        *st = idx.iter().map(|&k| st[k]).collect();
        let mut r = Vec::with_capacity(groups + 1);
        let mut start = 0;
        for g in 0..=groups {
            let end = start + els[start..].iter().take_while(|e| key(e) == g).count();
            r.push(start..end);
            start = end;
        }
        r
    }
    let tension = regroup(
        &mut cloth.tension,
        &mut cloth.tension_state,
        |s| group(&[s.a, s.b]),
        |s| s.a.min(s.b),
        t,
    );
    let shear = regroup(
        &mut cloth.shear,
        &mut cloth.shear_state,
        |s| group(&[s.a, s.b]),
        |s| s.a.min(s.b),
        t,
    );
    let hinge = regroup(
        &mut cloth.hinges,
        &mut cloth.hinge_state,
        |h| group(&h.v),
        |h| h.v.iter().copied().min().unwrap_or(0),
        t,
    );
    let span = cloth
        .tension
        .iter()
        .map(|s| s.a.abs_diff(s.b))
        .chain(cloth.shear.iter().map(|s| s.a.abs_diff(s.b)))
        .chain(cloth.hinges.iter().map(|h| {
            let (lo, hi) = (
                h.v.iter().min().unwrap_or(&0),
                h.v.iter().max().unwrap_or(&0),
            );
            hi - lo
        }))
        .max()
        .unwrap_or(0);
    Partition {
        bounds,
        tension,
        shear,
        hinge,
        span,
    }
}

/// Block positions of each element in the system matrix.
#[derive(Debug, Clone)]
pub struct Slots {
    pub tension: Vec<[usize; 4]>,
    pub shear: Vec<[usize; 4]>,
    pub hinge: Vec<[usize; 16]>,
    /// Blocks (p, q) of each seam stitch's three vertices, at `3p + q`.
    pub seam: Vec<[usize; 9]>,
}

impl Slots {
    pub fn new(a: &BlockMatrix, c: &Cloth) -> Slots {
        let pair =
            |i: usize, j: usize| [a.index(i, i), a.index(i, j), a.index(j, i), a.index(j, j)];
        Slots {
            tension: c.tension.iter().map(|s| pair(s.a, s.b)).collect(),
            shear: c.shear.iter().map(|s| pair(s.a, s.b)).collect(),
            hinge: c
                .hinges
                .iter()
                .map(|h| {
                    let mut r = [0; 16];
                    for p in 0..4 {
                        for q in 0..4 {
                            r[4 * p + q] = a.index(h.v[p], h.v[q]);
                        }
                    }
                    r
                })
                .collect(),
            seam: c
                .seams
                .iter()
                .map(|st| {
                    let mut r = [0; 9];
                    for p in 0..3 {
                        for q in 0..3 {
                            r[3 * p + q] = a.index(st.v[p], st.v[q]);
                        }
                    }
                    r
                })
                .collect(),
        }
    }
}

/// Adds the seam stitches ([`crate::cloth::Stitch`]) to the assembled step:
/// each is a linear spring on its gap `g = Σ c_k x_k` with damping on `ġ`,
/// so `∂f/∂x = −k c cᵀ`, `∂f/∂v = −d c cᵀ` exactly; `A += (h² k + h d) c cᵀ`,
/// `f += −c (k g + d ġ)` and `rhs += h (f − c (h k ġ + k ĝ_y))` with `ĝ_y`
/// the gap of the position correction `y` (the terms of
/// [`super::Simulation`]'s formula). Returns the damping power `−d |ġ|²`.
pub fn add_seams(
    h: f64,
    cloth: &Cloth,
    y: &[Vector3<f64>],
    slots: &Slots,
    a: &mut BlockMatrix,
    force: &mut [Vector3<f64>],
    rhs: &mut [Vector3<f64>],
) -> f64 {
    let mut power = 0.0;
    for (st, sl) in cloth.seams.iter().zip(&slots.seam) {
        let g = st.gap(&cloth.x);
        let gv = st.gap(&cloth.v);
        let gy = st.gap(y);
        let f = -(g * st.k + gv * st.d);
        let r = (f - (gv * (h * st.k) + gy * st.k)) * h;
        power -= st.d * gv.norm_squared();
        let w = h * h * st.k + h * st.d;
        for p in 0..3 {
            force[st.v[p]] += f * st.c[p];
            rhs[st.v[p]] += r * st.c[p];
            for q in 0..3 {
                a.val[sl[3 * p + q]] += Matrix3::identity() * (w * st.c[p] * st.c[q]);
            }
        }
    }
    power
}

/// What every thread reads.
struct Ctx<'a> {
    h: f64,
    fabrics: Fabrics<'a>,
    c: &'a ClothView<'a>,
    y: &'a [Vector3<f64>],
    slots: &'a Slots,
    gravity: Vector3<f64>,
    mass: &'a [f64],
    row_ptr: &'a [usize],
    diag: &'a [usize],
    span: usize,
}

/// The read-only part of the cloth.
struct ClothView<'a> {
    x: &'a [Vector3<f64>],
    v: &'a [Vector3<f64>],
    tension: &'a [crate::cloth::TensionSpring],
    shear: &'a [crate::cloth::ShearSpring],
    hinges: &'a [crate::cloth::Hinge],
}

/// What one thread writes: rows `voff..` of the matrix blocks (starting at
/// block `boff`), forces and right-hand sides; memories of its element ranges.
struct Out<'a> {
    val: &'a mut [Matrix3<f64>],
    boff: usize,
    force: &'a mut [Vector3<f64>],
    rhs: &'a mut [Vector3<f64>],
    voff: usize,
    tstate: &'a mut [LawState],
    sstate: &'a mut [LawState],
    hstate: &'a mut [LawState],
    power: f64,
}

/// Starts rows `rows` of the step: mass and Rayleigh-α terms on the
/// diagonal, zero elsewhere; gravity and α damping in the force.
#[inline(always)]
fn init_rows(ctx: &Ctx, o: &mut Out, rows: Range<usize>) {
    let h = ctx.h;
    for i in rows {
        let al = ctx.fabrics.at(i).damping.alpha;
        let m = ctx.mass[i];
        let v = ctx.c.v[i];
        o.force[i - o.voff] = ctx.gravity * m + v * (al * m);
        o.power += al * m * v.norm_squared();
        o.rhs[i - o.voff] = Vector3::zeros();
        for b in &mut o.val[ctx.row_ptr[i] - o.boff..ctx.row_ptr[i + 1] - o.boff] {
            *b = Matrix3::zeros();
        }
        o.val[ctx.diag[i] - o.boff] = Matrix3::identity() * ((1.0 - h * al) * m);
    }
}

/// Assembles the given element ranges into `o`; with `init`, `o`'s rows
/// are started (see [`init_rows`]) just ahead of the tiles that add to them,
/// so the matrix is walked once. The same code compiled for AVX2 where the
/// CPU has it (no FMA: the same roundings, the same results).
fn elements(
    ctx: &Ctx,
    tr: Range<usize>,
    sr: Range<usize>,
    hr: Range<usize>,
    o: &mut Out,
    init: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        unsafe { elements_avx2(ctx, tr, sr, hr, o, init) };
        return;
    }
    elements_impl(ctx, tr, sr, hr, o, init)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn elements_avx2(
    ctx: &Ctx,
    tr: Range<usize>,
    sr: Range<usize>,
    hr: Range<usize>,
    o: &mut Out,
    init: bool,
) {
    elements_impl(ctx, tr, sr, hr, o, init)
}

#[inline(always)]
fn elements_impl(
    ctx: &Ctx,
    tr: Range<usize>,
    sr: Range<usize>,
    hr: Range<usize>,
    o: &mut Out,
    init: bool,
) {
    // the three families advance together through tiles of vertices (the
    // elements of each group are sorted by lowest vertex), so each tile's
    // matrix rows are loaded into cache once instead of once per family
    let c = ctx.c;
    let (mut t, mut s, mut h) = (tr.start, sr.start, hr.start);
    let vend = o.voff + o.force.len();
    let mut started = o.voff;
    let mut bound = 0;
    while t < tr.end || s < sr.end || h < hr.end {
        bound += TILE;
        if init {
            // this tile's elements reach rows below bound + span
            let upto = (bound + ctx.span).min(vend);
            if upto > started {
                init_rows(ctx, o, started..upto);
                started = upto;
            }
        }
        let t1 = t + c.tension[t..tr.end].partition_point(|e| e.a.min(e.b) < bound);
        let s1 = s + c.shear[s..sr.end].partition_point(|e| e.a.min(e.b) < bound);
        let h1 = h + c.hinges[h..hr.end]
            .partition_point(|e| e.v.iter().copied().min().unwrap_or(0) < bound);
        elements_range(ctx, t..t1, s..s1, h..h1, tr.start, sr.start, hr.start, o);
        (t, s, h) = (t1, s1, h1);
    }
    if init && started < vend {
        init_rows(ctx, o, started..vend);
    }
}

/// Vertices per assembly tile (a few grid rows: their blocks fit in L2).
const TILE: usize = 256;

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn elements_range(
    ctx: &Ctx,
    tr: Range<usize>,
    sr: Range<usize>,
    hr: Range<usize>,
    t0: usize,
    s0: usize,
    h0: usize,
    o: &mut Out,
) {
    let (h, c, y) = (ctx.h, ctx.c, ctx.y);
    let v = c.v;
    let (bo, vo) = (o.boff, o.voff);
    for k in tr {
        let s = &c.tension[k];
        let st = &mut o.tstate[k - t0];
        let f = ctx.fabrics.at(s.a);
        let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
        let law = &f.dir(s.weft).tensile;
        law.commit(st, l / s.l0 - 1.0);
        let (t, dt, dts, _) = tension_law_step(s, law, &f.shear, st, l);
        let sp = AxialStep {
            a: s.a,
            b: s.b,
            t,
            dt,
            dts,
            l,
            dir,
            beta: f.damping.beta_tension,
        };
        axial_element(ctx, o, &ctx.slots.tension[k], &sp);
    }
    for k in sr {
        let s = &c.shear[k];
        let st = &mut o.sstate[k - s0];
        let f = ctx.fabrics.at(s.a);
        let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
        f.shear.commit(st, s.strain(l));
        let (t, dt, dts, _) = shear_law_step(s, &f.shear, st, l);
        let sp = AxialStep {
            a: s.a,
            b: s.b,
            t,
            dt,
            dts,
            l,
            dir,
            beta: f.damping.beta_shear,
        };
        axial_element(ctx, o, &ctx.slots.shear[k], &sp);
    }
    for k in hr {
        let hg = &c.hinges[k];
        let st = &mut o.hstate[k - h0];
        let f = ctx.fabrics.at(hg.v[0]);
        let d = f.damping;
        let law = &f.dir(hg.weft).bending;
        let (theta, g) = dihedral_and_grad(hinge_positions(hg, c.x));
        law.commit(st, theta / hg.h);
        let (s, ds, dss) = law.eval_for_step(st, theta / hg.h);
        let kd = hg.len * ds.max(0.0) / hg.h;
        let ks = hg.len * dss.max(0.0) / hg.h;
        let gs = |p: usize| Vector3::new(g[3 * p], g[3 * p + 1], g[3 * p + 2]);
        let gp = [gs(0), gs(1), gs(2), gs(3)];
        let mut gv = 0.0;
        let mut gy = 0.0;
        for p in 0..4 {
            gv += gp[p].dot(&v[hg.v[p]]);
            gy += gp[p].dot(&y[hg.v[p]]);
        }
        o.power += d.beta_bend * kd * gv * gv;
        let sl = &ctx.slots.hinge[k];
        let cm = h * h * ks - h * d.beta_bend * kd;
        for p in 0..4 {
            // elastic −L σ ∇θ; damping β K̃ v with K̃ v = kd g (g·v)
            o.force[hg.v[p] - vo] += gp[p] * (-hg.len * s + kd * gv * d.beta_bend);
            o.rhs[hg.v[p] - vo] -= gp[p] * (ks * (h * gv + gy));
            if cm != 0.0 {
                // symmetric: block (q, p) is the transpose of (p, q), bit for bit
                o.val[sl[5 * p] - bo] += gp[p] * gp[p].transpose() * cm;
                for q in p + 1..4 {
                    let m = gp[p] * gp[q].transpose() * cm;
                    o.val[sl[4 * p + q] - bo] += m;
                    o.val[sl[4 * q + p] - bo] += m.transpose();
                }
            }
        }
    }
}

/// One axial spring's response for this step.
struct AxialStep {
    a: usize,
    b: usize,
    /// Tension, its branch tangent and its step tangent (see [`crate::fabric::Law::eval_for_step`]).
    t: f64,
    dt: f64,
    dts: f64,
    l: f64,
    dir: Vector3<f64>,
    /// The family's Rayleigh coefficient.
    beta: f64,
}

/// Adds an axial spring (tension or shear) to the step: stiffness with the step
/// tangent, damping with the branch tangent.
#[inline(always)]
fn axial_element(ctx: &Ctx, o: &mut Out, slots: &[usize; 4], e: &AxialStep) {
    let (h, y, v) = (ctx.h, ctx.y, ctx.c.v);
    let (bo, vo) = (o.boff, o.voff);
    let pd = axial_block(
        &Axial {
            t: e.t,
            dt: e.dt,
            l: e.l,
            dir: e.dir,
        },
        true,
    );
    let ps = axial_block(
        &Axial {
            t: e.t,
            dt: e.dts,
            l: e.l,
            dir: e.dir,
        },
        true,
    );
    scatter(o.val, bo, slots, &(ps * (h * h) - pd * (h * e.beta)));
    let dvab = v[e.a] - v[e.b];
    let kdv = pd * dvab;
    o.power += e.beta * dvab.dot(&kdv);
    let fe = e.dir * e.t + kdv * e.beta;
    o.force[e.a - vo] += fe;
    o.force[e.b - vo] -= fe;
    let r = -(ps * (dvab * h + (y[e.a] - y[e.b])));
    o.rhs[e.a - vo] += r;
    o.rhs[e.b - vo] -= r;
}

#[inline]
fn scatter(val: &mut [Matrix3<f64>], off: usize, sl: &[usize; 4], p: &Matrix3<f64>) {
    val[sl[0] - off] += p;
    val[sl[1] - off] -= p;
    val[sl[2] - off] -= p;
    val[sl[3] - off] += p;
}

/// Builds `A`, the right-hand side `rhs` and the total force `force` of the
/// step (see [`super::Simulation`] for the formulas), advancing every
/// spring's hysteresis memory to the current shape in the same pass. Returns
/// the damping power `vᵀ C v` (≤ 0).
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
    let Cloth {
        x,
        v,
        tension,
        shear,
        hinges,
        tension_state,
        shear_state,
        hinge_state,
        mass,
        vertex_fabric,
        ..
    } = cloth;
    let view = ClothView {
        x,
        v,
        tension,
        shear,
        hinges,
    };
    let ctx = Ctx {
        h,
        fabrics: Fabrics {
            first: fabric,
            others: other_fabrics,
            of: vertex_fabric,
        },
        c: &view,
        y,
        slots,
        gravity,
        mass: &mass[..],
        row_ptr: &a.row_ptr,
        diag: &a.diag,
        span: part.span,
    };
    let nt = part.bounds.len() - 1;
    // split every output into per-chunk slices
    let mut outs: Vec<Out> = Vec::with_capacity(nt);
    {
        let mut val: &mut [Matrix3<f64>] = &mut a.val;
        let mut fo: &mut [Vector3<f64>] = force;
        let mut rh: &mut [Vector3<f64>] = rhs;
        let mut ts: &mut [LawState] = tension_state;
        let mut ss: &mut [LawState] = shear_state;
        let mut hs: &mut [LawState] = hinge_state;
        let (mut boff, mut toff, mut soff, mut hoff) = (0, 0, 0, 0);
        for t in 0..nt {
            let (v0, v1) = (part.bounds[t], part.bounds[t + 1]);
            let bend = a.row_ptr[v1];
            let (vh, vt) = std::mem::take(&mut val).split_at_mut(bend - boff);
            let (fh, ft) = std::mem::take(&mut fo).split_at_mut(v1 - v0);
            let (rhh, rht) = std::mem::take(&mut rh).split_at_mut(v1 - v0);
            let (tsh, tst) = std::mem::take(&mut ts).split_at_mut(part.tension[t].end - toff);
            let (ssh, sst) = std::mem::take(&mut ss).split_at_mut(part.shear[t].end - soff);
            let (hsh, hst) = std::mem::take(&mut hs).split_at_mut(part.hinge[t].end - hoff);
            outs.push(Out {
                val: vh,
                boff,
                force: fh,
                rhs: rhh,
                voff: v0,
                tstate: tsh,
                sstate: ssh,
                hstate: hsh,
                power: 0.0,
            });
            val = vt;
            fo = ft;
            rh = rht;
            ts = tst;
            ss = sst;
            hs = hst;
            boff = bend;
            toff = part.tension[t].end;
            soff = part.shear[t].end;
            hoff = part.hinge[t].end;
        }
        debug_assert!(val.is_empty() && fo.is_empty());
        let _ = (ts, ss, hs);
    }
    // chunk t on the team's thread t (the team has one thread per chunk)
    debug_assert_eq!(team.size(), nt);
    team.run_each(&mut outs, |t, o| {
        elements(
            &ctx,
            part.tension[t].clone(),
            part.shear[t].clone(),
            part.hinge[t].clone(),
            o,
            true,
        )
    });
    power += outs.iter().map(|o| o.power).sum::<f64>();
    drop(outs);
    // the straddling elements, on this thread, with whole-matrix slices
    let mut o = Out {
        val: &mut a.val,
        boff: 0,
        force,
        rhs,
        voff: 0,
        tstate: &mut tension_state[part.tension[nt].clone()],
        sstate: &mut shear_state[part.shear[nt].clone()],
        hstate: &mut hinge_state[part.hinge[nt].clone()],
        power: 0.0,
    };
    elements(
        &ctx,
        part.tension[nt].clone(),
        part.shear[nt].clone(),
        part.hinge[nt].clone(),
        &mut o,
        false,
    );
    power += o.power;
    for i in 0..o.force.len() {
        o.rhs[i] = (o.force[i] + o.rhs[i]) * h;
    }
    power
}
