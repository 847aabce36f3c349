//! Machine code for a model's straight-line program, compiled by Cranelift at load time
//! (the default `jit` feature).
//!
//! The compiled code reads t, y, α and u where they are, keeps every intermediate value
//! in machine registers (or Cranelift's spill slots), and writes only the registers of the
//! work space that are read afterwards (the function values and the Jacobian's entries).
//! A long program is compiled as several functions of at most [`SEGMENT`] operations, run
//! one after the other; a value one of them computes and a later one reads passes through
//! its register of the work space. The tape's operations on the parameters and constants
//! alone (its [fixed](Tape::fixed) part, first, where the emitter judged that skipping it
//! pays) are functions of their own, run only where the parameters differ from the last
//! run's, which the work space's parameter registers keep (the code reads the parameters
//! where they are, not there).
//! Each operation is the one the interpreter performs, in the same order: no contraction
//! into fused multiply-adds, no reassociation, and the library functions (exp, ln, sin, …,
//! powi, powf) are the same Rust functions called through the C ABI, so the compiled
//! program's results are bitwise those of the interpreted one (tested).
//!
//! Unsafe code is confined to this module: turning the finalized code's address into a
//! function pointer (sound because the code was compiled from a signature that matches it,
//! and it reads no memory but y, α and u and writes none but the work space, whose lengths
//! are checked before each call), and freeing the code's memory when the last user is gone.
#![allow(unsafe_code)]

use std::sync::Mutex;

use cranelift_codegen::ir::condcodes::FloatCC;
use cranelift_codegen::ir::{AbiParam, InstBuilder, MemFlags, Signature, Value, types};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{FuncId, Linkage, Module, default_libcall_names};

use crate::tape::{Instr, Tape};

/// The compiled function: (t, y, α, u, work space).
type Function = extern "C" fn(f64, *const f64, *const f64, *const f64, *mut f64);

/// Most operations compiled into one function. Cranelift's register allocation takes time
/// that grows faster than the function's length: SalazarCavazos' PEtab problem (75 states)
/// spent two thirds of its 1.3 s import there, and Laske's (41 states) took 537 ms to import.
/// Functions of this length, run in turn, compile in time proportional to the program: the
/// imports took 0.34-0.48 s and 165-220 ms then. The values passed between them are a few
/// loads and stores per thousand operations; their NLL + gradient took as long as one
/// function's, within this machine's noise (Laske 108-123 ms against 101 ms, Lucarelli
/// 270-323 ms against 285-296 ms). 4 096 imported slower and evaluated no faster.
const SEGMENT: usize = 256;

/// A tape compiled to machine code.
pub(crate) struct Compiled {
    /// The functions of the tape's segments, in order.
    functions: Vec<Function>,
    /// How many of them, from the first, compute the tape's fixed part: skipped where the
    /// parameters are those of the last run on the same work space.
    fixed: usize,
    /// The lengths of y, α and u the code reads.
    inputs: (usize, usize, usize),
    /// The work space's length the code writes within.
    registers: usize,
    /// Own the code's memory (one module per thread that compiled part of the tape); freed
    /// on drop.
    modules: Mutex<Vec<JITModule>>,
}

impl std::fmt::Debug for Compiled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Compiled").field("registers", &self.registers).finish_non_exhaustive()
    }
}

impl Drop for Compiled {
    fn drop(&mut self) {
        let modules = self.modules.get_mut().map(std::mem::take).unwrap_or_default();
        for module in modules {
            // SAFETY: the function pointers live in `self` alone and are not called again.
            unsafe { module.free_memory() };
        }
    }
}

impl Compiled {
    /// Runs the code at (t, y, α, u), writing into `work`: the fixed part only where α is
    /// not, bit for bit, the α of the last run on `work` (a NaN always differs; a fresh work
    /// space holds NaN there).
    pub(crate) fn run(&self, t: f64, y: &[f64], p: &[f64], u: &[f64], work: &mut [f64]) {
        let (n, np, nu) = self.inputs;
        assert!(y.len() >= n && p.len() >= np && u.len() >= nu, "the model's inputs");
        assert!(work.len() >= self.registers, "a work space of {} registers", self.registers);
        let mut from = 0;
        if self.fixed > 0 {
            // Without a branch per parameter: the comparison is a few vector operations.
            let held = &mut work[1 + n..1 + n + np];
            let (mut differ, mut nan) = (0, false);
            for (a, b) in held.iter().zip(&p[..np]) {
                differ |= a.to_bits() ^ b.to_bits();
                nan |= a.is_nan();
            }
            if differ == 0 && !nan {
                from = self.fixed;
            } else {
                held.copy_from_slice(&p[..np]);
            }
        }
        for function in &self.functions[from..] {
            function(t, y.as_ptr(), p.as_ptr(), u.as_ptr(), work.as_mut_ptr());
        }
    }
}

// The library functions, as the interpreter computes them.
extern "C" fn exp(x: f64) -> f64 {
    x.exp()
}
extern "C" fn ln(x: f64) -> f64 {
    x.ln()
}
extern "C" fn sin(x: f64) -> f64 {
    x.sin()
}
extern "C" fn cos(x: f64) -> f64 {
    x.cos()
}
extern "C" fn tan(x: f64) -> f64 {
    x.tan()
}
extern "C" fn tanh(x: f64) -> f64 {
    x.tanh()
}
extern "C" fn signum(x: f64) -> f64 {
    x.signum()
}
extern "C" fn powf(x: f64, y: f64) -> f64 {
    x.powf(y)
}
extern "C" fn powi(x: f64, n: i32) -> f64 {
    x.powi(n)
}

type Unary = extern "C" fn(f64) -> f64;

/// The unary library functions by symbol.
const UNARY: [(&str, Unary); 7] = [
    ("sysid_exp", exp),
    ("sysid_ln", ln),
    ("sysid_sin", sin),
    ("sysid_cos", cos),
    ("sysid_tan", tan),
    ("sysid_tanh", tanh),
    ("sysid_signum", signum),
];

/// Segments one thread compiles at least: below, a thread's module costs more than it saves.
const SEGMENTS_PER_THREAD: usize = 8;

/// Compiles `tape`, storing the registers `stores` back into the work space, with the
/// single-pass register allocator where `quick` (faster to compile, slower to run); `None`
/// when the host has no Cranelift backend or compilation fails (the tape is then interpreted).
/// A long tape's segments are compiled on several threads, each into a module of its own
/// (SalazarCavazos' first derivatives, 30 segments: 65-80 ms on one thread).
pub(crate) fn compile(tape: &Tape, stores: &[u32], quick: bool) -> Option<Compiled> {
    let (ranges, fixed) = segments(tape);
    let written = written(tape, stores, &ranges);
    let segments = ranges.len();
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let threads = cores.min(segments / SEGMENTS_PER_THREAD).max(1);
    let per = segments.div_ceil(threads);
    let part = |k: usize| {
        compile_segments(
            tape,
            (stores, &written),
            quick,
            (&ranges, k * per, segments.min((k + 1) * per)),
        )
    };
    let parts: Vec<Option<(JITModule, Vec<Function>)>> = if threads == 1 {
        vec![part(0)]
    } else {
        std::thread::scope(|scope| {
            let handles: Vec<_> = (1..threads).map(|k| scope.spawn(move || part(k))).collect();
            let mut parts = vec![part(0)];
            for h in handles {
                parts.push(h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)));
            }
            parts
        })
    };
    let mut modules = Vec::with_capacity(threads);
    let mut functions = Vec::with_capacity(segments);
    let mut failed = false;
    for part in parts {
        match part {
            Some((module, f)) => {
                modules.push(module);
                functions.extend(f);
            }
            None => failed = true,
        }
    }
    if failed {
        for module in modules {
            // SAFETY: no function of these modules has been handed out.
            unsafe { module.free_memory() };
        }
        return None;
    }
    Some(Compiled {
        functions,
        fixed,
        inputs: tape.dims(),
        registers: tape.len(),
        modules: Mutex::new(modules),
    })
}

/// The tape's segments: its fixed part in pieces of at most [`SEGMENT`] operations, then
/// the rest likewise (at least one segment, which may be empty: the last stores the inputs
/// among the stores at every run); and how many pieces the fixed part has.
fn segments(tape: &Tape) -> (Vec<std::ops::Range<usize>>, usize) {
    let pieces =
        |from: usize, to: usize| (from..to).step_by(SEGMENT).map(move |a| a..to.min(a + SEGMENT));
    let (fixed, len) = (tape.fixed(), tape.code().len());
    let mut ranges: Vec<_> = pieces(0, fixed).collect();
    let count = ranges.len();
    ranges.extend(pieces(fixed, len));
    if ranges.len() == count {
        ranges.push(len..len);
    }
    (ranges, count)
}

/// Compiles segments `from..to` of `ranges` into a module of their own: the module and the
/// segments' functions, in order.
fn compile_segments(
    tape: &Tape,
    (stores, written): (&[u32], &[bool]),
    quick: bool,
    (ranges, from, to): (&[std::ops::Range<usize>], usize, usize),
) -> Option<(JITModule, Vec<Function>)> {
    let mut flags = settings::builder();
    if quick {
        flags.set("regalloc_algorithm", "single_pass").ok()?;
    }
    flags.set("opt_level", "speed").ok()?;
    flags.set("use_colocated_libcalls", "false").ok()?;
    flags.set("is_pic", "false").ok()?;
    // Cranelift checks its IR's well-formedness by default: a tenth of a large model's
    // import. The IR here is written by `build` alone, from tapes, and the tests compare the
    // compiled tapes with the interpreted ones; debug builds (the tests') still verify.
    if !cfg!(debug_assertions) {
        flags.set("enable_verifier", "false").ok()?;
    }
    let isa = cranelift_native::builder().ok()?.finish(settings::Flags::new(flags)).ok()?;
    let mut builder = JITBuilder::with_isa(isa, default_libcall_names());
    for (name, f) in UNARY {
        builder.symbol(name, f as *const u8);
    }
    builder.symbol("sysid_powf", powf as extern "C" fn(f64, f64) -> f64 as *const u8);
    builder.symbol("sysid_powi", powi as extern "C" fn(f64, i32) -> f64 as *const u8);
    let mut module = JITModule::new(builder);
    let mut values = vec![None; tape.len()];
    let mut ids = Vec::with_capacity(to - from);
    for k in from..to {
        let (range, last) = (ranges[k].clone(), k + 1 == ranges.len());
        ids.push(define(&mut module, tape, (k, range, last), (stores, written), &mut values)?);
    }
    module.finalize_definitions().ok()?;
    // SAFETY: each code was compiled from the signature of `Function` (an f64 and four
    // pointers, the host's default calling convention, no result); it reads the first n, n_α
    // and n_u values behind the pointers y, α, u and reads and writes within the first
    // `registers` values of the work space, which `Compiled::run` checks.
    let functions = ids
        .iter()
        .map(|&id| unsafe {
            std::mem::transmute::<*const u8, Function>(module.get_finalized_function(id))
        })
        .collect();
    Some((module, functions))
}

/// Whether each register is written to the work space by the function that computes it: it
/// is in `stores`, or a later segment of `ranges` reads it.
fn written(tape: &Tape, stores: &[u32], ranges: &[std::ops::Range<usize>]) -> Vec<bool> {
    let first = tape.first();
    let mut segment = vec![0; tape.code().len()];
    for (k, range) in ranges.iter().enumerate() {
        segment[range.clone()].fill(k);
    }
    let mut written = vec![false; tape.len()];
    for &r in stores {
        written[r as usize] = true;
    }
    for (i, instr) in tape.code().iter().enumerate() {
        for r in instr.operands().map(|r| r as usize) {
            if r >= first && segment[r - first] != segment[i] {
                written[r] = true;
            }
        }
    }
    written
}

/// Declares the library functions and defines the function of segment `k` (the operations
/// `range`) in `module`: it computes its operations, loading what it reads from the inputs,
/// constants and (for registers earlier segments computed) the work space, and stores the
/// registers [`written`] says later code reads; the `last` segment stores the inputs among
/// `stores` too.
/// `values` is scratch space of the tape's length, all `None`, and left so.
fn define(
    module: &mut JITModule,
    tape: &Tape,
    (k, range, last): (usize, std::ops::Range<usize>, bool),
    (stores, written): (&[u32], &[bool]),
    values: &mut [Option<Value>],
) -> Option<FuncId> {
    let f64_signature = |module: &JITModule, params: &[types::Type]| {
        let mut s: Signature = module.make_signature();
        s.params.extend(params.iter().map(|&t| AbiParam::new(t)));
        s.returns.push(AbiParam::new(types::F64));
        s
    };
    let unary = f64_signature(module, &[types::F64]);
    let mut imports = Vec::new();
    for (name, _) in UNARY {
        imports.push(module.declare_function(name, Linkage::Import, &unary).ok()?);
    }
    let powf = module
        .declare_function("sysid_powf", Linkage::Import, &f64_signature(module, &[types::F64; 2]))
        .ok()?;
    let powi_signature = f64_signature(module, &[types::F64, types::I32]);
    let powi = module.declare_function("sysid_powi", Linkage::Import, &powi_signature).ok()?;

    let pointer = module.target_config().pointer_type();
    let mut ctx = module.make_context();
    ctx.func.signature.params.push(AbiParam::new(types::F64));
    for _ in 0..4 {
        ctx.func.signature.params.push(AbiParam::new(pointer));
    }
    let mut fctx = FunctionBuilderContext::new();
    let mut b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
    let block = b.create_block();
    b.append_block_params_for_function_params(block);
    b.switch_to_block(block);
    b.seal_block(block);
    let &[t, y, p, u, work] = b.block_params(block) else { return None };
    let flags = MemFlags::trusted();
    let offset = |r: u32| i32::try_from(8 * r as usize).ok();

    let unary_refs: Vec<_> =
        imports.iter().map(|&id| module.declare_func_in_func(id, b.func)).collect();
    let powf_ref = module.declare_func_in_func(powf, b.func);
    let powi_ref = module.declare_func_in_func(powi, b.func);

    // The value of every register this function reads, on first use: t, y, α and u loaded,
    // constants as immediates, and the registers earlier segments computed from the work
    // space.
    let first = tape.first();
    let (n, np, nu) = tape.dims();
    let code = tape.code();
    let mut touched: Vec<usize> = Vec::new();
    let load = |b: &mut FunctionBuilder, r: usize| -> Option<Value> {
        Some(match r {
            0 => t,
            r if r >= first => b.ins().load(types::F64, flags, work, offset(r as u32)?),
            r => match r - 1 {
                i if i < n => b.ins().load(types::F64, flags, y, offset(i as u32)?),
                i if i < n + np => b.ins().load(types::F64, flags, p, offset((i - n) as u32)?),
                i if i < n + np + nu => {
                    b.ins().load(types::F64, flags, u, offset((i - n - np) as u32)?)
                }
                _ => b.ins().f64const(tape.constant(r)?),
            },
        })
    };
    let value = |b: &mut FunctionBuilder,
                 values: &mut [Option<Value>],
                 touched: &mut Vec<usize>,
                 r: usize|
     -> Option<Value> {
        if values[r].is_none() {
            values[r] = Some(load(b, r)?);
            touched.push(r);
        }
        values[r]
    };
    for i in range.clone() {
        let instr = &code[i];
        let mut args = [None; 4];
        for (slot, r) in args.iter_mut().zip(instr.operands()) {
            *slot = Some(value(&mut b, values, &mut touched, r as usize)?);
        }
        let x = |j: usize| args[j].expect("an operand");
        let call = |b: &mut FunctionBuilder, f, args: &[Value]| {
            let inst = b.ins().call(f, args);
            b.inst_results(inst)[0]
        };
        let result = match *instr {
            Instr::Neg(_) => b.ins().fneg(x(0)),
            Instr::Add(..) => b.ins().fadd(x(0), x(1)),
            Instr::Sub(..) => b.ins().fsub(x(0), x(1)),
            Instr::Mul(..) => b.ins().fmul(x(0), x(1)),
            Instr::Div(..) => b.ins().fdiv(x(0), x(1)),
            Instr::Square(_) => b.ins().fmul(x(0), x(0)),
            Instr::Cube(_) => {
                let square = b.ins().fmul(x(0), x(0));
                b.ins().fmul(x(0), square)
            }
            Instr::PowI(_, k) => {
                let k = b.ins().iconst(types::I32, i64::from(k));
                call(&mut b, powi_ref, &[x(0), k])
            }
            Instr::PowF(..) | Instr::Pow(..) => call(&mut b, powf_ref, &[x(0), x(1)]),
            Instr::Exp(_) => call(&mut b, unary_refs[0], &[x(0)]),
            Instr::Log(_) => call(&mut b, unary_refs[1], &[x(0)]),
            Instr::Sin(_) => call(&mut b, unary_refs[2], &[x(0)]),
            Instr::Cos(_) => call(&mut b, unary_refs[3], &[x(0)]),
            Instr::Tan(_) => call(&mut b, unary_refs[4], &[x(0)]),
            Instr::Tanh(_) => call(&mut b, unary_refs[5], &[x(0)]),
            Instr::Signum(_) => call(&mut b, unary_refs[6], &[x(0)]),
            Instr::Sqrt(_) => b.ins().sqrt(x(0)),
            Instr::Abs(_) => b.ins().fabs(x(0)),
            Instr::Min(..) => {
                let less = b.ins().fcmp(FloatCC::LessThan, x(1), x(0));
                b.ins().select(less, x(1), x(0))
            }
            Instr::Max(..) => {
                let greater = b.ins().fcmp(FloatCC::GreaterThan, x(1), x(0));
                b.ins().select(greater, x(1), x(0))
            }
            Instr::Less(..) => {
                let less = b.ins().fcmp(FloatCC::LessThan, x(0), x(1));
                b.ins().select(less, x(2), x(3))
            }
        };
        values[first + i] = Some(result);
        touched.push(first + i);
    }
    // Constants are in the work space from its start; every other register read afterwards
    // is written, by the segment that computes it, and the inputs among `stores` (the work
    // space does not hold them) by the last.
    for r in range.map(|i| first + i).filter(|&r| written[r]) {
        let v = values[r].expect("computed here");
        b.ins().store(flags, v, work, offset(r as u32)?);
    }
    if last {
        for &r in stores.iter().filter(|&&r| (r as usize) < first) {
            if tape.constant(r as usize).is_none() {
                let v = value(&mut b, values, &mut touched, r as usize)?;
                b.ins().store(flags, v, work, offset(r)?);
            }
        }
    }
    for r in touched {
        values[r] = None;
    }
    b.ins().return_(&[]);
    b.finalize();
    let name = format!("tape{k}");
    let id = module.declare_function(&name, Linkage::Local, &ctx.func.signature).ok()?;
    module.define_function(id, &mut ctx).ok()?;
    module.clear_context(&mut ctx);
    Some(id)
}
