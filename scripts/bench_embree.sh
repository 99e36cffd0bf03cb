#!/usr/bin/env bash
# Our CWBVH traversal against Embree 3 in the same run (docs/results.md, "Ray tracing").
#
# Installs Debian's libembree-dev, builds `surfcache` and the bench-only crate
# benches/embree_compare (not a workspace member), makes ray files with `surfcache rays`
# (`box`: origins anywhere in the scene's bounding box, uniform directions; `surface`: the
# bake's own rays, from surface points with cosine-distributed directions), traces each
# through Embree and through `surfcache trace` at every SIMD level this CPU runs, checks
# that both report the same hits, and prints Mrays/s and the ratio ours/Embree.
#
#   scripts/bench_embree.sh [RAYS_PER_RUN] [REPEATS]    (default 2,000,000 rays, 1 repeat)
#
# With REPEATS > 1 both sides trace every file that many times, interleaved, and the best
# rate of each is printed: on a shared host the best run is the least disturbed one.
#
# Scenes: the built-in `cornell` and Crytek Sponza from ../shared/assets (skipped when
# absent). Run on an idle machine if you can; ratios within one run are what to compare.
set -euo pipefail
cd "$(dirname "$0")/.."
count=${1:-2000000}
repeats=${2:-1}
if ! [ -e /usr/include/embree3/rtcore.h ]; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libembree-dev >/dev/null
fi
cargo build --release -q --bin surfcache
cargo build --release -q --manifest-path benches/embree_compare/Cargo.toml
ours=target/release/surfcache
embree=benches/embree_compare/target/release/embree_compare
assets=../shared/assets
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

scenes=(cornell)
sponza="$assets/scenes/sponza_crytek/Sponza.gltf"
if [ -f "$sponza" ]; then scenes+=("$sponza"); else echo "skipping $sponza: not found"; fi

levels=$(python3 - <<'PY'
import re
flags = open('/proc/cpuinfo').read() if __import__('os').path.exists('/proc/cpuinfo') else ''
print('scalar avx2' if re.search(r'\bavx2\b', flags) else 'scalar')
PY
)

field() { python3 -c "import json,sys; print('%.${2:-2}f' % json.loads(sys.argv[1])['$1'])" "$3"; }

printf '%-8s %-8s %-8s %3s %-7s %9s %9s %7s %8s %9s  %s\n' \
  scene rays query thr level ours embree ratio build_s embree_b agreement
max() { python3 -c "import sys; print(max(float(x) for x in sys.argv[1:]))" "$@"; }
for scene in "${scenes[@]}"; do
  name=$(basename "$scene" | sed 's/\.[^.]*$//' | tr 'A-Z' 'a-z')
  for kind in box surface; do
    rays="$work/$name-$kind.bin"
    [ -f "$rays" ] || "$ours" rays "$scene" --kind "$kind" --count "$count" -o "$rays" 2>/dev/null
    for query in closest any; do
      flag=""; [ "$query" = any ] && flag="--any-hit"
      for threads in 1 2; do
        # Each side traced `repeats` times, interleaved; the best rate of each counts
        # (on a shared host the best run is the one least disturbed).
        me=0; declare -A mo=(); declare -A o=()
        for rep in $(seq "$repeats"); do
          e=$("$embree" trace "$scene" "$rays" $flag --threads "$threads" -o "$work/embree.bin" 2>/dev/null)
          me=$(max "$me" "$(field mrays_per_s 4 "$e")")
          for level in $levels; do
            o[$level]=$(SURFCACHE_SIMD=$level "$ours" trace "$scene" "$rays" $flag --threads "$threads" -o "$work/ours-$level.bin" 2>/dev/null)
            mo[$level]=$(max "${mo[$level]:-0}" "$(field mrays_per_s 4 "${o[$level]}")")
          done
        done
        for level in $levels; do
          c=$("$embree" compare "$work/embree.bin" "$work/ours-$level.bin" $flag)
          agree=$(python3 -c "import json,sys; c=json.loads(sys.argv[1]); print('%d/%d same, %d t>1e-4, %d hit/miss' % (c['identical']+c['t_within_1e-4'], c['rays'], c['different_t'], c['hit_vs_miss']))" "$c")
          ratio=$(python3 -c "print('%.2f' % (${mo[$level]} / $me))")
          printf '%-8s %-8s %-8s %3s %-7s %9.2f %9.2f %7s %8s %9s  %s\n' "$name" "$kind" "$query" \
            "$threads" "$level" "${mo[$level]}" "$me" "$ratio" "$(field build_seconds 3 "${o[$level]}")" \
            "$(field build_seconds 3 "$e")" "$agree"
        done
        unset mo o
      done
    done
  done
done
