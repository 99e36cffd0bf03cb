#!/usr/bin/env bash
# Ray-tracing benchmark through `surfcache trace` (docs/cli.md): BVH build time and
# Mrays/s with 1 and 2 threads, closest hit and any hit, for incoherent rays (origins on
# surfaces, cosine-distributed directions) and camera rays, on the built-in `cornell`, the
# Stanford bunny and Crytek Sponza from ../shared/assets (skipped when absent).
#
#   scripts/bench_trace.sh [RAYS_PER_RUN]      (default 2,000,000)
set -euo pipefail
cd "$(dirname "$0")/.."
count=${1:-2000000}
cargo build --release -q --bin surfcache
bin=target/release/surfcache
assets=../shared/assets
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

scenes=(cornell)
for f in "$assets/objects/stanford_bunny/stanford_bunny.gltf" "$assets/scenes/sponza_crytek/Sponza.gltf"; do
  if [ -f "$f" ]; then scenes+=("$f"); else echo "skipping $f: not found (../shared/assets absent)"; fi
done

printf '%-16s %-8s %-8s %7s %10s %10s\n' scene rays query threads build_s Mrays/s
for scene in "${scenes[@]}"; do
  name=$(basename "$scene" | sed 's/\.[^.]*$//')
  for kind in surface camera; do
    "$bin" rays "$scene" --kind "$kind" --count "$count" -o "$work/$name-$kind.bin" 2>/dev/null
    for query in closest any; do
      flag=""; [ "$query" = any ] && flag="--any-hit"
      for threads in 1 2; do
        json=$("$bin" trace "$scene" "$work/$name-$kind.bin" $flag --threads "$threads" 2>/dev/null)
        build=$(echo "$json" | python3 -c 'import json,sys; print("%.3f" % json.load(sys.stdin)["build_seconds"])')
        mrays=$(echo "$json" | python3 -c 'import json,sys; print("%.2f" % json.load(sys.stdin)["mrays_per_s"])')
        printf '%-16s %-8s %-8s %7s %10s %10s\n' "$name" "$kind" "$query" "$threads" "$build" "$mrays"
      done
    done
  done
done
