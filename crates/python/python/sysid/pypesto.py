"""A pyPESTO objective over a :class:`sysid.Problem`: pyPESTO's optimisers, profiles and
samplers on sysid's integration and sensitivities.

    import pypesto, pypesto.optimize
    import sysid, sysid.pypesto
    p = sysid.Problem.from_petab("Boehm_JProteomeRes2014.yaml")
    problem = sysid.pypesto.problem(p)
    result = pypesto.optimize.minimize(problem, n_starts=10)

The objective is :meth:`sysid.Problem.objective` (the NLL plus the priors' term) on the
parameter scale (ln of a log-scaled unknown's value), with its gradient and, as the Hessian,
the Fisher information (:meth:`sysid.Problem.fisher`). pyPESTO is not a dependency of sysid:
this module imports it when called.
"""

from __future__ import annotations

import numpy as np


def objective(p):
    """A ``pypesto.Objective`` giving fun, grad and the Fisher information as hess, on the
    parameter scale; the model is integrated once per point asked for. Where the model
    cannot be integrated (or its NLL overflows: :class:`sysid.SysidError`), fun is inf and
    grad and hess are NaN, as pyPESTO's own objectives give for a failed simulation, so that
    an optimiser backs off instead of ending the start. Bad input (a point of the wrong
    length) still raises."""
    import pypesto

    from . import SysidError

    cache = {}
    n = len(p.parameter_names)

    def at(x):
        key = np.asarray(x, dtype=float).tobytes()
        if key not in cache:
            cache.clear()
            try:
                value, gradient = p.objective_and_gradient(
                    np.asarray(x, dtype=float), scale="parameter"
                )
            except SysidError:
                value, gradient = np.inf, np.full(n, np.nan)
            cache[key] = (value, gradient)
        return cache[key]

    def hess(x):
        try:
            return p.fisher(np.asarray(x, dtype=float), scale="parameter")
        except SysidError:
            return np.full((n, n), np.nan)

    return pypesto.Objective(
        fun=lambda x: at(x)[0],
        grad=lambda x: at(x)[1],
        hess=hess,
        x_names=list(p.parameter_names),
    )


def problem(p, **kwargs):
    """A ``pypesto.Problem``: :func:`objective` with the bounds on the parameter scale;
    ``kwargs`` go to ``pypesto.Problem`` (``x_guesses`` on the parameter scale, for example)."""
    import pypesto

    lo, hi = p.bounds
    scales = p.scales

    def on_scale(v, s):
        # A log-scaled parameter without a lower bound has 0 there: -inf on its scale.
        if s != "log":
            return v
        return -np.inf if v == 0 else np.log(v)

    lb = np.array([on_scale(v, s) for v, s in zip(lo, scales)])
    ub = np.array([on_scale(v, s) for v, s in zip(hi, scales)])
    return pypesto.Problem(
        objective=objective(p), lb=lb, ub=ub, x_names=list(p.parameter_names), **kwargs
    )
