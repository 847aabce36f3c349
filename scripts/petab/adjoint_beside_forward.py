"""NLL + gradient at nominal by forward sensitivities, by adjoints and by the automatic choice
between them (each experiment by whichever did less work at its first gradient), one thread each.

    python3 scripts/petab/adjoint_beside_forward.py REPEAT DIR NAME [NAME ...]

DIR is a folder of PEtab problems (DIR/NAME/NAME.yaml), e.g. a clone's Benchmark-Models;
SYSID is the binary (default target/release/sysid). Prints per problem the NLL of each,
the largest gradient difference relative to the largest component, and the median
milliseconds of each (`evaluate --repeat REPEAT`; `auto`'s first evaluation, which computes both ways, is not timed),
with how many experiments `auto` took by adjoint.
"""
import json
import os
import subprocess
import sys

SYSID = os.environ.get("SYSID", "target/release/sysid")
rep, B = sys.argv[1], sys.argv[2]
for P in sys.argv[3:]:
    out = {}
    for h in ["forward", "adjoint", "auto"]:
        r = subprocess.run(
            [SYSID, "evaluate", "--petab", f"{B}/{P}/{P}.yaml", "--gradient",
             "--sensitivities", h, "--repeat", rep, "--no-integration-error", "--format", "json"],
            capture_output=True, text=True, env={**os.environ, "RAYON_NUM_THREADS": "1"})
        if r.returncode != 0:
            out[h] = None
            print(P, h, "failed", r.stderr.strip()[:300])
            continue
        out[h] = json.loads(r.stdout)
    f, a, c = out["forward"], out["adjoint"], out["auto"]
    if not f or not a or not c:
        continue
    gf, ga = f["gradient"], a["gradient"]
    size = max(abs(v) for v in gf.values()) or 1.0
    worst = max(gf, key=lambda k: abs(gf[k] - ga[k]))
    print(f"{P:40s} nll {f['nll']:.8f} {a['nll'] - f['nll']:+.1e}  "
          f"gradient difference / largest {abs(gf[worst] - ga[worst]) / size:.1e} (at {worst})  "
          f"ms forward {f['ms_per_evaluation']:.2f} adjoint {a['ms_per_evaluation']:.2f} "
          f"ratio {f['ms_per_evaluation'] / a['ms_per_evaluation']:.2f}  "
          f"auto {c['ms_per_evaluation']:.2f} ({len(c['adjoint_experiments'])} experiment(s) "
          f"by adjoint)", flush=True)
