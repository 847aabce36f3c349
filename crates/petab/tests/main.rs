//! PEtab problems of Benchmark-Models-PEtab (tests/data/petab, BSD-3) imported and
//! evaluated: the negative log-likelihood at the nominal parameters against AMICI's stored
//! reference (to 1e-3, AMICI's own check) or the collection's simulated data; the features
//! refused by name; bad input located by file, line and column.

mod events;

use std::path::{Path, PathBuf};

use sysid_petab::import;

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/petab")
}

fn yaml(problem: &str) -> PathBuf {
    data().join(problem).join(format!("{problem}.yaml"))
}

/// The NLL (likelihood only, priors apart) at the parameter table's nominal values.
fn nll_at_nominal(problem: &str) -> f64 {
    nll_at(&yaml(problem))
}

/// The NLL at the nominal values of the problem `path`.
fn nll_at(path: &Path) -> f64 {
    let name = path.display();
    let imported = import(path).unwrap_or_else(|e| panic!("{name}: {e}"));
    let problem = imported.model.problem(None).unwrap_or_else(|e| panic!("{name}: {e}"));
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).expect("integrates at nominal");
    problem.nll(&lin).expect("a likelihood")
}

/// AMICI's stored NLL at nominal (tests/benchmark_models/benchmark_models.yaml of
/// AMICI-dev/AMICI, as llh = −NLL), checked as AMICI checks itself: to 1e-3 absolute.
#[test]
fn nll_at_nominal_matches_amicis_reference() {
    let references = [
        ("Boehm_JProteomeRes2014", 138.22199693517703),
        ("Fujita_SciSignal2010", -53.08377736998929),
        ("Bachmann_MSB2011", -418.40573341425295),
        ("Elowitz_Nature2000", -63.20279991419332),
        ("Fiedler_BMCSystBiol2016", -58.58390161681),
        ("Bruno_JExpBot2016", -46.688176988431806),
        ("Sneyd_PNAS2002", -319.79177818768756),
        ("Borghans_BiophysChem1997", -83.3237191357272),
        // Preequilibration: a steady state before the experiment.
        ("Zheng_PNAS2012", -278.33353271001477),
        ("Weber_BMC2015", 296.2017922646865),
    ];
    for (problem, reference) in references {
        let nll = nll_at_nominal(problem);
        assert!((nll - reference).abs() <= 1e-3, "{problem}: NLL {nll} vs AMICI's {reference}");
    }
}

/// More of the collection against collection_references.tsv, to 1e-3: AMICI's stored
/// reference (Beer, Brannmark, Schwen), AMICI 1.0.1's value at rtol 1e-12 where it stores
/// none (Raia, whose σ repeats its observable's parameter; Alkan, a piecewise without
/// otherwise), else the NLL of the collection's own simulated data (Raimundez, with Laplace
/// priors; Armistead, Bertozzi, Blasi, Giordano, Perelson, Rahman; Liu, whose event resets a
/// state). The NLL of the model alone (no
/// sensitivities), at the problems' default tolerances.
#[test]
fn more_of_the_collection_matches_its_references() {
    let text = std::fs::read_to_string(data().join("collection_references.tsv")).expect("a table");
    let reference = |problem: &str| -> f64 {
        let row = text.lines().find(|l| l.split('\t').next() == Some(problem));
        let row = row.unwrap_or_else(|| panic!("{problem} has no reference"));
        row.split('\t').nth(1).and_then(|v| v.parse().ok()).expect("a number")
    };
    for (problem, file) in [
        ("Raia_CancerResearch2011", "Raia_CancerResearch2011.yaml"),
        ("Beer_MolBioSystems2014", "Beer_MolBioSystems2014.yaml"),
        ("Alkan_SciSignal2018", "Alkan_SciSignal2018.yaml"),
        ("Raimundez_PCB2020", "Raimundez_PCB2020.yaml"),
        ("Armistead_CellDeathDis2024", "Armistead_CellDeathDis2024.yaml"),
        ("Bertozzi_PNAS2020", "Bertozzi_PNAS2020.yaml"),
        ("Perelson_Science1996", "Perelson_Science1996.yaml"),
        ("Rahman_MBS2016", "Rahman_MBS2016.yaml"),
        ("Brannmark_JBC2010", "Brannmark_JBC2010.yaml"),
        ("Schwen_PONE2014", "Schwen_PONE2014.yaml"),
        ("Blasi_CellSystems2016", "Blasi_CellSystems2016.yaml"),
        ("Liu_IFACPapersOnLine2025", "Liu_IFACPapersOnLine2025.yaml"),
        ("Giordano_Nature2020", "Giordano_Nature2020.yaml"),
    ] {
        let path = data().join(problem).join(file);
        let imported = import(&path).unwrap_or_else(|e| panic!("{problem}: {e}"));
        assert!(imported.warnings.is_empty(), "{problem}: {:?}", imported.warnings);
        let p = imported.model.problem(None).unwrap_or_else(|e| panic!("{problem}: {e}"));
        let z = p.unknowns().coordinates(&p.guesses());
        let nll = p.nll_at(&z).expect("integrates at nominal").expect("a likelihood");
        let r = reference(problem);
        assert!((nll - r).abs() <= 1e-3, "{problem}: NLL {nll} vs {r}");
    }
}

/// Crauste: sysid's NLL agrees to 1e-7 with the one the collection's own simulated
/// observables give (simulatedData_*.tsv: the model at nominal, as published beside the
/// problem), and with itself at rtol 1e-12; AMICI's stored reference, 190.96521897, is
/// 1.24e-3 above both, outside AMICI's 1e-3, so it is not the test's reference here.
#[test]
fn crauste_matches_the_collections_simulated_data() {
    let dir = data().join("Crauste_CellSystems2017");
    let table = |name: &str| {
        let text = std::fs::read_to_string(dir.join(name)).expect("a table");
        let mut lines = text.lines();
        let header: Vec<String> =
            lines.next().expect("a header").split('\t').map(String::from).collect();
        let rows: Vec<Vec<String>> =
            lines.map(|l| l.split('\t').map(String::from).collect()).collect();
        (header, rows)
    };
    let column = |h: &[String], name: &str| h.iter().position(|c| c == name).expect("a column");
    let (ph, parameters) = table("parameters_Crauste_CellSystems2017.tsv");
    let (mh, measured) = table("measurementData_Crauste_CellSystems2017.tsv");
    let (sh, simulated) = table("simulatedData_Crauste_CellSystems2017.tsv");
    let nominal = |id: &str| -> f64 {
        match parameters.iter().find(|r| r[column(&ph, "parameterId")] == id) {
            Some(r) => r[column(&ph, "nominalValue")].parse().expect("a number"),
            None => id.parse().expect("a number"),
        }
    };
    let mut reference = 0.0;
    for (m, s) in measured.iter().zip(&simulated) {
        let sigma = nominal(&m[column(&mh, "noiseParameters")]);
        let b: f64 = m[column(&mh, "measurement")].parse().expect("a number");
        let y: f64 = s[column(&sh, "simulation")].parse().expect("a number");
        reference += 0.5 * (2.0 * std::f64::consts::PI * sigma * sigma).ln()
            + 0.5 * ((b - y) / sigma).powi(2);
    }
    let nll = nll_at_nominal("Crauste_CellSystems2017");
    assert!((nll - reference).abs() <= 1e-7, "NLL {nll} vs the simulated data's {reference}");
    assert!((nll - 190.96521897435176).abs() > 1e-3);
}

/// Weber's preequilibration at tight tolerances. Its fluxes cancel at the steady state, so
/// from t = 1e4 on rounding kept its derivatives at 2–4 times rtol 1e-11 (in quanta of 2⁻³¹)
/// and the steady state, judged by its derivatives alone, was never found: the NLL at rtol
/// 1e-11 and 1e-12 was an error ("initial state PKD became non-finite"). It is found once a
/// decade moves no component by more than 100 tolerances (its moves are the integration's
/// noise, 1.5–30 of them): the NLL at rtol 1e-11 and 1e-12 is the NLL at 1e-10 to 1e-8
/// (3.5e-10 and 3.9e-10 measured), and AMICI's stored reference to its 1e-3.
#[test]
fn webers_steady_state_is_found_at_tight_tolerances() {
    let imported = import(&yaml("Weber_BMC2015")).expect("imports");
    let problem = imported.model.problem(None).expect("a problem");
    let z = problem.unknowns().coordinates(&problem.guesses());
    let at = |rtol: f64| {
        let integrator = sysid_ode::Integrator { rtol, ..*problem.integrator() };
        let tight = problem.clone().with_integrator(integrator).expect("an integrator");
        tight.nll_at(&z).unwrap_or_else(|e| panic!("rtol {rtol:e}: {e}")).expect("a likelihood")
    };
    let reference = at(1e-10);
    assert!((reference - 296.2017922646865).abs() <= 1e-3, "{reference}");
    for rtol in [1e-11, 1e-12] {
        let nll = at(rtol);
        assert!(
            (nll - reference).abs() <= 1e-8,
            "rtol {rtol:e}: NLL {nll} vs {reference} at 1e-10"
        );
    }
}

/// Smith (133 species, 367 reactions, insulin switched off at t_ins and on again at 2880 by
/// SBML events, written as switches in time): the NLL at nominal of the model alone (a plain
/// integration at rtol 1e-10) against AMICI 1.0.1's at rtol 1e-14, 888198.438954
/// (`scripts/reference/amici_nominal.py --rtol`: .43899, .43896, .43895, .43895 at 1e-10,
/// 1e-12, 1e-13, 1e-14), to 1e-6 (3e-8 measured). AMICI's stored 888198.436541 lies 2.4e-3
/// below every one of them: the test says so.
#[test]
fn smiths_events_give_amicis_likelihood() {
    let imported = import(&yaml("Smith_BMCSystBiol2013")).expect("imports");
    let problem = imported.model.problem(None).expect("a problem");
    let integrator = sysid_ode::Integrator::rodas5p(1e-10, 1e-14).with_max_steps(1_000_000);
    let problem = problem.with_integrator(integrator).expect("an integrator");
    let z = problem.unknowns().coordinates(&problem.guesses());
    let nll = problem.nll_at(&z).expect("integrates").expect("a likelihood");
    let reference = 888198.4389539681;
    assert!((nll - reference).abs() <= 1e-6, "NLL {nll} vs AMICI's at rtol 1e-14 {reference}");
    assert!((nll - 888198.436541014).abs() > 2e-3);
}

/// A copy of Boehm's problem in a directory of its own, with `edit` applied to one file.
fn edited(test: &str, file: &str, edit: impl Fn(String) -> String) -> PathBuf {
    edited_files(test, &[(file, &edit)])
}

/// A copy of Boehm's problem in a directory of its own, each edit applied to the file whose
/// name starts with its prefix.
#[allow(clippy::type_complexity)]
fn edited_files(test: &str, edits: &[(&str, &dyn Fn(String) -> String)]) -> PathBuf {
    edited_problem("Boehm_JProteomeRes2014", test, edits)
}

/// A copy of `problem` in a directory of its own, each edit applied to the file whose name
/// starts with its prefix.
#[allow(clippy::type_complexity)]
fn edited_problem(
    problem: &str,
    test: &str,
    edits: &[(&str, &dyn Fn(String) -> String)],
) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sysid-petab-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a directory");
    for entry in std::fs::read_dir(data().join(problem)).expect("the problem") {
        let path = entry.expect("an entry").path();
        let name = path.file_name().expect("a name").to_string_lossy().to_string();
        let mut text = std::fs::read_to_string(&path).expect("a file");
        for (file, edit) in edits {
            if name.starts_with(file) {
                text = edit(text);
            }
        }
        std::fs::write(dir.join(&name), text).expect("written");
    }
    dir.join(format!("{problem}.yaml"))
}

fn error_of(path: &Path) -> String {
    import(path).map(|_| ()).expect_err("refused").to_string()
}

/// Bad input: each error names the file, the line and the column (the cell), and what is
/// wrong, with the offending name.
#[test]
fn bad_input_is_located() {
    let e = error_of(&data().join("missing/none.yaml"));
    assert!(e.contains("none.yaml: cannot be read"), "{e}");
    // The YAML reader's complaint at its line and column, in words, not its types ("cannot
    // deserialize null into string; use Option<String>").
    let path = edited("yaml", "Boehm_JProteomeRes2014.yaml", |t| {
        t.replacen("parameter_file: parameters_Boehm_JProteomeRes2014.tsv", "parameter_file:", 1)
    });
    let e = error_of(&path);
    assert!(e.contains("Boehm_JProteomeRes2014.yaml:"), "{e}");
    assert!(e.contains("not a PEtab problem file: ") && !e.contains("Option<"), "{e}");

    let path =
        edited("observable", "measurementData", |t| t.replacen("pSTAT5A_rel\t", "pSTAT5X\t", 1));
    let e = error_of(&path);
    assert!(e.contains("measurementData_Boehm_JProteomeRes2014.tsv:2:1: column `observableId`: `pSTAT5X` is not in the observable table"), "{e}");

    let path = edited("formula", "observables", |t| t.replacen("(100 * pApB", "(100 * * pApB", 1));
    let e = error_of(&path);
    assert!(
        e.contains("observables_Boehm_JProteomeRes2014.tsv:2:")
            && e.contains("column `observableFormula`"),
        "{e}"
    );

    let path = edited("condition", "measurementData", |t| t.replacen("model1_data1", "model9", 1));
    let e = error_of(&path);
    assert!(
        e.contains(".tsv:2:") && e.contains("condition `model9` is not in the condition table"),
        "{e}"
    );

    let path = edited("number", "measurementData", |t| {
        let mut lines: Vec<String> = t.lines().map(String::from).collect();
        let mut cells: Vec<String> = lines[1].split('\t').map(String::from).collect();
        cells[3] = "n/a".into();
        lines[1] = cells.join("\t");
        lines.join("\n")
    });
    let e = error_of(&path);
    assert!(
        e.contains(".tsv:2:") && e.contains("column `measurement`: `n/a` is not a number"),
        "{e}"
    );

    let path = edited("parameter", "observables", |t| t.replacen("specC17 - 1", "specC99 - 1", 1));
    let e = error_of(&path);
    assert!(e.contains("uses `specC99`, which is no species, parameter or compartment"), "{e}");

    // An observable no row measures is checked all the same, at its formula's cell; its
    // placeholders, which only a row would fill, are taken as given.
    let unused = |formula: &'static str, noise: &'static str| {
        move |t: String| format!("{}\nunused\t\t{formula}\t{noise}\tlin\tnormal\n", t.trim_end())
    };
    let path = edited("unused", "observables", unused("2 * STAT5A_typo", "1"));
    let e = error_of(&path);
    assert!(
        e.contains("observables_Boehm_JProteomeRes2014.tsv:5:")
            && e.contains("column `observableFormula`: observable `unused` uses `STAT5A_typo`"),
        "{e}"
    );
    let path = edited("unused-noise", "observables", unused("STAT5A", "0.1 * unused + sd_x"));
    let e = error_of(&path);
    assert!(e.contains("column `noiseFormula`: observable `unused` uses `sd_x`"), "{e}");
    let path = edited(
        "unused-placeholders",
        "observables",
        unused("observableParameter1_unused * STAT5A", "noiseParameter1_unused + 0.1 * unused"),
    );
    import(&path).expect("an unused observable's placeholders are left to the rows");

    // Rows of the parameter table that name no parameter (line 13, after the 11 of the
    // table): a species, an assignment rule's variable, an estimated id nothing uses. Read as
    // a parameter, the species' row had given the outputs the constant 10 where the equations
    // kept the state (NLL 420.9 instead of 138.2).
    for (test, row, message) in [
        ("species", "STAT5A\tSTAT5A\tlin\t0\t1000\t10\t0", "`STAT5A` is a state of the model"),
        (
            "rule",
            "BaF3_Epo\tBaF3_Epo\tlin\t0\t1000\t1\t1",
            "`BaF3_Epo` is the variable of an assignment rule",
        ),
        ("nowhere", "bogus\tbogus\tlin\t0\t1\t0.5\t1", "`bogus` is estimated but used nowhere"),
    ] {
        let path = edited(test, "parameters", |t| format!("{}\n{row}\n", t.trim_end()));
        let e = error_of(&path);
        assert!(
            e.contains("parameters_Boehm_JProteomeRes2014.tsv:13:1:") && e.contains(message),
            "{e}"
        );
    }
    // An estimated parameter that only an observable no measurement uses names is PEtab's
    // to require in the table, and is kept.
    let path = edited_files(
        "unmeasured-parameter",
        &[
            ("observables", &|t: String| {
                format!("{}\nunused\t\tscale_x * STAT5A\t1\tlin\tnormal\n", t.trim_end())
            }),
            ("parameters", &|t: String| {
                format!("{}\nscale_x\tscale_x\tlin\t0\t10\t1\t1\n", t.trim_end())
            }),
        ],
    );
    import(&path).expect("a parameter of an observable no measurement uses");
    // One that nothing uses and nothing estimates is its nominal value nowhere: harmless.
    let path = edited("unused-known", "parameters", |t| {
        format!("{}\nbogus\tbogus\tlin\t0\t1\t0.5\t0\n", t.trim_end())
    });
    import(&path).expect("a known parameter nothing uses is left alone");

    let path = edited("sbml", "model_", |t| t.replacen("<listOfReactions>", "<listOfReactions", 1));
    let e = error_of(&path);
    assert!(e.contains("model_Boehm_JProteomeRes2014.xml:") && e.contains("not valid XML"), "{e}");

    // A compartment whose size is not a positive number, at its element (line 45), with the
    // species whose concentrations it makes meaningless: at 0 the first integration had
    // failed on a species of the other compartment ("state STAT5A became non-finite at t =
    // 0"), and NaN or INF were "parameter `nuc` has no value".
    for size in ["0", "-0.45", "NaN", "INF"] {
        let path = edited(&format!("compartment{size}"), "model_", |t| {
            t.replacen(
                r#"id="nuc" spatialDimensions="3" size="0.45""#,
                &format!(r#"id="nuc" spatialDimensions="3" size="{size}""#),
                1,
            )
        });
        let e = error_of(&path);
        assert!(
            e.contains("model_Boehm_JProteomeRes2014.xml:45:")
                && e.contains("compartment `nuc` has size ")
                && e.contains("a size must be a positive number: the concentrations of its species (nucpApA, nucpApB, nucpBpB)"),
            "{size}: {e}"
        );
    }
    // A compartment with no size is taken as 1, with a warning at its element; on Boehm the
    // nucleus' size cancels (its species enter and leave by rates that carry it), so the
    // NLL is the published one, within its integration error (1.5e-8 at nominal, reported
    // by `evaluate`; a size of 1 instead of 0.45 changes the steps the integrator takes).
    let path = edited("compartment-sizeless", "model_", |t| {
        t.replacen(
            r#"id="nuc" spatialDimensions="3" size="0.45""#,
            r#"id="nuc" spatialDimensions="3""#,
            1,
        )
    });
    let imported = import(&path).expect("a compartment without a size is taken as 1");
    assert_eq!(imported.warnings.len(), 1, "{:?}", imported.warnings);
    let w = &imported.warnings[0];
    assert!(
        w.contains("model_Boehm_JProteomeRes2014.xml:45:")
            && w.contains("compartment `nuc` has no size: it is taken as 1"),
        "{w}"
    );
    let (sizeless, published) = (nll_at(&path), nll_at_nominal("Boehm_JProteomeRes2014"));
    assert!((sizeless - published).abs() < 1e-7, "{sizeless} against {published}");
    assert!(import(&yaml("Boehm_JProteomeRes2014")).unwrap().warnings.is_empty());
}

/// Bachmann's one prior (parameterScaleNormal on log10 init_EpoRJAK2) is a row of the
/// objective, reported apart: the likelihood is AMICI's reference without it, and the
/// negative log-prior at nominal is ½((log10 θ − μ)/σ)² + ln(σ√(2π)) from the table's
/// numbers. A prior type that is not supported is refused at its cell.
#[test]
fn a_prior_is_reported_apart_from_the_likelihood() {
    let imported = import(&yaml("Bachmann_MSB2011")).expect("imports");
    let problem = imported.model.problem(None).expect("a problem");
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).expect("integrates");
    let (theta, mean, sd) = (3.97622379188569_f64, 0.599470870492697, 0.193459292722329);
    let expected = 0.5 * ((theta.log10() - mean) / sd).powi(2)
        + (sd * (2.0 * std::f64::consts::PI).sqrt()).ln();
    let prior = problem.prior_nll(&lin).expect("a prior");
    assert!((prior - expected).abs() <= 1e-12, "{prior} vs {expected}");
    assert!((problem.nll(&lin).expect("a likelihood") + 418.40573341425295).abs() <= 1e-3);

    // The prior as a Laplace one (location, scale b) at μ = 0.5, away from its kink (the
    // nominal value is the normal prior's mean): |log10 θ − μ|/b + ln(2b), and its gradient
    // in z = ln θ, sign(log10 θ − μ)/(b ln 10), in place of the normal one's
    // (log10 θ − μ)/(sd² ln 10); the likelihood's part of the gradient is the same.
    let mean = 0.5;
    let with_prior = |kind: &str| {
        let edit = |t: String| {
            t.replace("parameterScaleNormal\t0.599470870492697", &format!("{kind}\t{mean}"))
        };
        let path = edited_problem("Bachmann_MSB2011", kind, &[("parameters_", &edit)]);
        let problem = import(&path).expect("imports").model.problem(None).expect("a problem");
        let z = problem.unknowns().coordinates(&problem.guesses());
        let lin = problem.linearize(&z).expect("integrates");
        let j = problem.unknowns().names().iter().position(|n| n == "init_EpoRJAK2");
        (problem.prior_nll(&lin).expect("a prior"), lin.gradient.clone(), j.expect("estimated"))
    };
    let (laplace, g_laplace, j) = with_prior("parameterScaleLaplace");
    let d = theta.log10() - mean;
    let expected = d.abs() / sd + (2.0 * sd).ln();
    assert!((laplace - expected).abs() <= 1e-12, "{laplace} vs {expected}");
    let (_, g_normal, _) = with_prior("parameterScaleNormal");
    let ln10 = std::f64::consts::LN_10;
    for (i, (l, n)) in g_laplace.iter().zip(&g_normal).enumerate() {
        let expected = if i == j { d.signum() / (sd * ln10) - d / (sd * sd * ln10) } else { 0.0 };
        assert!(
            (l - n - expected).abs() <= 1e-9 * (1.0 + n.abs()),
            "∂/∂z{i}: {l} − {n} vs {expected}"
        );
    }

    // logNormal's density has a term ln θ besides a residual: refused at its cell.
    let edit = |t: String| t.replace("parameterScaleNormal", "logNormal");
    let e = error_of(&edited_problem("Bachmann_MSB2011", "lognormal", &[("parameters_", &edit)]));
    assert!(
        e.contains("parameters_Bachmann_MSB2011.tsv:28:")
            && e.contains(
                "column `objectivePriorType`: a prior of type `logNormal` is not supported"
            ),
        "{e}"
    );
}

/// A measurement at time `inf` is the steady state: Boehm with its last measurement moved
/// to `inf` (its Epo input decays, so the system settles) gives the NLL of the same
/// measurement at t = 1e8, when the state has long settled, to 1e-6; the steady one is an
/// experiment of its own; after a preequilibration under the same condition, the same.
#[test]
fn a_measurement_at_time_inf_is_the_steady_state() {
    let at = |time: &str, tag: &str| {
        let path = edited(tag, "measurementData", |t| {
            let mut lines: Vec<String> = t.lines().map(String::from).collect();
            let last = lines.len() - 1;
            let mut cells: Vec<String> = lines[last].split('\t').map(String::from).collect();
            cells[4] = time.into();
            lines[last] = cells.join("\t");
            lines.join("\n")
        });
        let imported = import(&path).unwrap_or_else(|e| panic!("{e}"));
        let problem = imported.model.problem(None).expect("a problem");
        let z = problem.unknowns().coordinates(&problem.guesses());
        let nll = problem.nll(&problem.linearize(&z).expect("integrates")).expect("an nll");
        let names: Vec<String> =
            problem.experiments().iter().map(|e| e.name().to_string()).collect();
        (nll, names)
    };
    let (steady, names) = at("inf", "inf");
    assert_eq!(names, ["model1_data1", "model1_data1-steady"]);
    let (late, _) = at("1e8", "late");
    assert!((steady - late).abs() <= 1e-6, "{steady} vs {late}");

    // After a preequilibration under the same condition, the steady state is the same.
    let after = edited("inf-pre", "measurementData", |t| {
        let mut lines: Vec<String> = t.lines().map(String::from).collect();
        let last = lines.len() - 1;
        let mut cells: Vec<String> = lines[last].split('\t').map(String::from).collect();
        cells[1] = "model1_data1".into();
        cells[4] = "inf".into();
        lines[last] = cells.join("\t");
        lines.join("\n")
    });
    let imported = import(&after).unwrap_or_else(|e| panic!("{e}"));
    assert!(imported.text.contains("steady = true"), "{}", imported.text);
    let problem = imported.model.problem(None).expect("a problem");
    let names: Vec<&str> = problem.experiments().iter().map(|e| e.name()).collect();
    assert_eq!(names, ["model1_data1", "model1_data1-steady-after-model1_data1"]);
    let (after, _) = nll_and_gradient(&after);
    assert!((after - steady).abs() <= 1e-6, "{after} vs {steady}");
}

/// The NLL and gradient at the nominal parameters of a problem file.
fn nll_and_gradient(path: &Path) -> (f64, Vec<f64>) {
    let imported = import(path).unwrap_or_else(|e| panic!("{e}"));
    let problem = imported.model.problem(None).expect("a problem");
    let z = problem.unknowns().coordinates(&problem.guesses());
    let lin = problem.linearize(&z).expect("integrates");
    (problem.nll(&lin).expect("an nll"), lin.gradient.as_slice().to_vec())
}

/// Boehm's condition table with a column for species `pApB` (its SBML initial value 0).
fn setting_papb(value: &'static str) -> impl Fn(String) -> String {
    move |t: String| {
        t.lines()
            .enumerate()
            .map(|(i, l)| format!("{l}\t{}", if i == 0 { "pApB" } else { value }))
            .collect::<Vec<_>>()
            .join("\n")
    }
}

/// A condition that sets a species' initial value gives the NLL and gradient of the model
/// with that initial value written into its SBML (a number as the initial concentration,
/// an estimated parameter as an initial assignment), to rounding; `NaN` keeps the model's
/// value; after a preequilibration it re-initialises the species.
#[test]
fn a_condition_sets_a_species_initial_value() {
    let close = |(a, ga): (f64, Vec<f64>), (b, gb): (f64, Vec<f64>)| {
        assert!((a - b).abs() <= 1e-9 * b.abs(), "NLL {a} vs {b}");
        for (x, y) in ga.iter().zip(&gb) {
            assert!((x - y).abs() <= 1e-9 * y.abs().max(1e-3), "gradient {ga:?} vs {gb:?}");
        }
    };
    let by_condition =
        nll_and_gradient(&edited("species-5", "experimentalCondition", setting_papb("5")));
    let in_sbml = nll_and_gradient(&edited("species-5-sbml", "model_", |t| {
        t.replace(
            r#"<species id="pApB" name="pApB" compartment="cyt" initialConcentration="0""#,
            r#"<species id="pApB" name="pApB" compartment="cyt" initialConcentration="5""#,
        )
    }));
    let nominal = nll_and_gradient(&yaml("Boehm_JProteomeRes2014"));
    assert!((by_condition.0 - nominal.0).abs() > 1.0, "the setting changes the fit");
    close(by_condition, in_sbml);

    let by_parameter = nll_and_gradient(&edited(
        "species-k",
        "experimentalCondition",
        setting_papb("Epo_degradation_BaF3"),
    ));
    let assigned = nll_and_gradient(&edited("species-k-sbml", "model_", |t| {
        t.replace(
            "    </listOfInitialAssignments>",
            r#"      <initialAssignment symbol="pApB">
        <math xmlns="http://www.w3.org/1998/Math/MathML">
          <ci> Epo_degradation_BaF3 </ci>
        </math>
      </initialAssignment>
    </listOfInitialAssignments>"#,
        )
    }));
    close(by_parameter, assigned);

    let kept =
        nll_and_gradient(&edited("species-nan", "experimentalCondition", setting_papb("NaN")));
    close(kept, nominal);

    // After a preequilibration the species is re-initialised. Boehm settles back to its
    // unphosphorylated initial state once Epo has decayed, so preequilibrating under a
    // condition that leaves pApB alone and then setting pApB = 5 is the setting without the
    // preequilibration.
    let with_pre = |t: String| format!("{}\npre\tpre\tNaN", setting_papb("5")(t).trim_end());
    let after = edited_files(
        "species-pre",
        &[
            ("experimentalCondition", &with_pre),
            ("measurementData", &|t: String| {
                let lines: Vec<String> = t
                    .lines()
                    .enumerate()
                    .map(|(i, l)| {
                        let mut cells: Vec<String> = l.split('\t').map(String::from).collect();
                        if i > 0 {
                            cells[1] = "pre".into();
                        }
                        cells.join("\t")
                    })
                    .collect();
                lines.join("\n")
            }),
        ],
    );
    let imported = import(&after).unwrap_or_else(|e| panic!("{e}"));
    assert!(imported.text.contains("initial = { pApB = 5e0 }"), "{}", imported.text);
    // At rtol 1e-12, where the NLL's integration error (1.2e-7 at the problem's 1e-8) is far
    // below the difference the preequilibration makes.
    let tight = |path: &Path| {
        let imported = import(path).unwrap_or_else(|e| panic!("{e}"));
        let integrator = sysid_ode::Integrator::rodas5p(1e-12, 1e-16).with_max_steps(1_000_000);
        let problem = imported.model.problem(None).expect("a problem");
        let problem = problem.with_integrator(integrator).expect("an integrator");
        let z = problem.unknowns().coordinates(&problem.guesses());
        problem.nll(&problem.linearize(&z).expect("integrates")).expect("an nll")
    };
    let reinitialised = tight(&after);
    let set = tight(&edited("species-5b", "experimentalCondition", setting_papb("5")));
    // Measured: 1.4e-8 apart (what the preequilibration leaves of the phosphorylated forms).
    assert!((reinitialised - set).abs() <= 1e-7, "{reinitialised} vs {set}");
}

/// Conditions that set the same values are one simulation: Boehm with its condition copied
/// under another id, and every other measurement moved to the copy, gives one experiment
/// (the first condition's) and Boehm's NLL and gradient; Bachmann's 36 conditions are 12
/// experiments.
#[test]
fn conditions_that_set_the_same_values_share_one_experiment() {
    let copied = edited_files(
        "same-settings",
        &[
            ("experimentalCondition", &|t: String| format!("{}\ncopy\tcondition1", t.trim_end())),
            ("measurementData", &|t: String| {
                let lines: Vec<String> = t
                    .lines()
                    .enumerate()
                    .map(|(i, l)| match i > 0 && i % 2 == 0 {
                        true => l.replace("\tmodel1_data1\t", "\tcopy\t"),
                        false => l.to_string(),
                    })
                    .collect();
                lines.join("\n")
            }),
        ],
    );
    let imported = import(&copied).unwrap_or_else(|e| panic!("{e}"));
    assert!(imported.text.contains("also = [\"copy\"]"), "{}", imported.text);
    let problem = imported.model.problem(None).expect("a problem");
    let names: Vec<&str> = problem.experiments().iter().map(|e| e.name()).collect();
    assert_eq!(names, ["model1_data1"]);
    assert!(problem.experiments()[0].answers_to("copy"));
    let (a, ga) = nll_and_gradient(&copied);
    let (b, gb) = nll_and_gradient(&yaml("Boehm_JProteomeRes2014"));
    assert!((a - b).abs() <= 1e-12 * b.abs(), "NLL {a} vs {b}");
    for (x, y) in ga.iter().zip(&gb) {
        assert!((x - y).abs() <= 1e-12 * y.abs().max(1e-3), "gradient {ga:?} vs {gb:?}");
    }

    let bachmann = import(&yaml("Bachmann_MSB2011")).expect("imports");
    let problem = bachmann.model.problem(None).expect("a problem");
    assert_eq!(problem.experiments().len(), 12);
}

/// What the importer composes stays within bounds: rules that each use the previous one
/// twice (an expression that doubles with every rule), function definitions nested in each
/// other, and a rule setting something undeclared are refused at the SBML element, never
/// a stack overflow or a run out of memory.
#[test]
fn composed_expressions_are_bounded() {
    let math =
        |body: &str| format!("<math xmlns=\"http://www.w3.org/1998/Math/MathML\">{body}</math>");
    // a0 = 1, a_i = a_{i-1} + a_{i-1}: 2^40 terms at a40.
    let doubling =
        |t: String| {
            let parameters: String = (0..=40)
                .map(|i| format!("<parameter id=\"a{i}\" value=\"1\" constant=\"false\"/>"))
                .collect();
            let rules: String = (1..=40)
                .map(|i| {
                    let j = i - 1;
                    format!(
                        "<assignmentRule variable=\"a{i}\">{}</assignmentRule>",
                        math(&format!("<apply><plus/><ci>a{j}</ci><ci>a{j}</ci></apply>"))
                    )
                })
                .collect();
            t.replacen("</listOfParameters>", &format!("{parameters}</listOfParameters>"), 1)
                .replacen("<listOfRules>", &format!("<listOfRules>{rules}"), 1)
        };
    let e = error_of(&edited("doubling", "model_", doubling));
    assert!(e.contains("model_Boehm_JProteomeRes2014.xml:") && e.contains("grows to"), "{e}");
    // f_i(x) = f_{i-1}(f_{i-1}(…x…)), nested 150 deep each: 150^3 levels at f3's call.
    let functions = |t: String| {
        let nest = |f: &str| {
            let mut body = "<ci>x</ci>".to_string();
            for _ in 0..150 {
                body = format!("<apply><ci>{f}</ci>{body}</apply>");
            }
            body
        };
        let mut defs = format!(
            "<functionDefinition id=\"f0\">{}</functionDefinition>",
            math(
                "<lambda><bvar><ci>x</ci></bvar><apply><plus/><ci>x</ci><cn>1</cn></apply></lambda>"
            )
        );
        for i in 1..=3 {
            defs += &format!(
                "<functionDefinition id=\"f{i}\">{}</functionDefinition>",
                math(&format!(
                    "<lambda><bvar><ci>x</ci></bvar>{}</lambda>",
                    nest(&format!("f{}", i - 1))
                ))
            );
        }
        t.replacen(
            "<listOfCompartments>",
            &format!(
                "<listOfFunctionDefinitions>{defs}</listOfFunctionDefinitions><listOfCompartments>"
            ),
            1,
        )
        .replacen("<ci> k_phos </ci>", "<apply><ci>f3</ci><ci> k_phos </ci></apply>", 1)
    };
    let e = error_of(&edited("functions", "model_", functions));
    assert!(e.contains("model_Boehm_JProteomeRes2014.xml:") && e.contains("levels deep"), "{e}");
    let undeclared = |t: String| t.replacen("variable=\"BaF3_Epo\"", "variable=\"nothing\"", 1);
    let e = error_of(&edited("target", "model_", undeclared));
    assert!(e.contains(":93:") && e.contains("sets `nothing`"), "{e}");
}

/// PEtab's initialization priors become the unknowns' initializations, on the scale PEtab
/// gives them; `uniform` without parameters is the bounds on the linear scale;
/// `parameterScaleUniform` without parameters is the default (none); a type PEtab does not
/// know, or one that needs parameters without them, is refused at its cell.
#[test]
fn initialization_priors_are_imported() {
    let with = |types: [&'static str; 3], parameters: [&'static str; 3]| {
        move |text: String| {
            let mut lines: Vec<String> = text.lines().map(String::from).collect();
            lines[0] += "\tinitializationPriorType\tinitializationPriorParameters";
            for (i, line) in lines.iter_mut().enumerate().skip(1) {
                let j = (i - 1).min(2);
                *line += &format!("\t{}\t{}", types[j], parameters[j]);
            }
            lines.join("\n") + "\n"
        }
    };
    let path = edited(
        "initialization",
        "parameters",
        with(["logNormal", "uniform", "parameterScaleUniform"], ["-3;0.5", "", ""]),
    );
    let problem = import(&path).expect("imports").model.problem(None).expect("a problem");
    let list = problem.unknowns().list();
    use sysid_core::{Distribution, Initialization, Transform};
    assert_eq!(
        list[0].initialization,
        Some(Initialization {
            distribution: Distribution::Normal,
            a: -3.0,
            b: 0.5,
            on: Transform::Log
        })
    );
    assert_eq!(
        list[1].initialization,
        Some(Initialization {
            distribution: Distribution::Uniform,
            a: 1e-5,
            b: 1e5,
            on: Transform::Lin
        })
    );
    assert!(list[2..].iter().all(|u| u.initialization.is_none()), "the default");
    for (types, parameters, says) in [
        (
            ["beta", "", ""],
            ["", "", ""],
            "an initialization prior of type `beta` is not one of PEtab's",
        ),
        (["normal", "", ""], ["", "", ""], "`normal` needs `initializationPriorParameters`"),
        (
            ["laplace", "", ""],
            ["1;-2", "", ""],
            "`1;-2`: a laplace one needs finite a;b with b > 0",
        ),
    ] {
        let e = error_of(&edited("initialization-bad", "parameters", with(types, parameters)));
        assert!(e.contains("parameters_Boehm_JProteomeRes2014.tsv:2:") && e.contains(says), "{e}");
    }
}

/// A noise formula that repeats its observable's placeholder gets the row's observable
/// parameter too (as Raia's σ = a + b · scaling · (…)): Boehm with pSTAT5A_rel = s·y,
/// σ = sd·s and s = 2 in every row has residuals (m − 2y)/(2 sd) = (m/2 − y)/sd, so its NLL
/// is Boehm's with those measurements halved plus ln 2 per measurement, to 1e-9.
#[test]
fn observable_parameters_fill_the_noise_formula_too() {
    let rows = |halve: bool| {
        move |t: String| {
            let mut out = String::new();
            for line in t.lines() {
                let mut cells: Vec<String> = line.split('\t').map(String::from).collect();
                if cells[0] == "pSTAT5A_rel" {
                    match halve {
                        true => {
                            let m: f64 = cells[3].parse().expect("a number");
                            cells[3] = format!("{:e}", m / 2.0);
                        }
                        false => cells[5] = "2".into(),
                    }
                }
                out.push_str(&cells.join("\t"));
                out.push('\n');
            }
            out
        }
    };
    let n = std::fs::read_to_string(
        data().join("Boehm_JProteomeRes2014/measurementData_Boehm_JProteomeRes2014.tsv"),
    )
    .expect("the table")
    .lines()
    .filter(|l| l.starts_with("pSTAT5A_rel\t"))
    .count();
    let scaled = |t: String| {
        t.replace(
            "pSTAT5A_rel\t\t(100 * pApB + 200 * pApA * specC17) / (pApB + STAT5A * specC17 + 2 * pApA * specC17)\tnoiseParameter1_pSTAT5A_rel",
            "pSTAT5A_rel\t\tobservableParameter1_pSTAT5A_rel * (100 * pApB + 200 * pApA * specC17) / (pApB + STAT5A * specC17 + 2 * pApA * specC17)\tnoiseParameter1_pSTAT5A_rel * observableParameter1_pSTAT5A_rel",
        )
    };
    let placeholders = rows(false);
    let with = edited_files(
        "noise-placeholder",
        &[("observables_", &scaled), ("measurementData_", &placeholders)],
    );
    assert!(
        std::fs::read_to_string(with.with_file_name("observables_Boehm_JProteomeRes2014.tsv"))
            .expect("written")
            .contains("\tnoiseParameter1_pSTAT5A_rel * observableParameter1_pSTAT5A_rel")
    );
    let halved = rows(true);
    let reference = edited_files("noise-halved", &[("measurementData_", &halved)]);
    let nll = |path: &Path| {
        let problem = import(path).expect("imports").model.problem(None).expect("a problem");
        let z = problem.unknowns().coordinates(&problem.guesses());
        problem.nll_at(&z).expect("integrates").expect("a likelihood")
    };
    let (a, b) = (nll(&with), nll(&reference));
    let expected = n as f64 * std::f64::consts::LN_2;
    assert!(n > 10 && (a - b - expected).abs() <= 1e-9, "{a} − {b} vs {n} ln 2");
}

/// PEtab allows a nominal value outside the bounds (Lang's kDpApc_1: 0 on a log scale
/// bounded by 1e-24): the start is moved onto the nearer bound, and the import warns at the
/// cell, naming the parameter. The published value is kept for the NLL at nominal where the
/// scale can hold it (1e6 here), not where it cannot (0 on a log scale).
#[test]
fn a_nominal_value_outside_its_bounds_is_moved_onto_the_bound() {
    let path = edited("outside-bounds", "parameters_", |t| {
        t.replace("1E-05\t100000\t0.026982514033029\t1", "1E-05\t100000\t1e6\t1")
    });
    let imported = import(&path).expect("imports");
    let [warning] = imported.warnings.as_slice() else {
        panic!("one warning: {:?}", imported.warnings)
    };
    assert!(
        warning.contains("parameters_Boehm_JProteomeRes2014.tsv:2:")
            && warning.contains("nominal value 1000000 of `Epo_degradation_BaF3` is outside its bounds [0.00001, 100000]: the fits start from 100000, and the NLL at nominal is taken at the table's value"),
        "{warning}"
    );
    assert_eq!(imported.nominal, vec![("Epo_degradation_BaF3".to_string(), 1e6)]);
    let problem = imported.model.problem(None).expect("a problem");
    let j = problem.unknowns().names().iter().position(|n| n == "Epo_degradation_BaF3");
    assert!((problem.guesses()[j.expect("estimated")] - 1e5).abs() <= 1e-9);
    let boehm = import(&yaml("Boehm_JProteomeRes2014")).expect("imports");
    assert!(boehm.warnings.is_empty() && boehm.nominal.is_empty());
    let path = edited("outside-bounds-zero", "parameters_", |t| {
        t.replace("1E-05\t100000\t0.026982514033029\t1", "1E-05\t100000\t0\t1")
    });
    let imported = import(&path).expect("imports");
    assert!(imported.warnings[0].contains("the fits start from 0.00001, and the NLL at nominal is taken there too (a log scale cannot hold the table's value)"), "{:?}", imported.warnings);
    assert!(imported.nominal.is_empty());
}

/// Liu: an event sets the tumour cells U to 0 where they fall below 1e-8 (a state reset on a
/// condition of the state, located by root finding). At nominal it does not fire; at
/// ψ = 2e-8 it fires in the virus condition, and there the gradient of the NLL matches
/// central differences of the NLL on every unknown (each on its log10 scale, step 1e-5,
/// to 1e-5 relative, or 1e-7 absolute for a component that is nearly zero).
#[test]
fn liu_resets_a_state_with_the_gradient_across_the_reset() {
    let imported = import(&yaml("Liu_IFACPapersOnLine2025")).unwrap_or_else(|e| panic!("{e}"));
    let p = imported.model.problem(None).unwrap_or_else(|e| panic!("{e}"));
    let mut values = p.guesses();
    let psi = p.names().iter().position(|n| n == "psi").expect("ψ is estimated");
    let nominal = p.nll_at(&p.unknowns().coordinates(&values)).expect("integrates").expect("NLL");
    values[psi] = 2e-8;
    let z = p.unknowns().coordinates(&values);
    let lin = p.linearize(&z).expect("integrates across the event");
    let nll = p.nll(&lin).expect("a likelihood");
    assert!((nll - nominal).abs() > 1.0, "ψ moves the fit: {nll} vs {nominal}");
    let h = 1e-5;
    for j in 0..z.len() {
        let at = |d: f64| {
            let mut moved = z.clone();
            moved[j] += d;
            p.nll_at(&moved).expect("integrates").expect("a likelihood")
        };
        let slope = (at(h) - at(-h)) / (2.0 * h);
        let g = lin.gradient[j];
        assert!(
            (g - slope).abs() <= 1e-5 * slope.abs() + 1e-7,
            "{}: gradient {g:e}, central difference {slope:e}",
            p.names()[j]
        );
    }
}

/// The NLL's gradient at nominal by one backward adjoint integration per simulation against
/// the forward sensitivities' Jᵀr, both at rtol 1e-11 (atol 1e-14): every component to 1e-6
/// of the largest (issue 43's agreement; Bachmann measured 1.4e-8). Bachmann has 12
/// simulations of 25 states, 113 parameters, log10 observables, a prior and noise scales in
/// closed form.
#[test]
fn adjoint_gradient_agrees_with_forward_sensitivities_on_bachmann() {
    adjoint_agrees(&yaml("Bachmann_MSB2011"));
}

/// Chen_MSB2009 (500 states, 155 parameters, 120 data), from a copy of the collection:
/// `SYSID_PETAB_DIR=…/Benchmark-Models cargo test --release -p sysid-petab --test integration --
/// --ignored chen`. At rtol 1e-11 it took 33 min beside the report on two cores, niced,
/// 2026-11-29 (8.7 min of CPU); it passed. Again on 2026-12-03, after the adjoint's
/// vector error control (97ab3fa): passed in 403 s beside a Python build.
#[test]
#[ignore = "Chen takes minutes in release at rtol 1e-11; needs SYSID_PETAB_DIR"]
fn adjoint_gradient_agrees_with_forward_sensitivities_on_chen() {
    let dir = std::env::var_os("SYSID_PETAB_DIR").expect("SYSID_PETAB_DIR: the collection");
    adjoint_agrees(&Path::new(&dir).join("Chen_MSB2009/Chen_MSB2009.yaml"));
}

fn adjoint_agrees(path: &Path) {
    use sysid_core::Sensitivities;
    let imported = import(path).unwrap_or_else(|e| panic!("{e}"));
    let problem = imported.model.problem(None).expect("a problem");
    let tight = sysid_ode::Integrator { rtol: 1e-11, atol: 1e-14, ..*problem.integrator() };
    let problem = problem.with_integrator(tight).expect("a valid integrator");
    let z = problem.unknowns().coordinates(&problem.guesses());
    let forward = problem.nll_gradient(&z, Sensitivities::Forward).unwrap().expect("an NLL");
    let adjoint = problem.nll_gradient(&z, Sensitivities::Adjoint).unwrap().expect("an NLL");
    assert!((forward.nll - adjoint.nll).abs() <= 1e-10 * forward.nll.abs(), "NLL");
    within_1e6_of_the_largest(&problem, &adjoint.gradient, &forward.gradient);
}

/// Every component of the adjoint's `gradient` within 1e-6 of `reference`'s largest.
fn within_1e6_of_the_largest<S: sysid_ode::System>(
    problem: &sysid_core::Problem<S>,
    gradient: &[f64],
    reference: &[f64],
) {
    let largest = reference.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    for (i, (a, r)) in gradient.iter().zip(reference).enumerate() {
        assert!(
            (a - r).abs() <= 1e-6 * largest,
            "∂NLL/∂{}: adjoint {a:e}, reference {r:e} (largest {largest:e})",
            problem.parameters()[i].name
        );
    }
}

/// The adjoint at the problem's own tolerances (rtol 1e-8) on Raia_CancerResearch2011 (14
/// states, 39 parameters, 4 conditions), against the forward sensitivities at rtol 1e-11:
/// every component within 1e-6 of the largest (measured 2.5e-7; the forward sensitivities
/// at rtol 1e-8 are 7.9e-8 from it). Its backward integration measures λ and the quadratures
/// each as a vector, and runs across the forward steps' ends: it took 1 284 Jacobians against
/// the forward sensitivities' 476, the forward plain integration's included, and 3 580 when
/// each entry of λ was held to atol on its own and the backward steps stopped where the
/// forward ones ended. Since the backward parts keep Rodas5P from one to the next
/// (2026-12-05) it takes more Jacobians (1 891) in fewer steps (7 421 against 8 639) and less
/// time, so the bound is on the counted work, which those over-resolved steps would have
/// nearly tripled: below the forward sensitivities' (measured 0.56 of it).
#[test]
fn the_adjoint_at_the_problems_tolerances_is_accurate_without_resolving_what_the_gradient_does_not_see()
 {
    use sysid_core::Sensitivities;
    let imported = import(&yaml("Raia_CancerResearch2011")).unwrap_or_else(|e| panic!("{e}"));
    let problem = imported.model.problem(None).expect("a problem");
    let z = problem.unknowns().coordinates(&problem.guesses());
    let adjoint = problem.nll_gradient(&z, Sensitivities::Adjoint).unwrap().expect("an NLL");
    let forward = problem.nll_gradient(&z, Sensitivities::Forward).unwrap().expect("an NLL");
    assert!(adjoint.fell_back.is_empty(), "every condition by adjoint");
    let tight = sysid_ode::Integrator { rtol: 1e-11, atol: 1e-16, ..*problem.integrator() };
    let reference = problem.clone().with_integrator(tight).expect("a valid integrator");
    let reference =
        reference.nll_gradient(&z, Sensitivities::Forward).unwrap().expect("an NLL").gradient;
    within_1e6_of_the_largest(&problem, &adjoint.gradient, &reference);
    assert!(
        adjoint.counts.operations < forward.counts.operations,
        "the adjoint's counted work {:?}, forward's {:?}",
        adjoint.counts,
        forward.counts
    );
}

/// The importer builds the model file's document directly (its expressions as trees); the
/// TOML it prints (`Imported::text`) is that model file too: read back, with the same
/// measurements, it gives every problem's NLL and gradient at nominal to the bit.
#[test]
fn the_printed_model_file_is_the_imported_problem() {
    for problem in [
        "Boehm_JProteomeRes2014",
        "Bachmann_MSB2011",
        "Brannmark_JBC2010",
        "Fujita_SciSignal2010",
        "Liu_IFACPapersOnLine2025",
        "Raimundez_PCB2020",
        "Zheng_PNAS2012",
    ] {
        let path = yaml(problem);
        let imported = import(&path).unwrap_or_else(|e| panic!("{problem}: {e}"));
        let mut read = sysid_model::ModelFile::parse(&imported.text, &path)
            .unwrap_or_else(|e| panic!("{problem}: {e}\n{}", imported.text));
        read.tables = imported.model.file.tables.clone();
        assert!(read.origins.is_empty() && !imported.model.file.origins.is_empty(), "{problem}");
        let at_nominal = |model: &sysid_model::Model| {
            let p = model.problem(None).unwrap_or_else(|e| panic!("{problem}: {e}"));
            let lin = p.linearize(&p.unknowns().coordinates(&p.guesses())).expect("integrates");
            (p.nll(&lin).expect("an nll"), lin.gradient.as_slice().to_vec())
        };
        let (nll, gradient) = at_nominal(&imported.model);
        let (nll_read, gradient_read) = at_nominal(&sysid_model::Model { file: read });
        assert_eq!(nll.to_bits(), nll_read.to_bits(), "{problem}: {nll} against {nll_read}");
        assert_eq!(gradient, gradient_read, "{problem}");
    }
}
