#!/usr/bin/env python3
"""Reference optima of the bounded test problems, computed independently of sysid.

Reads tests/data/bounded/problems.json (the problems as sysid poses them, data included;
`cargo test --test bounded -- --ignored` writes it) and writes tests/data/bounded_reference.json:
for each problem the bounded least-squares optimum found by scipy's trust-region reflective
method (least_squares, method="trf", in units of the starting magnitudes, ftol = xtol = gtol
= 1e-15, 3-point finite-difference Jacobian; run three times, each from the last), on residuals integrated by solve_ivp's DOP853 at rtol 1e-12;
the cost in sysid's convention (sum of w r^2, no factor 1/2), the unknowns on a bound, and
scipy's first-order optimality.

Run: python3 scripts/reference/bounded.py   (scipy >= 1.10)
"""
import json
import os

import numpy as np
import scipy
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

HERE = os.path.dirname(__file__)
DATA = os.path.join(HERE, "..", "..", "tests", "data")


def rhs(name, y, p):
    """dy/dt of each problem: y and p are dicts by name."""
    if name == "rate-on-bound":
        a = y["A"]
        return {"A": -(p["k1"] + p["k2"]) * a, "B": p["k1"] * a, "C": p["k2"] * a}
    if name == "two-sided-bound":
        return {"x": -p["k"] * y["x"]}
    if name == "slow-rates":
        return {
            "A": -p["k1"] * y["A"],
            "B": p["k1"] * y["A"] - p["k2"] * y["B"],
            "C": p["k2"] * y["B"],
        }
    if name == "compartment-chain":
        out = {}
        for i in range(1, 9):
            flow = -p[f"d{i}"] * y[f"x{i}"]
            if i < 8:
                flow -= p[f"k{i}"] * y[f"x{i}"]
            if i > 1:
                flow += p[f"k{i - 1}"] * y[f"x{i - 1}"]
            out[f"x{i}"] = flow
        return out
    raise ValueError(name)


def residuals_of(problem):
    states, parameters = problem["states"], problem["parameters"]
    unknowns = problem["unknowns"]
    times = sorted({t for s in problem["series"] for t in s["times"]})

    def residuals(z):
        values = dict(problem["known"])
        values.update({u["name"]: v for u, v in zip(unknowns, z)})
        p = {n: values[n] for n in parameters}

        def f(_t, y):
            d = rhs(problem["name"], dict(zip(states, y)), p)
            return [d[s] for s in states]

        y0 = [values[s] for s in states]
        scale = max(1.0, max(abs(v) for v in y0))
        sol = solve_ivp(f, (problem["t0"], times[-1]), y0, method="DOP853", t_eval=times,
                        rtol=1e-12, atol=1e-14 * scale)
        at = {t: sol.y[:, m] for m, t in enumerate(sol.t)}
        r = []
        for s in problem["series"]:
            i = states.index(s["name"])
            w = np.sqrt(s["weight"])
            r.extend(w * (at[t][i] - b) for t, b in zip(s["times"], s["values"]))
        return np.array(r)

    return residuals


def main():
    problems = json.load(open(os.path.join(DATA, "bounded", "problems.json")))
    out = {"_how": f"scripts/reference/bounded.py, scipy {scipy.__version__}: least_squares "
                   "trf in units of the starting magnitudes (ftol = xtol = gtol = 1e-15, 3-point "
                   "Jacobian, three runs each from the last) on "
                   "solve_ivp DOP853 rtol 1e-12"}
    for problem in problems:
        unknowns = problem["unknowns"]
        lo = [u["min"] if u["min"] is not None else -np.inf for u in unknowns]
        hi = [u["max"] if u["max"] is not None else np.inf for u in unknowns]
        x0 = [u["guess"] for u in unknowns]
        # In units of the starting magnitudes (rates of 1e-5 sit beside initial values of
        # 1e4), then polished from where the first run stopped.
        scale = np.maximum(np.abs(x0), 1e-300)
        residuals = residuals_of(problem)
        fit = None
        for _ in range(3):
            start = np.array(x0) / scale if fit is None else fit.x
            fit = least_squares(lambda u: residuals(u * scale), start,
                                bounds=(np.array(lo) / scale, np.array(hi) / scale),
                                method="trf", jac="3-point", ftol=1e-15, xtol=1e-15,
                                gtol=1e-15, max_nfev=20000)
        fit.x = fit.x * scale
        active = {}
        x = list(fit.x)
        for i, (u, l, h) in enumerate(zip(unknowns, lo, hi)):
            # trf stays strictly inside; an unknown within 1e-10 of a bound is on it.
            if np.isfinite(l) and abs(x[i] - l) <= 1e-10 * max(1.0, abs(l)):
                active[u["name"]], x[i] = "lower", l
            elif np.isfinite(h) and abs(x[i] - h) <= 1e-10 * max(1.0, abs(h)):
                active[u["name"]], x[i] = "upper", h
        out[problem["name"]] = {
            "values": {u["name"]: float(v) for u, v in zip(unknowns, x)},
            "cost": float(2.0 * fit.cost),
            "active": active,
            "optimality": float(fit.optimality),
            "status": int(fit.status),
            "evaluations": int(fit.nfev),
        }
        print(problem["name"], out[problem["name"]]["cost"], active, fit.status, fit.optimality)
    with open(os.path.join(DATA, "bounded_reference.json"), "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")


if __name__ == "__main__":
    main()
