#!/usr/bin/env bash
# Remakes the README pictures in docs/images/ from the built-in Cornell box:
# a path-traced reference, vertex lighting and irradiance maps shaded from their bakes,
# and the thesis' diagnostic pictures (hemisphere samples per point, irradiance-map order
# per triangle). Usage: scripts/readme_pictures.sh [THREADS]   (from the repository root)
set -euo pipefail

threads=${1:-$(nproc)}
size=384x384
out=docs/images
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cargo build --release --quiet
surfcache=target/release/surfcache
mkdir -p "$out"

# Bakes with the default settings (1 % error bound, two gathering pre-passes).
"$surfcache" bake cornell --method vertex --threads "$threads" -o "$work/vertex"
"$surfcache" bake cornell --method irradiance-map --threads "$threads" -o "$work/imap"

render() { "$surfcache" render cornell --size "$size" --threads "$threads" "$@"; }
# The reference picks the exposure; the cached views reuse it so brightness compares.
exposure=$(render --reference 64 -o "$out/cornell_reference.png" 2>&1 |
  sed -n 's/.*(exposure \([0-9.]*\)).*/\1/p')
render --cache "$work/vertex" --exposure "$exposure" -o "$out/cornell_vertex.png"
render --cache "$work/imap" --exposure "$exposure" -o "$out/cornell_irradiance_map.png"
render --cache "$work/imap" --show samples -o "$out/cornell_samples.png"
render --cache "$work/imap" --show order -o "$out/cornell_order.png"

# Only the PNGs go into the repository (render writes the linear radiance beside them).
rm -f "$out"/*.exr
ls -l "$out"
