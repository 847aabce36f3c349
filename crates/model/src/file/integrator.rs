//! The `[integrator]` table: the scheme, tolerances and step budget.

use sysid_ode::{Integrator, Scheme};
use toml::Spanned;
use toml::de::DeValue;

use super::reader::Reader;
use crate::error::ModelError;

/// Reads `[integrator]` and checks the options are valid, located at the table.
pub(super) fn read_integrator(
    r: &Reader<'_>,
    value: &Spanned<DeValue<'_>>,
) -> Result<Integrator, ModelError> {
    let t = r.table(value, "[integrator]")?;
    let mut integrator = Integrator::default();
    for (key, v) in t.iter() {
        match key.get_ref().as_ref() {
            "method" => {
                integrator.scheme = match r.string(v, "[integrator] method")? {
                    "dopri5" => Scheme::Dopri5,
                    "rk4" => Scheme::Rk4,
                    "rodas4" => Scheme::Rodas4,
                    "auto" => Scheme::Auto,
                    other => {
                        return Err(r.err(
                            v.span().start,
                            format!(
                                "[integrator] method must be \"dopri5\", \"rk4\", \"rodas4\" or \"auto\", got \"{other}\""
                            ),
                        ));
                    }
                }
            }
            "rtol" => integrator.rtol = r.number(v, "[integrator] rtol")?,
            "atol" => integrator.atol = r.number(v, "[integrator] atol")?,
            "step" => integrator.fixed_step = Some(r.number(v, "[integrator] step")?),
            "max_steps" => integrator.max_steps = r.number(v, "[integrator] max_steps")? as usize,
            other => {
                return Err(r.err(key.span().start, format!("unknown key `{other}` in [integrator] (keys: method, rtol, atol, step, max_steps)")));
            }
        }
    }
    integrator.validate().map_err(|e| r.err(value.span().start, format!("[integrator]: {e}")))?;
    Ok(integrator)
}
