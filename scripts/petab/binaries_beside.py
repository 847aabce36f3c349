"""Two (or more) sysid binaries side by side: the NLL + gradient at nominal of each PEtab
problem, timed by each binary in turn, one thread, pinned to one core, interleaved so that the
machine's drift falls on all alike.

    python3 scripts/petab/binaries_beside.py BEFORE,AFTER DIR NAME[,NAME...] [ROUNDS] [CORE]

BEFORE and AFTER are paths to sysid binaries (copies of target/release/sysid built at two
commits); DIR is a folder of PEtab problems (DIR/NAME/NAME.yaml or DIR/NAME/problem.yaml),
e.g. a clone's Benchmark-Models. For each problem every binary runs `evaluate --gradient
--repeat N --no-integration-error` (N chosen so that a run takes about 1.5 s) ROUNDS times
(default 3) on core CORE (default 0) with RAYON_NUM_THREADS=1. Prints per problem each
binary's fastest median time in ms, the first's over the last's, and the difference of their
NLLs (the last's minus the first's).
"""
import json
import os
import subprocess
import sys


def problem_yaml(folder, name):
    for candidate in (f"{name}.yaml", "problem.yaml"):
        path = os.path.join(folder, name, candidate)
        if os.path.exists(path):
            return path
    sys.exit(f"{folder}/{name}: no {name}.yaml or problem.yaml")


def evaluate(binary, yaml, repeat, core):
    run = subprocess.run(
        ["taskset", "-c", core, binary, "evaluate", "--petab", yaml, "--gradient",
         "--repeat", str(repeat), "--no-integration-error", "--format", "json"],
        capture_output=True, text=True, env={**os.environ, "RAYON_NUM_THREADS": "1"})
    if run.returncode != 0:
        sys.exit(f"{binary} on {yaml}: {run.stderr.strip()[:300]}")
    return json.loads(run.stdout)


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    binaries = sys.argv[1].split(",")
    folder, names = sys.argv[2], sys.argv[3].split(",")
    rounds = int(sys.argv[4]) if len(sys.argv) > 4 else 3
    core = sys.argv[5] if len(sys.argv) > 5 else "0"
    for name in names:
        yaml = problem_yaml(folder, name)
        ms = evaluate(binaries[0], yaml, 1, core)["ms_per_evaluation"]
        repeat = max(3, min(300, int(1500 / max(ms, 1e-3))))
        times = {b: [] for b in binaries}
        nll = {}
        for _ in range(rounds):
            for b in binaries:
                d = evaluate(b, yaml, repeat, core)
                times[b].append(d["ms_per_evaluation"])
                nll[b] = d["nll"]
        best = [min(times[b]) for b in binaries]
        print(f"{name:36} " + "  ".join(f"{t:9.3f}" for t in best)
              + f"   ratio {best[0] / best[-1]:.3f}  dNLL {nll[binaries[-1]] - nll[binaries[0]]:.1e}",
              flush=True)


if __name__ == "__main__":
    main()
