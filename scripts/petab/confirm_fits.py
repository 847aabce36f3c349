"""Every "converged" of the default method's fits, checked by means that do not trust it.

For each PEtab problem of a folder, the default fit from nominal and from nominal + 0.1 (the
starts of `local_fits.py`). Where a fit says `converged`, its point is checked twice, at
integration tolerances 1 000 times tighter than the problem's (rtol 1e-11, atol 1e-15):

* the certificate again, at the point (`sysid fit --max-iterations 0 --start …`): its
  first-order test must hold with the gradient of the tighter integration, and the objective
  there, against the fit's own, is the integration error of the value the fit printed;
* levenberg-marquardt started at the point (`sysid fit --method levenberg-marquardt
  --start …`): it must not find a point lower by more than `--fall` (1e-6) times
  max(1, |objective|). Its own status is printed: where the minimum is flat along a sloppy
  direction it may move along it and stop uncertified at a point no lower. A lower point
  where some unknown moved by more than FAR (one e-fold) is not a local one (MINPACK's first
  radius lets the method leap, and it may walk along unknowns the model does not see, held on
  their bounds, at no cost): it does not fail the claim, and the row says how far it is.

A fit that does not claim convergence is listed with its status and not checked. With
`--starts N`, the claims of a multistart are checked the same way instead: `sysid fit
--starts N --starts-without-guess` from each problem's nominal folder, and every start the
waterfall calls converged (local minima included), one row each. Prints a Markdown table;
exits 1 when a claim fails its check.

    cargo build --release -p sysid-cli
    SYSID=target/release/sysid python3 scripts/petab/confirm_fits.py tests/data/petab \\
        --only Boehm_JProteomeRes2014,Fiedler_BMCSystBiol2016
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from local_fits import problem_yaml, shifted_copy

TIGHT = ["--rtol", "1e-11", "--atol", "1e-15"]

# A lower point this far away (an unknown moved by more e-folds) is not a local one: the
# point checked can still be the minimum of its neighbourhood.
FAR = 1.0


def run(sysid: str, args: list[str]) -> dict:
    out = subprocess.run([sysid, *args, "--format", "json"], capture_output=True, text=True)
    if not out.stdout.strip():
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr else "no output"}
    return json.loads(out.stdout)


def objective(out: dict) -> float | None:
    if "nll" not in out and "objective" in out:
        return out["objective"]  # a start's row of the waterfall
    nll = out.get("nll")
    return None if nll is None else nll + (out.get("prior") or 0.0)


def check(sysid: str, yaml: Path, fall: float) -> dict:
    fit = run(sysid, ["fit", "--petab", str(yaml)])
    if "error" in fit:
        return {"fit": fit}
    return check_point(sysid, yaml, fit, fall)


def check_point(sysid: str, yaml: Path, fit: dict, fall: float) -> dict:
    """The checks of a fit (or a start's row of a waterfall) that claims convergence."""
    row = {"fit": fit, "objective": objective(fit)}
    if not fit["converged"]:
        return row
    point = [f"{name}={value!r}" for name, value in fit["estimates"].items()]
    starts = [a for p in point for a in ("--start", p)]
    at = run(sysid, ["fit", "--petab", str(yaml), "--max-iterations", "0", *TIGHT, *starts])
    again = run(sysid, ["fit", "--petab", str(yaml), "--method", "levenberg-marquardt",
                        *TIGHT, *starts])
    row["tight"] = objective(at) if "error" not in at else None
    row["certified"] = at.get("converged") is True
    row["again"] = again
    if "error" in again or row["tight"] is None:
        row["holds"] = False
        return row
    row["fall"] = row["tight"] - objective(again)
    row["moved"] = displacement(fit["estimates"], again["estimates"])
    row["threshold"] = fall * max(1.0, abs(row["tight"]))
    row["holds"] = row["certified"] and (row["fall"] <= row["threshold"] or row["moved"] > FAR)
    return row


def displacement(before: dict, after: dict) -> float:
    """The largest move of one unknown between two points, in e-folds for positive values
    (the log scale every parameter of the collection's problems but a few offsets is on)."""
    def move(a: float, b: float) -> float:
        return abs(math.log(b / a)) if a > 0 and b > 0 else abs(b - a)
    return max(move(before[k], after[k]) for k in before)


def cells(r: dict) -> str:
    fit = r["fit"]
    if "error" in fit:
        return f"{fit['error']} | | | | |"
    if not fit["converged"]:
        return f"{r['objective']:.6f} ✗ {fit['termination_code']} | not claimed | | | |"
    again = r["again"]
    if "error" in again or r["tight"] is None:
        why = again.get("error", "the objective at the point cannot be evaluated")
        return f"{r['objective']:.6f} ✓ | {why} | | | | **fails**"
    status = "✓" if again["converged"] else f"✗ {again['termination_code']}"
    verdict = "holds" if r["holds"] else "**fails**"
    if r["fall"] > r["threshold"] and r["moved"] > FAR:
        verdict += f" (locally: the lower point is {r['moved']:.1f} e-folds away)"
    certified = "✓" if r["certified"] else "✗"
    return (f"{r['objective']:.6f} ✓ | {certified} | {r['tight'] - r['objective']:+.1e} "
            f"| {objective(again):.6f} {status}, {again['iterations']} it "
            f"| {r['fall']:+.1e} | {verdict}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a folder of PEtab problems, one per folder")
    parser.add_argument("--only", help="comma-separated problem names")
    parser.add_argument("--skip", help="comma-separated problem names to leave out")
    parser.add_argument("--fall", type=float, default=1e-6,
                        help="the largest fall the second method may find, relative")
    parser.add_argument("--starts", type=int,
                        help="check every converged start of a multistart of this many starts")
    args = parser.parse_args()
    sysid = os.environ.get("SYSID", "target/release/sysid")
    names = sorted(p.name for p in args.folder.iterdir()
                   if p.is_dir() and any(p.glob("*.yaml")))
    if args.only:
        names = [n for n in names if n in args.only.split(",")]
    if args.skip:
        names = [n for n in names if n not in args.skip.split(",")]
    print("| problem | start | default fit | certificate at rtol 1e-11 | Δ objective "
          "| levenberg-marquardt from the point, rtol 1e-11 | its fall | claim |")
    print("|---|---|---|---|---|---|---|---|")
    failed = 0
    if args.starts:
        for name in names:
            print(f"{name} ...", file=sys.stderr)
            yaml = problem_yaml(args.folder / name)
            out = run(sysid, ["fit", "--petab", str(yaml), "--starts", str(args.starts),
                              "--starts-without-guess"])
            for start in out.get("starts", {}).get("waterfall", []):
                if not start["converged"]:
                    continue
                r = check_point(sysid, yaml, start, args.fall)
                failed += r.get("holds") is False
                print(f"| {name} | start {start['start']} | {cells(r)} |", flush=True)
        return 1 if failed else 0
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            print(f"{name} ...", file=sys.stderr)
            starts = [("nominal", args.folder / name),
                      ("nominal + 0.1", shifted_copy(args.folder / name, Path(tmp)))]
            for start, folder in starts:
                r = check(sysid, problem_yaml(folder), args.fall)
                failed += r.get("holds") is False
                print(f"| {name} | {start} | {cells(r)} |", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
