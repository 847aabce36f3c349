//! Symbolic derivatives of a model's expressions, and one straight-line program that
//! evaluates the functions together with their Jacobian.
//!
//! At load time the compiled expressions ([`Program`]) of the right-hand side (or of the
//! outputs) are put into one [`Graph`] in which every subexpression is stored once
//! (hash-consing): building a term that already exists returns it, so subexpressions common
//! to several equations and to their derivatives are computed once. Each function is
//! differentiated with respect to every state and every parameter by the rules of
//! calculus, and each new term is simplified as it is built: constants folded, zero and
//! unit terms dropped (x + 0, x·1, x·0, 0/x, …), and commutative operands put in a fixed
//! order so that a·b and b·a are one term. A derivative that simplifies to the constant 0
//! is a structural zero of the Jacobian.
//!
//! The functions and the nonzero Jacobian entries are then emitted, children first, as one
//! [`Tape`]: a straight-line program over f64 registers (t, y, α, u, the constants, then one
//! register per operation), evaluated by one loop without recursion or allocation. Its
//! derivatives are those of the dual numbers ([`Program::eval`] with `num_dual` scalars),
//! term by term: min and max follow the branch that the value takes, |x| has the
//! derivative sign(x) (+1 at +0, as `num_dual` has it), so the two agree to rounding
//! wherever the subexpressions are finite. At infinities, NaN and signed zeros the
//! simplifications are those of algebra, not of IEEE arithmetic: x·0 is 0 where dual
//! numbers would give NaN for an infinite x, and 0 − x is −x, which is −0 at x = +0 (so
//! |0 − x| has the derivative −1 there, not +1).

use rustc_hash::FxHashMap as HashMap;

use sysid_ode::SparseJacobian;

use crate::expr::{Func, Node, Operand, Program, Slot, eval_func};
use crate::tape::{Instr, Tape};

/// The index of a term in a [`Graph`].
type Id = u32;

/// A term of the graph; children are terms built before it (smaller ids).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Term {
    /// A constant, by its bits.
    Const(u64),
    Var(Slot),
    Neg(Id),
    Add(Id, Id),
    Sub(Id, Id),
    Mul(Id, Id),
    Div(Id, Id),
    PowI(Id, i32),
    /// x^c for a constant term c.
    PowF(Id, Id),
    Pow(Id, Id),
    /// A function of one argument.
    Func(Func, Id),
    /// sign(x): +1 for x ≥ +0, −1 for x ≤ −0.
    Signum(Id),
    /// min(a, b) = b if b < a, else a (as [`Program::eval`] has it).
    Min(Id, Id),
    /// max(a, b) = b if b > a, else a.
    Max(Id, Id),
    /// c if a < b, else d: the derivative of min and max.
    Less(Id, Id, Id, Id),
}

/// Expressions with every subexpression stored once.
#[derive(Debug, Default)]
struct Graph {
    terms: Vec<Term>,
    ids: HashMap<Term, Id>,
}

impl Graph {
    /// The id of `term`, added if new.
    fn intern(&mut self, term: Term) -> Id {
        if let Some(&id) = self.ids.get(&term) {
            return id;
        }
        let id = self.terms.len() as Id;
        self.terms.push(term);
        self.ids.insert(term, id);
        id
    }

    fn constant(&mut self, c: f64) -> Id {
        self.intern(Term::Const(c.to_bits()))
    }

    /// The value of a constant term.
    fn value(&self, id: Id) -> Option<f64> {
        match self.terms[id as usize] {
            Term::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        }
    }

    fn is(&self, id: Id, c: f64) -> bool {
        self.value(id) == Some(c)
    }

    fn is_zero(&self, id: Id) -> bool {
        self.is(id, 0.0)
    }

    fn neg(&mut self, a: Id) -> Id {
        match (self.terms[a as usize], self.value(a)) {
            (_, Some(x)) => self.constant(-x),
            (Term::Neg(x), _) => x,
            _ => self.intern(Term::Neg(a)),
        }
    }

    fn add(&mut self, a: Id, b: Id) -> Id {
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => self.constant(x + y),
            (Some(0.0), _) => b,
            (_, Some(0.0)) => a,
            // Addition is commutative in floating point too: one order for both.
            _ => self.intern(Term::Add(a.min(b), a.max(b))),
        }
    }

    fn sub(&mut self, a: Id, b: Id) -> Id {
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => self.constant(x - y),
            (_, Some(0.0)) => a,
            (Some(0.0), _) => self.neg(b),
            _ => self.intern(Term::Sub(a, b)),
        }
    }

    fn mul(&mut self, a: Id, b: Id) -> Id {
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => self.constant(x * y),
            (Some(0.0), _) | (_, Some(0.0)) => self.constant(0.0),
            (Some(1.0), _) => b,
            (_, Some(1.0)) => a,
            (Some(-1.0), _) => self.neg(b),
            (_, Some(-1.0)) => self.neg(a),
            _ => self.intern(Term::Mul(a.min(b), a.max(b))),
        }
    }

    /// a/b: by a constant an exact division, else a·(1/b) as dual numbers divide, with 1/b
    /// shared by every quotient of the same denominator.
    fn div(&mut self, a: Id, b: Id) -> Id {
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => self.constant(x / y),
            (Some(0.0), _) => self.constant(0.0),
            (_, Some(1.0)) => a,
            (_, Some(-1.0)) => self.neg(a),
            (_, Some(_)) => self.intern(Term::Div(a, b)),
            _ => {
                let inverse = self.recip(b);
                self.mul(a, inverse)
            }
        }
    }

    /// 1/b.
    fn recip(&mut self, b: Id) -> Id {
        match self.value(b) {
            Some(y) => self.constant(1.0 / y),
            None => {
                let one = self.constant(1.0);
                self.intern(Term::Div(one, b))
            }
        }
    }

    fn powi(&mut self, a: Id, n: i32) -> Id {
        match (self.value(a), n) {
            (Some(x), _) => self.constant(x.powi(n)),
            (_, 0) => self.constant(1.0),
            (_, 1) => a,
            _ => self.intern(Term::PowI(a, n)),
        }
    }

    fn powf(&mut self, a: Id, c: f64) -> Id {
        match self.value(a) {
            Some(x) => self.constant(x.powf(c)),
            None => {
                let c = self.constant(c);
                self.intern(Term::PowF(a, c))
            }
        }
    }

    fn pow(&mut self, a: Id, b: Id) -> Id {
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => self.constant(x.powf(y)),
            _ => self.intern(Term::Pow(a, b)),
        }
    }

    fn func(&mut self, f: Func, a: Id) -> Id {
        match self.value(a) {
            Some(x) => self.constant(eval_func(f, x)),
            None => self.intern(Term::Func(f, a)),
        }
    }

    fn signum(&mut self, a: Id) -> Id {
        match self.value(a) {
            Some(x) => self.constant(x.signum()),
            None => self.intern(Term::Signum(a)),
        }
    }

    fn min(&mut self, a: Id, b: Id) -> Id {
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => self.constant(if y < x { y } else { x }),
            _ => self.intern(Term::Min(a, b)),
        }
    }

    fn max(&mut self, a: Id, b: Id) -> Id {
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => self.constant(if y > x { y } else { x }),
            _ => self.intern(Term::Max(a, b)),
        }
    }

    /// c if a < b, else d.
    fn less(&mut self, a: Id, b: Id, c: Id, d: Id) -> Id {
        if c == d {
            return c;
        }
        match (self.value(a), self.value(b)) {
            (Some(x), Some(y)) => {
                if x < y {
                    c
                } else {
                    d
                }
            }
            _ => self.intern(Term::Less(a, b, c, d)),
        }
    }

    /// The graph of a compiled expression; returns its root.
    fn program(&mut self, program: &Program) -> Id {
        let mut ids: Vec<Id> = Vec::with_capacity(program.nodes().len());
        let operand = |g: &mut Graph, ids: &[Id], o: Operand| match o {
            Operand::Node(i) => ids[i as usize],
            Operand::Var(slot) => g.intern(Term::Var(slot)),
            Operand::Const(c) => g.constant(c),
        };
        for node in program.nodes() {
            let mut get = |o: Operand| operand(self, &ids, o);
            let id = match *node {
                Node::Neg(a) => {
                    let a = get(a);
                    self.neg(a)
                }
                Node::Add(a, b) => {
                    let (a, b) = (get(a), get(b));
                    self.add(a, b)
                }
                Node::Sub(a, b) => {
                    let (a, b) = (get(a), get(b));
                    self.sub(a, b)
                }
                Node::Mul(a, b) => {
                    let (a, b) = (get(a), get(b));
                    self.mul(a, b)
                }
                Node::Div(a, b) => {
                    let (a, b) = (get(a), get(b));
                    self.div(a, b)
                }
                Node::AddC(a, c) => {
                    let (a, c) = (get(a), self.constant(c));
                    self.add(a, c)
                }
                Node::SubC(c, a) => {
                    let (a, c) = (get(a), self.constant(c));
                    self.sub(c, a)
                }
                Node::MulC(a, c) => {
                    let (a, c) = (get(a), self.constant(c));
                    self.mul(a, c)
                }
                Node::DivC(a, c) => {
                    let (a, c) = (get(a), self.constant(c));
                    self.div(a, c)
                }
                Node::CDiv(c, a) => {
                    let (a, c) = (get(a), self.constant(c));
                    self.div(c, a)
                }
                Node::PowI(a, n) => {
                    let a = get(a);
                    self.powi(a, n)
                }
                Node::PowF(a, c) => {
                    let a = get(a);
                    self.powf(a, c)
                }
                Node::Pow(a, b) => {
                    let (a, b) = (get(a), get(b));
                    self.pow(a, b)
                }
                Node::Func(f, a) => {
                    let a = get(a);
                    self.func(f, a)
                }
                Node::Min(a, b) => {
                    let (a, b) = (get(a), get(b));
                    self.min(a, b)
                }
                Node::Max(a, b) => {
                    let (a, b) = (get(a), get(b));
                    self.max(a, b)
                }
                Node::Less(a, b, c, d) => {
                    let (a, b, c, d) = (get(a), get(b), get(c), get(d));
                    self.less(a, b, c, d)
                }
            };
            ids.push(id);
        }
        operand(self, &ids, program.root())
    }

    /// The terms that `roots` depend on, ascending (children before parents).
    fn reachable(&self, roots: &[Id]) -> Vec<Id> {
        let mut seen = vec![false; self.terms.len()];
        let mut stack: Vec<Id> = roots.to_vec();
        while let Some(id) = stack.pop() {
            if std::mem::replace(&mut seen[id as usize], true) {
                continue;
            }
            stack.extend(children(self.terms[id as usize]));
        }
        (0..self.terms.len() as Id).filter(|&id| seen[id as usize]).collect()
    }

    /// ∂root/∂`wrt` for every root, built in the graph.
    fn derivatives(&mut self, roots: &[Id], wrt: Slot) -> Vec<Id> {
        let mut column = vec![self.constant(0.0); roots.len()];
        for (row, derivative) in self.columns(roots, &[wrt]).pop().unwrap_or_default() {
            column[row as usize] = derivative;
        }
        column
    }

    /// ∂root/∂s for each slot s of `wrt`, built in the graph: the column's nonzero entries
    /// (row, derivative), rows ascending. Forward mode from s's own term through the terms
    /// that use it, children first (no recursion): a state's column visits the few terms that
    /// depend on the state, not the whole right-hand side, and holds its nonzero entries
    /// alone (a model of 20 000 uncoupled states held 20 000² ids in its columns and
    /// visited as many terms, 3.2 GB and most of a minute before its first fit).
    fn columns(&mut self, roots: &[Id], wrt: &[Slot]) -> Vec<Vec<(u32, Id)>> {
        let reachable = self.reachable(roots);
        let mut walk = Walk::new(&self.terms, &reachable, roots);
        wrt.iter().map(|&wrt| self.column(wrt, &mut walk)).collect()
    }

    /// One column of [`columns`](Self::columns).
    fn column(&mut self, wrt: Slot, walk: &mut Walk) -> Vec<(u32, Id)> {
        let zero = self.constant(0.0);
        let Some(&start) = walk.var.get(&wrt) else {
            return Vec::new();
        };
        let dependents = walk.dependents(start);
        let (d, stamp, mark) = (&mut walk.d, &walk.stamp, walk.mark);
        for &id in &dependents {
            let term = self.terms[id as usize];
            // A child that does not depend on s has the derivative 0.
            let dx = |x: Id| if stamp[x as usize] == mark { d[x as usize] } else { zero };
            let derivative = match term {
                Term::Const(_) | Term::Signum(_) => zero,
                Term::Var(slot) => {
                    if slot == wrt {
                        self.constant(1.0)
                    } else {
                        zero
                    }
                }
                Term::Neg(a) => self.neg(dx(a)),
                Term::Add(a, b) => self.add(dx(a), dx(b)),
                Term::Sub(a, b) => self.sub(dx(a), dx(b)),
                Term::Mul(a, b) => {
                    let (da, db) = (dx(a), dx(b));
                    let left = self.mul(da, b);
                    let right = self.mul(a, db);
                    self.add(left, right)
                }
                Term::Div(a, b) => {
                    // (da − (a/b)·db) / b, with a/b the term itself (b is a constant, or
                    // a = 1 and the term is 1/b).
                    let (da, db) = (dx(a), dx(b));
                    let q = self.mul(id, db);
                    let top = self.sub(da, q);
                    self.div(top, b)
                }
                Term::PowI(a, n) => {
                    let da = dx(a);
                    if self.is_zero(da) {
                        zero
                    } else {
                        let (c, power) = (self.constant(f64::from(n)), self.powi(a, n - 1));
                        let slope = self.mul(c, power);
                        self.mul(slope, da)
                    }
                }
                Term::PowF(a, c) => {
                    let da = dx(a);
                    if self.is_zero(da) {
                        zero
                    } else {
                        let c = self.value(c).expect("a constant exponent");
                        let (k, power) = (self.constant(c), self.powf(a, c - 1.0));
                        let slope = self.mul(k, power);
                        self.mul(slope, da)
                    }
                }
                Term::Pow(a, b) => {
                    // a^b ln a · db + b a^(b−1) · da, each term in the form that has its
                    // limit at a = 0 (a Hill term Z^n with Z, or its initial value, on a
                    // bound of 0): a^b ln a → 0 for b > 0, b a^(b−1) → 0 for b > 1 (and
                    // b for b = 1), where a^b (db ln a + b da / a) is 0 · ∞ = NaN.
                    let (da, db) = (dx(a), dx(b));
                    let along_b = if self.is_zero(db) {
                        zero
                    } else {
                        let ln = self.func(Func::Log, a);
                        let power_ln = self.mul(id, ln);
                        // a^b ln a where a ≠ 0 (NaN below 0, as a^b), its limit 0 at a = 0.
                        let above = self.less(zero, a, power_ln, zero);
                        let limit = self.less(a, zero, power_ln, above);
                        self.mul(db, limit)
                    };
                    let along_a = if self.is_zero(da) {
                        zero
                    } else {
                        let one = self.constant(1.0);
                        let lower = self.sub(b, one);
                        let power = self.pow(a, lower);
                        let slope = self.mul(b, power);
                        self.mul(slope, da)
                    };
                    self.add(along_b, along_a)
                }
                Term::Func(f, a) => {
                    let da = dx(a);
                    if self.is_zero(da) { zero } else { self.chain(f, id, a, da) }
                }
                Term::Min(a, b) => {
                    let (da, db) = (dx(a), dx(b));
                    self.less(b, a, db, da)
                }
                Term::Max(a, b) => {
                    let (da, db) = (dx(a), dx(b));
                    self.less(a, b, db, da)
                }
                Term::Less(a, b, c, e) => {
                    let (dc, de) = (dx(c), dx(e));
                    self.less(a, b, dc, de)
                }
            };
            d[id as usize] = derivative;
        }
        let mut column: Vec<(u32, Id)> = dependents
            .iter()
            .flat_map(|&id| walk.rows_of(id).iter().map(move |&row| (row, id)))
            .map(|(row, id)| (row, walk.d[id as usize]))
            .filter(|&(_, derivative)| !self.is_zero(derivative))
            .collect();
        column.sort_unstable_by_key(|e| e.0);
        column
    }

    /// The derivative of f(a) (the term `fa`) given da ≠ 0.
    fn chain(&mut self, f: Func, fa: Id, a: Id, da: Id) -> Id {
        let one = self.constant(1.0);
        match f {
            Func::Exp => self.mul(fa, da),
            Func::Log => self.div(da, a),
            Func::Sqrt => {
                let half = self.constant(0.5);
                let top = self.mul(half, da);
                self.div(top, fa)
            }
            Func::Sin => {
                let cos = self.func(Func::Cos, a);
                self.mul(cos, da)
            }
            Func::Cos => {
                let sin = self.func(Func::Sin, a);
                let slope = self.neg(sin);
                self.mul(slope, da)
            }
            Func::Tan => {
                let square = self.mul(fa, fa);
                let slope = self.add(one, square);
                self.mul(slope, da)
            }
            Func::Tanh => {
                let square = self.mul(fa, fa);
                let slope = self.sub(one, square);
                self.mul(slope, da)
            }
            Func::Abs => {
                let sign = self.signum(a);
                self.mul(sign, da)
            }
            _ => unreachable!("functions of several arguments are terms of their own"),
        }
    }
}

/// What forward mode walks over the terms `roots` reach ([`Graph::columns`]): each term's
/// users, the rows each root is, and the work space of one column at a time.
struct Walk {
    /// The users of term `id` among the reachable terms are `users[starts[id]..starts[id +
    /// 1]]` (indexed by id, for the ids below the graph's length at the start).
    starts: Vec<u32>,
    users: Vec<Id>,
    /// The rows whose root is the term: `rows[row_starts[id]..row_starts[id + 1]]`.
    row_starts: Vec<u32>,
    rows: Vec<u32>,
    /// The term of each slot the roots reach.
    var: std::collections::HashMap<Slot, Id>,
    /// The derivatives of the column, valid where `stamp` is `mark`.
    d: Vec<Id>,
    stamp: Vec<u32>,
    mark: u32,
}

impl Walk {
    fn new(terms: &[Term], reachable: &[Id], roots: &[Id]) -> Self {
        let len = terms.len();
        let (mut starts, mut row_starts) = (vec![0u32; len + 1], vec![0u32; len + 1]);
        for &id in reachable {
            for c in children(terms[id as usize]) {
                starts[c as usize + 1] += 1;
            }
        }
        for &r in roots {
            row_starts[r as usize + 1] += 1;
        }
        for i in 0..len {
            starts[i + 1] += starts[i];
            row_starts[i + 1] += row_starts[i];
        }
        let (mut users, mut rows) = (vec![0; starts[len] as usize], vec![0; roots.len()]);
        let (mut next, mut next_row) = (starts.clone(), row_starts.clone());
        // A term with the same child twice (x·x) is its user twice: visited once, below.
        for &id in reachable {
            for c in children(terms[id as usize]) {
                users[next[c as usize] as usize] = id;
                next[c as usize] += 1;
            }
        }
        for (row, &r) in roots.iter().enumerate() {
            rows[next_row[r as usize] as usize] = row as u32;
            next_row[r as usize] += 1;
        }
        let var = reachable
            .iter()
            .filter_map(|&id| match terms[id as usize] {
                Term::Var(slot) => Some((slot, id)),
                _ => None,
            })
            .collect();
        Self { starts, users, row_starts, rows, var, d: vec![0; len], stamp: vec![0; len], mark: 0 }
    }

    /// The terms that depend on `start` (itself included), ascending: children before
    /// parents. Marks them for the column (a new `mark`).
    fn dependents(&mut self, start: Id) -> Vec<Id> {
        self.mark += 1;
        let mut found = vec![start];
        self.stamp[start as usize] = self.mark;
        let mut k = 0;
        while k < found.len() {
            let id = found[k] as usize;
            for &user in &self.users[self.starts[id] as usize..self.starts[id + 1] as usize] {
                if std::mem::replace(&mut self.stamp[user as usize], self.mark) != self.mark {
                    found.push(user);
                }
            }
            k += 1;
        }
        found.sort_unstable();
        found
    }

    /// The rows whose root is term `id`.
    fn rows_of(&self, id: Id) -> &[u32] {
        &self.rows[self.row_starts[id as usize] as usize..self.row_starts[id as usize + 1] as usize]
    }
}

/// The children of a term.
fn children(term: Term) -> impl Iterator<Item = Id> {
    let (list, len): ([Id; 4], usize) = match term {
        Term::Const(_) | Term::Var(_) => ([0; 4], 0),
        Term::Neg(a) | Term::PowI(a, _) | Term::Func(_, a) | Term::Signum(a) => ([a, 0, 0, 0], 1),
        Term::Add(a, b)
        | Term::PowF(a, b)
        | Term::Sub(a, b)
        | Term::Mul(a, b)
        | Term::Div(a, b)
        | Term::Pow(a, b)
        | Term::Min(a, b)
        | Term::Max(a, b) => ([a, b, 0, 0], 2),
        Term::Less(a, b, c, d) => ([a, b, c, d], 4),
    };
    list.into_iter().take(len)
}

/// The cost of a function's call and return, in loads ([`op_cost`]).
const SKIP_CALL: usize = 8;

/// An operation's cost in the units of a load from the work space: one for the arithmetic
/// the processor does in a cycle or two, more for a division or square root, and 20 for a
/// library call (exp, ln, pow, the trigonometric functions).
fn op_cost(term: Term) -> usize {
    match term {
        Term::Const(_) | Term::Var(_) => 0,
        Term::Div(..) | Term::Func(Func::Sqrt, _) => 4,
        Term::PowI(_, 2) | Term::PowI(_, 3) | Term::Func(Func::Abs, _) => 1,
        Term::PowI(..) | Term::PowF(..) | Term::Pow(..) | Term::Func(..) | Term::Signum(_) => 20,
        _ => 1,
    }
}

/// How many distinct terms that `keep` accepts the terms of `ids` that `from` accepts read.
fn operands_read(
    graph: &Graph,
    ids: &[Id],
    from: impl Fn(Id) -> bool,
    keep: impl Fn(Id) -> bool,
) -> usize {
    let mut read: Vec<Id> = ids
        .iter()
        .filter(|&&id| from(id))
        .flat_map(|&id| children(graph.terms[id as usize]))
        .filter(|&c| keep(c))
        .collect();
    read.sort_unstable();
    read.dedup();
    read.len()
}

/// The program computing the terms `outputs` of `graph`, and the register of each.
fn emit(graph: &Graph, outputs: &[Id], (n, np, nu): (usize, usize, usize)) -> (Tape, Vec<u32>) {
    let order = graph.reachable(outputs);
    let mut register: HashMap<Id, u32> =
        HashMap::with_capacity_and_hasher(order.len(), Default::default());
    let mut constants = Vec::new();
    let first_constant = 1 + n + np + nu;
    for &id in &order {
        let r = match graph.terms[id as usize] {
            Term::Var(Slot::Time) => 0,
            Term::Var(Slot::State(i)) => 1 + i,
            Term::Var(Slot::Parameter(q)) => 1 + n + q,
            Term::Var(Slot::Input(j)) => 1 + n + np + j,
            Term::Const(bits) => {
                constants.push(f64::from_bits(bits));
                first_constant + constants.len() - 1
            }
            _ => continue,
        };
        register.insert(id, r as u32);
    }
    let first = first_constant + constants.len();
    // The operations that read neither t, the states nor the inputs first (in the order
    // they had: each still follows what it reads), the others after them.
    // (`order` is by id: each term after its children.)
    let mut varying: HashMap<Id, bool> =
        HashMap::with_capacity_and_hasher(order.len(), Default::default());
    for &id in &order {
        let term = graph.terms[id as usize];
        let varies = match term {
            Term::Var(Slot::Parameter(_)) | Term::Const(_) => false,
            Term::Var(_) => true,
            _ => children(term).any(|a| varying[&a]),
        };
        varying.insert(id, varies);
    }
    let leaf = |id: Id| matches!(graph.terms[id as usize], Term::Const(_) | Term::Var(_));
    let fixed_op = |id: Id| !leaf(id) && !varying[&id];
    let moving_op = |id: Id| !leaf(id) && varying[&id];
    let parameter = |id: Id| matches!(graph.terms[id as usize], Term::Var(Slot::Parameter(_)));
    // Skipping the fixed part saves its operations at a call ([`op_cost`], in loads); it
    // costs a load for each of its values the rest reads, the comparison of the parameters
    // (counted as one load for each the part reads) and a function's call. Where it would
    // not pay twice over (the costs are estimates, and arithmetic done inline overlaps with
    // other work where loads and comparisons wait), the program keeps its order: measured,
    // a part that saved about its cost once made Smith's and Bachmann's NLL + gradient 3 %
    // slower. A part that reads no parameter (none survives constant folding) is never
    // skipped: nothing would tell a fresh work space from a computed one.
    let saved: usize =
        order.iter().filter(|&&id| fixed_op(id)).map(|&id| op_cost(graph.terms[id as usize])).sum();
    let crossing = operands_read(graph, &order, moving_op, fixed_op);
    let watched = operands_read(graph, &order, fixed_op, parameter);
    let pays = watched > 0 && saved > 2 * (crossing + watched + SKIP_CALL);
    let (fixed, moving): (Vec<Id>, Vec<Id>) = match pays {
        true => order.iter().partition(|&&id| !varying[&id]),
        false => (Vec::new(), order.clone()),
    };
    let fixed_count = fixed.iter().filter(|&&id| !leaf(id)).count();
    let mut code = Vec::new();
    for &id in fixed.iter().chain(&moving) {
        let r = |x: Id| register[&x];
        let instr = match graph.terms[id as usize] {
            Term::Const(_) | Term::Var(_) => continue,
            Term::Neg(a) => Instr::Neg(r(a)),
            Term::Add(a, b) => Instr::Add(r(a), r(b)),
            Term::Sub(a, b) => Instr::Sub(r(a), r(b)),
            Term::Mul(a, b) => Instr::Mul(r(a), r(b)),
            Term::Div(a, b) => Instr::Div(r(a), r(b)),
            Term::PowI(a, 2) => Instr::Square(r(a)),
            Term::PowI(a, 3) => Instr::Cube(r(a)),
            Term::PowI(a, k) => Instr::PowI(r(a), k),
            Term::PowF(a, c) => Instr::PowF(r(a), r(c)),
            Term::Pow(a, b) => Instr::Pow(r(a), r(b)),
            Term::Func(f, a) => {
                let a = r(a);
                match f {
                    Func::Exp => Instr::Exp(a),
                    Func::Log => Instr::Log(a),
                    Func::Sqrt => Instr::Sqrt(a),
                    Func::Sin => Instr::Sin(a),
                    Func::Cos => Instr::Cos(a),
                    Func::Tan => Instr::Tan(a),
                    Func::Tanh => Instr::Tanh(a),
                    Func::Abs => Instr::Abs(a),
                    _ => unreachable!("functions of several arguments are terms of their own"),
                }
            }
            Term::Signum(a) => Instr::Signum(r(a)),
            Term::Min(a, b) => Instr::Min(r(a), r(b)),
            Term::Max(a, b) => Instr::Max(r(a), r(b)),
            Term::Less(a, b, c, d) => Instr::Less(r(a), r(b), r(c), r(d)),
        };
        register.insert(id, (first + code.len()) as u32);
        code.push(instr);
    }
    let registers = outputs.iter().map(|id| register[id]).collect();
    (Tape::new((n, np, nu), constants, code, fixed_count), registers)
}

/// Functions f(t, y, α, u) (a model's right-hand side or its outputs) with their symbolic
/// Jacobian [∂f/∂y | ∂f/∂α], evaluated as one [`Tape`]: compiled to machine code with the
/// `jit` feature (where Cranelift supports the host), else interpreted.
#[derive(Clone, Debug)]
pub struct Linearized {
    tape: Tape,
    #[cfg(feature = "jit")]
    compiled: Option<std::sync::Arc<crate::jit::Compiled>>,
    /// The registers of the function values.
    values: Vec<u32>,
    /// The registers of the nonzero entries, in pattern order.
    entries: Vec<u32>,
    /// The nonzero entries (row, column), row by row, states' columns first.
    pattern: Vec<(u32, u32)>,
    /// The entries' derivatives with respect to the states, where built.
    curvature: Option<std::sync::Arc<Linearized>>,
    /// The same functions with fewer of their derivatives, where built: cheaper where the
    /// others are not read.
    parts: Option<std::sync::Arc<Parts>>,
    /// Whether the functions' derivative with respect to t is 0.
    time_free: bool,
    /// The sparse LU's order and fill of the pattern, found once.
    lu_plan: sysid_ode::PlanCell,
}

/// Which derivatives a [`Linearized`] program computes besides its functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Columns {
    None,
    States,
    All,
}

/// A [`Linearized`] program's functions with fewer derivatives: alone, and with the state
/// columns alone.
#[derive(Clone, Debug)]
struct Parts {
    values: Linearized,
    states: Linearized,
}

impl Linearized {
    /// Differentiates `functions` of n states, n_α parameters and n_u inputs.
    pub fn new(functions: &[Program], dims: (usize, usize, usize)) -> Self {
        Self::differentiate(functions, dims, false)
    }

    /// The same, with the [curvature](SparseJacobian::curvature): the Jacobian's entries
    /// differentiated once more with respect to the states (for implicit integrators).
    pub fn with_curvature(functions: &[Program], dims: (usize, usize, usize)) -> Self {
        Self::differentiate(functions, dims, true)
    }

    fn differentiate(functions: &[Program], dims: (usize, usize, usize), curvature: bool) -> Self {
        let mut graph = Graph::default();
        let roots: Vec<Id> = functions.iter().map(|f| graph.program(f)).collect();
        let (mut first, entries) = Self::build(&mut graph, &roots, dims, Columns::All);
        first.time_free =
            graph.derivatives(&roots, Slot::Time).into_iter().all(|d| graph.is_zero(d));
        if !curvature {
            first.compile(false);
            return first;
        }
        // An implicit integrator's system also evaluates f alone (at every stage) and f with
        // ∂f/∂y alone (at every factorisation without sensitivities): programs of their own,
        // in which the columns not read are not computed. Laske's f alone is 371 operations
        // and with ∂f/∂y 1 055, against 2 020 with ∂f/∂α too; SalazarCavazos' 2 983, 4 480
        // and 7 654. They are built from the same graph, so their values and entries are
        // those of the whole program to the bit. f with ∂f/∂y runs once per factorisation
        // and is compiled quickly, as the second derivatives are: SalazarCavazos' import then
        // takes 86 ms rather than 99 (two threads), its NLL + gradient and Laske's, Smith's
        // and Alkan's within 1.5 % of those with the slower compilation.
        let (mut values, _) = Self::build(&mut graph, &roots, dims, Columns::None);
        let (mut states, _) = Self::build(&mut graph, &roots, dims, Columns::States);
        // Compiling takes longer than differentiating: the first derivatives are compiled on
        // a thread of their own while the second ones are built and compiled here. The second
        // derivatives run far less often than the first (once per factorisation, and only
        // with sensitivities; the first at every stage) and are compiled quickly: Laske's
        // import 74 -> 33 ms, Chen's 608 -> 418 ms, the NLL + gradient unchanged within the
        // noise (criterion, six problems); the first derivatives compiled so would make it a
        // third slower.
        let second = std::thread::scope(|scope| {
            let compiling = scope.spawn(|| {
                first.compile(false);
                values.compile(false);
            });
            let (mut second, _) = Self::build(&mut graph, &entries, dims, Columns::States);
            second.compile(true);
            states.compile(true);
            compiling.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
            second
        });
        first.curvature = Some(std::sync::Arc::new(second));
        first.parts = Some(std::sync::Arc::new(Parts { values, states }));
        first
    }

    /// The program of `roots` and their derivatives with respect to the `columns` (all
    /// columns share the graph), and the ids of the nonzero entries; not compiled yet.
    fn build(
        graph: &mut Graph,
        roots: &[Id],
        (n, np, nu): (usize, usize, usize),
        columns: Columns,
    ) -> (Self, Vec<Id>) {
        let (states, parameters) = match columns {
            Columns::None => (0, 0),
            Columns::States => (n, 0),
            Columns::All => (n, np),
        };
        let slots: Vec<Slot> =
            (0..states).map(Slot::State).chain((0..parameters).map(Slot::Parameter)).collect();
        // The nonzero entries row by row, each row's columns ascending.
        let mut nonzero: Vec<(u32, u32, Id)> = (graph.columns(roots, &slots).into_iter())
            .enumerate()
            .flat_map(|(c, column)| column.into_iter().map(move |(row, d)| (row, c as u32, d)))
            .collect();
        nonzero.sort_unstable_by_key(|&(row, column, _)| (row, column));
        let pattern = nonzero.iter().map(|&(row, column, _)| (row, column)).collect();
        let mut outputs = roots.to_vec();
        outputs.extend(nonzero.iter().map(|e| e.2));
        let (tape, registers) = emit(graph, &outputs, (n, np, nu));
        let (values, entries) = registers.split_at(roots.len());
        let linearized = Self {
            #[cfg(feature = "jit")]
            compiled: None,
            tape,
            values: values.to_vec(),
            entries: entries.to_vec(),
            pattern,
            curvature: None,
            parts: None,
            time_free: false,
            lu_plan: sysid_ode::PlanCell::default(),
        };
        (linearized, outputs[roots.len()..].to_vec())
    }

    /// Compiles the tape to machine code, storing the values and the entries (with the `jit`
    /// feature; else nothing to do); `quick`: with Cranelift's single-pass register
    /// allocator, which compiles 2–3× faster and runs slower code.
    #[cfg_attr(not(feature = "jit"), allow(unused_variables))]
    fn compile(&mut self, quick: bool) {
        #[cfg(feature = "jit")]
        {
            let stores: Vec<u32> = self.values.iter().chain(&self.entries).copied().collect();
            self.compiled =
                crate::jit::compile(&self.tape, &stores, quick).map(std::sync::Arc::new);
        }
    }

    /// The same functions, second derivatives included, always interpreted (the reference
    /// of the compiled code).
    pub fn interpreted(&self) -> Self {
        Self {
            #[cfg(feature = "jit")]
            compiled: None,
            curvature: self.curvature.as_ref().map(|c| std::sync::Arc::new(c.interpreted())),
            parts: self.parts.as_ref().map(|p| {
                std::sync::Arc::new(Parts {
                    values: p.values.interpreted(),
                    states: p.states.interpreted(),
                })
            }),
            ..self.clone()
        }
    }

    /// Whether the functions do not change with t at fixed y, α and u: their derivative
    /// with respect to t simplifies to the constant 0. A switch in time
    /// (`if(le(t, 24), a, b)`) is constant in t between its stops, where the integrators
    /// evaluate it.
    pub fn independent_of_time(&self) -> bool {
        self.time_free
    }

    /// Whether the program runs as machine code.
    pub fn is_compiled(&self) -> bool {
        #[cfg(feature = "jit")]
        return self.compiled.is_some();
        #[cfg(not(feature = "jit"))]
        false
    }

    /// Number of operations of the program (functions and Jacobian together).
    pub fn operations(&self) -> usize {
        self.tape.code().len()
    }
}

impl SparseJacobian for Linearized {
    fn pattern(&self) -> &[(u32, u32)] {
        &self.pattern
    }

    fn values(&self) -> &[u32] {
        &self.values
    }

    fn entries(&self) -> &[u32] {
        &self.entries
    }

    fn workspace(&self) -> Vec<f64> {
        self.tape.registers()
    }

    fn lu_plan(&self) -> Option<&sysid_ode::PlanCell> {
        Some(&self.lu_plan)
    }

    fn operations(&self) -> usize {
        Linearized::operations(self)
    }

    fn curvature(&self) -> Option<&dyn SparseJacobian> {
        self.curvature.as_deref().map(|c| c as &dyn SparseJacobian)
    }

    fn values_alone(&self) -> Option<&dyn SparseJacobian> {
        self.parts.as_deref().map(|p| &p.values as &dyn SparseJacobian)
    }

    fn state_columns(&self) -> Option<&dyn SparseJacobian> {
        self.parts.as_deref().map(|p| &p.states as &dyn SparseJacobian)
    }

    fn eval(&self, t: f64, y: &[f64], p: &[f64], u: &[f64], work: &mut [f64]) {
        #[cfg(feature = "jit")]
        if let Some(compiled) = &self.compiled {
            compiled.run(t, y, p, u, work);
            return;
        }
        self.tape.load(t, y, p, u, work);
        self.tape.interpret(work);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::parse;

    fn compile(texts: &[&str]) -> Vec<Program> {
        let resolve = |name: &str| match name {
            "V" => Some(Slot::State(0)),
            "R" => Some(Slot::State(1)),
            "a" => Some(Slot::Parameter(0)),
            "b" => Some(Slot::Parameter(1)),
            "c" => Some(Slot::Parameter(2)),
            "t" => Some(Slot::Time),
            _ => None,
        };
        texts.iter().map(|t| Program::compile(&parse(t).unwrap(), &resolve).unwrap()).collect()
    }

    /// t written in an equation makes it depend on time, unless it cancels or only switches
    /// it (constant between the stops, where the integrators evaluate it).
    #[test]
    fn dependence_on_time() {
        for (texts, free) in [
            (&["c * (V - V^3 / 3 + R)", "-(V - a + b * R) / c"][..], true),
            (&["if(le(t, 24), a, b) * V", "lt(t - c, 0) * R"], true),
            (&["V + t - t"], true),
            (&["-a * V", "exp(-b * t) * R"], false),
            (&["if(le(t, 24), t, b) * V"], false),
            (&["V^t"], false),
        ] {
            let f = Linearized::new(&compile(texts), (2, 3, 0));
            assert_eq!(f.independent_of_time(), free, "{texts:?}");
        }
    }

    /// FitzHugh–Nagumo's Jacobian has the structure read off its equations, and the program
    /// shares what the functions and derivatives have in common: V² once, 1/c once.
    #[test]
    fn fitzhugh_nagumo_program() {
        let f = Linearized::new(
            &compile(&["c * (V - V^3 / 3 + R)", "-(V - a + b * R) / c"]),
            (2, 3, 0),
        );
        // Columns: V, R, a, b, c. dV'/da = dV'/db = 0 and dR'/dc ≠ 0.
        let pattern = [(0, 0), (0, 1), (0, 4), (1, 0), (1, 1), (1, 2), (1, 3), (1, 4)];
        assert_eq!(f.pattern, pattern);
        let count = |p: fn(&Instr) -> bool| f.tape.code().iter().filter(|i| p(i)).count();
        assert_eq!(count(|i| matches!(i, Instr::Square(_))), 1, "{:?}", f.tape.code());
        // c is register 5 (t, V, R, a, b, c): one division by it, the rest multiply by 1/c.
        assert_eq!(count(|i| matches!(i, Instr::Div(_, 5))), 1, "{:?}", f.tape.code());
        // dV'/dR = c and dR'/da = 1/c are registers the program already has: 10 operations
        // for the values, 13 for the eight entries.
        assert!(f.operations() <= 23, "{} operations: {:?}", f.operations(), f.tape.code());
    }

    /// An implicit integrator's system has f alone and f with ∂f/∂y alone as programs of
    /// their own, with fewer operations, whose values and entries are the whole program's to
    /// the bit (compiled and interpreted): where a solver reads them instead, nothing changes
    /// but the time.
    #[test]
    fn the_parts_are_the_whole_programs_values_to_the_bit() {
        let texts = ["c * (V - V^3 / 3 + R) * exp(-a * V)", "-(V - a + b * R) / c + sin(b * t)"];
        let whole = Linearized::with_curvature(&compile(&texts), (2, 3, 0));
        assert!(Linearized::new(&compile(&texts), (2, 3, 0)).values_alone().is_none());
        for f in [whole.clone(), whole.interpreted()] {
            let (values, states) = (f.values_alone().unwrap(), f.state_columns().unwrap());
            assert!(values.pattern().is_empty());
            let columns: Vec<_> = f.pattern.iter().copied().filter(|e| e.1 < 2).collect();
            assert_eq!(states.pattern(), &columns[..]);
            assert!(values.operations() < states.operations(), "{}", values.operations());
            assert!(states.operations() < f.operations(), "{}", states.operations());
            let (mut w, mut wv, mut ws) = (f.workspace(), values.workspace(), states.workspace());
            for (t, y, p) in
                [(0.0, [1.0, 2.0], [0.1, 0.2, 0.3]), (1.5, [-0.5, 3.0], [2.0, -1.0, 0.7])]
            {
                f.eval(t, &y, &p, &[], &mut w);
                values.eval(t, &y, &p, &[], &mut wv);
                states.eval(t, &y, &p, &[], &mut ws);
                let read = |work: &[f64], at: &[u32]| -> Vec<u64> {
                    at.iter().map(|&r| work[r as usize].to_bits()).collect()
                };
                assert_eq!(read(&wv, values.values()), read(&w, &f.values));
                assert_eq!(read(&ws, states.values()), read(&w, &f.values));
                let whole_states: Vec<u32> = f
                    .pattern
                    .iter()
                    .zip(&f.entries)
                    .filter(|(e, _)| e.1 < 2)
                    .map(|(_, &r)| r)
                    .collect();
                assert_eq!(read(&ws, states.entries()), read(&w, &whole_states));
            }
        }
    }

    /// The operations on the parameters alone come first, and the compiled code skips them
    /// only where the parameters are, bit for bit, those of the last run on the same work
    /// space: every run equals a fresh interpreted one, through a sequence that keeps the
    /// parameters while t and the states move, changes one by 1e-12 of itself, flips a zero's
    /// sign (1/c is +∞ or −∞) and comes back.
    #[test]
    #[cfg(feature = "jit")]
    fn the_parameters_part_runs_again_only_where_the_parameters_change() {
        let terms: Vec<String> =
            (1..=60).map(|i| format!("exp(a * {i}.5) / (b + {i}) * c^2")).collect();
        let first = format!("V * ({}) - R * exp(1 / c)", terms.join(" + "));
        let f = Linearized::new(&compile(&[&first, "R * a - b * V + sin(t)"]), (2, 3, 0));
        let code = f.tape.code();
        let fixed = f.tape.fixed();
        // More than one compiled function's worth, so that several are skipped.
        assert!(fixed > 256 && fixed < code.len(), "{fixed} of {} operations", code.len());
        // Registers 0, 1, 2: t, V, R.
        let reads_t_or_y = |i: &Instr| i.operands().any(|r| r <= 2);
        assert!(f.is_compiled());
        assert!(!code[..fixed].iter().any(reads_t_or_y), "the fixed part reads t or y");
        assert!(code[fixed..].iter().any(reads_t_or_y), "the rest reads t or y");
        // FitzHugh–Nagumo's part on the parameters alone (1/c and a few products) saves less
        // than skipping it costs: its program keeps its order.
        let cheap = Linearized::new(
            &compile(&["c * (V - V^3 / 3 + R)", "-(V - a + b * R) / c"]),
            (2, 3, 0),
        );
        assert_eq!(cheap.tape.fixed(), 0);
        let interpreted = f.interpreted();
        let mut work = f.workspace();
        let p0 = [0.1, 0.2, 0.3];
        let points: [(f64, [f64; 2], [f64; 3]); 7] = [
            (0.0, [1.0, 2.0], p0),
            (0.5, [1.5, -2.0], p0),
            (0.7, [1.5, -2.0], [0.1, 0.2, 0.3 * (1.0 + 1e-12)]),
            (0.9, [0.5, 2.0], p0),
            (1.1, [0.5, 2.0], [0.1, 0.2, 0.0]),
            (1.3, [0.5, 2.0], [0.1, 0.2, -0.0]),
            (1.5, [0.25, 1.0], p0),
        ];
        for (t, y, p) in points {
            f.eval(t, &y, &p, &[], &mut work);
            let mut fresh = interpreted.workspace();
            interpreted.eval(t, &y, &p, &[], &mut fresh);
            for &r in f.values.iter().chain(&f.entries) {
                let (u, v) = (work[r as usize], fresh[r as usize]);
                assert_eq!(
                    u.to_bits(),
                    v.to_bits(),
                    "t = {t}, p = {p:?}, register {r}: {u} vs {v}"
                );
            }
        }
    }
}
