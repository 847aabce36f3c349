//! The level the integrators work at: a first-order system dx/dt = f(t, x) on a flat state
//! vector, with the Jacobian solves an implicit scheme asks of it.

use crate::counts::Costs;
use crate::lu::FactorError;
use crate::signal::Side;

/// A first-order system dx/dt = f(t, x) on a flat state vector: the level the integrators
/// work at. [`System`](crate::System)s are turned into an `Rhs` with or without their
/// sensitivities by this crate; implement it directly for anything else.
pub trait Rhs {
    /// Length of x.
    fn dim(&self) -> usize;
    /// dx = f(t, x); at a discontinuity of the inputs, the limit from `side`.
    fn eval(&mut self, t: f64, side: Side, x: &[f64], dx: &mut [f64]);
    /// A readable name of component i, for error messages.
    fn describe(&self, i: usize) -> String {
        format!("component {i}")
    }
    /// How many leading components are the model's states (the others being sensitivities
    /// or other derived quantities): a blow-up is reported on a state when one grew.
    fn states(&self) -> usize {
        self.dim()
    }
    /// For an augmented state x = [y; S] (n states, S n × k row by row, so n = dim/(1 + k)):
    /// per sensitivity column, the factor c_j of atol in its units (see
    /// [`Ivp::weighted`](crate::Ivp::weighted)), for its error control. None (the default):
    /// every component is measured alone, against atol + rtol·|x_i|.
    fn column_atol(&self) -> Option<&[f64]> {
        None
    }
    /// The states' own sizes, from which each state's absolute floor is taken in place of
    /// atol (see [`Ivp::sized`](crate::Ivp::sized)): one per leading state. None (the
    /// default): every state is held to atol.
    fn state_sizes(&self) -> Option<&[f64]> {
        None
    }
    /// Whether the error control measures the leading [`states`](Self::states) components
    /// as one vector and the others as another: a component is then held to
    /// max(atol, rtol·m) + rtol·|x_i|, m the largest entry of its vector at either end of the
    /// step, instead of atol + rtol·|x_i| alone (as [`column_atol`](Self::column_atol) does
    /// for each sensitivity column). For quantities used only through their sum with other
    /// components, such as an adjoint λ whose products λᵀS make a gradient: an entry far
    /// below its vector's largest moves that sum by far less than atol on its own would
    /// suggest. Default: false.
    fn errors_as_vectors(&self) -> bool {
        false
    }
    /// Whether f does not depend on t: a Rosenbrock step then takes ∂f/∂t = 0 without
    /// evaluating f again. Default: false (∂f/∂t is differenced).
    fn autonomous(&self) -> bool {
        false
    }
    /// For implicit (Rosenbrock) steps: evaluates the Jacobian ∂f/∂x at (t, x) exactly and
    /// factorises E = I·`inv_gamma_h` − ∂f/∂x. Default: unsupported (explicit schemes only).
    fn factor(
        &mut self,
        t: f64,
        side: Side,
        x: &[f64],
        inv_gamma_h: f64,
    ) -> Result<(), FactorError> {
        let _ = (t, side, x, inv_gamma_h);
        Err(FactorError::Unsupported)
    }
    /// Overwrites r with E⁻¹ r, E from the last [`factor`](Self::factor).
    fn solve(&mut self, r: &mut [f64]) {
        let _ = r;
    }
    /// Called where the integration crosses a stop t inside it (in direction `dir`, ±1),
    /// between the segments on either side: the place to apply a jump of x there. Default:
    /// none (the solution is continuous).
    fn cross(&mut self, t: f64, x: &mut [f64], dir: f64) {
        let _ = (t, x, dir);
    }
    /// How many state events f has (see [`System::n_events`](crate::System::n_events)).
    /// Default: none.
    fn n_events(&self) -> usize {
        0
    }
    /// What one evaluation, factorisation and solve cost, estimated from the structure (see
    /// [`Costs`]); asked again after every factorisation, so it may change once the
    /// implicit matrix exists. Default: [`Costs::dense`] of [`dim`](Self::dim).
    fn costs(&self) -> Costs {
        Costs::dense(self.dim())
    }
    /// The events' conditions at (t, y), y the leading [`states`](Self::states) components
    /// of x (all that is read): event i fires where its condition falls from positive to
    /// zero or below.
    fn event_conditions(&mut self, t: f64, y: &[f64], c: &mut [f64]) {
        let _ = (t, y, c);
    }
    /// Event `i` fires at t: x jumps to its value just after (the state reset, the
    /// sensitivities with it).
    fn fire(&mut self, i: usize, t: f64, x: &mut [f64]) {
        let _ = (i, t, x);
    }
}
