"""pyPESTO + fides on the PEtab problems, as the field runs them: the peer figures sysid is
measured against (issue 41). Not run by any test: its output is committed
(scripts/reference/fides_petab.json) and read by people and by the report.

Set-up (about 3 minutes):

    python3 -m venv venv && venv/bin/pip install amici pypesto fides petab scipy
    venv/bin/python scripts/reference/fides_petab.py tests/data/petab --starts 20 \
        --out scripts/reference/fides_petab.json

For each problem (a folder with its YAML file):

* the objective pyPESTO minimises (the negative log-posterior: NLL plus the priors' term)
  at the nominal parameters;
* one fides fit (pyPESTO's defaults: hybrid FIM/BFGS, up to 1 000 iterations) from the
  nominal point and one from nominal + 0.1 on each parameter's scale, clipped into the
  bounds: final objective, wall time, evaluations, fides' exit flag;
* a multistart of --starts fits from PEtab's sampling (uniform on the parameter scale within
  the bounds, or the initialization priors), seed 0, one thread: every start's final
  objective and time, stopped after --budget seconds.

AMICI's forward sensitivities at its defaults (rtol 1e-8, atol 1e-16), one thread, as
the issue's figures were measured. AMICI compiles each model first (10-60 s, not counted).
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import petab.v1 as petab  # noqa: E402
import pypesto  # noqa: E402
import pypesto.optimize as optimize  # noqa: E402
import pypesto.petab  # noqa: E402

import published  # noqa: E402


def fit(problem, optimizer, x0):
    started = time.perf_counter()
    result = optimizer.minimize(problem, x0=np.array(x0), id="0")
    elapsed = time.perf_counter() - started
    return {
        "objective": float(result.fval) if np.isfinite(result.fval) else None,
        "seconds": elapsed,
        "evaluations": int(result.n_fval or 0),
        "exitflag": int(result.exitflag) if result.exitflag is not None else None,
        "message": str(result.message),
    }


def measure(folder: Path, starts: int, budget: float, output_root: Path) -> dict:
    petab_problem = published.load(folder, folder.name)
    # AMICI cannot import observable or noise parameters that differ between time points
    # (Fiedler): PEtab's own flattening gives the same problem in a form it reads.
    flat = petab.lint.measurement_table_has_timepoint_specific_mappings(
        petab_problem.measurement_df
    )
    if flat:
        petab.flatten_timepoint_specific_output_overrides(petab_problem)
    # The flattened problem has other observables: its compiled model is kept apart, or a
    # model compiled earlier from the unflattened tables is reused and fails with
    # "tuple.index(x): x not in tuple" (Bruno, Crauste, Fujita).
    model_name = folder.name + ("_flat" if flat else "")
    compiled = time.perf_counter()
    importer = pypesto.petab.PetabImporter(
        petab_problem, output_folder=str(output_root / model_name), model_name=model_name
    )
    problem = importer.create_problem()
    compiled = time.perf_counter() - compiled
    objective = problem.objective
    # Nominal, on the parameter scale, of the estimated parameters, in pyPESTO's order.
    scaled = dict(zip(petab_problem.x_ids, petab_problem.x_nominal_scaled))
    nominal_free = np.array([scaled[problem.x_names[i]] for i in problem.x_free_indices])
    lb, ub = problem.lb, problem.ub
    shifted = np.clip(nominal_free + 0.1, lb, ub)
    out = {
        "problem": folder.name,
        "estimated": int(problem.dim),
        "compile_seconds": compiled,
        "objective_at_nominal": float(objective(nominal_free)),
    }
    optimizer = optimize.FidesOptimizer(verbose=0)
    out["from_nominal"] = fit(problem, optimizer, nominal_free)
    out["from_nominal_plus_0.1"] = fit(problem, optimizer, shifted)
    # Multistart: PEtab's sampling, seed 0.
    np.random.seed(0)
    points = petab_problem.sample_parameter_startpoints(n_starts=starts)
    runs = []
    started = time.perf_counter()
    for i, x in enumerate(points):
        if time.perf_counter() - started > budget:
            break
        x = np.clip(np.asarray(x, dtype=float), lb, ub)
        runs.append(fit(problem, optimizer, x))
        print(f"  {folder.name} start {i}: {runs[-1]['objective']} in {runs[-1]['seconds']:.1f} s",
              file=sys.stderr)
    out["multistart"] = {
        "starts_asked": starts,
        "starts_run": len(runs),
        "budget_seconds": budget,
        "seconds": time.perf_counter() - started,
        "runs": runs,
    }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a folder of PEtab problems, one per folder")
    parser.add_argument("--starts", type=int, default=20)
    parser.add_argument("--budget", type=float, default=600.0, help="seconds per multistart")
    parser.add_argument("--only", help="comma-separated problem names")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--amici-dir", type=Path, default=Path("/tmp/amici_models"))
    args = parser.parse_args()
    done = json.loads(args.out.read_text()) if args.out.exists() else {}
    names = sorted(p.name for p in args.folder.iterdir() if p.is_dir())
    if args.only:
        names = [n for n in names if n in args.only.split(",")]
    for name in names:
        print(f"{name} ...", file=sys.stderr)
        try:
            done[name] = measure(args.folder / name, args.starts, args.budget, args.amici_dir)
        except Exception as e:  # noqa: BLE001 - a problem the peers cannot run is a result
            done[name] = {"problem": name, "error": f"{type(e).__name__}: {e}"}
        args.out.write_text(json.dumps(done, indent=1) + "\n")


if __name__ == "__main__":
    main()
