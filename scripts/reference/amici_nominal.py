"""AMICI's NLL at nominal for collection problems that have no stored reference.

AMICI's own benchmark test stores references for 18 problems; for others (and where the
collection's simulated data do not match its tables), this computes AMICI's value: the model
compiled by AMICI, simulated at the parameter table's nominal values at rtol 1e-12,
atol 1e-14, and the NLL (-llh) of the PEtab problem.

    pip install amici petab     # AMICI 1.0.1 was used
    python scripts/reference/amici_nominal.py DIR NAME [NAME ...]

DIR is the collection's Benchmark-Models folder. One line per problem: name, NLL, source.
"""

import os
import sys

import amici
from amici.importers.petab.v1 import import_petab_problem
from amici.sim.sundials.petab.v1 import simulate_petab
import petab.v1 as petab


def main(root, names):
    for name in names:
        directory = os.path.join(root, name)
        yaml = os.path.join(directory, f"{name}.yaml")
        problem = petab.Problem.from_yaml(yaml)
        model = import_petab_problem(
            problem, output_dir=os.path.join("/tmp/amici", name), compile_=True
        )
        solver = model.create_solver()
        solver.set_relative_tolerance(1e-12)
        solver.set_absolute_tolerance(1e-14)
        result = simulate_petab(problem, amici_model=model, solver=solver, scaled_parameters=False)
        print(f"{name}\t{-float(result['llh'])!r}\tAMICI {amici.__version__} at rtol 1e-12", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
