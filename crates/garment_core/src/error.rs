//! The core's errors: one [`Error`] enum whose variants are the kinds of
//! failure a caller can tell apart (a step that diverged, a linear solve
//! that failed, an input outside its bound, a bad mesh or index, …). Each
//! carries the figures its message names; [`std::fmt::Display`] gives the
//! message, and [`std::error::Error::source`] the error under a
//! [`Error::Context`] or [`Error::StepFailed`].

use std::fmt;

/// The result of the core's fallible functions.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// An error of the core. The variants are kinds; the message each shows is
/// in its fields (`message` where the text is specific to the place that
/// failed).
#[derive(Debug)]
#[non_exhaustive]
pub enum Error {
    /// A step met a non-finite value at a vertex.
    Diverged {
        /// The vertex.
        vertex: usize,
        /// The step's index (steps taken before it).
        step: u64,
        /// Simulated time at the step's start, s.
        time: f64,
        /// What was non-finite: `"force"`, `"velocity"` or `"position correction"`.
        quantity: &'static str,
        /// Whether the vertex was pinned.
        pinned: bool,
        /// [`crate::Simulation::diagnose`] at the step's start.
        diagnosis: String,
    },
    /// A step whose linear solve failed: `source` is the solver's error;
    /// the message is the diagnosis of the step's start.
    StepFailed {
        /// The step's index (steps taken before it).
        step: u64,
        /// [`crate::Simulation::diagnose`] at the step's start.
        diagnosis: String,
        /// The linear solver's error.
        source: Box<Error>,
    },
    /// The conjugate gradients did not reach the tolerance.
    NotConverged {
        /// The iteration cap.
        max_iterations: usize,
        /// The residual ratio ‖r‖/‖r₀‖ reached.
        residual_ratio: f64,
        /// `Some(it)`: stopped early at iteration `it`, the rate showing the
        /// cap would be passed; `None`: the cap was reached.
        stopped_at: Option<usize>,
    },
    /// The conjugate gradients broke down (non-finite values, an
    /// indefinite matrix, an underflow).
    Breakdown {
        /// Why, as the message names it after "PCG breakdown: ".
        reason: String,
    },
    /// The direct solver could not analyse or factor the matrix.
    Factorization {
        /// The message.
        message: String,
    },
    /// An input outside its bound.
    OutOfBound {
        /// The input's name (a parameter, a file's field).
        field: String,
        /// Its value (for a vector, the magnitude the bound is on).
        value: f64,
        /// The message, naming the field, the value and the bound with its unit.
        message: String,
    },
    /// An input with a non-finite entry.
    NonFinite {
        /// What holds it.
        field: String,
        /// The entry's index.
        index: usize,
        /// The message.
        message: String,
    },
    /// A list of the wrong length.
    Length {
        /// What the list holds.
        what: String,
        /// Its length.
        got: usize,
        /// The length it must have.
        expected: usize,
        /// The message.
        message: String,
    },
    /// An index beyond what it indexes.
    Index {
        /// What the index names (a vertex, a fabric, …).
        what: String,
        /// The index.
        index: usize,
        /// How many there are.
        len: usize,
        /// The message.
        message: String,
    },
    /// A mesh, outline or grid that cannot be used as given.
    Mesh {
        /// The message.
        message: String,
    },
    /// A start state the contacts cannot resolve: cloth tangled, caught on
    /// or overlapping an obstacle, a panel inside the body.
    Placement {
        /// The message.
        message: String,
    },
    /// A cloth larger than a limit on vertices or memory.
    TooLarge {
        /// The message.
        message: String,
    },
    /// Fabric data that cannot be used: a missing or inconsistent value, a
    /// malformed KES curve.
    Fabric {
        /// The message.
        message: String,
    },
    /// Another input that cannot be used (a name nothing has, a change the
    /// simulation does not allow while it runs, …).
    Invalid {
        /// The message.
        message: String,
    },
    /// An error with what was being done when it happened.
    Context {
        /// What was being done (the message).
        context: String,
        /// The error.
        source: Box<Error>,
    },
    /// An error from outside the core (a number that does not parse, a
    /// curve the caller could not read), with what was being done.
    External {
        /// What was being done (the message).
        context: String,
        /// The error.
        source: Box<dyn std::error::Error + Send + Sync + 'static>,
    },
}

/// `$body` with `$m` bound to the message of a kind whose message is a
/// field of its own, else `$other`.
macro_rules! with_message {
    ($e:expr, $m:ident => $body:expr, $other:expr) => {
        match $e {
            Error::Factorization { message: $m }
            | Error::OutOfBound { message: $m, .. }
            | Error::NonFinite { message: $m, .. }
            | Error::Length { message: $m, .. }
            | Error::Index { message: $m, .. }
            | Error::Mesh { message: $m }
            | Error::Placement { message: $m }
            | Error::TooLarge { message: $m }
            | Error::Fabric { message: $m }
            | Error::Invalid { message: $m } => $body,
            _ => $other,
        }
    };
}

impl Error {
    /// The error under every [`Error::Context`] and [`Error::StepFailed`]:
    /// the kind of the failure itself.
    pub fn root(&self) -> &Error {
        match self {
            Error::Context { source, .. } | Error::StepFailed { source, .. } => source.root(),
            e => e,
        }
    }

    /// This error under `context` (what was being done).
    pub fn context(self, context: impl Into<String>) -> Error {
        Error::Context {
            context: context.into(),
            source: Box::new(self),
        }
    }

    /// This error with `prefix` before its message, of the same kind (a
    /// kind whose message is not a field of its own: [`Error::Invalid`]).
    pub(crate) fn prefixed(self, prefix: &str) -> Error {
        let mut e = self;
        let own = with_message!(&mut e, message => {
            message.insert_str(0, prefix);
            true
        }, false);
        match own {
            true => e,
            false => Error::invalid(format!("{prefix}{e}")),
        }
    }

    pub(crate) fn bound(field: impl Into<String>, value: f64, message: String) -> Error {
        Error::OutOfBound {
            field: field.into(),
            value,
            message,
        }
    }

    pub(crate) fn non_finite(field: impl Into<String>, index: usize, message: String) -> Error {
        Error::NonFinite {
            field: field.into(),
            index,
            message,
        }
    }

    pub(crate) fn length(
        what: impl Into<String>,
        got: usize,
        expected: usize,
        message: String,
    ) -> Error {
        Error::Length {
            what: what.into(),
            got,
            expected,
            message,
        }
    }

    pub(crate) fn index(
        what: impl Into<String>,
        index: usize,
        len: usize,
        message: String,
    ) -> Error {
        Error::Index {
            what: what.into(),
            index,
            len,
            message,
        }
    }

    pub(crate) fn mesh(message: impl Into<String>) -> Error {
        Error::Mesh {
            message: message.into(),
        }
    }

    pub(crate) fn placement(message: impl Into<String>) -> Error {
        Error::Placement {
            message: message.into(),
        }
    }

    pub(crate) fn too_large(message: impl Into<String>) -> Error {
        Error::TooLarge {
            message: message.into(),
        }
    }

    pub(crate) fn fabric(message: impl Into<String>) -> Error {
        Error::Fabric {
            message: message.into(),
        }
    }

    pub(crate) fn invalid(message: impl Into<String>) -> Error {
        Error::Invalid {
            message: message.into(),
        }
    }

    pub(crate) fn breakdown(reason: impl Into<String>) -> Error {
        Error::Breakdown {
            reason: reason.into(),
        }
    }

    pub(crate) fn factorization(message: impl Into<String>) -> Error {
        Error::Factorization {
            message: message.into(),
        }
    }

    pub(crate) fn external(
        context: impl Into<String>,
        source: impl Into<Box<dyn std::error::Error + Send + Sync + 'static>>,
    ) -> Error {
        Error::External {
            context: context.into(),
            source: source.into(),
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Diverged {
                vertex,
                time,
                quantity,
                pinned,
                diagnosis,
                ..
            } => write!(
                f,
                "the step diverged at vertex {vertex} (non-finite {quantity}{}) at t = {time:.4} s; \
                 {diagnosis}",
                if *pinned { ", pinned" } else { "" },
            ),
            Error::StepFailed { diagnosis, .. } => f.write_str(diagnosis),
            Error::NotConverged {
                max_iterations,
                residual_ratio,
                stopped_at: None,
            } => write!(
                f,
                "PCG did not converge in {max_iterations} iterations (residual ratio \
                 {residual_ratio:.2e})"
            ),
            Error::NotConverged {
                max_iterations,
                residual_ratio,
                stopped_at: Some(it),
            } => write!(
                f,
                "PCG would not converge in {max_iterations} iterations (residual ratio \
                 {residual_ratio:.2e} after {it})"
            ),
            Error::Breakdown { reason } => write!(f, "PCG breakdown: {reason}"),
            Error::Context { context, .. } | Error::External { context, .. } => f.write_str(context),
            e => with_message!(
                e,
                message => f.write_str(message),
                unreachable!("each kind without a message field is written above")
            ),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Context { source, .. } | Error::StepFailed { source, .. } => Some(&**source),
            Error::External { source, .. } => Some(&**source),
            _ => None,
        }
    }
}

/// `return Err(Error::$kind(format!(...)))`, or with the constructor's
/// leading arguments `fail!(bound(field, value), ...)`: the core's `bail!`.
macro_rules! fail {
    ($kind:ident($($a:expr),*), $($arg:tt)+) => {
        return Err($crate::Error::$kind($($a,)* format!($($arg)+)))
    };
    ($kind:ident, $($arg:tt)+) => {
        return Err($crate::Error::$kind(format!($($arg)+)))
    };
}
pub(crate) use fail;

#[cfg(test)]
mod tests {
    use super::Error;
    use crate::solver::linear::{Cap, Direct, Filter, Pcg, Precision, Preconditioner};
    use crate::solver::sparse::BlockMatrix;
    use crate::solver::team::Team;
    use nalgebra::{Matrix3, Vector3};

    /// Two coupled vertices whose matrix is −I: not positive definite.
    fn negative() -> BlockMatrix {
        let mut a = BlockMatrix::from_cliques(2, [&[0usize, 1][..]].into_iter());
        for i in 0..2 {
            let d = a.diag[i];
            a.val[d] = -Matrix3::identity();
        }
        a
    }

    #[test]
    fn the_conjugate_gradients_on_a_negative_matrix_break_down() {
        let a = negative();
        let b = vec![Vector3::new(1.0, 0.0, 0.0); 2];
        let (filter, z) = (vec![Filter::Free; 2], vec![Vector3::zeros(); 2]);
        let mut x = vec![Vector3::zeros(); 2];
        for precond in [Preconditioner::BlockJacobi, Preconditioner::Sgs] {
            let e = Pcg::default()
                .solve(
                    &a,
                    &b,
                    &filter,
                    &z,
                    &mut x,
                    1e-6,
                    Cap::Hard(10),
                    precond,
                    &mut Team::new(1),
                )
                .unwrap_err();
            match &e {
                Error::Breakdown { reason } => assert!(!reason.is_empty()),
                e => panic!("not Breakdown: {e:?}"),
            }
            assert!(e.to_string().starts_with("PCG breakdown: "), "{e}");
        }
    }

    #[test]
    fn the_cholesky_factor_of_a_negative_matrix_is_a_factorization_error() {
        let a = negative();
        let mut d = Direct::new(&a).unwrap();
        let e = d
            .factorize(&a, &[Filter::Free; 2], &[1.0; 2], Precision::F64)
            .unwrap_err();
        assert!(matches!(e, Error::Factorization { .. }), "{e:?}");
        assert!(e.to_string().starts_with("sparse Cholesky failed"), "{e}");
    }
}
