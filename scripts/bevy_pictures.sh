#!/usr/bin/env bash
# Remakes the README's Bevy pictures in docs/images/: the built-in Cornell box as the
# screenshot test captures it (Bevy next to `surfcache render` of the same bake, and their
# difference), and Crytek Sponza in the viewer under a sunny sky.
# Needs Xvfb and Mesa's software Vulkan (apt-get install xvfb mesa-vulkan-drivers).
# Usage: scripts/bevy_pictures.sh [SHARED_ASSETS]   (from the repository root)
set -euo pipefail

assets=${1:-../shared/assets}
out=docs/images
mkdir -p "$out"

# The screenshot test writes bevy_cornell*.png where it is told and prints its figure.
SURFCACHE_SCREENSHOT_DIR="$out" SURFCACHE_REQUIRE_DISPLAY=1 \
    cargo test --workspace --test screenshot

if [ -f "$assets/scenes/sponza_crytek/Sponza.gltf" ]; then
    # The viewer as the test build made it (the test profile is optimised): a release
    # build of Bevy would take as long again.
    cargo test --workspace --no-run
    xvfb-run -a -s "-screen 0 1280x720x24" \
        target/debug/examples/bevy_viewer --scene sponza --assets "$(realpath "$assets")" \
        --size 960x540 --screenshot "$out/bevy_sponza.png"
else
    echo "no Sponza under $assets: docs/images/bevy_sponza.png not remade" >&2
fi
