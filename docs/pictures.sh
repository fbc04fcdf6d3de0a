#!/bin/sh
# Renders the README's pictures (lavapipe is enough; about two minutes).
# The camera poses were picked on seed 11's Earth: a mountain range near
# the equator, its highest peak, a forest coast.
set -e
cd "$(dirname "$0")/.."
cargo build --release -p nebula-demo
demo=target/release/nebula-demo
earth="--planet earth --headless --size 960x540 --msaa on"
$demo $earth --camera-pos=7830681,29224500,-2647007 --look-at=0,0,0 --fov 30 --sun 60,-50 \
    --screenshot docs/earth-orbit.png
$demo $earth --camera-pos=-2853425.89,5698159.83,-144616.37 --look-at=-2921362.76,5660036.65,-77821.85 \
    --sun 30,-70 --screenshot docs/earth-mountains.png
$demo $earth --camera-pos=-2901622.70,5671976.61,-85292.75 --look-at=-2914136.06,5667132.35,-85311.50 \
    --sun 25,-70 --screenshot docs/earth-peak.png
$demo $earth --camera-pos=-1207367.81,6252140.34,211236.78 --look-at=-1207648.18,6253592.19,155658.21 \
    --sun 30,-40 --screenshot docs/earth-coast.png
$demo $earth --camera-pos=-2901622.70,5671976.61,-85292.75 --look-at=-2914136.06,5667132.35,-85311.50 \
    --sun 6,-40 --screenshot docs/earth-sunset.png
# A pose from the render test views_from_inside_caves_show_all_the_rock_near_them_and_no_crack.
$demo $earth --fov 70 --camera-pos=1285881.09,3236467.56,5335300.75 --look-at=1285871.31,3236468.12,5335302.77 \
    --screenshot docs/earth-cave.png
# In a cave mouth (the render test cave_mouths_seen_from_the_surface..., mouth 3).
$demo $earth --fov 75 --camera-pos=-277443.46,-2030223.41,6032750.88 --look-at=-277521.50,-2030234.56,6032735.09 \
    --screenshot docs/earth-cave-mouth.png
$demo --headless --size 960x540 --msaa on --camera-pos 2500,3200,3600 --screenshot docs/orbit.png
rm -rf target/flight-coast
$demo --planet earth --flight docs/flight-coast.json --fps 1 --frames-dir target/flight-coast \
    --size 640x400 --headless --msaa on
python3 docs/contact_sheet.py docs/flight-coast.png 5 target/flight-coast/*.png
$demo --headless --radius 20000 --voxel-size 1.5 --seed 7 --size 640x400 --view lod \
    --camera-pos=12008.89,12008.89,12008.89 --look-at=15496.09,8940.67,8940.67 --screenshot docs/lod-colours.png
# docs/earth-underwater.png is the render test under_the_sea_the_view_is_water's picture:
#   cargo test -p nebula_tests --test render under_the_sea -- then target/tmp/nebula-render-tests/under-water.png
# A world a game brings (nebula_tests' FloatingIslands source).
cargo run --release -p nebula_tests --example islands && mv islands.png docs/islands.png
