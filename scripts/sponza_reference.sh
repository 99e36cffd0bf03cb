#!/usr/bin/env bash
# The converged reference for Sponza's visible points (docs/results.md, "Sponza at the
# defaults: the reference"): every point of assets/reference/sponza_visible_points.csv
# path-traced with FIRST samples (full paths, Russian roulette, next-event estimation), then
# the points whose relative standard error is still above LIMIT again with SECOND samples and
# another seed, the two estimates merged in proportion to their samples.
#
#   scripts/sponza_reference.sh ENV.exr OUT.csv [FIRST [SECOND [LIMIT]]]
#
# Defaults: 65,536 and 524,288 samples, limit 0.004 (about an hour on 2 idle cores).
# The points were made by
#   surfcache points Sponza.gltf --visible --count 1500 --seed 7 -o sponza_visible_points.csv
set -euo pipefail
cd "$(dirname "$0")/.."
env=$1
out=$2
first=${3:-65536}
second=${4:-524288}
limit=${5:-0.004}
scene=${SPONZA:-../shared/assets/scenes/sponza_crytek/Sponza.gltf}
points=assets/reference/sponza_visible_points.csv
bin=${SURFCACHE:-target/release/surfcache}
[ -x "$bin" ] || cargo build --release -q --bin surfcache
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bin" reference "$scene" --env "$env" "$points" --samples "$first" -o "$work/first.csv"
python3 - "$points" "$work/first.csv" "$work/noisy.csv" "$limit" <<'PY'
import csv, sys
pts = list(csv.DictReader(open(sys.argv[1])))
ref = list(csv.DictReader(open(sys.argv[2])))
limit = float(sys.argv[4])
with open(sys.argv[3], "w") as f:
    f.write("x,y,z,nx,ny,nz\n")
    for p, r in zip(pts, ref):
        if float(r["rel_std"]) > limit:
            f.write(",".join(p[k] for k in ["x", "y", "z", "nx", "ny", "nz"]) + "\n")
PY
"$bin" reference "$scene" --env "$env" "$work/noisy.csv" --samples "$second" --seed 1 -o "$work/second.csv"
python3 - "$work/first.csv" "$work/second.csv" "$work/merged.csv" "$first" "$second" <<'PY'
import csv, sys
first = list(csv.DictReader(open(sys.argv[1])))
second = {(r["x"], r["y"], r["z"]): r for r in csv.DictReader(open(sys.argv[2]))}
wa, wb = float(sys.argv[4]), float(sys.argv[5])
with open(sys.argv[3], "w") as f:
    f.write("x,y,z,r,g,b,rel_std\n")
    for a in first:
        b = second.get((a["x"], a["y"], a["z"]))
        if b is None:
            f.write(",".join(a[k] for k in ["x", "y", "z", "r", "g", "b", "rel_std"]) + "\n")
            continue
        # Weighted by sample count (unbiased: the weights do not depend on the estimates).
        ya = (float(a["r"]) + float(a["g"]) + float(a["b"])) / 3
        yb = (float(b["r"]) + float(b["g"]) + float(b["b"])) / 3
        sa, sb = float(a["rel_std"]) * ya, float(b["rel_std"]) * yb
        rgb = [(wa * float(a[c]) + wb * float(b[c])) / (wa + wb) for c in "rgb"]
        y = sum(rgb) / 3
        rel = ((wa * sa) ** 2 + (wb * sb) ** 2) ** 0.5 / (wa + wb) / y if y > 0 else 0.0
        f.write("%s,%s,%s,%.7g,%.7g,%.7g,%.6g\n" % (a["x"], a["y"], a["z"], *rgb, rel))
PY
mv "$work/merged.csv" "$out"
