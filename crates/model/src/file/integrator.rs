//! The `[integrator]` table: the scheme, tolerances and step budget.

use super::document::Node;
use sysid_ode::{Integrator, Scheme};

use super::reader::Reader;
use crate::error::ModelError;

/// Reads `[integrator]` (optional, default DOPRI5 with its default tolerances): its keys,
/// then the options' own validation, located at the table.
pub(super) fn read_integrator(
    r: &Reader<'_>,
    value: Option<&Node>,
) -> Result<Integrator, ModelError> {
    let Some(value) = value else {
        return Ok(Integrator::default());
    };
    let mut integrator = Integrator::default();
    for (key, v) in r.table(value, "[integrator]")?.iter() {
        match key.name.as_str() {
            "method" => integrator.scheme = read_scheme(r, v)?,
            "rtol" => integrator.rtol = r.number(v, "[integrator] rtol")?,
            "atol" => integrator.atol = r.number(v, "[integrator] atol")?,
            "step" => integrator.fixed_step = Some(r.number(v, "[integrator] step")?),
            "max_steps" => integrator.max_steps = r.number(v, "[integrator] max_steps")? as usize,
            other => {
                return Err(r.err(
                    key.at,
                    format!(
                        "unknown key `{other}` in [integrator] (keys: method, rtol, atol, step, max_steps)"
                    ),
                ));
            }
        }
    }
    integrator.validate().map_err(|e| {
        // The file's key for the setting: `step` is the integrator's fixed step.
        let key = if e.name == "fixed_step" { "step" } else { e.name };
        r.err(value.at, format!("[integrator] {key} {}", e.problem))
    })?;
    Ok(integrator)
}

/// Reads `[integrator] method`: "dopri5", "dop853", "rk4", "rodas4", "rodas5p", "bdf" or "auto".
fn read_scheme(r: &Reader<'_>, v: &Node) -> Result<Scheme, ModelError> {
    match r.string(v, "[integrator] method")? {
        "dopri5" => Ok(Scheme::Dopri5),
        "dop853" => Ok(Scheme::Dop853),
        "rk4" => Ok(Scheme::Rk4),
        "rodas4" => Ok(Scheme::Rodas4),
        "rodas5p" => Ok(Scheme::Rodas5p),
        "bdf" => Ok(Scheme::Bdf),
        "auto" => Ok(Scheme::Auto),
        other => Err(r.err(
            v.at,
            format!(
                "[integrator] method must be \"dopri5\", \"dop853\", \"rk4\", \"rodas4\", \"rodas5p\", \"bdf\" or \"auto\", got \"{other}\""
            ),
        )),
    }
}
