"""The gradient of `sysid evaluate --gradient` against central differences of its NLL.

    cargo build --release -p sysid-cli
    python3 scripts/petab/gradient_check.py tests/data/petab [NAME ...] [--sample N] [--part K/M]

With `--sample N`, only 2N parameters of each problem are checked: the N whose gradient moves
the NLL most per relative step (|∂NLL/∂v·v|), and N others drawn at random (seed 0), for
problems whose evaluations take seconds (Lang: 294 parameters). With `--part K/M`, the K-th
of M parts of the parameters in the order `evaluate` lists them (parameter i is in part
i mod M + 1): the M parts together are every parameter, each run in a sitting of its own.

For every problem (each folder's NAME.yaml), at the nominal values and rtol 1e-10,
atol 1e-14: each parameter is moved by ±1e-4 of its value (±1e-6 where it is 0) with
`--set`, and the central difference of the NLL is compared with the forward-sensitivity
gradient, both as the change of the NLL per step. Where they disagree, steps of 1e-5 and then
1e-6 are tried (an NLL that bends within the step: Borghans' oscillations). Within a step of
a bound, a parameter cannot move past it (the value is held on the bound), so there the
difference is one-sided, inwards. A parameter passes when the two agree to 1e-3 of the
larger, or to 0.1 times the relative step in absolute terms (1e-5 at steps of 1e-4). At
rtol 1e-10 the NLL's own noise is about 1e-9, far below that.
Prints one line per problem and the parameters that do not agree. Only the Python standard
library is needed.
"""

import json
import os
import random
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SYSID = os.environ.get("SYSID", os.path.join(ROOT, "target", "release", "sysid"))
TOLERANCES = ["--rtol", "1e-10", "--atol", "1e-14"]


def evaluate(yaml, *extra):
    out = subprocess.run(
        [SYSID, "evaluate", "--petab", yaml, "--format", "json", "--no-integration-error",
         *TOLERANCES, *extra],
        capture_output=True, text=True,
    )
    if out.returncode != 0:
        raise RuntimeError(out.stderr.strip().splitlines()[-1])
    return json.loads(out.stdout)


def compare(yaml, name, value, step, base, at):
    """The gap between the central difference of the NLL over ±step and the gradient's
    change over a step; one-sided, inwards, within a step of a bound (where the value is held
    on the bound, so that half a step past it gives the same NLL as a whole one)."""
    up = evaluate(yaml, "--set", f"{name}={value + step!r}")["nll"]
    down = evaluate(yaml, "--set", f"{name}={value - step!r}")["nll"]
    numeric = (up - down) / 2.0
    analytic = at["gradient"][name] * step
    if abs(numeric - analytic) > 1e-3 * max(abs(numeric), abs(analytic)):
        if evaluate(yaml, "--set", f"{name}={value + step / 2!r}")["nll"] == up:
            numeric = base - down
        elif evaluate(yaml, "--set", f"{name}={value - step / 2!r}")["nll"] == down:
            numeric = up - base
    return abs(numeric - analytic), numeric, analytic


def sample(at, n):
    """The n parameters of the largest |∂NLL/∂v·v|, then n others drawn with seed 0."""
    names = list(at["parameters"])
    if n is None or 2 * n >= len(names):
        return names
    size = lambda k: abs(at["gradient"][k] * at["parameters"][k])  # noqa: E731
    largest = sorted(names, key=size, reverse=True)[:n]
    rest = [k for k in names if k not in largest]
    return largest + random.Random(0).sample(rest, n)


def check(yaml, n=None, part=None):
    at = evaluate(yaml, "--gradient", "--sensitivities", "forward")
    base = evaluate(yaml)["nll"]
    failures = []
    worst = 0.0
    chosen = sample(at, n)
    if part is not None:
        k, m = part
        chosen = [name for i, name in enumerate(chosen) if i % m == k - 1]
    for name in chosen:
        value = at["parameters"][name]
        # A model whose NLL bends within 1e-4 of a value (Borghans' oscillations) is checked
        # again at steps of 1e-5 and 1e-6.
        for relative in (1e-4, 1e-5, 1e-6):
            step = relative * abs(value) if value != 0 else relative * 1e-2
            try:
                gap, numeric, analytic = compare(yaml, name, value, step, base, at)
            except RuntimeError as e:
                result = f"{name}: a step of {step:.3e} cannot be evaluated: {e}"
                continue
            result = None
            if gap > 1e-3 * max(abs(numeric), abs(analytic)) and gap > 0.1 * relative:
                result = f"{name}: analytic {analytic:.6e}, differences {numeric:.6e} per step {step:.3e}"
                continue
            worst = max(worst, gap / max(abs(numeric), abs(analytic), 1e-2))
            break
        if result:
            failures.append(result)
    return len(chosen), worst, failures


def main(root, names, n=None, part=None):
    names = names or sorted(d for d in os.listdir(root) if os.path.isdir(os.path.join(root, d)))
    bad = 0
    for name in names:
        yaml = os.path.join(root, name, f"{name}.yaml")
        try:
            count, worst, failures = check(yaml, n, part)
        except (RuntimeError, ValueError) as e:
            print(f"{name}: cannot be evaluated: {e}", flush=True)
            bad += 1
            continue
        status = "agrees" if not failures else f"{len(failures)} disagree"
        print(f"{name}: {count} parameters, {status} (largest relative gap {worst:.1e})", flush=True)
        for f in failures:
            print(f"    {f}")
        bad += bool(failures)
    print(f"{len(names) - bad} of {len(names)} problems' gradients agree with central differences")


if __name__ == "__main__":
    args = sys.argv[2:]
    n = None
    if "--sample" in args:
        i = args.index("--sample")
        n = int(args[i + 1])
        args = args[:i] + args[i + 2:]
    part = None
    if "--part" in args:
        i = args.index("--part")
        k, m = (int(v) for v in args[i + 1].split("/"))
        if not 1 <= k <= m:
            sys.exit(f"--part {args[i + 1]}: K/M with 1 ≤ K ≤ M")
        part = (k, m)
        args = args[:i] + args[i + 2:]
    main(sys.argv[1], args, n, part)
