//! SBML events that fire when time reaches a value, against closed forms: a boundary
//! species S drives A' = k·S; S starts at 1, an event sets it to 2 at t_on and another to 0
//! at t = 3, in either order. The negative log-likelihood and its gradient with respect to
//! k and to an estimated t_on, and the events the importer refuses, each named where written.

use std::path::{Path, PathBuf};

use sysid_petab::import;

/// The SBML model; `events` replaces the list of events.
fn sbml(events: &str) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<sbml xmlns="http://www.sbml.org/sbml/level3/version1/core" level="3" version="1">
  <model id="switched">
    <listOfCompartments><compartment id="c" size="1" constant="true"/></listOfCompartments>
    <listOfSpecies>
      <species id="A" compartment="c" initialConcentration="0" hasOnlySubstanceUnits="false" boundaryCondition="false" constant="false"/>
      <species id="S" compartment="c" initialConcentration="1" hasOnlySubstanceUnits="false" boundaryCondition="true" constant="false"/>
    </listOfSpecies>
    <listOfParameters>
      <parameter id="k" value="1" constant="true"/>
      <parameter id="t_on" value="1" constant="true"/>
    </listOfParameters>
    <listOfReactions>
      <reaction id="production" reversible="false" fast="false">
        <listOfProducts><speciesReference species="A" stoichiometry="1" constant="true"/></listOfProducts>
        <listOfModifiers><modifierSpeciesReference species="S"/></listOfModifiers>
        <kineticLaw>
          <math xmlns="http://www.w3.org/1998/Math/MathML">
            <apply><times/><ci> k </ci><ci> S </ci></apply>
          </math>
        </kineticLaw>
      </reaction>
    </listOfReactions>
    <listOfEvents>
{events}
    </listOfEvents>
  </model>
</sbml>
"#
    )
}

/// An event setting `variable` to `value` when `trigger` (MathML) becomes true.
fn event(id: &str, trigger: &str, variable: &str, value: &str) -> String {
    format!(
        r#"      <event id="{id}" useValuesFromTriggerTime="true">
        <trigger initialValue="true" persistent="true">
          <math xmlns="http://www.w3.org/1998/Math/MathML">{trigger}</math>
        </trigger>
        <listOfEventAssignments>
          <eventAssignment variable="{variable}">
            <math xmlns="http://www.w3.org/1998/Math/MathML">{value}</math>
          </eventAssignment>
        </listOfEventAssignments>
      </event>"#
    )
}

const TIME: &str = r#"<csymbol encoding="text" definitionURL="http://www.sbml.org/sbml/symbols/time"> time </csymbol>"#;

/// S = 2 from t_on on, S = 0 from t = 3 on (the later event wins).
fn two_events() -> String {
    let on = event(
        "switch_on",
        &format!("<apply><geq/>{TIME}<ci> t_on </ci></apply>"),
        "S",
        "<cn> 2 </cn>",
    );
    // Written the other way round: 3 ≤ time.
    let off = event(
        "switch_off",
        &format!("<apply><leq/><cn> 3 </cn>{TIME}</apply>"),
        "S",
        "<cn> 0 </cn>",
    );
    format!("{on}\n{off}")
}

const TIMES: [f64; 6] = [0.5, 1.0, 2.0, 2.5, 3.5, 5.0];
const SIGMA: f64 = 0.1;

/// The data: A at the times, for each condition's t_on.
fn measured(t_on: f64) -> Vec<f64> {
    TIMES
        .iter()
        .enumerate()
        .map(|(i, &t)| 0.8 * integral(t, t_on) + 0.03 * (i as f64 - 2.5))
        .collect()
}

/// ∫₀ᵗ S: S = 1 until the first event, then the value of the latest event fired.
fn integral(t: f64, t_on: f64) -> f64 {
    if t_on < 3.0 {
        t.min(t_on) + 2.0 * (t - t_on).clamp(0.0, 3.0 - t_on)
    } else {
        t.min(3.0) + 2.0 * (t - t_on).max(0.0)
    }
}

/// The NLL of the conditions' data at k (σ = 0.1).
fn nll(k: f64, conditions: &[(f64, f64)]) -> f64 {
    let mut sum = 0.0;
    for &(t_on, data_t_on) in conditions {
        for (&t, b) in TIMES.iter().zip(measured(data_t_on)) {
            let r = (b - k * integral(t, t_on)) / SIGMA;
            sum += 0.5 * r * r + (SIGMA * (2.0 * std::f64::consts::PI).sqrt()).ln();
        }
    }
    sum
}

/// A PEtab problem in a directory of its own: the SBML, the parameter table's rows after
/// the header, the conditions (id → t_on, or none), the measurements' conditions.
fn problem(
    test: &str,
    sbml: &str,
    parameters: &str,
    conditions: &[(&str, Option<f64>)],
    preequilibration: Option<&str>,
) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("sysid-petab-events-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a directory");
    let write = |name: &str, text: &str| std::fs::write(dir.join(name), text).expect("written");
    write("model.xml", sbml);
    write(
        "parameters.tsv",
        &format!(
            "parameterId\tparameterScale\tlowerBound\tupperBound\tnominalValue\testimate\n{parameters}"
        ),
    );
    write(
        "observables.tsv",
        &format!("observableId\tobservableFormula\tnoiseFormula\nA_obs\tA\t{SIGMA}\n"),
    );
    let with_t_on = conditions.iter().any(|c| c.1.is_some());
    let mut table = String::from(if with_t_on { "conditionId\tt_on\n" } else { "conditionId\n" });
    let mut data = String::from(
        "observableId\tpreequilibrationConditionId\tsimulationConditionId\tmeasurement\ttime\n",
    );
    for (id, t_on) in conditions {
        match t_on {
            Some(t) => table.push_str(&format!("{id}\t{t}\n")),
            None => table.push_str(&format!("{id}\n")),
        }
        for (&t, b) in TIMES.iter().zip(measured(t_on.unwrap_or(1.5))) {
            let pre = preequilibration.unwrap_or("");
            data.push_str(&format!("A_obs\t{pre}\t{id}\t{b}\t{t}\n"));
        }
    }
    write("conditions.tsv", &table);
    write("measurements.tsv", &data);
    write(
        "problem.yaml",
        "format_version: 1\nparameter_file: parameters.tsv\nproblems:\n- condition_files: [conditions.tsv]\n  measurement_files: [measurements.tsv]\n  observable_files: [observables.tsv]\n  sbml_files: [model.xml]\n",
    );
    dir.join("problem.yaml")
}

/// The NLL and its gradient at the nominal values.
fn nll_and_gradient(path: &Path) -> (f64, Vec<f64>) {
    let imported = import(path).unwrap_or_else(|e| panic!("{e}"));
    let problem = imported.model.problem(None).unwrap_or_else(|e| panic!("{e}"));
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).expect("integrates");
    (problem.nll(&lin).expect("a likelihood"), lin.gradient.as_slice().to_vec())
}

/// The NLL at (k, t_on) = (0.7, 1.2) and its gradient against the closed form `at`: the NLL
/// to 1e-9, each derivative to 1e-7 against its central difference (step 1e-6).
#[track_caller]
fn agrees_at_k_and_t_on((value, gradient): (f64, &[f64]), at: impl Fn(f64, f64) -> f64) {
    assert!((value - at(0.7, 1.2)).abs() <= 1e-9, "NLL {value} vs {}", at(0.7, 1.2));
    let h = 1e-6;
    let slopes = [
        (at(0.7 + h, 1.2) - at(0.7 - h, 1.2)) / (2.0 * h),
        (at(0.7, 1.2 + h) - at(0.7, 1.2 - h)) / (2.0 * h),
    ];
    for (g, s) in gradient.iter().zip(slopes) {
        assert!((g - s).abs() <= 1e-7 * s.abs().max(1.0), "{gradient:?} vs {slopes:?}");
    }
}

/// Two conditions, t_on = 1.5 (S: 1, 2, then 0) and t_on = 4 (S: 1, 0 from t = 3, then 2
/// from t = 4): the NLL to 1e-9 and ∂NLL/∂k to 1e-8 against the closed form.
#[test]
fn events_set_a_boundary_species_in_either_order() {
    let path = problem(
        "order",
        &sbml(&two_events()),
        "k\tlin\t0.01\t10\t0.7\t1\n",
        &[("early", Some(1.5)), ("late", Some(4.0))],
        None,
    );
    let (value, gradient) = nll_and_gradient(&path);
    let conditions = [(1.5, 1.5), (4.0, 4.0)];
    let expected = nll(0.7, &conditions);
    assert!((value - expected).abs() <= 1e-9, "NLL {value} vs {expected}");
    let h = 1e-6;
    let slope = (nll(0.7 + h, &conditions) - nll(0.7 - h, &conditions)) / (2.0 * h);
    assert!((gradient[0] - slope).abs() <= 1e-8 * slope.abs().max(1.0), "{gradient:?} vs {slope}");
    let _ = std::fs::remove_dir_all(path.parent().expect("a directory"));
}

/// t_on estimated: the switch moves with it, and ∂NLL/∂t_on (A loses k·(2 − 1) for every
/// unit the event comes later) matches central differences of the closed form to 1e-7.
#[test]
fn an_estimated_event_time_has_its_gradient() {
    let path = problem(
        "estimated",
        &sbml(&two_events()),
        "k\tlin\t0.01\t10\t0.7\t1\nt_on\tlin\t0.1\t2.9\t1.2\t1\n",
        &[("only", None)],
        None,
    );
    let (value, gradient) = nll_and_gradient(&path);
    let at = |k: f64, t_on: f64| nll(k, &[(t_on, 1.5)]);
    agrees_at_k_and_t_on((value, &gradient), at);
    let _ = std::fs::remove_dir_all(path.parent().expect("a directory"));
}

/// An event at t_on (estimated) resets the state A, which the reaction changes, to 0: A = k·t
/// before t_on and k·(t − t_on) after. The NLL to 1e-9 and its gradient in k and t_on (the
/// reset moving with t_on: ∂A/∂t_on = −k after it) to 1e-7 against central differences of
/// the closed form.
#[test]
fn an_event_resets_a_state_with_its_gradient() {
    let reset =
        event("reset", &format!("<apply><geq/>{TIME}<ci> t_on </ci></apply>"), "A", "<cn> 0 </cn>");
    let path = problem(
        "reset",
        &sbml(&reset),
        "k\tlin\t0.01\t10\t0.7\t1\nt_on\tlin\t0.1\t2.9\t1.2\t1\n",
        &[("only", None)],
        None,
    );
    let (value, gradient) = nll_and_gradient(&path);
    let at = |k: f64, t_on: f64| {
        let mut sum = 0.0;
        for (&t, b) in TIMES.iter().zip(measured(1.5)) {
            let a = if t < t_on { k * t } else { k * (t - t_on) };
            let r = (b - a) / SIGMA;
            sum += 0.5 * r * r + (SIGMA * (2.0 * std::f64::consts::PI).sqrt()).ln();
        }
        sum
    };
    agrees_at_k_and_t_on((value, &gradient), at);
    let _ = std::fs::remove_dir_all(path.parent().expect("a directory"));
}

/// What cannot be written as a switch in time or as a state event is refused, naming the
/// event at its line.
#[test]
fn events_that_are_not_switches_in_time_are_refused_where_written() {
    let refused = |test: &str, events: &str, pre: Option<&str>, expected: &str| {
        let path =
            problem(test, &sbml(events), "k\tlin\t0.01\t10\t0.7\t1\n", &[("c1", Some(1.5))], pre);
        let e = import(&path).map(|_| ()).expect_err("refused").to_string();
        assert!(e.contains(expected), "{test}: {e}");
        let _ = std::fs::remove_dir_all(path.parent().expect("a directory"));
        e
    };
    let on = |variable: &str, value: &str| {
        event("pulse", &format!("<apply><geq/>{TIME}<ci> t_on </ci></apply>"), variable, value)
    };
    // The event element is on line 25 of the SBML.
    let e = refused(
        "state-trigger",
        &event("pulse", "<apply><geq/><ci> A </ci><cn> 1 </cn></apply>", "S", "<cn> 0 </cn>"),
        None,
        "event `pulse`: it sets `S`, which is not a state, beside states or on a trigger of states",
    );
    assert!(e.contains("model.xml:25:7:"), "{e}");
    let reset =
        event("pulse", "<apply><geq/><ci> A </ci><cn> 1 </cn></apply>", "A", "<cn> 0 </cn>");
    refused(
        "initially-false",
        &reset.replace("initialValue=\"true\"", "initialValue=\"false\""),
        None,
        "event `pulse`: its trigger has initialValue=\"false\"",
    );
    refused(
        "two-comparisons",
        &reset.replace(
            "<apply><geq/><ci> A </ci><cn> 1 </cn></apply>",
            "<apply><and/><apply><geq/><ci> A </ci><cn> 1 </cn></apply><apply><geq/><ci> k </ci><cn> 0 </cn></apply></apply>",
        ),
        None,
        "its trigger is not one comparison (<, ≤, >, ≥), which is not supported",
    );
    refused(
        "compartment",
        &on("c", "<cn> 2 </cn>"),
        None,
        "event `pulse`: it sets `c`, which is no species or parameter",
    );
    refused(
        "state-value",
        &on("S", "<apply><times/><cn> 2 </cn><ci> A </ci></apply>"),
        None,
        "event `pulse`: the value it gives `S` depends on species, time or variables that events set",
    );
    refused(
        "delay",
        &on("S", "<cn> 0 </cn>").replace(
            "<listOfEventAssignments>",
            "<delay><math xmlns=\"http://www.w3.org/1998/Math/MathML\"><cn> 1 </cn></math></delay><listOfEventAssignments>",
        ),
        None,
        "event `pulse`: delays are not supported",
    );
    refused(
        "preequilibration",
        &on("S", "<cn> 0 </cn>"),
        Some("c1"),
        "a preequilibration (or a steady state) in a model with events (event `pulse`) is not supported",
    );
}

/// The same model without events (A = k·t), its observable with `noiseDistribution`
/// `laplace` (σ = 0.1 is the Laplace scale b): the NLL Σ ln(2b) + |m − k t|/b to 1e-9 and
/// ∂NLL/∂k = Σ sign(k t − m)·t/b to 1e-9 relative.
#[test]
fn laplace_noise_is_read_from_the_observable_table() {
    let path = problem("laplace", &sbml(""), "k\tlin\t0.01\t10\t0.7\t1\n", &[("only", None)], None);
    let observables = path.with_file_name("observables.tsv");
    std::fs::write(
        &observables,
        format!("observableId\tobservableFormula\tnoiseFormula\tnoiseDistribution\nA_obs\tA\t{SIGMA}\tlaplace\n"),
    )
    .expect("written");
    let (value, gradient) = nll_and_gradient(&path);
    let (mut expected, mut slope) = (0.0, 0.0);
    for (&t, m) in TIMES.iter().zip(measured(1.5)) {
        let d = 0.7 * t - m;
        expected += (2.0 * SIGMA).ln() + d.abs() / SIGMA;
        slope += d.signum() * t / SIGMA;
    }
    assert!((value - expected).abs() <= 1e-9 * expected.abs(), "NLL {value} vs {expected}");
    assert!((gradient[0] - slope).abs() <= 1e-9 * slope.abs(), "{gradient:?} vs {slope}");
    let _ = std::fs::remove_dir_all(path.parent().expect("a directory"));
}
