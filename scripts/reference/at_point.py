"""AMICI's objective (through pyPESTO: NLL plus the priors' term) at the points of
tests/data/petab/best_points.tsv: an independent evaluation of the best known values sysid
found away from the nominal parameters. Not run by any test; its output is quoted in
tests/data/petab/best_known.tsv and in the test that checks the points
(crates/cli/tests/petab.rs).

    python3 -m venv venv && venv/bin/pip install amici pypesto fides petab scipy
    PATH=venv/bin:$PATH venv/bin/python scripts/reference/at_point.py tests/data/petab

Printed on this machine (amici 1.0.1 and the pypesto of December 2026, AMICI's default
tolerances; 2026-12-03):

    Elowitz_Nature2000 -65.63322893916738
    Zheng_PNAS2012 -293.713858350513
    Schwen_PONE2014 952.4217258244647

and with `--rtol 1e-12 --atol 1e-16`, Zheng_PNAS2012 -293.7138963241364.

(sysid: −65.633227, −293.713896 and 952.421726. Zheng's gap at AMICI's defaults, 3.8e-5,
closes at AMICI's tighter tolerances, to 1e-7; sysid gives the same value at its
tolerances and at 1000 times tighter ones (crates/cli/tests/petab.rs). At Zheng's nominal
point the two agree to 1e-6. Zheng's points of before: −293.309462, which AMICI gave as
−293.3099347984426 at its defaults, and −292.982545, as −292.9831237. Elowitz's point of
before, −65.493149, AMICI gave as −65.49314849568135. Schwen's row printed
952.4217262175704 with the pypesto of 2026-12-03, morning.)

`--points uncertified_points.tsv` evaluates the best known points that sysid has not
certified at the problem's tolerances (an oscillator), where the NLL needs tight integration
to be resolved; printed 2026-12-03 with `--rtol 1e-14 --atol 1e-24` and without:

    Borghans_BiophysChem1997 -123.68535086220659   (rtol 1e-14, atol 1e-24)
    Borghans_BiophysChem1997 -87.2835229844346     (AMICI's defaults)

(sysid at the point: −123.6853508644 with Rodas5P at rtol 1e-12, −123.6853508647 with DOPRI5
at rtol 1e-13. The point of 2026-12-02, evening, gave −109.2891402115272 and
−109.27531575139228; the morning's −108.9794713 and −108.91897810835675.)
"""

import argparse
import csv
import os
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pypesto.petab  # noqa: E402

import published  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="tests/data/petab")
    parser.add_argument("--amici-dir", type=Path, default=Path("/tmp/amici_models"))
    parser.add_argument("--points", default="best_points.tsv",
                        help="the table of points in FOLDER (default best_points.tsv)")
    parser.add_argument("--rtol", type=float, help="AMICI's relative tolerance (default its own)")
    parser.add_argument("--atol", type=float, help="AMICI's absolute tolerance (default its own)")
    args = parser.parse_args()
    points = defaultdict(dict)
    with open(args.folder / args.points, newline="") as f:
        for row in csv.DictReader(f, delimiter="\t"):
            points[row["problem"]][row["parameterId"]] = float(row["value"])
    for name, values in points.items():
        problem = published.load(args.folder / name, name)
        importer = pypesto.petab.PetabImporter(
            problem, output_folder=str(args.amici_dir / name), model_name=name
        )
        objective = importer.create_problem()
        # With priors (Schwen) the objective is an aggregate of AMICI's and the priors'.
        inner = objective.objective
        parts = getattr(inner, "_objectives", [inner])
        solver = next(p.amici_solver for p in parts if hasattr(p, "amici_solver"))
        if args.rtol is not None:
            solver.set_relative_tolerance(args.rtol)
        if args.atol is not None:
            solver.set_absolute_tolerance(args.atol)
        solver.set_max_steps(10**7)
        scales = problem.parameter_df["parameterScale"]
        x = []
        for i in objective.x_free_indices:
            pid = objective.x_names[i]
            v = values[pid]
            x.append({"lin": v, "log": np.log(v), "log10": np.log10(v)}[scales[pid]])
        print(name, float(objective.objective(np.array(x))))


if __name__ == "__main__":
    main()
