"""The Python binding's overhead: one `nll_and_gradient` call on Boehm's problem at its nominal
point against the same evaluation called from Rust, in the same process, batch by batch:

    python scripts/python/overhead.py

Each round times a batch of Python calls and then the same number of evaluations in a Rust
loop (`Problem._rust_seconds_per_evaluation`: `residuals_and_jacobian` and `nll`, what a Rust
program calls), so both see the same state of the machine. It prints the mean of each and the
median over the rounds of their ratio. criterion's `petab/nll-gradient/Boehm` (`cargo bench -p
sysid-petab --bench petab -- nll-gradient/Boehm`) times the Rust side on its own.
"""

import os
import statistics
import time

import sysid

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BOEHM = os.path.join(ROOT, "tests", "data", "petab", "Boehm_JProteomeRes2014", "Boehm_JProteomeRes2014.yaml")
BATCH = 200
ROUNDS = 20

p = sysid.Problem.from_petab(BOEHM)
z = p.to_parameter_scale(p.nominal)
end = time.perf_counter() + 0.5
while time.perf_counter() < end:
    p.nll_and_gradient(z, scale="parameter", sensitivities="forward")
python, rust = [], []
for _ in range(ROUNDS):
    start = time.perf_counter()
    for _ in range(BATCH):
        p.nll_and_gradient(z, scale="parameter", sensitivities="forward")
    python.append((time.perf_counter() - start) / BATCH * 1e3)
    rust.append(p._rust_seconds_per_evaluation(z, BATCH) * 1e3)
ratios = sorted(a / b for a, b in zip(python, rust))
print(f"nll_and_gradient on Boehm from Python: {statistics.mean(python):.3f} ms per call (batch means {min(python):.3f} to {max(python):.3f} ms)")
print(f"the same evaluation from Rust:          {statistics.mean(rust):.3f} ms per call (batch means {min(rust):.3f} to {max(rust):.3f} ms)")
print(
    f"Python / Rust, batch by batch: median {statistics.median(ratios):.4f} "
    f"(quartiles {ratios[len(ratios) // 4]:.4f} to {ratios[3 * len(ratios) // 4]:.4f})"
)
