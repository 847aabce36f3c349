//! The JSON contract under test: docs/json.md is read for the keys it documents (the tables
//! of `sysid fit`, its history rows and nested objects, `starts`, `compare`'s error objects
//! and `sysid profile`), and fits of every kind are held to it, key by key: every key of the
//! output is documented, of the documented type, objects keyed by unknown name are keyed by
//! exactly the unknowns, and what the JSON says is what the table prints. A documented key
//! that no run writes fails too: each may be absent only where the docs say so, and the runs
//! below are chosen so that every one appears.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use sysid_core::format::significant;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// One documented key: its name, its type as the docs write it, and whether the docs allow
/// it to be absent.
#[derive(Clone, Debug)]
struct Key {
    name: String,
    ty: String,
    optional: bool,
    /// The docs' null / absent column says when it is null.
    nullable: bool,
}

/// The key tables of docs/json.md, by the heading above each.
struct Docs {
    tables: BTreeMap<String, Vec<Key>>,
}

impl Docs {
    fn read() -> Self {
        let text = std::fs::read_to_string(root().join("docs/json.md")).expect("docs/json.md");
        let mut tables: BTreeMap<String, Vec<Key>> = BTreeMap::new();
        let mut heading = String::new();
        let mut in_table = false;
        for line in text.lines() {
            if let Some(h) = line.strip_prefix('#') {
                heading = h.trim_start_matches('#').trim().to_string();
                in_table = false;
                continue;
            }
            let row = line.trim_start();
            if !row.starts_with("| `") {
                in_table &= row.starts_with('|');
                continue;
            }
            // The first table under a heading documents its keys; later ones (the outcomes'
            // codes, say) are not key tables.
            if !in_table && tables.contains_key(&heading) {
                continue;
            }
            in_table = true;
            let cells: Vec<&str> = row.trim_matches('|').split(" | ").map(str::trim).collect();
            let name = cells[0].trim_matches('`').to_string();
            let ty = cells.get(1).copied().unwrap_or_default().to_string();
            let optional = cells.get(3).is_some_and(|c| c.to_lowercase().contains("absent"));
            let nullable = cells.get(3).is_some_and(|c| c.contains("null"));
            tables.entry(heading.clone()).or_default().push(Key { name, ty, optional, nullable });
        }
        Self { tables }
    }

    fn keys(&self, heading: &str) -> &[Key] {
        self.tables.get(heading).unwrap_or_else(|| panic!("docs/json.md has no table `{heading}`"))
    }
}

/// Whether `v` is of the documented type `ty`: `string`, `bool`, `integer`, `number`,
/// `object`, `array`, `X or null`, `object: name → X`, `array of objects|strings|numbers`,
/// `[X, Y]`, and a choice of quoted strings (`` `"lower"` or `"upper"` ``).
fn conforms(v: &Value, ty: &str) -> Result<(), String> {
    let ty = ty.trim();
    let fail = || Err(format!("{v} is not of type `{ty}`"));
    if let Some(inner) = ty.strip_prefix("object: name → ") {
        let Some(map) = v.as_object() else { return fail() };
        return map.values().try_for_each(|x| conforms(x, inner));
    }
    if let Some(inner) = ty.strip_suffix(" or null") {
        return if v.is_null() { Ok(()) } else { conforms(v, inner) };
    }
    if let Some(inner) = ty.strip_prefix("array of ") {
        let Some(list) = v.as_array() else { return fail() };
        let item = match inner {
            "objects" => "object",
            "strings" => "string",
            "numbers" => "number",
            other => return Err(format!("unknown element type in `{other}`")),
        };
        return list.iter().try_for_each(|x| conforms(x, item));
    }
    if let Some(inner) = ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        let parts: Vec<&str> = inner.split(", ").collect();
        let Some(list) = v.as_array() else { return fail() };
        if list.len() != parts.len() {
            return fail();
        }
        // `[low, high]`: numbers named by what they are.
        return list.iter().zip(parts).try_for_each(|(x, p)| {
            conforms(x, if matches!(p, "low" | "high") { "number" } else { p })
        });
    }
    if ty.starts_with("`\"") {
        let choices: Vec<&str> = ty
            .split(" or ")
            .flat_map(|c| c.split(", "))
            .map(|c| c.trim_matches('`').trim_matches('"'))
            .collect();
        return match v.as_str() {
            Some(s) if choices.contains(&s) => Ok(()),
            _ => fail(),
        };
    }
    let ok = match ty {
        "string" => v.is_string(),
        "bool" => v.is_boolean(),
        "integer" => v.is_u64() || v.is_i64(),
        "number" => v.is_number(),
        "object" => v.is_object(),
        "array" => v.is_array(),
        other => {
            return Err(format!("docs/json.md writes a type this test cannot read: `{other}`"));
        }
    };
    if ok { Ok(()) } else { fail() }
}

/// Every key of every JSON output checked, and the keys seen, by table.
struct Contract {
    docs: Docs,
    seen: BTreeMap<String, BTreeSet<String>>,
    /// Whether some fit named an undetermined unknown (so that check ran).
    undetermined_seen: bool,
}

impl Contract {
    fn new() -> Self {
        Self { docs: Docs::read(), seen: BTreeMap::new(), undetermined_seen: false }
    }

    /// `v` holds exactly keys of the table `heading`, each of its documented type, and
    /// every key the docs do not allow to be absent.
    fn object(&mut self, v: &Value, heading: &str, what: &str) {
        let keys = self.docs.keys(heading).to_vec();
        let map = v.as_object().unwrap_or_else(|| panic!("{what}: {v} is not an object"));
        for (name, value) in map {
            let key = keys.iter().find(|k| &k.name == name).unwrap_or_else(|| {
                panic!("{what}: key `{name}` is not documented in docs/json.md (`{heading}`)")
            });
            self.seen.entry(heading.to_string()).or_default().insert(name.clone());
            if key.nullable && value.is_null() {
                continue;
            }
            if let Err(e) = conforms(value, &key.ty) {
                panic!("{what}: `{name}`: {e}");
            }
        }
        for key in keys.iter().filter(|k| !k.optional) {
            assert!(
                map.contains_key(&key.name),
                "{what}: documented key `{}` is missing",
                key.name
            );
        }
    }

    /// A fit object and everything nested in it; its unknowns' names key its objects.
    fn fit(&mut self, v: &Value, what: &str) {
        self.object(v, "sysid fit --format json", what);
        let names: Vec<&String> = v["estimates"].as_object().expect("estimates").keys().collect();
        for key in ["std_errors", "intervals"] {
            let keys: Vec<&String> = v[key].as_object().expect(key).keys().collect();
            assert_eq!(keys, names, "{what}: `{key}` is keyed by the unknowns, in their order");
        }
        let within = |list: Vec<&str>, key: &str| {
            for n in list {
                assert!(names.iter().any(|m| *m == n), "{what}: `{key}` names `{n}`, no unknown");
            }
        };
        within(
            v["active_bounds"].as_object().expect("bounds").keys().map(|s| s.as_str()).collect(),
            "active_bounds",
        );
        let undetermined: Vec<&str> = v["undetermined"]
            .as_array()
            .expect("list")
            .iter()
            .map(|s| s.as_str().expect("a name"))
            .collect();
        if !undetermined.is_empty() {
            assert_eq!(
                v["converged"], false,
                "{what}: converged with {undetermined:?} undetermined"
            );
            self.undetermined_seen = true;
        }
        within(undetermined, "undetermined");
        if let Some(at) = v.get("failed_at") {
            within(
                at.as_object().expect("failed_at").keys().map(|s| s.as_str()).collect(),
                "failed_at",
            );
        }
        if let Some(u) = v.get("unidentifiable") {
            self.object(u, "unidentifiable", what);
            within(
                u["unknowns"]
                    .as_array()
                    .expect("list")
                    .iter()
                    .map(|s| s.as_str().expect("a name"))
                    .collect(),
                "unidentifiable.unknowns",
            );
        }
        self.object(&v["counts"], "counts", what);
        if let Some(retry) = v.get("retry") {
            self.object(retry, "retry", what);
            let trust = ["levenberg-marquardt", "hybrid-newton", "nl2sol", "geodesic-lm"];
            assert!(trust.contains(&v["method"].as_str().unwrap_or("")), "{what}: a retry");
        }
        for x in v["experiments"].as_array().expect("experiments") {
            self.object(x, "experiments", what);
        }
        for (i, row) in v["history"].as_array().expect("history").iter().enumerate() {
            self.object(row, "History rows", &format!("{what}, history row {i}"));
        }
        let best = v["best_iteration"].as_u64().expect("best_iteration") as usize;
        if let Some(row) = v["history"].get(best)
            && let (Some(a), Some(b)) = (row["optimality"].as_f64(), v["optimality"].as_f64())
        {
            assert!(
                (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1e-300),
                "{what}: optimality {b} is not history[{best}].optimality {a}: the docs define both as the certificate's measure at that point"
            );
        }
        if let Some(starts) = v.get("starts") {
            self.object(starts, "starts", what);
            let waterfall = starts["waterfall"].as_array().expect("waterfall");
            assert_eq!(
                Some(waterfall.len() as u64),
                starts["count"].as_u64(),
                "{what}: a row per start"
            );
            let objectives: Vec<f64> = waterfall
                .iter()
                .map(|r| r["objective"].as_f64().unwrap_or(f64::INFINITY))
                .collect();
            assert!(objectives.windows(2).all(|w| w[0] <= w[1]), "{what}: the waterfall is sorted");
            let converged = waterfall.iter().filter(|r| r["converged"] == true).count();
            assert_eq!(Some(converged as u64), starts["converged"].as_u64(), "{what}");
            for row in waterfall {
                self.object(row, "A start", what);
            }
            for m in starts["minima"].as_array().expect("minima") {
                self.object(m, "A minimum", what);
                let keys: Vec<&String> =
                    m["estimates"].as_object().expect("estimates").keys().collect();
                assert_eq!(keys, names, "{what}: a minimum's estimates are keyed by the unknowns");
            }
        }
    }

    /// Fails naming every documented key that no output wrote.
    fn all_seen(&self, headings: &[&str]) {
        let mut missing = Vec::new();
        for h in headings {
            for k in self.docs.keys(h) {
                if !self.seen.get(*h).is_some_and(|s| s.contains(&k.name)) {
                    missing.push(format!("`{}` of `{h}`", k.name));
                }
            }
        }
        assert!(missing.is_empty(), "documented keys no run wrote: {}", missing.join(", "));
    }
}

fn sysid(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_sysid"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("the binary runs");
    let text = |b: &[u8]| String::from_utf8(b.to_vec()).expect("utf-8");
    (out.status.code(), text(&out.stdout), text(&out.stderr))
}

/// The JSON of `args` with `--format json`, parsed; its exit code must be 0 or 1.
fn json(args: &[&str]) -> Value {
    let mut all = args.to_vec();
    all.extend(["--format", "json"]);
    let (code, stdout, stderr) = sysid(&all);
    assert!(matches!(code, Some(0 | 1)), "{args:?}: exit {code:?}: {stderr}");
    serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("{args:?}: {e}: {stdout}"))
}

/// What `sysid fit` prints as a table holds what its JSON says: each unknown's row
/// (estimate, standard error, interval, bound), the verdict, the termination, the
/// iterations, the cost, the likelihood and the degrees of freedom.
fn table_agrees(args: &[&str], fit: &Value) {
    let (_, table, stderr) = sysid(args);
    assert!(!table.is_empty(), "{args:?}: {stderr}");
    let bounds = fit["active_bounds"].as_object().expect("bounds");
    let scales: Vec<String> = table
        .lines()
        .filter(|l| l.ends_with("(noise scale, closed form)"))
        .map(String::from)
        .collect();
    let estimates = fit["estimates"].as_object().expect("estimates");
    // The names' column is as wide as the longest name (noise scales included), at least 10.
    let w = estimates.keys().map(|n| n.chars().count()).max().unwrap_or(0).max(10);
    for (name, estimate) in estimates {
        let bound = bounds.get(name).and_then(Value::as_str);
        let se = match (bound, fit["std_errors"][name].as_f64()) {
            (Some("prior_location"), _) => "at prior".to_string(),
            (Some("switch_on_sample"), _) => "at sample".to_string(),
            (Some(_), _) if !scales.iter().any(|l| l.trim_start().starts_with(name.as_str())) => {
                "on bound".to_string()
            }
            (_, Some(v)) => significant(v, 5),
            (_, None) => "—".to_string(),
        };
        let interval = match (bound, fit["intervals"][name].as_array()) {
            (None, Some(pair)) => format!(
                "[{}, {}]",
                significant(pair[0].as_f64().expect("low"), 6),
                significant(pair[1].as_f64().expect("high"), 6)
            ),
            _ => "—".to_string(),
        };
        let row = format!(
            "  {name:<w$} {:>24} {se:>14} {interval:>34}",
            significant(estimate.as_f64().expect("a finite estimate"), 10)
        );
        assert!(
            table.lines().any(|l| l.starts_with(&row)),
            "{args:?}: the table has no row\n{row}\nfor the JSON's `{name}`:\n{table}"
        );
        if let Some(b) = bound {
            let words = match b {
                "prior_location" => "at its Laplace prior's location".to_string(),
                "switch_on_sample" => "its switch on a sample time".to_string(),
                _ => format!("on its {b} bound"),
            };
            assert!(
                table.lines().any(|l| l.starts_with(&row) && l.contains(&words)),
                "{args:?}: `{name}` is `{b}` in active_bounds, the table does not say so"
            );
        }
    }
    let converged = if fit["converged"] == true { "yes" } else { "no" };
    let line = |prefix: &str| {
        table
            .lines()
            .find(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("{args:?}: no `{prefix}` line:\n{table}"))
    };
    assert!(line("  converged    ").starts_with(&format!("  converged    {converged}")));
    assert_eq!(
        line("  termination  "),
        format!("  termination  {}", fit["termination"].as_str().expect("text"))
    );
    assert!(line("  iterations   ").starts_with(&format!("  iterations   {}", fit["iterations"])));
    let cost = significant(fit["cost"].as_f64().expect("cost"), 10);
    assert!(line("  cost ε       ").starts_with(&format!("  cost ε       {cost}")));
    let dof = fit["dof"].as_u64().map_or("—".to_string(), |d| d.to_string());
    assert!(line("  dof          ").starts_with(&format!("  dof          {dof} ")));
    for name in fit["undetermined"].as_array().expect("list") {
        assert!(line("  converged    ").contains(name.as_str().expect("a name")));
    }
    if let Some(nll) = fit["nll"].as_f64()
        && table.contains("  nll          ")
    {
        assert!(
            line("  nll          ")
                .starts_with(&format!("  nll          {}", significant(nll, 10)))
        );
        let error = fit["nll_error"].as_f64().expect("nll_error where nll is");
        assert_eq!(
            line("  nll          ").contains(&format!(" ± {error:.1e} (integration)")),
            error > 0.0,
            "{args:?}: nll_error {error} and the table's nll line disagree"
        );
        // The prior and what the fit minimised, where the JSON has a prior (the table showed
        // the NLL alone).
        match fit["prior"].as_f64() {
            Some(prior) => assert!(
                line("  prior        ").starts_with(&format!(
                    "  prior        {} (negative log-prior); objective {}",
                    significant(prior, 10),
                    significant(nll + prior, 10)
                )),
                "{args:?}: the table's prior line"
            ),
            None => assert!(!table.contains("  prior        "), "{args:?}: a prior line"),
        }
    }
}

/// A model file written for a case of the contract: one of `examples/`, changed.
fn case_file(dir: &Path, name: &str, text: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("writes");
    path.display().to_string()
}

#[test]
fn every_documented_key_holds_in_every_kind_of_run() {
    let mut contract = Contract::new();
    let dir = std::env::temp_dir().join(format!("sysid-contract-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    let kinetics = root().join("examples/kinetics");
    let data = kinetics.join("data.csv").display().to_string();
    let model = std::fs::read_to_string(kinetics.join("model.toml")).expect("the example");
    // A prior on k2, and k1·k2 only in product (a direction the data cannot see).
    let with_prior = case_file(
        &dir,
        "prior.toml",
        &model
            .replace(
                "k2 = { guess = 0.5, log = true }",
                "k2 = { guess = 0.5, log = true, prior = { mean = -1.2, sd = 0.5, on = \"log\" } }",
            )
            .replace("file = \"data.csv\"", &format!("file = \"{data}\"")),
    );
    let with_laplace = case_file(
        &dir,
        "laplace.toml",
        &model
            .replace(
                "k2 = { guess = 0.5, log = true }",
                "k2 = { guess = 0.5, log = true, prior = { mean = -0.7, sd = 1e-4, on = \"log\", distribution = \"laplace\" } }",
            )
            .replace("file = \"data.csv\"", &format!("file = \"{data}\"")),
    );
    let product = case_file(
        &dir,
        "product.toml",
        &model
            .replace("parameters = [\"k1\", \"k2\"]", "parameters = [\"k1\", \"k2\", \"c\"]")
            .replace("A = \"-k1 * A\"", "A = \"-k1 * c * A\"")
            .replace("B = \"k1 * A - k2 * B\"", "B = \"k1 * c * A - k2 * B\"")
            .replace(
                "k2 = { guess = 0.5, log = true }",
                "k2 = { guess = 0.5, log = true }\nc = { guess = 1.0, log = true }",
            )
            .replace("file = \"data.csv\"", &format!("file = \"{data}\"")),
    );
    let kinetics_model = kinetics.join("model.toml").display().to_string();
    let slipped =
        std::fs::read_to_string(&data).expect("the data").replace("7.5,0.170053", "7.5,170053.0");
    let slipped = case_file(&dir, "slipped.csv", &slipped);
    let slip = case_file(
        &dir,
        "slip.toml",
        &model.replace("file = \"data.csv\"", &format!("file = \"{slipped}\"")),
    );
    let boehm = "tests/data/petab/Boehm_JProteomeRes2014/Boehm_JProteomeRes2014.yaml";
    let fits: Vec<Vec<&str>> = vec![
        // No bounds (the paper's example).
        vec!["fit", "--system", "falling-body"],
        // Bounds active at the optimum.
        vec!["fit", "--system", "compartment-chain", "--method", "levenberg-marquardt"],
        // A noise model with a noise scale in closed form, two experiments.
        vec!["fit", "--model", "examples/two-doses/model.toml", "--method", "levenberg-marquardt"],
        // --fix.
        vec!["fit", "--model", &kinetics_model, "--fix", "k1=0.79"],
        // A failure at a point (Goodman's full steps blow up).
        vec!["fit", "--system", "lotka-volterra", "--method", "goodman"],
        // A prior.
        vec!["fit", "--model", &with_prior],
        // A Laplace prior that holds its unknown at its location.
        vec!["fit", "--model", &with_laplace],
        // A direction the data do not see.
        vec!["fit", "--model", &product, "--method", "levenberg-marquardt"],
        // A PEtab problem (noise scales, log10 scales, bounds).
        vec!["fit", "--petab", boehm, "--method", "levenberg-marquardt"],
        // A rate running off to 0 (a unit slip in the data): undetermined.
        vec!["fit", "--model", &slip, "--method", "levenberg-marquardt"],
        // Quasilinearization's and multiple shooting's diagnostics.
        vec!["fit", "--system", "van-der-pol", "--method", "quasilinearization"],
        vec!["fit", "--system", "van-der-pol", "--method", "multiple-shooting"],
    ];
    for args in &fits {
        let fit = json(args);
        contract.fit(&fit, &format!("{args:?}"));
        table_agrees(args, &fit);
    }
    assert!(contract.undetermined_seen, "no run had an undetermined unknown");
    // Multistart.
    let args =
        ["fit", "--system", "lotka-volterra", "--method", "gauss-newton-ls", "--starts", "4"];
    let fit = json(&args);
    assert!(fit.get("starts").is_some());
    contract.fit(&fit, "--starts");
    table_agrees(&args, &fit);
    // compare: fit objects, and an error object (quasilinearization refuses a log-scale
    // initial value).
    let log_initial = case_file(
        &dir,
        "log_initial.toml",
        &model
            .replace("A = 1.0\n", "")
            .replace(
                "k2 = { guess = 0.5, log = true }",
                "k2 = { guess = 0.5, log = true }\nA = { guess = 1.0, log = true }",
            )
            .replace("file = \"data.csv\"", &format!("file = \"{data}\"")),
    );
    let compared =
        json(&["compare", "--model", &log_initial, "--methods", "goodman,quasilinearization"]);
    let list = compared.as_array().expect("a list");
    assert_eq!(list.len(), 2);
    contract.fit(&list[0], "compare, goodman");
    contract.object(&list[1], "sysid compare --format json", "compare, quasilinearization");
    assert!(list[1]["error"].is_string(), "{}", list[1]);
    let compared = json(&["compare", "--system", "falling-body", "--starts", "2"]);
    for (i, fit) in compared.as_array().expect("a list").iter().enumerate() {
        contract.fit(fit, &format!("compare --starts, method {i}"));
    }
    // profile, with one unknown too.
    for args in [
        vec!["profile", "--system", "falling-body"],
        vec!["profile", "--model", &kinetics_model, "--fix", "k1=0.7935"],
    ] {
        let p = json(&args);
        contract.object(&p, "sysid profile --format json", &format!("{args:?}"));
        contract.fit(&p["optimum"], &format!("{args:?}: optimum"));
        for (name, profile) in p["profiles"].as_object().expect("profiles") {
            contract.object(profile, "A profile", &format!("{args:?}: {name}"));
            for point in profile["points"].as_array().expect("points") {
                contract.object(point, "A point", &format!("{args:?}: a point of {name}"));
            }
        }
        for point in p["better_optimum_found"].as_array().expect("a list") {
            contract.object(point, "A point", &format!("{args:?}: better_optimum_found"));
        }
    }
    // `evaluate`: a model file with a prior, with and without the gradient; a PEtab problem
    // whose σ are noise scales (parameters too).
    let boehm = "tests/data/petab/Boehm_JProteomeRes2014/Boehm_JProteomeRes2014.yaml";
    for args in [
        vec!["evaluate", "--model", &with_prior, "--gradient", "--repeat", "3"],
        vec!["evaluate", "--model", &with_prior],
        vec!["evaluate", "--petab", boehm, "--gradient"],
    ] {
        let e = json(&args);
        contract.object(&e, "sysid evaluate --format json", &format!("{args:?}"));
        contract.object(&e["counts"], "counts", &format!("{args:?}: counts"));
        assert!(e["counts"]["steps"].as_u64().expect("steps") > 0, "{args:?}: it integrated");
        let names: Vec<&String> = e["parameters"].as_object().expect("parameters").keys().collect();
        if let Some(g) = e["gradient"].as_object() {
            assert_eq!(g.keys().collect::<Vec<_>>(), names, "{args:?}: the gradient's names");
        }
        let objective = e["nll"].as_f64().expect("nll") + e["prior"].as_f64().unwrap_or(0.0);
        assert!((e["objective"].as_f64().expect("objective") - objective).abs() <= 1e-12);
    }
    contract.all_seen(&[
        "sysid fit --format json",
        "History rows",
        "unidentifiable",
        "counts",
        "retry",
        "experiments",
        "starts",
        "A minimum",
        "A start",
        "sysid compare --format json",
        "sysid profile --format json",
        "A profile",
        "A point",
        "sysid evaluate --format json",
    ]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The reader of the docs' types: what it accepts and what it refuses.
#[test]
fn documented_types_are_read_as_written() {
    use serde_json::json;
    assert!(conforms(&json!({"a": 1.5, "b": null}), "object: name → number or null").is_ok());
    assert!(conforms(&json!({"a": "x"}), "object: name → number").is_err());
    assert!(
        conforms(&json!({"k": [1.0, 2.0], "d": null}), "object: name → [low, high] or null")
            .is_ok()
    );
    assert!(conforms(&json!({"k": [1.0]}), "object: name → [low, high] or null").is_err());
    assert!(conforms(&json!({"d1": "lower"}), "object: name → `\"lower\"` or `\"upper\"`").is_ok());
    assert!(
        conforms(&json!({"d1": "below"}), "object: name → `\"lower\"` or `\"upper\"`").is_err()
    );
    assert!(conforms(&json!(3), "integer").is_ok());
    assert!(conforms(&json!(3.5), "integer").is_err());
    assert!(conforms(&json!([null, 2.0]), "[number or null, number or null]").is_ok());
    assert!(conforms(&json!(["a", 1]), "array of strings").is_err());
    assert!(conforms(&json!(1), "a type nobody wrote").is_err());
}

/// `fit --trace`: every line is an iterate or a trial of docs/json.md's tables, key by key,
/// and the trials say what the fit did. Checked against the fit's own record, not the
/// method's: a trial starts from the ε of the iterate line before it; ρ is actual /
/// predicted, and a trial is taken exactly where ρ ≥ ¼; an accepted trial's actual decrease
/// is what the next iterate's ε shows (to ε's accuracy); and the fit's iterations are its
/// accepted trials.
#[test]
fn the_trace_follows_the_contract() {
    let docs = Contract::new();
    let mut contract = docs;
    let dir = std::env::temp_dir().join(format!("sysid-trace-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut models = BTreeSet::new();
    for (system, method) in [
        ("lotka-volterra", "nl2sol"),
        ("lotka-volterra", "hybrid-newton"),
        ("falling-body", "goodman"),
    ] {
        let path = dir.join(format!("{system}-{method}.jsonl"));
        let fit = json(&[
            "fit",
            "--system",
            system,
            "--method",
            method,
            "--trace",
            path.to_str().unwrap(),
        ]);
        let what = format!("{system} {method}");
        let text = std::fs::read_to_string(&path).expect("the trace is written");
        let lines: Vec<Value> =
            text.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect();
        let mut last_cost: Option<f64> = None;
        let mut moved: Option<f64> = None;
        let (mut accepted, mut trials) = (0, 0);
        for (i, line) in lines.iter().enumerate() {
            let at = format!("{what}, line {}", i + 1);
            assert_eq!(line["method"], method, "{at}");
            match line["event"].as_str() {
                Some("iterate") => {
                    contract.object(line, "Iterate lines", &at);
                    let cost = line["cost"].as_f64().unwrap();
                    // To ε's accuracy at the coarse stage's rtol 1e-6: where two costs differ
                    // by less than that, the trial measured its decrease on the gradients.
                    if let Some(expected) = moved.take() {
                        assert!(
                            (cost - expected).abs() <= 1e-6 * cost.abs(),
                            "{at}: ε {cost} after a trial that measured it at {expected}"
                        );
                    }
                    last_cost = Some(cost);
                }
                Some("trial") => {
                    contract.object(line, "Trial lines", &at);
                    trials += 1;
                    models.insert(line["model"].as_str().unwrap().to_string());
                    let from = line["from"].as_f64().unwrap();
                    assert_eq!(Some(from), last_cost, "{at}: from the iterate line before it");
                    let taken = line["accepted"].as_bool().unwrap();
                    match (line["actual"].as_f64(), line["ratio"].as_f64()) {
                        (Some(actual), Some(ratio)) => {
                            let predicted = line["predicted"].as_f64().unwrap();
                            assert!(
                                (ratio - actual / predicted).abs() <= 1e-12 * ratio.abs(),
                                "{at}"
                            );
                            assert_eq!(taken, ratio >= 0.25, "{at}: ρ {ratio}");
                            if taken {
                                moved = Some(from - actual);
                            }
                        }
                        _ => assert!(!taken, "{at}: taken without being integrated"),
                    }
                    accepted += usize::from(taken);
                }
                other => panic!("{at}: event {other:?}"),
            }
        }
        assert!(moved.is_none(), "{what}: an accepted trial with no iterate after it");
        let iterations = fit["iterations"].as_u64().unwrap() as usize;
        if method == "goodman" {
            assert_eq!(trials, 0, "{what}: Goodman's steps are not trials");
            assert!(lines.len() > iterations, "{what}: an iterate line for each iterate");
        } else {
            assert_eq!(accepted, iterations, "{what}: a move per accepted trial");
            assert!(trials > accepted, "{what}: the run rejected none; pick a harder case");
        }
    }
    assert!(models.contains("newton") && models.contains("gauss-newton"), "{models:?}");
    contract.all_seen(&["Iterate lines", "Trial lines"]);
    let _ = std::fs::remove_dir_all(&dir);
}
