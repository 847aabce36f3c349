#!/usr/bin/env python3
"""Data and maximum-likelihood reference of the two-dose example, computed independently of sysid.

The model (time in h, concentrations in arbitrary units): a dose of A becomes B, B becomes C.

  A' = -k1 A,   B' = kp A - k2 B,   C' = k2 B,   A(0) = dose, B(0) = C(0) = 0.

kp is not k1 (not all that leaves A arrives in B), so A + B + C is not conserved. The system is
linear; for k1 != k2 its solution is

  A = dose e^(-k1 t)
  B = dose kp / (k2 - k1) (e^(-k1 t) - e^(-k2 t))
  C = dose kp / (k2 - k1) (k2 / k1 (1 - e^(-k1 t)) - (1 - e^(-k2 t)))     (the integral of k2 B)

Observables: Bm = scale B, normal noise of s.d. sigma_B on the linear scale; Ct = C measured on
the log10 scale, normal noise of s.d. 0.02 (known) on log10 C. Two experiments, both at
t = 0.5, 1.0, ..., 10.0 (20 times):

  low   dose 1, scale 1            Bm and Ct   (40 points)
  high  dose 5, scale scale_high   Bm only     (20 points)

Truth: k1 = 0.7, kp = 0.5, k2 = 0.25, scale_high = 1.6, sigma_B = 0.03.

Data. True values integrated by solve_ivp DOP853 at rtol = atol = 1e-13, checked against the
closed form (the run fails above 1e-12 relative; 5.8e-13 with scipy 1.17.1) and against LSODA
at 1e-13 (printed only: 2.5e-12).
Noise from numpy.random.default_rng(20261124), drawn in this order: 20 standard normals z for
low's Bm, 20 for low's Ct, 20 for high's Bm; Bm = B_true + sigma_B z and
Ct = 10^(log10 C_true + 0.02 z). Written with repr() (shortest round trip) to
examples/two-doses/low.csv (t,Bm,Ct) and examples/two-doses/high.csv (t,Bm); the fit below reads
the values back from those files.

NLL (PEtab): for each point 1/2 ln(2 pi sigma^2) + 1/2 ((m~ - y~) / sigma)^2, with ~ the
identity for Bm and log10 for Ct, plus ln(m ln 10) for each Ct point (m the measurement).
AIC = 2 k + 2 NLL, BIC = k ln N + 2 NLL, with k = 5 unknowns and N = 60 points.

Optimum of the five unknowns, in w = ln(k1, kp, k2, scale_high, sigma_B):
  1. sigma_B profiled out: with sigma_B held, scipy's least_squares (trf, x_scale = "jac",
     ftol = xtol = gtol = 1e-15) over the other four on the weighted residuals (m~ - y~) / sigma;
     then sigma_B^2 = the mean squared Bm residual (its closed-form optimum); repeated until
     sigma_B no longer moves. The fixed point is where the full NLL is stationary.
  2. Newton polish of the full five-parameter NLL: gradient from the sensitivities, Hessian by
     central differences of that gradient, until the step is below 1e-13.
  Run from three starts (the truth, a far start, one with k1 and k2 swapped) and with two models
  of the predictions: the closed form, and DOP853 at rtol = atol = 1e-12. The reference is the
  closed form's best optimum; the others are printed as differences from it. The gradient at
  the optimum is checked again by central differences of the NLL itself, and the NLL there is
  evaluated with LSODA too.
Sensitivities d y~ / d w are complex-step derivatives, Im y~(w + i h e_j) / h with h = 1e-30:
exact to rounding for the closed form, and the derivative of the discrete solution for DOP853
(solve_ivp works in complex arithmetic when y0 is complex; imaginary parts of order 1e-30 do not
change its step sizes).

Fisher information at the joint optimum, for each experiment alone and for both: J^T J, J the
sensitivities of the weighted residuals (rows: points; columns: the four kinetic and scale
unknowns), plus the sigma_B block (2 per Bm point in ln sigma_B; its cross terms vanish). Given
in w (ln of each unknown) and in the unknowns themselves. Rank: singular values of the
square-root matrix above 1e-8 times the largest. Expected: high alone sees only the product
scale_high kp (rank 4, null direction ln kp - ln scale_high); low alone does not see scale_high
(rank 4); both together rank 5. condition_number is null where the rank is deficient (there the
smallest eigenvalue is rounding); reciprocal_condition_number is always given.

Writes examples/two-doses/{low,high}.csv and tests/data/two_doses_reference.json, which the tests
read. Run from anywhere: python3 scripts/reference/two_doses.py   (numpy, scipy >= 1.10)
"""
import json
import math
import os
import time

import numpy as np
import scipy
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
EXAMPLE = os.path.join(REPO, "examples", "two-doses")
OUT = os.path.join(REPO, "tests", "data", "two_doses_reference.json")

NAMES = ["k1", "kp", "k2", "scale_high", "sigma_B"]
TRUTH = {"k1": 0.7, "kp": 0.5, "k2": 0.25, "scale_high": 1.6, "sigma_B": 0.03}
SIGMA_CT = 0.02  # s.d. of log10 Ct, known
SEED = 20261124
TIMES = np.array([0.5 * i for i in range(1, 21)])  # 0.5, 1.0, ..., 10.0, exact in binary
DOSE = {"low": 1.0, "high": 5.0}
# The series in a fixed order: (experiment, observable).
SERIES = [("low", "Bm"), ("low", "Ct"), ("high", "Bm")]
STARTS = {
    "truth": TRUTH,
    "far": {"k1": 2.0, "kp": 0.1, "k2": 0.05, "scale_high": 1.0, "sigma_B": 0.1},
    "swapped": {"k1": 0.25, "kp": 1.0, "k2": 0.7, "scale_high": 3.0, "sigma_B": 0.01},
}
RANK_TOL = 1e-8


# ---------------------------------------------------------------------------------------------
# Model. p = (k1, kp, k2), real or complex (complex step); returns B and C at TIMES.

def states_closed(p, dose):
    k1, kp, k2 = p
    e1, e2 = np.exp(-k1 * TIMES), np.exp(-k2 * TIMES)
    f = dose * kp / (k2 - k1)
    b = f * (e1 - e2)
    c = f * (k2 / k1 * -np.expm1(-k1 * TIMES) + np.expm1(-k2 * TIMES))
    return b, c


def states_ode(p, dose, method, tol):
    k1, kp, k2 = p

    def rhs(_t, x):
        return np.array([-k1 * x[0], kp * x[0] - k2 * x[1], k2 * x[1]])

    dtype = complex if np.iscomplexobj(np.asarray(p)) else float
    sol = solve_ivp(rhs, (0.0, TIMES[-1]), np.array([dose, 0.0, 0.0], dtype=dtype), method=method,
                    t_eval=TIMES, rtol=tol, atol=tol)
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y[1], sol.y[2]


# The predictions used in the fits: name -> function of (p, dose).
MODELS = {
    "closed": states_closed,
    "DOP853": lambda p, dose: states_ode(p, dose, "DOP853", 1e-12),
}


def predictions(w4, model):
    """y~ at every point, in SERIES order (60 values). w4 = ln(k1, kp, k2, scale_high)."""
    k1, kp, k2, scale = np.exp(w4)
    states = {e: model((k1, kp, k2), DOSE[e]) for e in DOSE}
    out = []
    for experiment, observable in SERIES:
        b, c = states[experiment]
        if observable == "Bm":
            out.append(b * (scale if experiment == "high" else 1.0))
        else:
            out.append(np.log10(c))
    return np.concatenate(out)


def sensitivities(w4, model, h=1e-30):
    """d y~ / d w4 (60 x 4) by complex step."""
    columns = []
    for j in range(4):
        shifted = np.array(w4, dtype=complex)
        shifted[j] += 1j * h
        columns.append(np.imag(predictions(shifted, model)) / h)
    return np.column_stack(columns)


# ---------------------------------------------------------------------------------------------
# Data.

def generate():
    """True values (DOP853, rtol = atol = 1e-13), cross-checked; noisy data written as CSV."""
    p = (TRUTH["k1"], TRUTH["kp"], TRUTH["k2"])
    worst = {"closed": 0.0, "LSODA": 0.0}
    true = {}
    for e, dose in DOSE.items():
        b, c = states_ode(p, dose, "DOP853", 1e-13)
        for name, (bb, cc) in [("closed", states_closed(p, dose)),
                               ("LSODA", states_ode(p, dose, "LSODA", 1e-13))]:
            worst[name] = max(worst[name], np.max(np.abs(bb / b - 1)), np.max(np.abs(cc / c - 1)))
        true[e] = (b, c)
    print("true values, DOP853 at rtol = atol = 1e-13; largest relative difference to the "
          f"closed form {worst['closed']:.1e}, to LSODA at 1e-13 {worst['LSODA']:.1e}")
    assert worst["closed"] < 1e-12, worst

    rng = np.random.default_rng(SEED)
    z_low_b, z_low_c, z_high_b = (rng.standard_normal(20) for _ in range(3))
    low_bm = true["low"][0] + TRUTH["sigma_B"] * z_low_b
    low_ct = 10.0 ** (np.log10(true["low"][1]) + SIGMA_CT * z_low_c)
    high_bm = TRUTH["scale_high"] * true["high"][0] + TRUTH["sigma_B"] * z_high_b

    os.makedirs(EXAMPLE, exist_ok=True)
    write_csv("low.csv", ["t", "Bm", "Ct"], [TIMES, low_bm, low_ct])
    write_csv("high.csv", ["t", "Bm"], [TIMES, high_bm])


def write_csv(name, header, columns):
    with open(os.path.join(EXAMPLE, name), "w") as f:
        f.write(",".join(header) + "\n")
        for row in zip(*columns):
            f.write(",".join(repr(float(v)) for v in row) + "\n")


def read_csv(name):
    with open(os.path.join(EXAMPLE, name)) as f:
        header = f.readline().strip().split(",")
        rows = [[float(v) for v in line.split(",")] for line in f if line.strip()]
    columns = dict(zip(header, np.array(rows).T))
    assert np.array_equal(columns["t"], TIMES)
    return columns


class Data:
    """The measurements as flat arrays in SERIES order."""

    def __init__(self):
        files = {e: read_csv(f"{e}.csv") for e in DOSE}
        raw = [files[e][o] for e, o in SERIES]
        self.raw = np.concatenate(raw)
        self.is_b = np.concatenate([np.full(20, o == "Bm") for _, o in SERIES])
        self.experiment = np.concatenate([np.full(20, e) for e, _ in SERIES])
        self.transformed = np.where(self.is_b, self.raw, np.log10(np.where(self.is_b, 1.0, self.raw)))
        self.points = {e: int(np.sum(self.experiment == e)) for e in DOSE}

    def sigma(self, sigma_b):
        return np.where(self.is_b, sigma_b, SIGMA_CT)


# ---------------------------------------------------------------------------------------------
# Likelihood. w = ln(k1, kp, k2, scale_high, sigma_B).

def nll_terms(w, data, model):
    """The NLL of each point."""
    sigma = data.sigma(math.exp(w[4]))
    r = (data.transformed - predictions(w[:4], model)) / sigma
    terms = 0.5 * np.log(2 * np.pi * sigma ** 2) + 0.5 * r ** 2
    return terms + np.where(data.is_b, 0.0, np.log(np.where(data.is_b, 1.0, data.raw) * np.log(10)))


def nll(w, data, model):
    return float(np.sum(nll_terms(w, data, model)))


def gradient(w, data, model):
    """d NLL / d w from the complex-step sensitivities."""
    sigma = data.sigma(math.exp(w[4]))
    r = (data.transformed - predictions(w[:4], model)) / sigma
    g = -(r / sigma) @ sensitivities(w[:4], model)
    return np.append(g, np.sum(1.0 - r[data.is_b] ** 2))


def gradient_by_differences(w, data, model, h=1e-6):
    """d NLL / d w by central differences of the NLL itself: an independent check."""
    g = np.zeros(5)
    for j in range(5):
        step = np.zeros(5)
        step[j] = h
        g[j] = (nll(w + step, data, model) - nll(w - step, data, model)) / (2 * h)
    return g


def fit(start, data, model):
    """Profiled least squares, then Newton on the full NLL. Returns w and a log of the run."""
    w4 = np.log([start[n] for n in NAMES[:4]])
    sigma_b = start["sigma_B"]
    rounds = 0
    for rounds in range(1, 201):
        sigma = data.sigma(sigma_b)
        result = least_squares(
            lambda v: (data.transformed - predictions(v, model)) / sigma, w4,
            jac=lambda v: -sensitivities(v, model) / sigma[:, None],
            method="trf", x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=2000)
        w4 = result.x
        residual_b = (data.transformed - predictions(w4, model))[data.is_b]
        new = math.sqrt(np.mean(residual_b ** 2))
        moved = abs(new / sigma_b - 1)
        sigma_b = new
        if moved < 1e-14:
            break
    w = np.append(w4, math.log(sigma_b))
    profiled = nll(w, data, model)

    steps = []
    for _ in range(10):
        g = gradient(w, data, model)
        step = -np.linalg.solve(hessian(w, data, model), g)
        w = w + step
        steps.append(float(np.max(np.abs(step))))
        if steps[-1] < 1e-13:
            break
    return w, {"rounds": rounds, "nll_profiled": profiled, "newton_steps": steps}


def hessian(w, data, model, h=1e-5):
    """Central differences of the gradient, symmetrised."""
    columns = []
    for j in range(5):
        step = np.zeros(5)
        step[j] = h
        columns.append((gradient(w + step, data, model) - gradient(w - step, data, model)) / (2 * h))
    m = np.column_stack(columns)
    return 0.5 * (m + m.T)


# ---------------------------------------------------------------------------------------------
# Fisher information.

def fisher(w, data, experiments):
    """Square-root matrix of the Fisher information in w for the given experiments (closed form)."""
    sigma = data.sigma(math.exp(w[4]))
    keep = np.isin(data.experiment, experiments)
    rows = sensitivities(w[:4], states_closed)[keep] / sigma[keep, None]
    root = np.hstack([rows, np.zeros((rows.shape[0], 1))])
    n_b = int(np.sum(data.is_b[keep]))
    sigma_row = np.zeros((1, 5))
    sigma_row[0, 4] = math.sqrt(2.0 * n_b)  # 2 per Bm point in ln sigma_B
    return np.vstack([root, sigma_row])


def conditioning(root):
    s = np.linalg.svd(root, compute_uv=False)
    rank = int(np.sum(s > RANK_TOL * s[0]))
    reciprocal = float((s[-1] / s[0]) ** 2)
    _, _, vt = np.linalg.svd(root)
    null = vt[-1] * np.sign(vt[-1][np.argmax(np.abs(vt[-1]))])
    return {
        "rank": rank,
        "condition_number": float((s[0] / s[-1]) ** 2) if rank == 5 else None,
        "reciprocal_condition_number": reciprocal,
        "eigenvalues": [float(v) for v in sorted(s ** 2, reverse=True)],
        "weakest_direction": [float(v) for v in null],
    }


def fisher_report(w, data, experiments):
    root = fisher(w, data, experiments)
    in_w = conditioning(root)
    # In the unknowns themselves: d/dp = (1/p) d/dw.
    in_p = conditioning(root / np.exp(w)[None, :])
    return {"log": in_w, "linear": in_p}


# ---------------------------------------------------------------------------------------------

def main():
    print(f"numpy {np.__version__}, scipy {scipy.__version__}")
    generate()
    data = Data()
    print(f"points: {data.points}")

    w_true = np.log([TRUTH[n] for n in NAMES])
    nll_truth = nll(w_true, data, states_closed)
    nll_truth_by = {name: nll(w_true, data, m) for name, m in MODELS.items()}
    nll_truth_by["LSODA"] = nll(w_true, data, lambda p, d: states_ode(p, d, "LSODA", 1e-12))
    print(f"\nNLL at the truth: {nll_truth!r}")
    for name, v in nll_truth_by.items():
        print(f"  {name:8s} {v!r:>22}  ({v - nll_truth:+.1e})")

    results = {}
    for model_name, model in MODELS.items():
        for start_name, start in STARTS.items():
            began = time.perf_counter()
            w, log = fit(start, data, model)
            value = nll(w, data, model)
            results[(model_name, start_name)] = (w, value)
            g = gradient(w, data, model)
            print(f"\n{model_name}, start {start_name}: NLL {value!r} "
                  f"({time.perf_counter() - began:.1f} s; {log['rounds']} least-squares rounds, "
                  f"profiled NLL {log['nll_profiled']!r}; Newton steps "
                  + ", ".join(f"{s:.1e}" for s in log["newton_steps"]) + ")")
            print(f"  |gradient| (complex step) {np.linalg.norm(g):.2e}")
            for n, v in zip(NAMES, np.exp(w)):
                print(f"  {n:10s} {float(v)!r}")

    # The reference: the closed form's best optimum.
    best = min((k for k in results if k[0] == "closed"), key=lambda k: results[k][1])
    w_opt, nll_opt = results[best]
    print(f"\nreference: {best}; differences of the others (relative in each unknown, NLL absolute):")
    for key, (w, value) in results.items():
        rel = np.max(np.abs(np.exp(w - w_opt) - 1))
        print(f"  {key[0]:7s} {key[1]:8s} max rel {rel:.1e}   NLL {value - nll_opt:+.1e}")

    g = gradient(w_opt, data, states_closed)
    g_fd = gradient_by_differences(w_opt, data, states_closed)
    g_linear = g / np.exp(w_opt)
    print(f"\ngradient at the optimum (in ln of the unknowns): complex step {g}, |g| {np.linalg.norm(g):.2e}")
    print(f"  by central differences of the NLL (h = 1e-6): {g_fd}, |g| {np.linalg.norm(g_fd):.2e}")
    print(f"  in the unknowns themselves: |g| {np.linalg.norm(g_linear):.2e}")
    h = hessian(w_opt, data, states_closed)
    print(f"Hessian of the NLL in w: eigenvalues {np.linalg.eigvalsh(h)}")

    per = {e: float(np.sum(nll_terms(w_opt, data, states_closed)[data.experiment == e])) for e in DOSE}
    lsoda = nll(w_opt, data, lambda p, d: states_ode(p, d, "LSODA", 1e-12))
    print(f"\nNLL at the optimum {nll_opt!r} (LSODA rtol 1e-12: {lsoda - nll_opt:+.1e}); "
          f"per experiment {per}, sum {sum(per.values()) - nll_opt:+.1e}")
    k, n = 5, sum(data.points.values())
    aic = 2 * k + 2 * nll_opt
    bic = k * math.log(n) + 2 * nll_opt
    print(f"AIC {aic!r}, BIC {bic!r}")

    fisher_out = {}
    for label, experiments in [("low", ["low"]), ("high", ["high"]), ("joint", ["low", "high"])]:
        fisher_out[label] = fisher_report(w_opt, data, experiments)
        for scale in ("log", "linear"):
            c = fisher_out[label][scale]
            print(f"Fisher {label:5s} ({scale:6s}): rank {c['rank']}, condition {c['condition_number']}, "
                  f"1/condition {c['reciprocal_condition_number']:.2e}, weakest direction "
                  + " ".join(f"{v:+.3f}" for v in c["weakest_direction"]))
    covariance = np.linalg.inv(fisher(w_opt, data, ["low", "high"]).T @ fisher(w_opt, data, ["low", "high"]))
    print("relative standard errors (joint Fisher, in w): "
          + ", ".join(f"{nm} {s:.3f}" for nm, s in zip(NAMES, np.sqrt(np.diag(covariance)))))

    out = {
        "generated_by": "python3 scripts/reference/two_doses.py",
        "software": f"numpy {np.__version__}, scipy {scipy.__version__}",
        "truth": TRUTH,
        "sigma_Ct_log10": SIGMA_CT,
        "seed": SEED,
        "nll_optimum": nll_opt,
        "nll_truth": nll_truth,
        "estimates": {nm: float(v) for nm, v in zip(NAMES, np.exp(w_opt))},
        "nll_per_experiment": per,
        "points": data.points,
        "parameters": k,
        "aic": aic,
        "bic": bic,
        "gradient_norm_at_optimum": float(np.linalg.norm(g)),
        "gradient_norm_at_optimum_note": "Euclidean norm of d NLL / d ln(unknown), complex-step "
                                         "sensitivities of the closed form",
        "fisher": {
            "note": "Fisher information at the joint optimum; 'log': in ln of each unknown, "
                    "'linear': in the unknowns; unknowns ordered " + ", ".join(NAMES) + "; rank: "
                    f"singular values of its square root above {RANK_TOL} times the largest; "
                    "condition_number null where the rank is deficient",
            **fisher_out,
        },
    }
    with open(OUT, "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    print(f"\nwrote {os.path.normpath(OUT)}")


if __name__ == "__main__":
    main()
