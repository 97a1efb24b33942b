"""scripts/surface_map_study.sh's options reach what it does (ctest surface_map_script).

  /usr/bin/python3 tests/surface_map_script.py SOURCE_DIR BUILD_DIR WORK_DIR

The map script's --no-symmetric once read its "0" as true (fixed in c541dad): it then refused
every body with a lump and mirrored the references of any other block. Here, on the lump
scene, one site off the axis, with the stored reference of that very site in the cache:
  - --symmetric is refused with a message that names the way out (a body with inclusions has
    not the square's symmetry);
  - --no-symmetric presses the site against its own reference, not a mirrored one, and the
    depth is within 2 % of that converged finite-block reference (computed by another method:
    the linear hex FEM; docs/verification/surface_map/palpation_lump_follow.md gives 1.9 %).
Standard library only; the script runs palpate-verify from BUILD_DIR and compiles nothing.
"""
import csv
import os
import shutil
import subprocess
import sys


def run(source, build, out, symmetry):
    shutil.rmtree(out, ignore_errors=True)
    command = ["bash", os.path.join(source, "scripts", "surface_map_study.sh"), "--build", build,
               "--scene", "scenes/palpation_lump_follow.json", symmetry, "--sites", "-0.035,0",
               "--cache", "data/verification/surface_map/references", "--out", out]
    return subprocess.run(command, cwd=source, capture_output=True, text=True, timeout=300)


def main():
    source, build, work = sys.argv[1:4]
    failures = []

    refused = run(source, build, os.path.join(work, "symmetric"), "--symmetric")
    if "the body has inclusions: use --no-symmetric" not in refused.stderr:
        failures.append("--symmetric on a body with a lump was not refused by name:\n" + refused.stderr)

    result = run(source, build, os.path.join(work, "no_symmetric"), "--no-symmetric")
    if result.returncode != 0:
        failures.append(f"--no-symmetric exited {result.returncode}:\n{result.stderr}")
    else:
        with open(os.path.join(work, "no_symmetric", "palpation_lump_follow.csv")) as f:
            rows = list(csv.DictReader(f))
        if len(rows) != 1:
            failures.append(f"expected one site in the map, got {len(rows)}")
        else:
            row = rows[0]
            own = "data/verification/surface_map/references/palpation_lump_follow_site_-0.035_0.json"
            if row["reference"] != own:
                failures.append(f"the site was pressed against {row['reference']}, not its own reference {own}")
            if row["status"] != "ok":
                failures.append(f"the press's status is {row['status']}")
            errors = [float(v) for k, v in row.items() if k.startswith("err_")]
            if len(errors) != 6 or max(abs(e) for e in errors) > 0.02:
                failures.append(f"depth errors {errors} against the reference: expected six, each within 2 %")

    for failure in failures:
        print("surface_map_script:", failure)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
