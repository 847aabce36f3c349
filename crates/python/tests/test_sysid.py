"""Tests of the sysid Python package, run against the installed package:

    pip install ./crates/python scipy pypesto
    python -m unittest discover -s crates/python/tests -v

Every number is checked against an independent reference: AMICI's NLL at nominal, central
differences at tight tolerances, the closed form of a falling body, the command line's fit.
"""

import ast
import csv
import inspect
import json
import logging
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np

import sysid

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
PETAB = os.path.join(ROOT, "tests", "data", "petab")
BOEHM = os.path.join(PETAB, "Boehm_JProteomeRes2014", "Boehm_JProteomeRes2014.yaml")
FALLING = os.path.join(ROOT, "examples", "falling-body", "model.toml")


def cli():
    """The sysid binary `cargo build` made (CI runs these tests after it)."""
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))
    clis = [os.path.join(target, d, "sysid") for d in ("release", "debug")]
    found = [c for c in clis if os.path.exists(c)]
    if not found:
        raise AssertionError(f"no sysid binary at {' or '.join(clis)}: run `cargo build` first")
    # The newer of the two: an old release build may predate the code under test.
    return max(found, key=os.path.getmtime)


def reference_nll(problem):
    """AMICI's NLL at nominal (tests/data/petab/references.tsv)."""
    with open(os.path.join(PETAB, "references.tsv")) as f:
        for row in csv.DictReader(f, delimiter="\t"):
            if row["problem"] == problem:
                return float(row["nll"])
    raise KeyError(problem)


class Stubs(unittest.TestCase):
    def test_the_stubs_name_every_keyword_of_the_compiled_module(self):
        # The type stubs are what editors and type checkers show: each function and method
        # must take the parameters the compiled module takes, in its order.
        stub = os.path.join(os.path.dirname(sysid.__file__), "_sysid.pyi")
        with open(stub) as f:
            tree = ast.parse(f.read())
        compiled = sysid._sysid
        checked = 0

        def compare(function, actual):
            nonlocal checked
            if any(isinstance(d, ast.Name) and d.id == "property" for d in function.decorator_list):
                return
            stubbed = [a.arg for a in function.args.posonlyargs + function.args.args + function.args.kwonlyargs]
            stubbed = [a for a in stubbed if a != "self"]
            wanted = [n for n in inspect.signature(actual).parameters if n != "self"]
            self.assertEqual(stubbed, wanted, f"{function.name}: the stub against the module")
            checked += 1

        for node in tree.body:
            if isinstance(node, ast.FunctionDef):
                compare(node, getattr(compiled, node.name))
            elif isinstance(node, ast.ClassDef) and hasattr(compiled, node.name):
                cls = getattr(compiled, node.name)
                for item in node.body:
                    if isinstance(item, ast.FunctionDef):
                        compare(item, getattr(cls, item.name))
        self.assertGreaterEqual(checked, 15)


class Boehm(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.p = sysid.Problem.from_petab(BOEHM)
        # Central differences need an integration whose error is far below h²·f‴.
        cls.tight = cls.p.with_integrator(rtol=1e-12, atol=1e-14)
        lo, hi = cls.p.bounds
        z = cls.p.to_parameter_scale(cls.p.nominal) + 0.1
        cls.z = np.clip(z, np.log(lo) + 0.2, np.log(hi) - 0.2)

    def test_the_parameters_are_petabs_estimated_ones(self):
        # The six rates and the three noise scales (which sysid's fits set in closed form).
        self.assertEqual(len(self.p.parameter_names), 9)
        self.assertEqual(self.p.parameter_names[-3:], ["sd_pSTAT5A_rel", "sd_pSTAT5B_rel", "sd_rSTAT5A_rel"])
        self.assertEqual(self.p.scales, ["log"] * 9)
        lo, hi = self.p.bounds
        np.testing.assert_array_equal(lo, np.full(9, 1e-5))
        np.testing.assert_array_equal(hi, np.full(9, 1e5))

    def test_the_nll_at_nominal_is_amicis(self):
        # AMICI checks its own value to 1e-3.
        nll = self.p.nll(self.p.nominal)
        self.assertAlmostEqual(nll, reference_nll("Boehm_JProteomeRes2014"), delta=1e-3)
        # Boehm has no priors: the objective is the NLL.
        self.assertEqual(self.p.objective(self.p.nominal), nll)

    def test_the_gradient_is_the_central_differences(self):
        value, gradient = self.tight.objective_and_gradient(self.z, scale="parameter", sensitivities="forward")
        h = 1e-4
        fd = np.array(
            [
                (self.tight.objective(self.z + h * e, scale="parameter") - self.tight.objective(self.z - h * e, scale="parameter")) / (2 * h)
                for e in np.eye(len(self.z))
            ]
        )
        # h² f‴/6 and the integration's 1e-12 relative error over h: about 1e-7 relative.
        np.testing.assert_allclose(gradient, fd, rtol=2e-6, atol=1e-6 * np.abs(gradient).max())
        self.assertEqual(value, self.tight.objective(self.z, scale="parameter"))
        # Without priors the NLL's gradient is the objective's.
        np.testing.assert_array_equal(
            self.tight.nll_and_gradient(self.z, scale="parameter", sensitivities="forward")[1], gradient
        )
        # By adjoint, and by whichever of the two `auto` counts cheaper (the default): the same
        # gradient to 1e-7 of its largest component (two integrations at rtol 1e-12), the same
        # value to 1e-9; `auto` keeps its choice, so a second call is the first.
        for how in ["adjoint", "auto"]:
            other_value, other = self.tight.objective_and_gradient(self.z, scale="parameter", sensitivities=how)
            np.testing.assert_allclose(other, gradient, rtol=0, atol=1e-7 * np.abs(gradient).max())
            self.assertAlmostEqual(other_value, value, delta=1e-9 * abs(value))
        np.testing.assert_array_equal(self.tight.objective_and_gradient(self.z, scale="parameter")[1], other)
        with self.assertRaisesRegex(ValueError, "sensitivities must be"):
            self.tight.nll_and_gradient(self.z, sensitivities="backward")

    def test_the_linear_scale_is_the_chain_rule(self):
        x = self.p.to_linear_scale(self.z)
        np.testing.assert_allclose(np.log(x), self.z, rtol=1e-15)
        _, g_parameter = self.p.objective_and_gradient(self.z, scale="parameter")
        _, g_linear = self.p.objective_and_gradient(x)
        # ∂f/∂ln x = x ∂f/∂x.
        np.testing.assert_allclose(g_linear * x, g_parameter, rtol=1e-12)
        f_parameter = self.p.fisher(self.z, scale="parameter")
        f_linear = self.p.fisher(x)
        np.testing.assert_allclose(f_linear * np.outer(x, x), f_parameter, rtol=1e-12)

    def test_the_fisher_information_is_jtj_and_the_scales_own(self):
        r, jac = self.p.residuals_and_jacobian(self.z, scale="parameter")
        fisher = self.p.fisher(self.z, scale="parameter")
        k = 6
        np.testing.assert_allclose(fisher[:k, :k], jac[:, :k].T @ jac[:, :k], rtol=1e-12)
        # A normal's information about ln σ is 2 per sample: 16 samples per noise scale.
        np.testing.assert_allclose(np.diag(fisher)[k:], [32.0, 32.0, 32.0], rtol=1e-15)
        self.assertTrue(np.all(fisher[:k, k:] == 0.0))
        # The residuals' Jacobian with respect to ln s is −r on the scale's rows.
        self.assertEqual(jac.shape, (len(r), 9))
        for col in range(k, 9):
            rows = jac[:, col] != 0.0
            self.assertEqual(rows.sum(), 16)
            np.testing.assert_allclose(jac[rows, col], -r[rows], rtol=1e-15)

    def test_the_fit_is_the_command_lines(self):
        fit = self.p.fit()
        self.assertTrue(fit.converged, fit.termination)
        # The same fit from the command line (`cargo test` builds it; CI runs these tests
        # after it): the same numbers, up to the rounding of another build profile.
        out = subprocess.run([cli(), "fit", "--petab", BOEHM, "--format", "json"], capture_output=True, text=True, check=True)
        record = json.loads(out.stdout)
        self.assertAlmostEqual(fit.nll, record["nll"], delta=1e-9)
        self.assertEqual(list(fit.estimates), list(record["estimates"]))
        for name, value in record["estimates"].items():
            self.assertAlmostEqual(fit.estimates[name], value, delta=1e-6 * abs(value))
        # tests/data/petab/best_known.tsv: 138.221976.
        self.assertAlmostEqual(fit.nll, 138.221976, delta=1e-6)
        self.assertEqual(fit.parameter_names, self.p.parameter_names)
        # The fitted point's objective, evaluated afresh, is the fit's.
        self.assertAlmostEqual(self.p.objective(fit.x), fit.objective, delta=1e-6)

    def test_coarse_first_false_is_the_command_lines_no_coarse_first(self):
        # Without the coarse stage (docs/methods.md#coarse-first) the trust region integrates
        # at the problem's rtol 1e-8 throughout: Boehm from nominal takes 7 iterations
        # instead of 10 to the same minimum.
        fine = self.p.fit(coarse_first=False)
        out = subprocess.run([cli(), "fit", "--petab", BOEHM, "--no-coarse-first", "--format", "json"], capture_output=True, text=True, check=True)
        record = json.loads(out.stdout)
        self.assertTrue(fine.converged, fine.termination)
        self.assertEqual(fine.record["iterations"], record["iterations"])
        self.assertAlmostEqual(fine.nll, record["nll"], delta=1e-9)
        self.assertNotEqual(fine.record["iterations"], self.p.fit().record["iterations"])
        self.assertAlmostEqual(fine.nll, 138.221976, delta=1e-6)

    def test_a_multistart_reports_its_waterfall(self):
        fit = self.p.fit(starts=4, seed=3, max_iterations=200)
        w = fit.waterfall
        self.assertEqual(len(w["objective"]), 4)
        self.assertEqual(sorted(w["start"]), [0, 1, 2, 3])
        self.assertTrue(np.all(np.diff(w["objective"]) >= 0))
        self.assertEqual(fit.starts["count"], 4)
        self.assertEqual(fit.starts["converged"], int(w["converged"].sum()))
        self.assertEqual(fit.nll + fit.prior, w["objective"][0])
        # Where each start began and ended, and any one of them fitted again alone ends
        # where it ended among the others.
        self.assertEqual(w["x0"].shape, (4, len(fit.parameter_names)))
        self.assertEqual(w["x"].shape, (4, len(fit.parameter_names)))
        np.testing.assert_array_equal(w["x"][0], fit.x)
        row = int(np.flatnonzero(w["start"] == 2)[0])
        again = self.p.fit(start=dict(zip(fit.parameter_names, w["x0"][row])), max_iterations=200)
        self.assertEqual(again.objective, w["objective"][row])
        np.testing.assert_array_equal(again.x, w["x"][row])

    def test_progress_hears_every_iterate_and_every_start(self):
        heard = []
        fit = self.p.fit(progress=heard.append)
        self.assertTrue(fit.converged, fit.termination)
        iterations = [h["iteration"] for h in heard]
        self.assertEqual(iterations, sorted(iterations))
        self.assertEqual(sorted(set(iterations)), list(range(fit.record["iterations"] + 1)))
        # The last iterate heard of is the point returned.
        self.assertEqual(heard[-1]["objective"], fit.objective)
        self.assertFalse(heard[-1]["coarse"])
        self.assertTrue(heard[0]["coarse"], "the trust region integrates coarsely first")
        # With starts, one call as each start ends.
        ends = []
        fit = self.p.fit(starts=3, seed=3, max_iterations=50, progress=ends.append)
        self.assertEqual(sorted(e["done"] for e in ends), [1, 2, 3])
        self.assertEqual(sorted(e["start"] for e in ends), [0, 1, 2])
        by_start = {e["start"]: e for e in ends}
        w = fit.waterfall
        for start, objective, converged in zip(w["start"], w["objective"], w["converged"]):
            self.assertEqual(by_start[int(start)]["objective"], objective)
            self.assertEqual(by_start[int(start)]["converged"], bool(converged))

        # An exception in it ends its calls and is raised by the fit.
        calls = []

        def fails(d):
            calls.append(d)
            raise KeyError("stop")

        with self.assertRaises(KeyError) as caught:
            self.p.fit(progress=fails)
        self.assertEqual(len(calls), 1)
        # The fit it stopped comes with the exception: its best point, `interrupted`.
        stopped = caught.exception.result
        self.assertIsInstance(stopped, sysid.FitResult)
        self.assertEqual(stopped.record["termination_code"], "interrupted")
        self.assertLessEqual(stopped.record["iterations"], 1)
        self.assertEqual(len(stopped.x), len(self.p.parameter_names))
        if sys.version_info >= (3, 11):
            self.assertIn("this exception's .result", caught.exception.__notes__[0])
        with self.assertRaisesRegex(TypeError, "progress must be a callable"):
            self.p.fit(progress=3)

    def test_trials_hear_every_trial_step(self):
        # Checked against the fit's own record: a move per accepted trial, rho = actual /
        # predicted, and a trial taken exactly where rho >= 1/4.
        trials = []
        fit = self.p.fit(trials=trials.append)
        self.assertTrue(fit.converged, fit.termination)
        self.assertGreater(len(trials), 0)
        self.assertEqual(sum(t["accepted"] for t in trials), fit.record["iterations"])
        for t in trials:
            self.assertEqual(t["method"], fit.record["method"])
            self.assertIn(t["model"], ("gauss-newton", "augmented", "newton"))
            if t["ratio"] is None:
                self.assertFalse(t["accepted"])
                continue
            self.assertLessEqual(abs(t["ratio"] - t["actual"] / t["predicted"]), 1e-12 * abs(t["ratio"]))
            self.assertEqual(t["accepted"], t["ratio"] >= 0.25)
        with self.assertRaisesRegex(ValueError, "trials hears one fit"):
            self.p.fit(starts=2, trials=trials.append)
        with self.assertRaisesRegex(TypeError, "trials must be a callable"):
            self.p.fit(trials=3)

    def test_ctrl_c_stops_a_multistart(self):
        # KeyboardInterrupt, as Ctrl-C raises it, during 400 starts: the starts running end
        # their iteration, no other begins, and the fit raises it. Heard of only when the run
        # returned, it let every start run first, ten times the work of 40 starts; stopped,
        # the run ends in well under that (a ratio of this machine's own times, not a speed).
        import _thread
        import threading
        import time

        began = time.perf_counter()
        self.p.fit(starts=40, seed=1)
        forty = time.perf_counter() - began
        timer = threading.Timer(0.5 * forty, _thread.interrupt_main)
        began = time.perf_counter()
        timer.start()
        try:
            with self.assertRaises(KeyboardInterrupt) as caught:
                self.p.fit(starts=400, seed=1)
        finally:
            timer.cancel()
        self.assertLess(time.perf_counter() - began, 5 * forty)
        # What the run had is the exception's `result`: the starts that ended, the rest
        # counted as not begun.
        starts = caught.exception.result.record["starts"]
        self.assertTrue(starts["stopped"])
        self.assertGreater(starts["not_started"], 0)
        self.assertEqual(starts["count"] + starts["not_started"], 400)

    def test_scipy_minimises_it(self):
        from scipy.optimize import minimize

        lo, hi = self.p.bounds
        result = minimize(
            self.p.objective_and_gradient,
            self.z,
            args=("parameter",),
            jac=True,
            method="L-BFGS-B",
            bounds=list(zip(np.log(lo), np.log(hi))),
            options={"maxiter": 2000},
        )
        # L-BFGS-B's own stopping rule: within 1e-3 of the certified optimum (138.221976).
        self.assertLess(result.fun, 138.221976 + 1e-3)

    def test_pypesto_and_fides_minimise_it(self):
        # CI installs both (.ci/run); a machine without them skips, saying so.
        try:
            import fides  # noqa: F401
            import pypesto.optimize
        except ImportError as e:
            self.skipTest(f"{e.name} is not installed (pip install pypesto fides)")
        import sysid.pypesto

        problem = sysid.pypesto.problem(self.p, x_guesses=[self.z])
        self.assertEqual(problem.x_names, self.p.parameter_names)
        fun, grad, hess = problem.objective(self.z, sensi_orders=(0, 1, 2))
        self.assertEqual(fun, self.p.objective(self.z, scale="parameter"))
        np.testing.assert_array_equal(hess, self.p.fisher(self.z, scale="parameter"))
        # fides with the Fisher information as its Hessian (no quasi-Newton update): the
        # field's trust-region optimiser on sysid's objective, gradient and FIM.
        result = pypesto.optimize.minimize(
            problem,
            optimizer=pypesto.optimize.FidesOptimizer(hessian_update=None, verbose=logging.WARNING),
            n_starts=1,
            progress_bar=False,
        )
        best = result.optimize_result[0]
        np.testing.assert_array_equal(best.x0, self.z)
        self.assertLess(best.fval, 138.221976 + 1e-3)

    def test_bad_input_raises_with_the_reason(self):
        with self.assertRaisesRegex(ValueError, "x has 3 entries; the problem has 9 unknowns"):
            self.p.nll(np.ones(3))
        with self.assertRaisesRegex(ValueError, "k_phos = -1.*must be positive"):
            x = self.p.nominal.copy()
            x[5] = -1.0
            self.p.nll(x)
        with self.assertRaisesRegex(ValueError, 'scale must be "linear" or "parameter"'):
            self.p.nll(self.p.nominal, scale="log10")
        with self.assertRaisesRegex(ValueError, "unknown method|no method"):
            self.p.fit(method="newton")
        with self.assertRaisesRegex(sysid.SysidError, "nowhere.yaml"):
            sysid.Problem.from_petab(os.path.join(PETAB, "nowhere.yaml"))
        # The path once, as the command line says it (it was said twice).
        with self.assertRaises(sysid.SysidError) as missing:
            sysid.Problem.from_petab(os.path.join(PETAB, "nowhere.yaml"))
        self.assertEqual(str(missing.exception).count("nowhere.yaml"), 1, str(missing.exception))
        # A negative count is named (pyo3 alone raises OverflowError without the name).
        for keyword, message in [
            ({"starts": -1}, "starts must be at least 1, got -1"),
            ({"max_iterations": -2}, "max_iterations must be at least 0, got -2"),
            ({"max_integrations": 0}, "max_integrations must be at least 1, got 0"),
            ({"seed": -1}, r"seed must be a whole number in \[0, 2\^64\), got -1"),
        ]:
            with self.assertRaisesRegex(ValueError, message):
                self.p.fit(**keyword)
        with self.assertRaisesRegex(ValueError, "fix: unknown `k_phos`: fixed at 1e9: above its max 100000"):
            self.p.fit(fix={"k_phos": 1e9})
        with self.assertRaisesRegex(ValueError, "max_points must be at least 1, got 0"):
            self.p.profile(only=["k_phos"], max_points=0)
        with self.assertRaisesRegex(TypeError, "argument 'x'"):
            self.p.nll(np.ones((2, 9)))
        # What was given, not the Rust type it could not become (`PyArray<T, D>`).
        for x, got in [
            (np.ones((1, 9)), r"got a 2-D array of shape \(1, 9\)"),
            (3.0, "got a single float"),
            (None, "got None"),
            ("abc", "got a str that is not numbers"),
            # What numpy would convert quietly: None to NaN, a complex number to its real
            # part (with a warning only).
            ([1.0, None] + [1.0] * 7, "got a list whose entry 1 is None"),
            (np.ones(9) * (1 + 1j), "got a ndarray of complex numbers"),
            ([1.0 + 0j] * 9, "got a list of complex numbers"),
            ([[1.0], [1.0, 2.0]], "got a list that numpy makes no array of"),
            # Numbers written as text, dates, and masked entries are no point either (numpy
            # read "1.0" as 1.0 and a date as its days since 1970; a mask was dropped).
            (["1.0"] * 9, "got a list of text, not numbers"),
            (np.array(["1.0"] * 9, dtype=object), "got a ndarray of text, not numbers"),
            (np.array([b"1"] * 9), "got a ndarray of text, not numbers"),
            (np.array(["2020-01-01"] * 9, dtype="datetime64[D]"), "got a ndarray of dates or times"),
            (np.ma.array(np.ones(9), mask=[True] + [False] * 8), "got a MaskedArray with masked entries"),
        ]:
            with self.assertRaisesRegex(TypeError, "expected a 1-D array of numbers.*" + got):
                self.p.nll(x)
        with self.assertRaisesRegex(TypeError, "experiment is an index or a name, got a float: 0.5"):
            self.p.simulate([1.0], experiment=0.5)
        with self.assertRaisesRegex(TypeError, "experiment is an index or a name, got a bool: True"):
            self.p.simulate([1.0], experiment=True)
        with self.assertRaisesRegex(ValueError, "experiment 1180591620717411303424: the problem has 1 experiments"):
            self.p.simulate([1.0], experiment=2**70)
        with self.assertRaisesRegex(TypeError, r"only takes a list of names, got the name 'k_phos': write only=\['k_phos'\]"):
            self.p.profile(only="k_phos")
        with self.assertRaisesRegex(ValueError, "experiment -1: the problem has 1 experiments"):
            self.p.simulate([1.0], experiment=-1)
        # A noise scale of 0 (its ln far below any bound) names the residual it made infinite.
        with self.assertRaisesRegex(sysid.SysidError, "the residual of the observable `pSTAT5A_rel` of experiment"):
            self.p.nll(np.full(9, -800.0), scale="parameter")
        # A noise scale near 0 whose residual's square overflows: nll returned inf.
        x = np.array(self.p.nominal)
        x[self.p.parameter_names.index("sd_pSTAT5A_rel")] = 1e-300
        for f in (self.p.nll, self.p.objective, self.p.nll_and_gradient):
            with self.assertRaisesRegex(sysid.SysidError, "the square of the residual of the observable `pSTAT5A_rel`"):
                f(x)

    def test_anything_numpy_makes_a_vector_of_is_a_vector(self):
        # The stubs promise array-likes: a list, a tuple, integers, a matrix's column (not
        # contiguous) are the array they stand for; they raised TypeError.
        x = self.p.nominal
        nll = self.p.nll(x)
        self.assertEqual(self.p.nll(list(x)), nll)
        self.assertEqual(self.p.nll(tuple(x)), nll)
        self.assertEqual(self.p.nll(np.column_stack([x, x])[:, 1]), nll)
        ones = self.p.nll(np.ones(9))
        self.assertEqual(self.p.nll([1] * 9), ones)
        times = [0.0, 10.0, 20.0]
        self.assertEqual(
            {k: list(v) for k, v in self.p.simulate(times).items()},
            {k: list(v) for k, v in self.p.simulate(np.array(times), x=x).items()},
        )
        np.testing.assert_array_equal(self.p.to_parameter_scale(list(x)), self.p.to_parameter_scale(x))


class Readme(unittest.TestCase):
    def test_the_readmes_example_runs_as_written(self):
        with open(os.path.join(ROOT, "README.md")) as f:
            text = f.read()
        blocks = [b.split("```", 1)[0] for b in text.split("```python\n")[1:]]
        self.assertEqual(len(blocks), 1, "one Python example in the README")
        self.assertLessEqual(len(blocks[0].strip().splitlines()), 12)
        cwd = os.getcwd()
        try:
            os.chdir(ROOT)
            exec(compile(blocks[0], "README.md", "exec"), {})
        finally:
            os.chdir(cwd)


class FallingBody(unittest.TestCase):
    """Goodman's falling body (examples/falling-body): y = y0 + v0 t + g t²/2."""

    def test_the_fit_is_the_papers(self):
        p = sysid.Problem.from_model(FALLING)
        self.assertEqual(p.parameter_names, ["y", "v", "g"])
        self.assertEqual(p.scales, ["lin"] * 3)
        fit = p.fit(method="goodman")
        self.assertTrue(fit.converged)
        np.testing.assert_allclose(fit.x, [-0.25, -0.25, 32.5], rtol=1e-10)

    def test_simulate_is_the_closed_form(self):
        p = sysid.Problem.from_model(FALLING)
        t = np.linspace(0.0, 3.0, 7)
        x = np.array([-0.25, -0.25, 32.5])
        states = p.simulate(t, x)
        self.assertEqual(list(states), ["y", "v"])
        np.testing.assert_allclose(states["y"], -0.25 - 0.25 * t + 16.25 * t**2, rtol=1e-8)
        np.testing.assert_allclose(states["v"], -0.25 + 32.5 * t, rtol=1e-8)

    def test_the_profiles_are_the_closed_form(self):
        # The model is linear in (y0, v0, g) and σ = 1: each profile is the parabola
        # ΔNLL = (θ − θ̂)²/(2 C_ii), C = (JᵀJ)⁻¹, which crosses the threshold at
        # θ̂ ± √(2·threshold·C_ii).
        p = sysid.Problem.from_model(FALLING)
        result = p.profile()
        self.assertTrue(result.from_certified_optimum)
        self.assertAlmostEqual(result.threshold, 3.841458820694124 / 2, delta=1e-15)
        t = np.arange(4.0)
        jac = np.column_stack([np.ones(4), t, t**2 / 2])
        cov = np.linalg.inv(jac.T @ jac)
        for i, name in enumerate(p.parameter_names):
            profile = result.profiles[name]
            half = np.sqrt(2 * result.threshold * cov[i, i])
            expected = (result.optimum.x[i] - half, result.optimum.x[i] + half)
            np.testing.assert_allclose(profile.interval, expected, rtol=1e-10, atol=1e-10)
            self.assertEqual(profile.label, "identifiable")
            self.assertTrue(np.all(np.diff(profile.values) > 0))
            self.assertEqual(profile.estimates.shape, (len(profile.values), 3))
        # The progress: the optimum's iterates, then each profile as it is traced.
        heard = []
        only = p.profile(only=["g"], progress=heard.append)
        self.assertEqual(list(only.profiles), ["g"])
        stages = [h["stage"] for h in heard]
        fits = stages.count("optimum")
        points = stages.count("point")
        self.assertEqual(stages, ["optimum"] * fits + ["point"] * points + ["traced"])
        # Every point of the profile was told (the optimum is its one point not fitted;
        # a fit the step control refits closer is told and not kept), with its rise from
        # the optimum's objective.
        told = [(h["value"], h["objective"], h["rise"]) for h in heard[fits:-1]]
        g = only.profiles["g"]
        kept = list(zip(g.values, g.nll))
        kept.remove((only.optimum.estimates["g"], only.optimum.objective))
        self.assertLessEqual(set(kept), {(v, nll) for v, nll, _ in told})
        for _, nll, rise in told:
            self.assertEqual(rise, nll - only.optimum.objective)
            self.assertGreater(rise, 0)
        heard = heard[:fits] + heard[-1:]
        # (the iterate where the coarse stage ends is told again at the fine tolerances)
        iterations = [h["iteration"] for h in heard[:-1]]
        self.assertEqual(iterations, sorted(iterations))
        self.assertEqual(set(iterations), set(range(only.optimum.record["iterations"] + 1)))
        self.assertEqual(heard[-2]["objective"], only.optimum.objective)
        self.assertEqual(heard[-1], {"stage": "traced", "unknown": "g", "done": 1, "total": 1})
        traced = []
        p.profile(progress=lambda d: traced.append(d) if d["stage"] == "traced" else None)
        self.assertEqual(sorted(d["done"] for d in traced), [1, 2, 3])
        self.assertEqual(sorted(d["unknown"] for d in traced), sorted(p.parameter_names))

        def fails(d):
            raise KeyError("stop")

        # Stopped while the optimum is fitted, the exception holds that fit so far; stopped
        # at the first profile traced, the profiles, each done or `stopped` with its points.
        with self.assertRaises(KeyError) as caught:
            p.profile(progress=fails)
        self.assertEqual(caught.exception.result.record["termination_code"], "interrupted")

        def fails_when_traced(d):
            if d["stage"] == "traced":
                raise KeyError("stop")

        with self.assertRaises(KeyError) as caught:
            p.profile(progress=fails_when_traced)
        stopped = caught.exception.result
        self.assertIsInstance(stopped, sysid.ProfileResult)
        self.assertTrue(stopped.from_certified_optimum)
        self.assertEqual(sorted(stopped.profiles), sorted(p.parameter_names))
        labels = [profile.label for profile in stopped.profiles.values()]
        self.assertIn("identifiable", labels)
        self.assertLessEqual(set(labels), {"identifiable", "stopped"})
        with self.assertRaisesRegex(TypeError, "progress must be a callable"):
            p.profile(progress=3)
        with self.assertRaisesRegex(ValueError, 'only: "h" is not a profiled unknown'):
            p.profile(only=["h"])

    def test_the_residuals_jacobian_is_the_closed_forms(self):
        # r = y(t) − b at t = 0, 1, 2, 3: ∂r/∂(y0, v0, g) = (1, t, t²/2).
        p = sysid.Problem.from_model(FALLING)
        _, jac = p.residuals_and_jacobian(p.nominal)
        t = np.arange(4.0)
        np.testing.assert_allclose(jac, np.column_stack([np.ones(4), t, t**2 / 2]), atol=1e-9)


class Probed(unittest.TestCase):
    """What a probe of the package found: each once returned a false number, aborted the
    interpreter or ignored what it was given."""

    def test_a_count_too_large_is_refused_by_name(self):
        p = sysid.Problem.from_model(FALLING)
        # 10**12 starts asked for 8 TB and aborted the process.
        with self.assertRaisesRegex(ValueError, "starts must be at most 1000000, got 1000000000000"):
            p.fit(starts=10**12)
        # 2**63 raised OverflowError without the argument's name.
        with self.assertRaisesRegex(ValueError, "max_iterations must be at most"):
            p.fit(max_iterations=2**64)

    def test_a_start_no_fit_can_use_raises_once_said(self):
        path = os.path.join(self.scratch(), "blow.toml")
        with open(path, "w") as f:
            f.write('states = ["x"]\nparameters = ["k"]\n[equations]\nx = "k * x * x"\n'
                    '[initial]\nx = 1.0\n[unknowns]\nk = { guess = 3, min = 2, max = 100, log = true }\n'
                    '[data]\nfile = "blow.csv"\n')
        with open(os.path.join(self.scratch(), "blow.csv"), "w") as f:
            f.write("t,x\n0,1\n1,2\n2,3\n3,4\n")
        p = sysid.Problem.from_model(path)
        for call in (p.fit, p.profile):
            with self.assertRaises(sysid.SysidError) as raised:
                call()
            message = str(raised.exception)
            # The profile returned NaN everywhere; the fit said "the start cannot be used" twice.
            self.assertTrue(message.startswith("the starting guess cannot be used (k = 3"), message)
            self.assertIn("): the solution blows up: state x reaches", message)
            self.assertEqual(message.count("cannot be used"), 1, message)

    def test_keywords_are_not_ignored(self):
        p = sysid.Problem.from_model(FALLING)
        with self.assertRaisesRegex(ValueError, 'sampling must be "uniform" or "latin-hypercube"'):
            p.fit(sampling="bogus")
        with self.assertRaisesRegex(ValueError, "include_nominal=False is for a multistart"):
            p.fit(include_nominal=False)
        with self.assertRaisesRegex(ValueError, "start sets the first start of the multistart"):
            p.fit(starts=3, include_nominal=False, start={"g": 30.0})
        with self.assertRaisesRegex(ValueError, "max_seconds must be a finite non-negative number"):
            p.fit(max_seconds=float("inf"))

    def test_rk4_takes_its_fixed_step(self):
        # y = y0 + v0 t + g t²/2 is a cubic-free polynomial: RK4 integrates it exactly.
        p = sysid.Problem.from_model(FALLING)
        rk4 = p.with_integrator(scheme="rk4", fixed_step=0.5)
        x = np.array([-0.25, -0.25, 32.5])
        self.assertLessEqual(abs(rk4.objective(x) - p.objective(x)), 1e-12)
        with self.assertRaisesRegex(ValueError, "fixed_step is needed by RK4"):
            p.with_integrator(scheme="rk4")

    def test_a_log_scaled_parameter_is_positive_in_its_bounds(self):
        p = sysid.Problem.from_model(os.path.join(ROOT, "examples", "kinetics", "model.toml"))
        lo, hi = p.bounds
        self.assertEqual(list(lo), [0.0, 0.0])
        self.assertEqual(list(hi), [np.inf, np.inf])
        self.assertIn("2 parameters (2 unknowns, 0 noise scales), 1 experiment", repr(p))

    def test_the_fisher_information_is_never_nan(self):
        p = sysid.Problem.from_petab(BOEHM)
        x = np.array(p.nominal)
        x[0] = 1e-200
        with self.assertRaisesRegex(ValueError, "cannot be had on the linear scale here"):
            p.fisher(x)
        self.assertTrue(np.all(np.isfinite(p.fisher(p.to_parameter_scale(x), scale="parameter"))))

    def test_pypesto_hears_a_point_that_cannot_be_integrated_as_inf(self):
        # pyPESTO's convention (AMICI's objective's): a failed simulation is fval inf with a
        # NaN gradient and Hessian, so that its optimisers back off and a start goes on; a
        # SysidError raised through it ended the start. x′ = k x², x(0) = 1 blows up at t = 1/k.
        try:
            import pypesto  # noqa: F401
        except ImportError as e:
            self.skipTest(f"{e.name} is not installed (pip install pypesto)")
        import sysid.pypesto

        folder = self.scratch()
        with open(os.path.join(folder, "bu.csv"), "w") as f:
            f.write("t,x\n0,1\n0.5,1.06\n1,1.11\n1.5,1.18\n2,1.25\n")
        model = os.path.join(folder, "blowup.toml")
        with open(model, "w") as f:
            f.write(
                'states = ["x"]\nparameters = ["k"]\n[equations]\nx = "k * x * x"\n'
                "[initial]\nx = 1.0\n[unknowns]\n"
                "k = { guess = 0.1, min = 0.01, max = 10.0, log = true }\n"
                '[data]\nfile = "bu.csv"\n'
            )
        p = sysid.Problem.from_model(model)
        objective = sysid.pypesto.problem(p).objective
        blows_up = np.log([10.0])
        with self.assertRaises(sysid.SysidError):
            p.objective(blows_up, scale="parameter")
        fun, grad, hess = objective(blows_up, sensi_orders=(0, 1, 2))
        self.assertEqual(fun, np.inf)
        self.assertTrue(np.all(np.isnan(grad)) and np.all(np.isnan(hess)))
        self.assertEqual(grad.shape, (1,))
        self.assertEqual(hess.shape, (1, 1))
        fine = np.log([0.1])
        fun, grad = objective(fine, sensi_orders=(0, 1))
        self.assertEqual(fun, p.objective(fine, scale="parameter"))
        self.assertTrue(np.all(np.isfinite(grad)))

    def scratch(self):
        if not hasattr(self, "_scratch"):
            self._scratch = tempfile.mkdtemp(prefix="sysid-python-")
        return self._scratch


class Catalogue(unittest.TestCase):
    """The benchmark catalogue's systems, by the names `sysid systems` prints."""

    def test_the_falling_body_is_the_papers(self):
        p = sysid.Problem.from_catalogue("falling-body")
        self.assertEqual(p.name, "falling-body")
        fit = p.fit(method="goodman")
        self.assertTrue(fit.converged, fit.termination)
        # Goodman (1966): y0 = −0.25, v0 = −0.25, g = 32.5, exact in the model's quadratic.
        np.testing.assert_allclose(fit.x, [-0.25, -0.25, 32.5], rtol=1e-10)

    def test_a_profile_that_finds_a_lower_point_says_so(self):
        # With two iterations a fit stops short of Lotka–Volterra's minimum, so the profile
        # of `a` finds lower points: each is told as stage "better" (its objective below
        # the optimum's it replaced) and kept in `better_optimum_found`, in order, and the
        # optimum returned is the fit from the last of them.
        p = sysid.Problem.from_catalogue("lotka-volterra", seed=3)
        heard = []
        result = p.profile(max_iterations=2, only=["a"], progress=heard.append)
        better = [h for h in heard if h["stage"] == "better"]
        found = result.record["better_optimum_found"]
        self.assertGreater(len(better), 0)
        self.assertEqual([b["objective"] for b in better], [f["nll"] for f in found])
        for b in better:
            self.assertEqual(set(b), {"stage", "objective", "was"})
            self.assertLess(b["objective"], b["was"])
        self.assertFalse(result.from_certified_optimum)
        self.assertLessEqual(result.optimum.record["nll"], better[-1]["objective"])
        # With one iteration they keep finding lower points, and the profile gives up with
        # the reason after telling each.
        heard = []
        with self.assertRaisesRegex(sysid.SysidError, "found a better optimum 5 times over"):
            p.profile(max_iterations=1, only=["a"], progress=heard.append)
        self.assertEqual(sum(h["stage"] == "better" for h in heard), 5)

    def test_synthetic_data_are_the_command_lines(self):
        # Lotka–Volterra with data drawn with seed 3: the command line's `--seed 3` draws the
        # same data, so the two fits agree.
        p = sysid.Problem.from_catalogue("lotka-volterra", seed=3)
        fit = p.fit()
        self.assertTrue(fit.converged, fit.termination)
        out = subprocess.run(
            [cli(), "fit", "--system", "lotka-volterra", "--seed", "3", "--format", "json"],
            capture_output=True, text=True, check=True,
        )
        record = json.loads(out.stdout)
        self.assertEqual(list(fit.estimates), list(record["estimates"]))
        for name, value in record["estimates"].items():
            self.assertAlmostEqual(fit.estimates[name], value, delta=1e-8 * abs(value))
        # Another seed draws other data.
        other = sysid.Problem.from_catalogue("lotka-volterra", seed=4)
        self.assertNotEqual(other.nll(p.nominal), p.nll(p.nominal))

    def test_the_gradient_is_the_central_differences(self):
        p = sysid.Problem.from_catalogue("lotka-volterra", seed=3).with_integrator(rtol=1e-12, atol=1e-14)
        x = p.nominal
        _, gradient = p.nll_and_gradient(x)
        h = 1e-5
        fd = np.array([(p.nll(x + h * e) - p.nll(x - h * e)) / (2 * h) for e in np.eye(len(x))])
        np.testing.assert_allclose(gradient, fd, rtol=1e-6)

    def test_every_scheme_gives_the_same_nll_and_gradient_at_tight_tolerances(self):
        # Lotka–Volterra is not stiff: the explicit schemes and the automatic choice agree to
        # their tolerances, and an unknown scheme is refused with the list of schemes.
        p = sysid.Problem.from_catalogue("lotka-volterra", seed=3)
        x = p.nominal
        reference = p.with_integrator(rtol=1e-12, atol=1e-14, scheme="dopri5").nll_and_gradient(x)
        for scheme in ["dop853", "auto", "rodas5p"]:
            nll, gradient = p.with_integrator(rtol=1e-12, atol=1e-14, scheme=scheme).nll_and_gradient(x)
            self.assertAlmostEqual(nll, reference[0], delta=1e-9 * abs(reference[0]), msg=scheme)
            np.testing.assert_allclose(gradient, reference[1], rtol=1e-7, err_msg=scheme)
        with self.assertRaisesRegex(ValueError, r"unknown scheme \"euler\" \(schemes: dopri5, dop853, "):
            p.with_integrator(scheme="euler")

    def test_bad_names_and_records_raise_with_the_reason(self):
        with self.assertRaisesRegex(ValueError, r'unknown system "nope" \(systems: falling-body, '):
            sysid.Problem.from_catalogue("nope")
        continuous = sysid.Problem.from_catalogue("falling-body-continuous")
        with self.assertRaisesRegex(sysid.SysidError, "continuous record: it has no likelihood"):
            continuous.nll(continuous.nominal)


if __name__ == "__main__":
    unittest.main()
