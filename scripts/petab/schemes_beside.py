"""One sysid binary, two integrators side by side: the NLL + gradient at nominal of each PEtab
problem with the default integrator (`auto`) and with another (default `bdf`), one thread.

    python3 scripts/petab/schemes_beside.py SYSID DIR NAME[,NAME...] [SCHEME] [REPEAT]

DIR is a folder of PEtab problems (DIR/NAME/NAME.yaml or DIR/NAME/problem.yaml). For each
problem it runs `sysid evaluate --petab P --gradient --no-integration-error --repeat REPEAT
--format json` (REPEAT default 5) without and with `--integrator SCHEME`, and prints the two
NLLs' difference, the
largest difference of the gradients over the largest entry, both median times, their
ratio, and the steps, rejected steps and factorisations of each. A problem that fails is
printed with the error's last line. Pin it to a core (`taskset -c 1`) and run nothing else
there: the times are medians of one sitting.
"""
import json
import os
import subprocess
import sys


def run(binary, yaml, scheme, repeat):
    command = [binary, "evaluate", "--petab", yaml, "--gradient", "--no-integration-error",
               "--repeat", str(repeat), "--format", "json"]
    if scheme:
        command += ["--integrator", scheme]
    done = subprocess.run(command, capture_output=True, text=True,
                          env=dict(os.environ, RAYON_NUM_THREADS="1"))
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines()
        return None, lines[-1] if lines else f"exit {done.returncode}"
    return json.loads(done.stdout), None


def main():
    binary, folder, names = sys.argv[1], sys.argv[2], sys.argv[3].split(",")
    scheme = sys.argv[4] if len(sys.argv) > 4 else "bdf"
    repeat = int(sys.argv[5]) if len(sys.argv) > 5 else 5
    for name in names:
        yaml = os.path.join(folder, name, f"{name}.yaml")
        if not os.path.exists(yaml):
            yaml = os.path.join(folder, name, "problem.yaml")
        (a, error_a), (b, error_b) = run(binary, yaml, None, repeat), run(binary, yaml, scheme, repeat)
        if a is None or b is None:
            print(f"{name:40s} auto: {error_a or 'ok'} | {scheme}: {error_b or 'ok'}", flush=True)
            continue
        ga, gb = a["gradient"], b["gradient"]
        largest = max(abs(v) for v in ga.values()) or 1.0
        apart = max(abs(ga[k] - gb[k]) for k in ga) / largest
        ca, cb = a["counts"], b["counts"]
        print(f"{name:40s} NLL {b['nll'] - a['nll']:+.1e}  gradient {apart:.1e}  "
              f"auto {a['ms_per_evaluation']:.3f} ms  {scheme} {b['ms_per_evaluation']:.3f} ms  "
              f"{a['ms_per_evaluation'] / b['ms_per_evaluation']:.2f}x  "
              f"steps {ca['steps']}/{cb['steps']}  rejected {ca['rejected_steps']}/{cb['rejected_steps']}  "
              f"factorisations {ca['jacobians']}/{cb['jacobians']}", flush=True)


if __name__ == "__main__":
    main()
