"""sysid: identify ODE models from data.

A :class:`Problem` is a PEtab problem or a sysid model file, imported and compiled once::

    import sysid
    p = sysid.Problem.from_petab("Boehm_JProteomeRes2014.yaml")
    value, gradient = p.nll_and_gradient(p.nominal)
    fit = p.fit(starts=20)
    print(fit.nll, fit.converged, fit.estimates)

Points are numpy arrays in the order of ``p.parameter_names``. Every evaluation takes
``scale="linear"`` (the parameters' values, the default) or ``scale="parameter"``, sysid's
estimation coordinates: the natural logarithm of the value for a log-scaled unknown (PEtab's
``log`` and ``log10`` both; the optimum and the NLL do not depend on the base), the value
itself otherwise (``p.scales`` says which). Gradients and the Fisher information are with
respect to the point on the scale it is given on.

The objective of the fits is the negative log-likelihood plus, where the problem has priors,
the priors' negative log-density (what pyPESTO minimises): :meth:`Problem.objective`.
:meth:`Problem.nll` is the likelihood alone, as the fit JSON's ``nll``.

Bad input raises ``ValueError``; what the model or a method cannot do (a point where the model
cannot be integrated, a file that cannot be read) raises :class:`SysidError`, with the
message the command line prints. The GIL is released while the model is integrated.
"""

from ._sysid import Problem, SysidError, methods
from ._result import FitResult, Profile, ProfileResult

__all__ = ["Problem", "FitResult", "Profile", "ProfileResult", "SysidError", "methods"]
