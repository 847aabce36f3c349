"""The NLL at nominal of each Benchmark-Models-PEtab problem from its own simulated data.

Each problem of the collection publishes `simulatedData_*.tsv`: its observables simulated at
the nominal parameters by the authors' tool. Given those simulations, the PEtab likelihood is
a sum over the measurement rows that needs no simulator: this script computes it with the
`petab` package's own formulas (`calculate_single_llh`, `evaluate_noise_formula`), so that
sysid's NLL at nominal (`sysid fit --petab P.yaml --max-iterations 0`) can be checked on the
problems for which AMICI stores no reference.

    pip install petab      # 0.8.2 was used
    python scripts/reference/collection.py DIR > tests/data/petab/simulated_references.tsv

DIR is the collection's Benchmark-Models folder. A measurement row takes the simulation of
the same observable, conditions and time (to 10 significant digits, as the files write times
with different digits); where the simulation table has several for these, the one of the
same observable and noise parameters. None, or several still, is an error. A noise formula that repeats its observable's
placeholders (Raia's σ = a + b · scaling · (…)) gets the row's observable parameters, as
sysid's importer reads it (the petab package leaves those unreplaced), and where it repeats
the observable's formula (Armistead's σ = c · Sphinga for the observable Sphinga), that
formula is the simulation.
"""

import math
import os
import sys

import pandas as pd
import petab.v1 as petab
from petab.v1 import calculate
import sympy as sp
from petab.v1.math import sympify_petab


def problem_files(directory):
    name = os.path.basename(directory.rstrip("/"))
    yamls = [f for f in os.listdir(directory) if f.endswith(".yaml") and "test" not in f]
    yaml = f"{name}.yaml" if f"{name}.yaml" in yamls else sorted(yamls)[0]
    return petab.Problem.from_yaml(os.path.join(directory, yaml))


KEYS = ("observableId", "preequilibrationConditionId", "simulationConditionId")
OPTIONAL = ("observableParameters", "noiseParameters")


def text(row, column):
    v = row.get(column, None)
    return "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v).strip()


def key(row):
    """A row's simulation key: its ids and its time to 10 significant digits (the files
    write times with different digits)."""
    return (*(text(row, c) for c in KEYS), float(f"{float(row['time']):.10g}"))


def nll(problem, simulations):
    measurements = problem.measurement_df.reset_index(drop=True)
    simulated = {}
    for _, s in simulations.iterrows():
        simulated.setdefault(key(s), []).append(s)
    observables = problem.observable_df
    parameters = problem.parameter_df
    noise_formulas = calculate.get_symbolic_noise_formulas(observables)
    total = 0.0
    for _, m in measurements.iterrows():
        candidates = simulated.get(key(m), [])
        values = {float(s["simulation"]) for s in candidates}
        if len(values) > 1:
            # Rows that differ by their observable or noise parameters only.
            candidates = [
                s for s in candidates
                if all(c not in s or text(s, c) == text(m, c) for c in OPTIONAL)
            ]
            values = {float(s["simulation"]) for s in candidates}
        if len(values) != 1:
            raise ValueError(f"{len(values)} simulations for {key(m)}")
        simulation = values.pop()
        observable_id = m["observableId"]
        observable = observables.loc[observable_id]
        formulas = dict(noise_formulas)
        overrides = petab.split_parameter_replacement_list(m.get("observableParameters", None))
        replace = {
            sp.Symbol(f"observableParameter{i + 1}_{observable_id}", real=True): (
                v if isinstance(v, (int, float)) else parameters.loc[v, "nominalValue"]
            )
            for i, v in enumerate(overrides)
        }
        # The observable's formula where the noise formula repeats it is the simulation.
        formula = sympify_petab(observable["observableFormula"]).subs(replace)
        formulas[observable_id] = (
            formulas[observable_id].subs(replace).subs(formula, sp.Symbol(observable_id, real=True))
        )
        sigma = calculate.evaluate_noise_formula(m, formulas, parameters, simulation)
        total -= calculate.calculate_single_llh(
            float(m["measurement"]),
            simulation,
            observable.get("observableTransformation", "lin") or "lin",
            observable.get("noiseDistribution", "normal") or "normal",
            sigma,
        )
    return total


def main(root):
    print("problem\tnll\tsource")
    for name in sorted(os.listdir(root)):
        directory = os.path.join(root, name)
        simulated = [
            f for f in os.listdir(directory)
            if f.startswith("simulatedData") or f == "simulations.tsv"
        ]
        if not simulated:
            continue
        try:
            problem = problem_files(directory)
            simulations = pd.read_csv(os.path.join(directory, simulated[0]), sep="\t")
            value = nll(problem, simulations)
            print(f"{name}\t{float(value)!r}\t{simulated[0]}")
        except Exception as e:  # a problem the script cannot read is named, not fatal
            print(f"# {name}: {type(e).__name__}: {str(e).splitlines()[0]}", file=sys.stderr)


if __name__ == "__main__":
    main(sys.argv[1])
