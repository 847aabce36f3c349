//! Every system sysid can fit by name, as one type: the catalogue's systems and a model
//! file's (a PEtab problem is one too). The command line and the Python package work on
//! `Problem<AnySystem>`, so each command is a plain function, and the methods are compiled
//! once for all of them instead of once per system type; the match on the variant costs
//! nothing next to an evaluation of the model.

use std::sync::Arc;

use nalgebra::DMatrix;
use sysid_core::Problem;
use sysid_model::ModelSystem;
use sysid_ode::{Function, Scalar, Side, Signature, SparseJacobian, System};
use sysid_systems::{
    Case, Chain, FallingBody, FitzHughNagumo, LotkaVolterra, Robertson, ShortPeriod, VanDerPol,
    Visit,
};

macro_rules! any_system {
    ($($variant:ident($ty:ty)),* $(,)?) => {
        /// One of the systems sysid fits by name: a catalogue system or a model file's.
        #[derive(Clone, Debug)]
        pub enum AnySystem {
            $(
                #[doc = concat!("A [`", stringify!($ty), "`].")]
                $variant(Arc<$ty>),
            )*
        }

        $(
            impl From<$ty> for AnySystem {
                fn from(s: $ty) -> Self {
                    AnySystem::$variant(Arc::new(s))
                }
            }
            impl From<Arc<$ty>> for AnySystem {
                fn from(s: Arc<$ty>) -> Self {
                    AnySystem::$variant(s)
                }
            }
        )*

        /// `$body` with `$s` bound to the system inside, whatever its variant.
        macro_rules! each {
            ($self:expr, $s:ident => $body:expr) => {
                match $self {
                    $(AnySystem::$variant($s) => $body,)*
                }
            };
        }
    };
}

any_system! {
    FallingBody(FallingBody),
    VanDerPol(VanDerPol),
    LotkaVolterra(LotkaVolterra),
    FitzHughNagumo(FitzHughNagumo),
    ShortPeriod(ShortPeriod),
    Robertson(Robertson),
    Chain(Chain),
    Model(ModelSystem),
}

impl System for AnySystem {
    fn signature(&self) -> &Signature {
        each!(self, s => s.signature())
    }
    fn rhs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], dy: &mut [T]) {
        each!(self, s => s.rhs(t, y, p, u, dy))
    }
    fn outputs<T: Scalar>(&self, t: f64, y: &[T], p: &[T], u: &[f64], h: &mut [T]) {
        each!(self, s => s.outputs(t, y, p, u, h))
    }
    fn input_values(&self, t: f64, side: Side, u: &mut [f64]) {
        each!(self, s => s.input_values(t, side, u))
    }
    fn autonomous(&self) -> bool {
        each!(self, s => s.autonomous())
    }
    fn discontinuities(&self) -> &[f64] {
        each!(self, s => s.discontinuities())
    }
    fn switches(&self, p: &[f64]) -> Vec<f64> {
        each!(self, s => s.switches(p))
    }
    fn moving_switches(&self, p: &[f64]) -> Vec<(f64, usize, f64)> {
        each!(self, s => s.moving_switches(p))
    }
    fn n_events(&self) -> usize {
        each!(self, s => s.n_events())
    }
    fn event_condition<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T]) -> T {
        each!(self, s => s.event_condition(i, t, y, p))
    }
    fn event_reset<T: Scalar>(&self, i: usize, t: f64, y: &[T], p: &[T], y_new: &mut [T]) {
        each!(self, s => s.event_reset(i, t, y, p, y_new))
    }
    fn sparse_jacobian(&self, function: Function) -> Option<&dyn SparseJacobian> {
        each!(self, s => s.sparse_jacobian(function))
    }
    fn analytic_jacobians(&self) -> bool {
        each!(self, s => s.analytic_jacobians())
    }
    fn jacobians(
        &self,
        t: f64,
        y: &[f64],
        p: &[f64],
        u: &[f64],
        jy: &mut DMatrix<f64>,
        jp: &mut DMatrix<f64>,
    ) {
        each!(self, s => s.jacobians(t, y, p, u, jy, jp))
    }
}

/// The catalogue case called `name`, its system as an [`AnySystem`]; `None` if there is none.
pub fn case(name: &str) -> Option<Case<AnySystem>> {
    struct Erase;
    impl Visit for Erase {
        type Output = Case<AnySystem>;
        fn visit<S: System + Clone + Send + Sync + 'static>(self, case: Case<S>) -> Self::Output {
            case.map_system(erase)
        }
    }
    sysid_systems::visit(name, Erase)
}

/// A catalogue system as an [`AnySystem`]: the catalogue's types are the variants, so this
/// only fails if a system is added to the catalogue and not to [`AnySystem`].
fn erase<S: System + 'static>(system: S) -> AnySystem {
    let any: Box<dyn std::any::Any> = Box::new(system);
    macro_rules! try_as {
        ($any:ident; $($ty:ty),*) => {
            $(let $any = match $any.downcast::<$ty>() {
                Ok(s) => return AnySystem::from(*s),
                Err(other) => other,
            };)*
        };
    }
    try_as!(any; FallingBody, VanDerPol, LotkaVolterra, FitzHughNagumo, ShortPeriod, Robertson, Chain);
    drop(any);
    unreachable!("a catalogue system that AnySystem does not list")
}

/// A model file's problem on [`AnySystem`].
pub fn model_problem(problem: Problem<ModelSystem>) -> Problem<AnySystem> {
    problem.map_system(AnySystem::from)
}
