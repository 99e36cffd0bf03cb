#!/usr/bin/env bash
# Remakes the Sponza pictures of the README in docs/images/: two views (the courtyard seen
# from under an end arch, and a ground-floor gallery) shaded from a bake at the defaults,
# each beside a path-traced view at the same exposure.
#
#   scripts/sponza_pictures.sh BAKE_DIR [SAMPLES]
#
# BAKE_DIR: a finished `surfcache bake` of Sponza.gltf under immenstadter_horn_1k.exr.
# SAMPLES: hemisphere samples per visible point of the courtyard's path-traced view (4 × that
# for the gallery's) [default: 64].
set -euo pipefail
cd "$(dirname "$0")/.."
bake=$1
samples=${2:-64}
scene=${SPONZA:-../shared/assets/scenes/sponza_crytek/Sponza.gltf}
env=${SPONZA_ENV:-../shared/assets/envmaps/immenstadter_horn_1k.exr}
bin=${SURFCACHE:-target/release/surfcache}
[ -x "$bin" ] || cargo build --release -q --bin surfcache
out=docs/images
mkdir -p "$out"
view() { # name eye,target size samples
  local name=$1 camera=$2 size=$3 samples=$4
  # The path-traced view picks the exposure; the baked view reuses it.
  exposure=$("$bin" render "$scene" --env "$env" --camera="$camera" --fov 60 --size "$size" \
    --reference "$samples" -o "$out/sponza_${name}_path_traced.png" 2>&1 |
    sed -n 's/.*(exposure \([0-9.]*\)).*/\1/p')
  "$bin" render "$scene" --env "$env" --camera="$camera" --fov 60 --size "$size" \
    --cache "$bake" --exposure "$exposure" -o "$out/sponza_${name}_baked.png"
}
# The gallery is lit by light bounced in from the courtyard: a path tracer needs far more
# samples there, so it is drawn at half the size with four times the samples (same cost).
view courtyard -11,1.6,0.5,10,4,0 480x320 "$samples"
view gallery -9,1.6,-5,9,1.6,-5 240x160 $((4 * samples))
rm -f "$out"/sponza_*.exr
ls -l "$out"/sponza_*
