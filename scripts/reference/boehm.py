#!/usr/bin/env python3
"""Independent reference for the PEtab problem Boehm_JProteomeRes2014 (STAT5 dimerisation).

Written by hand from a reading of the published problem (Benchmark-Models-PEtab, commit
4d20850): the SBML model, the observable, parameter and measurement tables. No SBML or PEtab
library is used and nothing is shared with sysid, so agreement between the two is evidence
that sysid's importer reads the problem as the SBML/PEtab semantics say. The model as read:

  Compartments cyt = 1.4, nuc = 0.45. All 8 species are concentrations
  (hasOnlySubstanceUnits = false). Every kinetic law is written as (compartment size) x
  (rate in concentration), so the reaction rate is an amount per time and d[X]/dt =
  sum(stoichiometry x rate) / size(compartment of X): reactions within one compartment
  reduce to plain mass action, transport between cyt and nuc picks up a volume ratio.

  Epo(t) = 1.25e-7 exp(-Epo_degradation_BaF3 t)          (assignment rule BaF3_Epo)
  A = STAT5A, B = STAT5B, k = k_phos, r = cyt/nuc
  A'       = -2 k Epo A^2 - k Epo A B + (2 k_exp_homo nucpApA + k_exp_hetero nucpApB) / r
  B'       = -2 k Epo B^2 - k Epo A B + (2 k_exp_homo nucpBpB + k_exp_hetero nucpApB) / r
  pApA'    = k Epo A^2 - k_imp_homo pApA
  pApB'    = k Epo A B - k_imp_hetero pApB
  pBpB'    = k Epo B^2 - k_imp_homo pBpB
  nucpApA' = r k_imp_homo pApA - k_exp_homo nucpApA
  nucpApB' = r k_imp_hetero pApB - k_exp_hetero nucpApB
  nucpBpB' = r k_imp_homo pBpB - k_exp_homo nucpBpB
  A(0) = 207.6 ratio, B(0) = 207.6 - 207.6 ratio           (initial assignments), others 0.

  The compartment sizes do not reach the observables: in terms of n = nuclear concentration
  / r (nuclear amount per cytoplasmic volume) the equations above lose r altogether. They
  show only in the nuclear states, which the script prints at a few times for that check.

  Observables (lin, normal; sigma = sd_<observable>):
    pSTAT5A_rel = (100 pApB + 200 pApA s) / (pApB + A s + 2 pApA s)
    pSTAT5B_rel = -(100 pApB - 200 pBpB (s - 1)) / ((B (s - 1) - pApB) + 2 pBpB (s - 1))
    rSTAT5A_rel = (100 pApB + 100 A s + 200 pApA s)
                  / (2 pApB + A s + 2 pApA s - B (s - 1) - 2 pBpB (s - 1))
    with s = specC17.

  NLL = sum over the 48 data of 1/2 ln(2 pi sigma^2) + 1/2 ((m - y) / sigma)^2; the
  published value at the nominal parameters is 138.22199693517703 (AMICI benchmark test).

Integration: solve_ivp, Radau with analytic Jacobian, rtol = atol = 1e-12 (k_imp_homo ~ 1e5
makes the problem stiff); the NLL at nominal agrees with LSODA and BDF at rtol 1e-14 to 1e-12.

--optimise: with the three sigmas held at their nominal values, minimise chi^2 over the six
kinetic parameters on the log10 scale within [1e-5, 1e5] by scipy's least_squares (trf,
x_scale = "jac", ftol = xtol = gtol = 1e-15, max_nfev = 2000, 3-point finite-difference
Jacobian, from the nominal values), integrating with LSODA (rtol = atol = 1e-12) for speed;
the optimum's chi^2 and NLL are then evaluated with Radau.

Run: python3 scripts/reference/boehm.py [--optimise] [--petab DIR]   (numpy, scipy >= 1.10)
The measurement table is read from DIR (default: tests/data/petab/Boehm_JProteomeRes2014 in
the repository, else ../shared/petab/Boehm_JProteomeRes2014 beside it).
"""
import argparse
import csv
import os
import time

import numpy as np
import scipy
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

PROBLEM = "Boehm_JProteomeRes2014"
REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
PETAB_DIRS = [
    os.path.join(REPO, "tests", "data", "petab", PROBLEM),
    os.path.join(REPO, "..", "shared", "petab", PROBLEM),
]
PUBLISHED_NLL = 138.22199693517703

# Compartment sizes (SBML listOfCompartments).
CYT = 1.4
NUC = 0.45

STATES = ["STAT5A", "STAT5B", "pApB", "pApA", "pBpB", "nucpApA", "nucpApB", "nucpBpB"]

# Parameter table: nominal values (these, not the SBML <parameter> values, are the problem's).
NOMINAL = {
    "Epo_degradation_BaF3": 0.026982514033029,
    "k_exp_hetero": 1.00067973851508e-05,
    "k_exp_homo": 0.006170228086381,
    "k_imp_hetero": 0.0163679184468,
    "k_imp_homo": 97749.3794024716,
    "k_phos": 15766.5070195731,
    "ratio": 0.693,  # fixed
    "specC17": 0.107,  # fixed
    "sd_pSTAT5A_rel": 3.85261197844677,
    "sd_pSTAT5B_rel": 6.59147818673419,
    "sd_rSTAT5A_rel": 3.15271275648527,
}
KINETIC = ["Epo_degradation_BaF3", "k_exp_hetero", "k_exp_homo", "k_imp_hetero", "k_imp_homo", "k_phos"]
LOWER, UPPER = 1e-5, 1e5  # bounds of every estimated parameter (log10 scale)


def epo(t, p):
    """Assignment rule BaF3_Epo."""
    return 1.25e-7 * np.exp(-p["Epo_degradation_BaF3"] * t)


def rhs(t, x, p):
    a, b, papb, papa, pbpb, napa, napb, nbpb = x
    e = p["k_phos"] * epo(t, p)
    r = CYT / NUC
    return [
        -2 * e * a * a - e * a * b + (2 * p["k_exp_homo"] * napa + p["k_exp_hetero"] * napb) / r,
        -2 * e * b * b - e * a * b + (2 * p["k_exp_homo"] * nbpb + p["k_exp_hetero"] * napb) / r,
        e * a * b - p["k_imp_hetero"] * papb,
        e * a * a - p["k_imp_homo"] * papa,
        e * b * b - p["k_imp_homo"] * pbpb,
        r * p["k_imp_homo"] * papa - p["k_exp_homo"] * napa,
        r * p["k_imp_hetero"] * papb - p["k_exp_hetero"] * napb,
        r * p["k_imp_homo"] * pbpb - p["k_exp_homo"] * nbpb,
    ]


def jacobian(t, x, p):
    """d rhs / dx."""
    a, b = x[0], x[1]
    e = p["k_phos"] * epo(t, p)
    r = CYT / NUC
    kih, kie, keh, kee = p["k_imp_homo"], p["k_imp_hetero"], p["k_exp_homo"], p["k_exp_hetero"]
    j = np.zeros((8, 8))
    j[0, 0], j[0, 1], j[0, 5], j[0, 6] = -4 * e * a - e * b, -e * a, 2 * keh / r, kee / r
    j[1, 0], j[1, 1], j[1, 7], j[1, 6] = -e * b, -4 * e * b - e * a, 2 * keh / r, kee / r
    j[2, 0], j[2, 1], j[2, 2] = e * b, e * a, -kie
    j[3, 0], j[3, 3] = 2 * e * a, -kih
    j[4, 1], j[4, 4] = 2 * e * b, -kih
    j[5, 3], j[5, 5] = r * kih, -keh
    j[6, 2], j[6, 6] = r * kie, -kee
    j[7, 4], j[7, 7] = r * kih, -keh
    return j


def initial_state(p):
    """Initial assignments (concentrations, since hasOnlySubstanceUnits = false)."""
    return [207.6 * p["ratio"], 207.6 - 207.6 * p["ratio"], 0, 0, 0, 0, 0, 0]


def observables(x, p):
    """x: states by rows (8 x n). Returns a dict of arrays."""
    a, b, papb, papa, pbpb = x[0], x[1], x[2], x[3], x[4]
    s = p["specC17"]
    return {
        "pSTAT5A_rel": (100 * papb + 200 * papa * s) / (papb + a * s + 2 * papa * s),
        "pSTAT5B_rel": -(100 * papb - 200 * pbpb * (s - 1))
        / ((b * (s - 1) - papb) + 2 * pbpb * (s - 1)),
        "rSTAT5A_rel": (100 * papb + 100 * a * s + 200 * papa * s)
        / (2 * papb + a * s + 2 * papa * s - b * (s - 1) - 2 * pbpb * (s - 1)),
    }


def read_measurements(directory):
    """(observableId, time, measurement, noise parameter id) for each row of the table."""
    path = os.path.join(directory, f"measurementData_{PROBLEM}.tsv")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    data = []
    for row in rows:
        assert row["simulationConditionId"] == "model1_data1" and not row["preequilibrationConditionId"]
        assert row["noiseParameters"] == "sd_" + row["observableId"]
        data.append((row["observableId"], float(row["time"]), float(row["measurement"]), row["noiseParameters"]))
    return data


def states(p, times, method="Radau"):
    """States (8 x len(times)), rtol = atol = 1e-12."""
    sol = solve_ivp(rhs, (0.0, times[-1]), initial_state(p), method=method, t_eval=times,
                    args=(p,), jac=jacobian, rtol=1e-12, atol=1e-12)
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y


def residuals(p, data, method="Radau"):
    """(m - y) / sigma for each datum, and the sigmas."""
    times = np.array(sorted({t for _, t, _, _ in data}))
    y = observables(states(p, times, method), p)
    index = {t: i for i, t in enumerate(times)}
    res = np.array([(m - y[obs][index[t]]) / p[sd] for obs, t, m, sd in data])
    sigma = np.array([p[sd] for _, _, _, sd in data])
    return res, sigma


def nll(p, data):
    res, sigma = residuals(p, data)
    chi2 = float(np.sum(res ** 2))
    return float(np.sum(0.5 * np.log(2 * np.pi * sigma ** 2))) + 0.5 * chi2, chi2


def optimise(data):
    """Minimise chi^2 over the kinetic parameters (log10 scale), sigmas at nominal."""

    def params(z):
        p = dict(NOMINAL)
        p.update({k: 10.0 ** zk for k, zk in zip(KINETIC, z)})
        return p

    z0 = np.log10([NOMINAL[k] for k in KINETIC])
    lo, hi = np.log10(LOWER), np.log10(UPPER)
    # LSODA is some 30 times faster here than Radau (its NLL at nominal differs by 7e-10);
    # the optimum is evaluated again with Radau by the caller.
    fit = least_squares(lambda z: residuals(params(z), data, "LSODA")[0], z0, bounds=(lo, hi),
                        method="trf", x_scale="jac", jac="3-point",
                        ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=2000)
    return fit, params(fit.x)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--optimise", action="store_true",
                        help="also minimise chi^2 over the six kinetic parameters (sigmas fixed)")
    parser.add_argument("--petab", help="directory of the PEtab problem (for its measurement table)")
    args = parser.parse_args()

    directory = args.petab or next((d for d in PETAB_DIRS if os.path.isdir(d)), None)
    if directory is None:
        raise SystemExit(f"no PEtab directory found; pass --petab (looked in {PETAB_DIRS})")
    data = read_measurements(directory)
    print(f"{PROBLEM}: {len(data)} measurements from {os.path.normpath(directory)}")
    print(f"numpy {np.__version__}, scipy {scipy.__version__}")

    start = time.perf_counter()
    value, chi2 = nll(NOMINAL, data)
    print(f"at nominal: NLL  = {value!r}")
    print(f"            chi2 = {chi2!r}")
    print(f"published   NLL  = {PUBLISHED_NLL!r}, difference {value - PUBLISHED_NLL:.3e}")
    print(f"({time.perf_counter() - start:.3f} s)")

    # The observables see only the cytoplasmic states, which do not depend on the
    # compartment sizes; the nuclear states are where the sizes show.
    times = np.array([0.0, 2.5, 60.0, 240.0])
    x = states(NOMINAL, times)
    print("\nstates (concentrations) at nominal:")
    print(f"  {'t':>6} " + " ".join(f"{name:>22}" for name in STATES))
    for i, t in enumerate(times):
        print(f"  {t:6.1f} " + " ".join(f"{v:22.15e}" for v in x[:, i]))

    if args.optimise:
        start = time.perf_counter()
        fit, p = optimise(data)
        value, chi2 = nll(p, data)
        print(f"\nleast_squares (trf, sigmas fixed): status {fit.status} ({fit.message})")
        print(f"  nfev {fit.nfev}, njev {fit.njev}, optimality {fit.optimality:.3e}, "
              f"{time.perf_counter() - start:.1f} s")
        print(f"  chi2 = {chi2!r}")
        print(f"  NLL  = {value!r}")
        for k, z, active in zip(KINETIC, fit.x, fit.active_mask):
            where = ""
            if active < 0 or z - np.log10(LOWER) < 1e-8:
                where = "  <- lower bound"
            elif active > 0 or np.log10(UPPER) - z < 1e-8:
                where = "  <- upper bound"
            print(f"  {k:22s} {float(10.0 ** z)!r:>24}  (log10 {z:+.12f}){where}")


if __name__ == "__main__":
    main()
