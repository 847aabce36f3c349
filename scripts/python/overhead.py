"""The Python binding's overhead: one `nll_and_gradient` call on Boehm's problem at its nominal
point, timed as criterion times the same evaluation from Rust (`cargo bench -p sysid-petab --bench
petab -- nll-gradient/Boehm`): the mean over batches after a warm-up, with the spread of the
batches' means. Run it beside the bench, one process at a time:

    python scripts/python/overhead.py
"""

import os
import statistics
import time

import sysid

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BOEHM = os.path.join(ROOT, "tests", "data", "petab", "Boehm_JProteomeRes2014", "Boehm_JProteomeRes2014.yaml")

p = sysid.Problem.from_petab(BOEHM)
z = p.to_parameter_scale(p.nominal)
end = time.perf_counter() + 0.5
while time.perf_counter() < end:
    p.nll_and_gradient(z, scale="parameter")
means = []
for _ in range(10):
    start = time.perf_counter()
    for _ in range(220):
        p.nll_and_gradient(z, scale="parameter")
    means.append((time.perf_counter() - start) / 220 * 1e3)
means.sort()
print(f"nll_and_gradient on Boehm: {statistics.mean(means):.3f} ms per call (batch means {means[0]:.3f} to {means[-1]:.3f} ms)")
