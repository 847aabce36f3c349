"""The table of docs/petab.md: every problem of Benchmark-Models-PEtab through `sysid evaluate`.

    cargo build --release -p sysid-cli
    python3 scripts/petab/collection_table.py DIR > table.md

DIR is the collection's Benchmark-Models folder (a clone of
Benchmarking-Initiative/Benchmark-Models-PEtab). For each problem it runs
`sysid evaluate --petab P.yaml --format json` (the NLL at nominal, no gradient) and compares
the NLL with tests/data/petab/collection_references.tsv: AMICI's reference where there is
one, else the NLL of the collection's own simulated data (scripts/reference/). Where the
default tolerances (rtol 1e-8) miss the reference by more than 1e-3, it evaluates again at
rtol 1e-12, atol 1e-14. A problem sysid refuses shows the first line of its error. Only the
Python standard library is needed.
"""

import csv
import json
import os
import re
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SYSID = os.environ.get("SYSID", os.path.join(ROOT, "target", "release", "sysid"))
TIMEOUT = float(os.environ.get("SYSID_TIMEOUT", "1800"))


def references():
    path = os.path.join(ROOT, "tests", "data", "petab", "collection_references.tsv")
    with open(path) as f:
        return {row["problem"]: row for row in csv.DictReader(f, delimiter="\t")}


def problem_yaml(directory):
    name = os.path.basename(directory)
    if os.path.exists(os.path.join(directory, f"{name}.yaml")):
        return os.path.join(directory, f"{name}.yaml")
    yamls = sorted(f for f in os.listdir(directory) if f.endswith(".yaml") and "test" not in f)
    return os.path.join(directory, yamls[0]) if yamls else None


def evaluate(yaml, *extra):
    started = time.monotonic()
    try:
        out = subprocess.run(
            [SYSID, "evaluate", "--petab", yaml, "--format", "json", "--no-integration-error",
             *extra],
            capture_output=True, text=True, timeout=TIMEOUT,
        )
    except subprocess.TimeoutExpired:
        return None, f"no result within {TIMEOUT:.0f} s", time.monotonic() - started
    if out.returncode != 0:
        error = out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}"
        return None, error, time.monotonic() - started
    return json.loads(out.stdout), None, time.monotonic() - started


def short(error, directory):
    """The error without the folder's path."""
    return error.replace(directory + "/", "").replace("error: ", "")


def species(directory, yaml):
    text = open(yaml).read()
    sbml = re.search(r"sbml_files:\s*\n?\s*-?\s*\[?\s*([^\]\n]+)", text)
    try:
        model = open(os.path.join(directory, sbml.group(1).strip().strip("'\""))).read()
    except (AttributeError, OSError):
        return ""
    return str(len(re.findall(r"<(?:\w+:)?species\b", model)))


def main(root):
    refs = references()
    print("| problem | species | parameters | import (ms) | sysid's NLL at nominal | reference | difference | status |")
    print("|---|---|---|---|---|---|---|---|")
    matched = 0
    names = sorted(d for d in os.listdir(root) if os.path.isdir(os.path.join(root, d)))
    for name in names:
        directory = os.path.join(root, name)
        yaml = problem_yaml(directory)
        ref = refs.get(name)
        reference = float(ref["nll"]) if ref else None
        source = ref["source"].split(" (")[0] if ref else "none"
        if yaml is None:
            print(f"| {name} | | | | | | | no problem file |")
            continue
        result, error, _ = evaluate(yaml)
        if result is None:
            print(f"| {name} | {species(directory, yaml)} | | | | {'' if reference is None else f'{reference:.8f}'} | | refused: {short(error, directory)} |")
            continue
        nll = result["nll"]
        parameters = len(result["parameters"])
        cells = [name, species(directory, yaml), str(parameters), f"{result['import_ms']:.1f}", f"{nll:.8f}"]
        if reference is None:
            print("| " + " | ".join(cells + ["", "", "no reference"]) + " |")
            continue
        difference = nll - reference
        status = "matches"
        if abs(difference) > 1e-3:
            tight, _, _ = evaluate(yaml, "--rtol", "1e-12", "--atol", "1e-14")
            if tight is not None and abs(tight["nll"] - reference) <= 1e-3:
                status = f"matches at rtol 1e-12 ({tight['nll'] - reference:+.1e})"
            else:
                at = "" if tight is None else f"; at rtol 1e-12 {tight['nll'] - reference:+.1e}"
                relative = abs(difference) / max(abs(reference), 1.0)
                status = f"differs: {difference:+.1e} (relative {relative:.0e}{at})"
                simulated = ref.get("simulated_data_nll")
                if simulated and abs(nll - float(simulated)) <= 1e-3:
                    status += f"; the simulated data's NLL to {nll - float(simulated):+.1e}"
        if status.startswith("matches"):
            matched += 1
        cells += [f"{reference:.8f} ({source})", f"{difference:+.1e}", status]
        print("| " + " | ".join(cells) + " |")
        sys.stdout.flush()
    print(f"\n{matched} of {len(names)} problems match their reference to 1e-3.")


if __name__ == "__main__":
    main(sys.argv[1])
