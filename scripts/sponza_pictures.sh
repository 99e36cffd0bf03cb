#!/usr/bin/env bash
# Remakes the Sponza pictures of the README in docs/images/: two views (the courtyard seen
# from under an end arch, and a ground-floor gallery) shaded from a bake at the defaults,
# each beside a path-traced view at the same exposure.
#
#   scripts/sponza_pictures.sh BAKE_DIR [SAMPLES]
#
# BAKE_DIR: a finished `surfcache bake` of Sponza.gltf under immenstadter_horn_1k.exr.
# SAMPLES: hemisphere samples per visible point of the path-traced views [default: 256].
set -euo pipefail
cd "$(dirname "$0")/.."
bake=$1
samples=${2:-256}
scene=${SPONZA:-../shared/assets/scenes/sponza_crytek/Sponza.gltf}
env=${SPONZA_ENV:-../shared/assets/envmaps/immenstadter_horn_1k.exr}
bin=${SURFCACHE:-target/release/surfcache}
[ -x "$bin" ] || cargo build --release -q --bin surfcache
out=docs/images
size=480x320
mkdir -p "$out"
view() { # name eye,target
  local name=$1 camera=$2
  # The path-traced view picks the exposure; the baked view reuses it.
  exposure=$("$bin" render "$scene" --env "$env" --camera="$camera" --fov 60 --size $size \
    --reference "$samples" -o "$out/sponza_${name}_path_traced.png" 2>&1 |
    sed -n 's/.*(exposure \([0-9.]*\)).*/\1/p')
  "$bin" render "$scene" --env "$env" --camera="$camera" --fov 60 --size $size \
    --cache "$bake" --exposure "$exposure" -o "$out/sponza_${name}_baked.png"
}
view courtyard -11,1.6,0.5,10,4,0
view gallery -9,1.6,-5,9,1.6,-5
rm -f "$out"/sponza_*.exr
ls -l "$out"/sponza_*
