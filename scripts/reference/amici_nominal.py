"""AMICI's NLL at nominal for collection problems that have no stored reference.

AMICI's own benchmark test stores references for 18 problems; for others (and where the
collection's simulated data do not match its tables), this computes AMICI's value: the model
compiled by AMICI, simulated at the parameter table's nominal values at rtol 1e-12,
atol 1e-14, and the NLL (-llh) of the PEtab problem.

    pip install amici petab     # AMICI 1.0.1 was used
    python scripts/reference/amici_nominal.py DIR NAME [NAME ...] [--rtol R,R,...]

DIR is the collection's Benchmark-Models folder. One line per problem and tolerance: name,
NLL, source. `--rtol 1e-10,1e-12,1e-14` (atol 1e-2·rtol, at least 1e-16) shows how far
AMICI's own value moves with its tolerances: a reference is no truer than that spread.
"""

import os
import sys

import amici
from amici.importers.petab.v1 import import_petab_problem
from amici.sim.sundials.petab.v1 import simulate_petab
import petab.v1 as petab


def main(root, names, rtols):
    for name in names:
        directory = os.path.join(root, name)
        yaml = os.path.join(directory, f"{name}.yaml")
        problem = petab.Problem.from_yaml(yaml)
        model = import_petab_problem(
            problem, output_dir=os.path.join("/tmp/amici", name), compile_=True
        )
        for rtol in rtols:
            solver = model.create_solver()
            solver.set_relative_tolerance(rtol)
            solver.set_absolute_tolerance(max(1e-2 * rtol, 1e-16))
            solver.set_max_steps(10**7)
            result = simulate_petab(
                problem, amici_model=model, solver=solver, scaled_parameters=False
            )
            nll = -float(result["llh"])
            print(f"{name}\t{nll!r}\tAMICI {amici.__version__} at rtol {rtol:g}", flush=True)


if __name__ == "__main__":
    args = sys.argv[2:]
    rtols = [1e-12]
    if "--rtol" in args:
        i = args.index("--rtol")
        rtols = [float(r) for r in args[i + 1].split(",")]
        del args[i : i + 2]
    main(sys.argv[1], args, rtols)
