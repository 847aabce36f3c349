"""AMICI's NLL + gradient at nominal, timed, beside sysid's (issue 43): one thread each.

    python3 -m venv venv && venv/bin/pip install amici petab cmake   # AMICI 1.0.1 was used
    cargo build --release -p sysid-cli
    PATH=venv/bin:$PATH venv/bin/python scripts/reference/amici_speed.py DIR \\
        [--only A,B] [--skip A,B] [--out speed.tsv]

DIR is the collection's Benchmark-Models folder. For each problem: AMICI compiles its model
(into /tmp/amici/NAME, reused when already there; not timed), then simulates the PEtab
problem at the parameter table's nominal values with first-order sensitivities, forward and
adjoint, at AMICI's default tolerances (rtol 1e-8, atol 1e-16), one thread: the median wall
time of `run_simulations` on the conditions' data built once (as pyPESTO's objective does) and
the sum of their log-likelihoods, over runs of about 2 s in all (one, where a run takes
longer). `simulate_petab` builds the data again at every call, which costs more than the
simulation on small problems (Boehm: 111 ms a call). sysid: `sysid evaluate --petab P --gradient --repeat N --format json` with
RAYON_NUM_THREADS=1, its `ms_per_evaluation` (the median after the import). The ratio is the
faster AMICI mode's time over sysid's, of the modes whose runs succeeded with a finite
gradient. Prints a Markdown table; --out also writes a TSV.
A run AMICI fails, or whose gradient has a non-finite entry, is marked (its time still counts).
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import amici.sim.sundials as sundials  # noqa: E402
import petab.v1 as petab  # noqa: E402
from amici.importers.petab.v1 import import_petab_problem  # noqa: E402
from amici.sim.sundials.petab.v1 import create_parameterized_edatas  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SYSID = os.environ.get("SYSID", os.path.join(ROOT, "target", "release", "sysid"))


def problem_yaml(directory):
    name = os.path.basename(directory)
    for candidate in (f"{name}.yaml", "problem.yaml"):
        path = os.path.join(directory, candidate)
        if os.path.exists(path):
            return path
    return None


def amici_times(yaml, name, budget):
    problem = petab.Problem.from_yaml(yaml)
    # AMICI does not read observable or noise parameters that change from row to row
    # (Fiedler): PEtab's own flattening gives the same problem in a form it reads, compiled
    # apart from the unflattened one.
    if petab.lint.measurement_table_has_timepoint_specific_mappings(problem.measurement_df):
        petab.flatten_timepoint_specific_output_overrides(problem)
        name += "_flat"
    model = import_petab_problem(problem, output_dir=os.path.join("/tmp/amici", name))
    nominal = dict(zip(problem.x_ids, problem.x_nominal))
    # The conditions' data, built once (as pyPESTO's objective does): what is timed is
    # AMICI's simulation of every condition with its sensitivities and the log-likelihood.
    edatas = create_parameterized_edatas(
        amici_model=model, petab_problem=problem, problem_parameters=nominal
    )
    out = {}
    for mode, method in (
        ("forward", sundials.SensitivityMethod.forward),
        ("adjoint", sundials.SensitivityMethod.adjoint),
    ):
        solver = model.create_solver()
        solver.set_sensitivity_order(sundials.SensitivityOrder.first)
        solver.set_sensitivity_method(method)
        times, rdatas = [], None
        while not times or (sum(times) < budget and len(times) < 50):
            start = time.perf_counter()
            rdatas = sundials.run_simulations(model, solver, edatas, num_threads=1)
            llh = sum(r["llh"] for r in rdatas)
            times.append(time.perf_counter() - start)
        finite = all(
            r["sllh"] is not None and all(math.isfinite(v) for v in r["sllh"]) for r in rdatas
        ) and all(r["status"] == 0 for r in rdatas)
        out[mode] = (1e3 * statistics.median(times), -llh, finite)
    return out


def sysid_time(yaml):
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    args = [SYSID, "evaluate", "--petab", yaml, "--gradient", "--no-integration-error",
            "--format", "json"]
    first = subprocess.run(args + ["--repeat", "1"], capture_output=True, text=True, env=env)
    if first.returncode != 0:
        return None
    once = json.loads(first.stdout)["ms_per_evaluation"]
    repeat = max(3, min(50, int(2000 / max(once, 1e-3))))
    r = subprocess.run(args + ["--repeat", str(repeat)], capture_output=True, text=True, env=env)
    result = json.loads(r.stdout)
    return result["ms_per_evaluation"], result["nll"]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("root")
    parser.add_argument("--only", help="comma-separated problem names")
    parser.add_argument("--skip", help="comma-separated problem names", default="")
    parser.add_argument("--budget", type=float, default=2.0, help="seconds of runs per mode")
    parser.add_argument("--out")
    args = parser.parse_args()
    names = sorted(d for d in os.listdir(args.root) if os.path.isdir(os.path.join(args.root, d)))
    if args.only:
        names = [n for n in names if n in args.only.split(",")]
    names = [n for n in names if n not in args.skip.split(",")]
    print("| problem | AMICI forward | AMICI adjoint | sysid | AMICI's faster / sysid |")
    print("|---|---|---|---|---|")
    rows = []
    for name in names:
        yaml = problem_yaml(os.path.join(args.root, name))
        if yaml is None:
            continue
        ours = sysid_time(yaml)
        try:
            theirs = amici_times(yaml, name, args.budget)
        except Exception as e:  # noqa: BLE001 (a model AMICI cannot import is reported)
            theirs = None
            print(f"{name}: AMICI failed: {type(e).__name__}: {e}", file=sys.stderr)
        cell = lambda mode: "failed" if theirs is None else (  # noqa: E731
            f"{theirs[mode][0]:.3g} ms" + ("" if theirs[mode][2] else " (failed or not finite)")
        )
        ratio = ""
        succeeded = [] if theirs is None else [t[0] for t in theirs.values() if t[2]]
        if succeeded and ours is not None:
            ratio = f"{min(succeeded) / ours[0]:.2g}×"
        sysid_cell = "refused" if ours is None else f"{ours[0]:.3g} ms"
        print(f"| {name} | {cell('forward')} | {cell('adjoint')} | {sysid_cell} | {ratio} |")
        sys.stdout.flush()
        rows.append((name, theirs, ours))
    if args.out:
        with open(args.out, "w") as f:
            f.write("problem\tamici_forward_ms\tamici_adjoint_ms\tsysid_ms\tamici_nll\tsysid_nll\n")
            for name, theirs, ours in rows:
                fwd = theirs["forward"][0] if theirs else float("nan")
                adj = theirs["adjoint"][0] if theirs else float("nan")
                nll = theirs["forward"][1] if theirs else float("nan")
                mine = ours if ours else (float("nan"), float("nan"))
                f.write(f"{name}\t{fwd}\t{adj}\t{mine[0]}\t{nll}\t{mine[1]}\n")


if __name__ == "__main__":
    main()
