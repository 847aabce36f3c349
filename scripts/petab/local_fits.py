"""The default method's fits of PEtab problems from two starts, as issue 41 measures them:
the parameter table's nominal values, and nominal + 0.1 on each estimated parameter's own
scale (lin, log or log10), clipped into its bounds. Prints a Markdown table; with
--fides JSON (the output of scripts/reference/fides_petab.py) the peer's fits from the same
starts stand beside sysid's.

    cargo build --release -p sysid-cli
    SYSID=target/release/sysid python3 scripts/petab/local_fits.py tests/data/petab \\
        --only Boehm_JProteomeRes2014,Fiedler_BMCSystBiol2016 \\
        --fides scripts/reference/fides_petab.json

The objective is the NLL plus the priors' term where there are priors (what pyPESTO
minimises). ✓: sysid's certificate holds at the point returned (`converged` in the JSON).
"""

import argparse
import csv
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path


def shifted_copy(folder: Path, into: Path) -> Path:
    """A copy of the problem whose nominal values are moved by 0.1 on their own scale."""
    target = into / folder.name
    shutil.copytree(folder, target)
    for table in target.glob("parameters*.tsv"):
        rows = list(csv.reader(table.open(), delimiter="\t"))
        head = rows[0]
        col = {k: head.index(k) for k in
               ("parameterScale", "lowerBound", "upperBound", "nominalValue", "estimate")}
        for row in rows[1:]:
            if row[col["estimate"]].strip() != "1":
                continue
            value = float(row[col["nominalValue"]])
            lo, hi = float(row[col["lowerBound"]]), float(row[col["upperBound"]])
            scale = row[col["parameterScale"]].strip()
            if scale == "log10":
                value = 10 ** (math.log10(value) + 0.1) if value > 0 else lo
            elif scale == "log":
                value = math.exp(math.log(value) + 0.1) if value > 0 else lo
            else:
                value += 0.1
            row[col["nominalValue"]] = repr(min(max(value, lo), hi))
        with table.open("w") as f:
            csv.writer(f, delimiter="\t", lineterminator="\n").writerows(rows)
    return target


def problem_yaml(folder: Path) -> Path:
    """The problem's YAML file: `<folder>.yaml`, else `problem.yaml`, else the only one.
    (Zhao's folder also holds `petab_test_*.yaml`, a variant whose files are absent.)"""
    for name in (f"{folder.name}.yaml", "problem.yaml"):
        if (folder / name).exists():
            return folder / name
    return next(folder.glob("*.yaml"))


def fit(sysid: str, folder: Path) -> dict:
    yaml = problem_yaml(folder)
    run = subprocess.run([sysid, "fit", "--petab", str(yaml), "--format", "json"],
                         capture_output=True, text=True)
    if not run.stdout.strip():
        return {"error": run.stderr.strip().splitlines()[-1] if run.stderr else "no output"}
    out = json.loads(run.stdout)
    objective = out["nll"] + out.get("prior", 0.0) if out["nll"] is not None else None
    return {"objective": objective, "converged": out["converged"],
            "iterations": out["iterations"], "seconds": out["elapsed_ms"] / 1000,
            "termination": out["termination_code"]}


def cell(r: dict) -> str:
    if "error" in r:
        return f"{r['error']} | | |"
    mark = "✓" if r["converged"] else f"✗ {r['termination']}"
    return f"{r['objective']:.6f} {mark} | {r['iterations']} | {r['seconds']:.2f}"


def peer(fides: dict, name: str, key: str) -> str:
    r = fides.get(name, {}).get(key)
    if not r or r.get("objective") is None:
        return "— |"
    return f"{r['objective']:.6f} | {r['seconds']:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a folder of PEtab problems, one per folder")
    parser.add_argument("--only", help="comma-separated problem names")
    parser.add_argument("--fides", type=Path, help="fides_petab.py's output")
    args = parser.parse_args()
    sysid = os.environ.get("SYSID", "target/release/sysid")
    fides = json.loads(args.fides.read_text()) if args.fides else {}
    names = sorted(p.name for p in args.folder.iterdir()
                   if p.is_dir() and any(p.glob("*.yaml")))
    if args.only:
        names = [n for n in names if n in args.only.split(",")]
    print("| problem | from nominal: objective | it | s | fides | s "
          "| from nominal + 0.1: objective | it | s | fides | s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            print(f"{name} ...", file=sys.stderr)
            nominal = fit(sysid, args.folder / name)
            shifted = fit(sysid, shifted_copy(args.folder / name, Path(tmp)))
            print(f"| {name} | {cell(nominal)} | {peer(fides, name, 'from_nominal')} "
                  f"| {cell(shifted)} | {peer(fides, name, 'from_nominal_plus_0.1')} |",
                  flush=True)


if __name__ == "__main__":
    main()
