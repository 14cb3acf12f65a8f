//! Constitutive laws of the springs: an elastic part and a rate-independent
//! hysteretic ("plastic") part, σ = σe + σp (thesis §3.4, after Denise, with a
//! member of the Bliman–Sorine family of hysteresis operators).
//!
//! Every law is a function of one scalar deformation `x`:
//! - tension springs: relative elongation ε (dimensionless), σ in N/m (force per width);
//! - shear springs: sin θ of the shear angle (≈ θ in rad over the KES range), σ in N/m;
//! - bending hinges: curvature κ in 1/m, σ in N·m/m (moment per width).
//!
//! The elastic part is the thesis' odd polynomial (§3.4.2)
//! `σe = a x + b x|x| + c x³ + d x³|x|`.
//!
//! The hysteretic part is a generalised Dahl operator: along a monotone path of
//! direction `s = sign(dx)`,
//! `dσp/dx = (s·h(x) − σp) / xs`, with half-width `h(x) = h0 + h1|x| + h2 x²`
//! and memory length `xs`. It is rate independent (only the path matters), its
//! loop width tends to `2h(x)` once the path has run a few `xs` past a reversal,
//! and the drive terms of the thesis' forms (`b_p + c_p|ε| + d_p ε²` for shear,
//! `a_p σp` fading memory) appear as `h(x)/xs` and `−σp/xs`. Over one step the
//! operator is integrated in closed form with `h` taken at the end point:
//! `σp(x) = s h(x) + (σp0 − s h(x)) exp(−|x − x0| / xs)`,
//! so that the force is an exact, differentiable function of the positions on
//! each branch and its derivative is exact (tested against finite differences).

use serde::{Deserialize, Serialize};

/// Odd polynomial `σe = c[0] x + c[1] x|x| + c[2] x³ + c[3] x³|x|` (thesis §3.4.2).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct ElasticPoly {
    /// Coefficients `c0..c3` of `σ(x) = c0 x + c1 x|x| + c2 x³ + c3 x³|x|`.
    pub c: [f64; 4],
}

impl ElasticPoly {
    /// The linear law `σ = k x`.
    pub fn linear(k: f64) -> Self {
        ElasticPoly {
            c: [k, 0.0, 0.0, 0.0],
        }
    }

    /// Value and derivative.
    #[inline]
    pub fn eval(&self, x: f64) -> (f64, f64) {
        let a = x.abs();
        let [c0, c1, c2, c3] = self.c;
        let x2 = x * x;
        let v = x * (c0 + c1 * a + c2 * x2 + c3 * x2 * a);
        let d = c0 + 2.0 * c1 * a + 3.0 * c2 * x2 + 4.0 * c3 * x2 * a;
        (v, d)
    }

    /// Energy density ∫₀ˣ σe.
    #[inline]
    pub fn energy(&self, x: f64) -> f64 {
        let a = x.abs();
        let [c0, c1, c2, c3] = self.c;
        let x2 = x * x;
        c0 * x2 / 2.0 + c1 * a * x2 / 3.0 + c2 * x2 * x2 / 4.0 + c3 * x2 * x2 * a / 5.0
    }
}

/// Rate-independent hysteresis operator (generalised Dahl), see the module doc.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Hysteresis {
    /// Half-width of the saturated loop: `h(x) = h0 + h1|x| + h2 x²`.
    pub h0: f64,
    /// See `h0`.
    pub h1: f64,
    /// See `h0`.
    pub h2: f64,
    /// Memory length (same unit as x): the loop saturates after a few `xs` of travel.
    pub xs: f64,
}

impl Hysteresis {
    /// No hysteresis.
    pub const NONE: Hysteresis = Hysteresis {
        h0: 0.0,
        h1: 0.0,
        h2: 0.0,
        xs: 1.0,
    };

    /// Whether there is no hysteresis.
    pub fn is_none(&self) -> bool {
        self.h0 == 0.0 && self.h1 == 0.0 && self.h2 == 0.0
    }

    #[inline]
    /// The saturated loop's half-width `h(x)` and its derivative.
    pub fn half_width(&self, x: f64) -> (f64, f64) {
        let a = x.abs();
        (
            self.h0 + self.h1 * a + self.h2 * x * x,
            self.h1 * x.signum() + 2.0 * self.h2 * x,
        )
    }

    /// σp and dσp/dx at `x`, from the committed state.
    #[inline]
    pub fn eval(&self, st: &LawState, x: f64) -> (f64, f64) {
        if self.is_none() {
            return (0.0, 0.0);
        }
        let dx = x - st.x;
        let s = if dx > 0.0 {
            1.0
        } else if dx < 0.0 {
            -1.0
        } else {
            st.dir
        };
        let (h, dh) = self.half_width(x);
        // exp(−0) = 1 exactly: skip the call when the state is evaluated
        // where it was committed (every assembly does that)
        let e = if dx == 0.0 {
            1.0
        } else {
            (-dx.abs() / self.xs).exp()
        };
        let sp = s * h + (st.sp - s * h) * e;
        let dsp = s * dh * (1.0 - e) + (h - s * st.sp) * e / self.xs;
        (sp, dsp)
    }
}

/// Per-spring memory of the hysteresis operator.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LawState {
    /// σp at the last committed deformation.
    pub sp: f64,
    /// Last committed deformation.
    pub x: f64,
    /// Direction of the last non-zero increment (+1 or −1).
    pub dir: f64,
}

impl LawState {
    /// A fresh memory at `x`.
    pub fn at(x: f64) -> Self {
        LawState {
            sp: 0.0,
            x,
            dir: 1.0,
        }
    }
}

/// A complete spring law: σ = σe(x) + σp(x; memory).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Law {
    /// The elastic part.
    pub elastic: ElasticPoly,
    /// The hysteretic part.
    pub hysteresis: Hysteresis,
}

impl Law {
    /// A law without hysteresis.
    pub fn elastic_only(elastic: ElasticPoly) -> Self {
        Law {
            elastic,
            hysteresis: Hysteresis::NONE,
        }
    }

    /// σ and dσ/dx at `x` given the committed memory `st`.
    #[inline]
    pub fn eval(&self, st: &LawState, x: f64) -> (f64, f64) {
        let (se, dse) = self.elastic.eval(x);
        let (sp, dsp) = self.hysteresis.eval(st, x);
        (se + sp, dse + dsp)
    }

    /// σ and a tangent for the implicit step's matrix: the larger of the
    /// current branch's tangent and the tangent just after a reversal at `x`,
    /// `(h(x) + |σp(x)|)/xs`. A path that reverses within a step then meets the
    /// stiffness it will really see; linearising with the softer branch alone
    /// lets a hysteretic spring chatter at rest (seen on 1 cm drapes).
    #[inline]
    /// Returns (σ, dσ/dx on the current branch, that step tangent).
    pub fn eval_for_step(&self, st: &LawState, x: f64) -> (f64, f64, f64) {
        let (se, dse) = self.elastic.eval(x);
        if self.hysteresis.is_none() {
            return (se, dse, dse);
        }
        let (sp, dsp) = self.hysteresis.eval(st, x);
        let (h, _) = self.hysteresis.half_width(x);
        (
            se + sp,
            dse + dsp,
            dse + dsp.max((h + sp.abs()) / self.hysteresis.xs),
        )
    }

    /// Advances the memory to `x` (end of a time step).
    #[inline]
    pub fn commit(&self, st: &mut LawState, x: f64) {
        let (sp, _) = self.hysteresis.eval(st, x);
        if x > st.x {
            st.dir = 1.0;
        } else if x < st.x {
            st.dir = -1.0;
        }
        st.sp = sp;
        st.x = x;
    }

    /// Same law without its hysteretic part.
    pub fn without_hysteresis(&self) -> Law {
        Law::elastic_only(self.elastic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn elastic_poly_hand_values() {
        let p = ElasticPoly {
            c: [2.0, 3.0, 5.0, 7.0],
        };
        // x = -0.5: 2(-0.5) + 3(-0.5)(0.5) + 5(-0.125) + 7(-0.125)(0.5)
        let (v, d) = p.eval(-0.5);
        assert!((v - (-1.0 - 0.75 - 0.625 - 0.4375)).abs() < 1e-14);
        // d = 2 + 6|x| + 15x² + 28x²|x|
        assert!((d - (2.0 + 3.0 + 3.75 + 3.5)).abs() < 1e-14);
        // energy: x²+ |x|³ + 5/4 x⁴ + 7/5 |x|⁵
        let e = p.energy(-0.5);
        assert!((e - (0.25 + 0.125 + 5.0 / 4.0 * 0.0625 + 7.0 / 5.0 * 0.03125)).abs() < 1e-14);
        // energy derivative is the force
        let h = 1e-6;
        let fd = (p.energy(0.3 + h) - p.energy(0.3 - h)) / (2.0 * h);
        assert!((fd - p.eval(0.3).0).abs() < 1e-8);
    }

    #[test]
    fn dahl_hand_values_and_saturation() {
        let hy = Hysteresis {
            h0: 1.0,
            h1: 0.0,
            h2: 0.0,
            xs: 0.1,
        };
        let law = Law {
            elastic: ElasticPoly::linear(10.0),
            hysteresis: hy,
        };
        let mut st = LawState::at(0.0);
        // from σp = 0, going up by 0.1: σp = 1 - e^{-1}
        let (s, _) = law.eval(&st, 0.1);
        assert!((s - (1.0 + 1.0 - (-1.0f64).exp())).abs() < 1e-12);
        // saturate upward, then come back: width of loop tends to 2 h0
        for k in 1..=100 {
            law.commit(&mut st, k as f64 * 0.02);
        }
        let up = law.eval(&st, 2.0).0 - 20.0;
        assert!((up - 1.0).abs() < 1e-8); // e^{-20} short of saturation
        for k in 1..=100 {
            law.commit(&mut st, 2.0 - k as f64 * 0.02);
        }
        let down = st.sp;
        assert!((down + 1.0).abs() < 1e-8); // 2 e^{-20} left of the old branch
                                            // rate independence: one big increment equals many small ones (h const)
        let mut a = LawState::at(0.0);
        let mut b = LawState::at(0.0);
        law.commit(&mut a, 0.3);
        for k in 1..=30 {
            law.commit(&mut b, k as f64 * 0.01);
        }
        assert!((a.sp - b.sp).abs() < 1e-12);
    }

    #[test]
    fn hysteresis_derivative_matches_fd_on_both_branches() {
        let hy = Hysteresis {
            h0: 0.3,
            h1: 2.0,
            h2: 5.0,
            xs: 0.05,
        };
        let st = LawState {
            sp: 0.1,
            x: 0.2,
            dir: 1.0,
        };
        for &x in &[0.27, 0.13, -0.1, 0.5] {
            let h = 1e-7;
            let fd = (hy.eval(&st, x + h).0 - hy.eval(&st, x - h).0) / (2.0 * h);
            let d = hy.eval(&st, x).1;
            assert!(
                (fd - d).abs() <= 1e-6 * d.abs().max(1.0),
                "x={x} fd={fd} d={d}"
            );
        }
    }
}
