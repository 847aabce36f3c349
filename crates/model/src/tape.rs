//! The straight-line program of a model's functions and derivatives: operations on f64
//! registers, interpreted here and compiled to machine code by `jit.rs` (the `jit` feature).

/// One operation of a [`Tape`], on registers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Instr {
    Neg(u32),
    Add(u32, u32),
    Sub(u32, u32),
    Mul(u32, u32),
    Div(u32, u32),
    /// x² (as `powi(2)` computes it).
    Square(u32),
    /// x³ (as `powi(3)` computes it: x·x²).
    Cube(u32),
    PowI(u32, i32),
    /// x^c, c in a register.
    PowF(u32, u32),
    Pow(u32, u32),
    Exp(u32),
    Log(u32),
    Sqrt(u32),
    Sin(u32),
    Cos(u32),
    Tan(u32),
    Tanh(u32),
    Abs(u32),
    Signum(u32),
    Min(u32, u32),
    Max(u32, u32),
    Less(u32, u32, u32, u32),
}

impl Instr {
    /// The registers the operation reads (the JIT's segments pass on those a later one reads).
    #[cfg(feature = "jit")]
    pub(crate) fn operands(&self) -> impl Iterator<Item = u32> {
        let (list, count) = match *self {
            Instr::Neg(a)
            | Instr::Square(a)
            | Instr::Cube(a)
            | Instr::PowI(a, _)
            | Instr::Exp(a)
            | Instr::Log(a)
            | Instr::Sqrt(a)
            | Instr::Sin(a)
            | Instr::Cos(a)
            | Instr::Tan(a)
            | Instr::Tanh(a)
            | Instr::Abs(a)
            | Instr::Signum(a) => ([a, 0, 0, 0], 1),
            Instr::Add(a, c)
            | Instr::Sub(a, c)
            | Instr::Mul(a, c)
            | Instr::Div(a, c)
            | Instr::PowF(a, c)
            | Instr::Pow(a, c)
            | Instr::Min(a, c)
            | Instr::Max(a, c) => ([a, c, 0, 0], 2),
            Instr::Less(a, c, d, e) => ([a, c, d, e], 4),
        };
        list.into_iter().take(count)
    }
}

/// A straight-line program over f64 registers: register 0 holds t, then the n states, the
/// parameters, the inputs and the constants; instruction i writes register `first + i`,
/// reading only registers before it. The first [`fixed`](Self::fixed) instructions (none,
/// or a part that reads at least one parameter) read neither t, the states nor the inputs:
/// at the parameters of the last run their registers still hold their values, and the
/// compiled code skips them.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Tape {
    n: usize,
    np: usize,
    nu: usize,
    constants: Vec<f64>,
    code: Vec<Instr>,
    fixed: usize,
}

impl Tape {
    /// The program of `constants` and `code` for n states, n_α parameters and n_u inputs,
    /// whose first `fixed` instructions depend on the parameters and constants alone.
    pub(crate) fn new(
        (n, np, nu): (usize, usize, usize),
        constants: Vec<f64>,
        code: Vec<Instr>,
        fixed: usize,
    ) -> Self {
        debug_assert!(fixed <= code.len());
        Self { n, np, nu, constants, code, fixed }
    }

    /// How many instructions, from the first, depend on the parameters and constants alone.
    #[cfg(feature = "jit")]
    pub(crate) fn fixed(&self) -> usize {
        self.fixed
    }

    /// The first register holding a constant.
    fn first_constant(&self) -> usize {
        1 + self.n + self.np + self.nu
    }

    /// The first register written by an instruction.
    pub(crate) fn first(&self) -> usize {
        self.first_constant() + self.constants.len()
    }

    /// The numbers of states, parameters and inputs.
    #[cfg(feature = "jit")]
    pub(crate) fn dims(&self) -> (usize, usize, usize) {
        (self.n, self.np, self.nu)
    }

    /// The number of registers.
    pub(crate) fn len(&self) -> usize {
        self.first() + self.code.len()
    }

    /// The value of register `r` if it holds a constant.
    #[cfg(feature = "jit")]
    pub(crate) fn constant(&self, r: usize) -> Option<f64> {
        r.checked_sub(self.first_constant()).and_then(|c| self.constants.get(c).copied())
    }

    /// The instructions; instruction i writes register `first() + i`.
    pub(crate) fn code(&self) -> &[Instr] {
        &self.code
    }

    /// Registers with the constants loaded, and the parameters' NaN: no run has computed
    /// the [fixed](Self::fixed) instructions' registers yet.
    pub(crate) fn registers(&self) -> Vec<f64> {
        let mut r = vec![0.0; self.len()];
        r[1 + self.n..1 + self.n + self.np].fill(f64::NAN);
        let at = self.first_constant();
        r[at..at + self.constants.len()].copy_from_slice(&self.constants);
        r
    }

    /// Sets the registers of (t, y, α, u).
    pub(crate) fn load(&self, t: f64, y: &[f64], p: &[f64], u: &[f64], r: &mut [f64]) {
        let (n, np) = (self.n, self.np);
        r[0] = t;
        r[1..1 + n].copy_from_slice(&y[..n]);
        r[1 + n..1 + n + np].copy_from_slice(&p[..np]);
        r[1 + n + np..1 + n + np + self.nu].copy_from_slice(&u[..self.nu]);
    }

    /// Interprets the program on registers from [`registers`](Self::registers) whose inputs
    /// are [loaded](Self::load).
    pub(crate) fn interpret(&self, r: &mut [f64]) {
        // Cells: every instruction reads registers before its own and writes its own.
        let r = std::cell::Cell::from_mut(r).as_slice_of_cells();
        for (instr, out) in self.code.iter().zip(&r[self.first()..]) {
            let x = |a: u32| r[a as usize].get();
            let value = match *instr {
                Instr::Neg(a) => -x(a),
                Instr::Add(a, b) => x(a) + x(b),
                Instr::Sub(a, b) => x(a) - x(b),
                Instr::Mul(a, b) => x(a) * x(b),
                Instr::Div(a, b) => x(a) / x(b),
                Instr::Square(a) => x(a) * x(a),
                Instr::Cube(a) => x(a) * (x(a) * x(a)),
                Instr::PowI(a, k) => x(a).powi(k),
                Instr::PowF(a, c) => x(a).powf(x(c)),
                Instr::Pow(a, b) => x(a).powf(x(b)),
                Instr::Exp(a) => x(a).exp(),
                Instr::Log(a) => x(a).ln(),
                Instr::Sqrt(a) => x(a).sqrt(),
                Instr::Sin(a) => x(a).sin(),
                Instr::Cos(a) => x(a).cos(),
                Instr::Tan(a) => x(a).tan(),
                Instr::Tanh(a) => x(a).tanh(),
                Instr::Abs(a) => x(a).abs(),
                Instr::Signum(a) => x(a).signum(),
                Instr::Min(a, b) => {
                    if x(b) < x(a) {
                        x(b)
                    } else {
                        x(a)
                    }
                }
                Instr::Max(a, b) => {
                    if x(b) > x(a) {
                        x(b)
                    } else {
                        x(a)
                    }
                }
                Instr::Less(a, b, c, d) => {
                    if x(a) < x(b) {
                        x(c)
                    } else {
                        x(d)
                    }
                }
            };
            out.set(value);
        }
    }
}
