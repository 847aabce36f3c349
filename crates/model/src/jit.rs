//! Machine code for a model's straight-line program, compiled by Cranelift at load time
//! (the default `jit` feature).
//!
//! The compiled function reads t, y, α and u where they are, keeps every intermediate value
//! in machine registers (or Cranelift's spill slots), and writes only the registers of the
//! work space that are read afterwards (the function values and the Jacobian's entries).
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

/// A tape compiled to machine code.
pub(crate) struct Compiled {
    function: Function,
    /// The lengths of y, α and u the code reads.
    inputs: (usize, usize, usize),
    /// The work space's length the code writes within.
    registers: usize,
    /// Owns the code's memory; freed on drop.
    module: Mutex<Option<JITModule>>,
}

impl std::fmt::Debug for Compiled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Compiled").field("registers", &self.registers).finish_non_exhaustive()
    }
}

impl Drop for Compiled {
    fn drop(&mut self) {
        if let Some(module) = self.module.get_mut().ok().and_then(Option::take) {
            // SAFETY: the function pointer lives in `self` alone and is not called again.
            unsafe { module.free_memory() };
        }
    }
}

impl Compiled {
    /// Runs the code at (t, y, α, u), writing into `work`.
    pub(crate) fn run(&self, t: f64, y: &[f64], p: &[f64], u: &[f64], work: &mut [f64]) {
        let (n, np, nu) = self.inputs;
        assert!(y.len() >= n && p.len() >= np && u.len() >= nu, "the model's inputs");
        assert!(work.len() >= self.registers, "a work space of {} registers", self.registers);
        (self.function)(t, y.as_ptr(), p.as_ptr(), u.as_ptr(), work.as_mut_ptr());
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

/// Compiles `tape`, storing the registers `stores` back into the work space; `None` when
/// the host has no Cranelift backend or compilation fails (the tape is then interpreted).
pub(crate) fn compile(tape: &Tape, stores: &[u32]) -> Option<Compiled> {
    let mut flags = settings::builder();
    flags.set("opt_level", "speed").ok()?;
    flags.set("use_colocated_libcalls", "false").ok()?;
    flags.set("is_pic", "false").ok()?;
    let isa = cranelift_native::builder().ok()?.finish(settings::Flags::new(flags)).ok()?;
    let mut builder = JITBuilder::with_isa(isa, default_libcall_names());
    for (name, f) in UNARY {
        builder.symbol(name, f as *const u8);
    }
    builder.symbol("sysid_powf", powf as extern "C" fn(f64, f64) -> f64 as *const u8);
    builder.symbol("sysid_powi", powi as extern "C" fn(f64, i32) -> f64 as *const u8);
    let mut module = JITModule::new(builder);
    let id = define(&mut module, tape, stores)?;
    module.finalize_definitions().ok()?;
    let code = module.get_finalized_function(id);
    // SAFETY: `code` was compiled from the signature of `Function` (an f64 and four
    // pointers, the host's default calling convention, no result); it reads the first n, n_α
    // and n_u values behind the pointers y, α, u and writes within the first `registers`
    // values of the work space, which `Compiled::run` checks.
    let function = unsafe { std::mem::transmute::<*const u8, Function>(code) };
    Some(Compiled {
        function,
        inputs: tape.dims(),
        registers: tape.len(),
        module: Mutex::new(Some(module)),
    })
}

/// Declares the library functions and defines the tape's function in `module`.
fn define(module: &mut JITModule, tape: &Tape, stores: &[u32]) -> Option<FuncId> {
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

    // The value of every register: t, y, α, u loaded once, constants as immediates.
    let first = tape.first();
    let (n, np, nu) = tape.dims();
    let mut values: Vec<Option<Value>> = vec![None; tape.len()];
    values[0] = Some(t);
    for (r, value) in values.iter_mut().enumerate().take(first).skip(1) {
        let (from, at) = match r - 1 {
            i if i < n => (y, i),
            i if i < n + np => (p, i - n),
            i if i < n + np + nu => (u, i - n - np),
            _ => {
                *value = tape.constant(r).map(|c| b.ins().f64const(c));
                continue;
            }
        };
        *value = Some(b.ins().load(types::F64, flags, from, offset(at as u32)?));
    }
    for (i, instr) in tape.code().iter().enumerate() {
        let x = |r: u32| values[r as usize].expect("registers are written before they are read");
        let call = |b: &mut FunctionBuilder, f, args: &[Value]| {
            let inst = b.ins().call(f, args);
            b.inst_results(inst)[0]
        };
        let value = match *instr {
            Instr::Neg(a) => b.ins().fneg(x(a)),
            Instr::Add(a, c) => b.ins().fadd(x(a), x(c)),
            Instr::Sub(a, c) => b.ins().fsub(x(a), x(c)),
            Instr::Mul(a, c) => b.ins().fmul(x(a), x(c)),
            Instr::Div(a, c) => b.ins().fdiv(x(a), x(c)),
            Instr::Square(a) => b.ins().fmul(x(a), x(a)),
            Instr::Cube(a) => {
                let square = b.ins().fmul(x(a), x(a));
                b.ins().fmul(x(a), square)
            }
            Instr::PowI(a, k) => {
                let k = b.ins().iconst(types::I32, i64::from(k));
                call(&mut b, powi_ref, &[x(a), k])
            }
            Instr::PowF(a, c) | Instr::Pow(a, c) => call(&mut b, powf_ref, &[x(a), x(c)]),
            Instr::Exp(a) => call(&mut b, unary_refs[0], &[x(a)]),
            Instr::Log(a) => call(&mut b, unary_refs[1], &[x(a)]),
            Instr::Sin(a) => call(&mut b, unary_refs[2], &[x(a)]),
            Instr::Cos(a) => call(&mut b, unary_refs[3], &[x(a)]),
            Instr::Tan(a) => call(&mut b, unary_refs[4], &[x(a)]),
            Instr::Tanh(a) => call(&mut b, unary_refs[5], &[x(a)]),
            Instr::Signum(a) => call(&mut b, unary_refs[6], &[x(a)]),
            Instr::Sqrt(a) => b.ins().sqrt(x(a)),
            Instr::Abs(a) => b.ins().fabs(x(a)),
            Instr::Min(a, c) => {
                let less = b.ins().fcmp(FloatCC::LessThan, x(c), x(a));
                b.ins().select(less, x(c), x(a))
            }
            Instr::Max(a, c) => {
                let greater = b.ins().fcmp(FloatCC::GreaterThan, x(c), x(a));
                b.ins().select(greater, x(c), x(a))
            }
            Instr::Less(a, c, d, e) => {
                let less = b.ins().fcmp(FloatCC::LessThan, x(a), x(c));
                b.ins().select(less, x(d), x(e))
            }
        };
        values[first + i] = Some(value);
    }
    // Constants are in the work space from its start; every other register read afterwards
    // is written, inputs included (the work space does not hold them).
    for &r in stores {
        if tape.constant(r as usize).is_none() {
            let value = values[r as usize].expect("a computed register");
            b.ins().store(flags, value, work, offset(r)?);
        }
    }
    b.ins().return_(&[]);
    b.finalize();
    let id = module.declare_function("tape", Linkage::Local, &ctx.func.signature).ok()?;
    module.define_function(id, &mut ctx).ok()?;
    module.clear_context(&mut ctx);
    Some(id)
}
