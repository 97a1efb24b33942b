#!/usr/bin/env bash
# The neo-Hookean MLS at large depth against the neo-Hookean hex FEM (docs/verification.md,
# "Large depth: the neo-Hookean MLS against the neo-Hookean hex FEM"): scenes/palpation_block_neo.json
# (the hand-scale block, material.law neo_hookean, a cloud refined to 1 mm over the whole
# contact patch of d = R) pressed with the forces that the large-strain reference
# (palpate-reference --depths --core-half-width: neo-Hookean bricks on a quarter of the block
# with mirror planes, lattices uniform over the contact patch and graded beyond, the tool
# held at each depth, Richardson on the force; stored in scenes/references/) spans at the
# depths d/R = 0.22 ... 1.
# Also the small-depth check: the same scene at its default sweep (d/R = 0.065 ... 0.2)
# against the linear finite-block reference with the neo-Hookean and corotational laws,
# and at d/R = 0.015 ... 0.065 the three laws (linear, corotational, neo-Hookean) on the
# same cloud.
# Writes RAW/large_depth.json, RAW/small_depth_<law>.json, RAW/tiny_<law>.json
# (palpate-verify --json) and DIR/neo_hookean_depth.md (the tables).
#
# usage: scripts/neo_hookean_depth_study.sh [--reference] [--out DIR] [--raw RAW]
#   --reference   recompute the large-strain reference (quarter levels 11,16,21,26 with a
#                 12 mm core: about 10 min on one core; the stored one is used otherwise)
# The verify runs take about 15 min more (the refined cloud at d = R: ~600 particles in
# contact).
#   --out DIR     output folder (default docs/verification/neo_hookean_depth)
#   --raw RAW     the runs' JSON (default data/verification/neo_hookean_depth; with --out
#                 alone, DIR/raw)
# BUILD_DIR (default build) holds bin/palpate-verify and bin/palpate-reference; they are
# built there (Release) when stale, through scripts/build.sh.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

recompute=0
out=docs/verification/neo_hookean_depth
raw=
while [[ $# -gt 0 ]]; do
  case "$1" in
    --reference) recompute=1 ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --raw) raw=${2:?--raw needs a folder}; shift ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
  shift
done

# The runs' JSON (data/README.md): under data/ for an output under docs/, else DIR/raw.
[[ -n $raw ]] || { [[ $out == docs/* ]] && raw=data/${out#docs/} || raw=$out/raw; }
verify="$BUILD_DIR/bin/palpate-verify"
reference="$BUILD_DIR/bin/palpate-reference"
study_build palpate-verify palpate-reference
mkdir -p "$out" "$raw"
scene=scenes/palpation_block_neo.json
ref=scenes/references/palpation_block_large_strain.json

# The quarter block, each axis uniform over 12 mm from the site (1.2-1.5 times the contact
# radius of d = R) with 60 % of its intervals, spacing 2, 1.33, 1, 0.8 mm at the levels
# 11, 16, 21, 26 nodes per axis (docs/verification.md, "Large depth").
if [[ $recompute == 1 || ! -f "$ref" ]]; then
  echo "neo_hookean_depth_study.sh: palpate-reference --depths (about 10 min)" >&2
  "$reference" --scene "$scene" --depths 0.0022,0.003,0.005,0.0075,0.01 --levels 11,16,21,26 \
    --core-half-width 0.012 --out "$ref"
fi

# Forces inside the reference's range F*(2.2 mm) ... F*(10 mm); palpate-verify takes d_ref
# at each from the reference's curve (d^(3/2) linear in F between its depths).
forces=0.36,0.55,1.2,2.2,3.0
echo "neo_hookean_depth_study.sh: large depth, forces $forces N" >&2
"$verify" --scene "$scene" --forces "$forces" --reference "$ref" --json --quiet > "$raw/large_depth.json" || true

for law in neo_hookean corotational; do
  echo "neo_hookean_depth_study.sh: default sweep, $law" >&2
  "$verify" --scene "$scene" --set material.law=$law --json --quiet > "$raw/small_depth_$law.json" || true
done
for law in linear corotational neo_hookean; do
  echo "neo_hookean_depth_study.sh: small forces, $law" >&2
  "$verify" --scene "$scene" --set material.law=$law --forces 0.005,0.01,0.02,0.05 --reference none \
    --json --quiet > "$raw/tiny_$law.json" || true
done

"$python" - "$out" "$ref" "$raw" <<'EOF'
import json, sys
out, ref_file, raw = sys.argv[1], sys.argv[2], sys.argv[3]
ref = json.load(open(ref_file))
R = 0.01
def load(name):
    return json.load(open(f"{raw}/{name}.json"))
lines = ["# The neo-Hookean MLS at large depth (scripts/neo_hookean_depth_study.sh)", ""]
lines += ["## Large depth, against the large-strain reference", "",
          "levels: " + ", ".join(f"{l['per_edge']}^3 ({l['nodes']} nodes, spacing {1000 * l['first_spacing']:.2f} mm, "
                                 f"{l['seconds']:.0f} s)" for l in ref["levels"]), "",
          "| d (m) | d/R | " + " | ".join(f"F {l['per_edge']}^3 (N)" for l in ref["levels"]) +
          " | F* (N) | p | ± d (m) |",
          "|---:|---:|" + "---:|" * len(ref["levels"]) + "---:|---:|---:|"]
for k, d in enumerate(ref["indentation"]):
    levels = " | ".join(f"{l['forces'][k]:.4f}" for l in ref["levels"])
    lines.append(f"| {d:.4f} | {d / R:.2f} | {levels} | {ref['forces'][k]:.4f} | {ref['order'][k]:.2f} | "
                 f"{ref['uncertainty'][k]:.1e} |")
lines += ["", "| F (N) | MLS d (m) | d_ref (m) | ± (m) | error | status |", "|---:|---:|---:|---:|---:|---|"]
large = load("large_depth")
for row in large["rows"]:
    err, u = row["error_reference"], row["d_reference_uncertainty"]
    lines.append(f"| {row['force']:.3f} | {row['d_sim']:.5f} | {row['d_reference']:.5f} | "
                 + (f"{u:.1e}" if u is not None else "-") + " | "
                 + (f"{100 * err:+.2f} %" if err is not None else "-") + f" | {row['status']} |")
l2 = large["l2_error_reference"]
lines += ["", f"L2 over the depths: " + (f"{100 * l2:.2f} %" if l2 is not None else "-"), ""]
lines += ["## Default sweep, against the linear finite-block reference", "",
          "| F (N) | d_ref (m) | neo-Hookean d (m) | error | corotational d (m) | error |", "|---:|---:|---:|---:|---:|---:|"]
neo, cor = load("small_depth_neo_hookean"), load("small_depth_corotational")
for a, b in zip(neo["rows"], cor["rows"]):
    lines.append(f"| {a['force']:.3f} | {a['d_reference']:.6f} | {a['d_sim']:.6f} | {100 * a['error_reference']:+.2f} % | "
                 f"{b['d_sim']:.6f} | {100 * b['error_reference']:+.2f} % |")
lines += ["", f"L2: neo-Hookean {100 * neo['l2_error_reference']:.2f} %, corotational {100 * cor['l2_error_reference']:.2f} %", ""]
lines += ["## Small forces, the three laws on the same cloud", "",
          "| F (N) | d/R | linear d (m) | corotational d (m) | neo-Hookean d (m) | neo vs linear | neo vs corotational |",
          "|---:|---:|---:|---:|---:|---:|---:|"]
tiny = {law: load(f"tiny_{law}")["rows"] for law in ("linear", "corotational", "neo_hookean")}
for l, c, n in zip(tiny["linear"], tiny["corotational"], tiny["neo_hookean"]):
    lines.append(f"| {l['force']:.3f} | {n['d_sim'] / R:.3f} | {l['d_sim']:.6f} | {c['d_sim']:.6f} | {n['d_sim']:.6f} | "
                 f"{100 * (n['d_sim'] - l['d_sim']) / l['d_sim']:+.2f} % | {100 * (n['d_sim'] - c['d_sim']) / c['d_sim']:+.2f} % |")
open(f"{out}/neo_hookean_depth.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
