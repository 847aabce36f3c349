//! Jacobian–matrix products by forward-mode dual numbers: g(t, y, α, u) and
//! J_y V_y + J_α V_α for a batch of K directions, W directions per model evaluation.
//!
//! This is how sysid differentiates models: the right-hand side (or the outputs) is
//! evaluated with vector dual numbers whose derivative parts are the directions, so the
//! Jacobian is never formed and nothing is allocated per call. The sensitivity equations
//! use the columns of S as directions; quasilinearization uses the columns of Φ and the
//! displacement from the previous trajectory.

use nalgebra::{Const, SVector, U1};
use num_dual::{Derivative, DualSVec64};

use crate::system::System;

/// Which function of the system to differentiate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Function {
    /// The right-hand side g (length n).
    Rhs,
    /// The outputs h (length of the signature's outputs).
    Outputs,
}

/// Preallocated work space for g and J·V with K directions.
///
/// Directions are given row by row: `vy` is n × K (row i: the K directions' components for
/// state i) and `vp` is n_α × K; the products come back row by row in the same way. The
/// parameters and their directions are set once ([`set_parameters`](Self::set_parameters))
/// and reused by every evaluation: they are constant during an integration.
pub struct JacobianProducts {
    duals: Duals,
    /// The parameter values, for evaluations without directions.
    p: Vec<f64>,
}

impl JacobianProducts {
    /// Work space for `n` states, the parameters `p` with directions `vp` (n_α × K, row by
    /// row), `m` function values and K = `directions` directions.
    pub fn new(n: usize, p: &[f64], vp: &[f64], m: usize, directions: usize) -> Self {
        let mut products = Self { duals: Duals::new(n, p.len(), m, directions), p: p.to_vec() };
        products.set_parameters(p, vp);
        products
    }

    /// New parameter values and directions.
    pub fn set_parameters(&mut self, p: &[f64], vp: &[f64]) {
        self.p.copy_from_slice(p);
        self.duals.set_parameters(p, vp);
    }

    /// value = f(t, y, p, u) and out = J_y vy + J_p vp (both row-major with K columns),
    /// where f is the right-hand side or the outputs.
    #[allow(clippy::too_many_arguments)]
    pub fn eval<S: System>(
        &mut self,
        sys: &S,
        function: Function,
        (t, y, u): (f64, &[f64], &[f64]),
        vy: &[f64],
        value: &mut [f64],
        out: &mut [f64],
    ) {
        self.duals.eval(sys, function, (t, y, &self.p, u), vy, value, out);
    }
}

/// Dual-number buffers of one chunk width W (a const generic, chosen at run time).
struct Chunked<const W: usize> {
    /// Number of directions K.
    k: usize,
    yd: Vec<DualSVec64<W>>,
    /// Per chunk of directions: the seeded parameters.
    pd: Vec<Vec<DualSVec64<W>>>,
    fd: Vec<DualSVec64<W>>,
}

impl<const W: usize> Chunked<W> {
    fn new(n: usize, np: usize, m: usize, k: usize) -> Self {
        let zero = DualSVec64::<W>::from_re(0.0);
        let chunks = k.div_ceil(W);
        Self { k, yd: vec![zero; n], pd: vec![vec![zero; np]; chunks], fd: vec![zero; m] }
    }

    fn set_parameters(&mut self, p: &[f64], vp: &[f64]) {
        let k = self.k;
        for (c, pd) in self.pd.iter_mut().enumerate() {
            let first = c * W;
            Self::seed(pd, p, vp, k, first, W.min(k - first));
        }
    }

    /// Seeds `duals` with values `x` and directions `v[i*K + first ..][..width]`.
    #[inline(always)]
    fn seed(
        duals: &mut [DualSVec64<W>],
        x: &[f64],
        v: &[f64],
        k: usize,
        first: usize,
        width: usize,
    ) {
        // Copies of compile-time length for a full chunk (the usual case): no memcpy call.
        for (i, d) in duals.iter_mut().enumerate() {
            let at = i * k + first;
            let seed = if width == W {
                let row: [f64; W] = v[at..at + W].try_into().expect("a full chunk");
                SVector::from(row)
            } else {
                SVector::from_fn(|j, _| if j < width { v[at + j] } else { 0.0 })
            };
            *d = DualSVec64::new(x[i], Derivative::some(seed));
        }
    }

    // One function per width, never inlined into the dispatch over widths: the model's
    // right-hand side then compiles the same way whichever crate instantiates it (25 %
    // apart on van der Pol between two such crates otherwise).
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn eval<S: System>(
        &mut self,
        sys: &S,
        function: Function,
        (t, y, u): (f64, &[f64], &[f64]),
        vy: &[f64],
        value: &mut [f64],
        out: &mut [f64],
    ) {
        let k = self.k;
        for (c, pd) in self.pd.iter().enumerate() {
            let first = c * W;
            let width = W.min(k - first);
            Self::seed(&mut self.yd, y, vy, k, first, width);
            match function {
                Function::Rhs => sys.rhs(t, &self.yd, pd, u, &mut self.fd),
                Function::Outputs => sys.outputs(t, &self.yd, pd, u, &mut self.fd),
            }
            for (i, d) in self.fd.iter().enumerate() {
                let eps = d.eps.unwrap_generic(Const::<W>, U1);
                let at = i * k + first;
                if width == W {
                    let row: &mut [f64; W] =
                        (&mut out[at..at + W]).try_into().expect("a full chunk");
                    *row = eps.into();
                } else {
                    out[at..at + width].copy_from_slice(&eps.as_slice()[..width]);
                }
                if first == 0 {
                    value[i] = d.re;
                }
            }
        }
    }
}

macro_rules! duals {
    ($($w:literal => $variant:ident),*) => {
        /// The chunk width for a number of directions: K itself up to 8, else 8.
        enum Duals { None, $($variant(Chunked<$w>)),* }

        impl Duals {
            fn new(n: usize, np: usize, m: usize, k: usize) -> Self {
                match k {
                    0 => Duals::None,
                    $($w => Duals::$variant(Chunked::new(n, np, m, k)),)*
                    _ => Duals::W8(Chunked::new(n, np, m, k)),
                }
            }

            fn set_parameters(&mut self, p: &[f64], vp: &[f64]) {
                match self {
                    Duals::None => {}
                    $(Duals::$variant(c) => c.set_parameters(p, vp),)*
                }
            }

            fn eval<S: System>(
                &mut self,
                sys: &S,
                function: Function,
                (t, y, p, u): (f64, &[f64], &[f64], &[f64]),
                vy: &[f64],
                value: &mut [f64],
                out: &mut [f64],
            ) {
                match self {
                    Duals::None => match function {
                        Function::Rhs => sys.rhs(t, y, p, u, value),
                        Function::Outputs => sys.outputs(t, y, p, u, value),
                    },
                    $(Duals::$variant(c) => c.eval(sys, function, (t, y, u), vy, value, out),)*
                }
            }
        }
    };
}
duals!(1 => W1, 2 => W2, 3 => W3, 4 => W4, 5 => W5, 6 => W6, 7 => W7, 8 => W8);
