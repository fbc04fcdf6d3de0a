#!/usr/bin/env python3
"""Whole-view figures of the demo on Earth views nobody picked by hand.

Draws directions from a fixed seed, keeps those whose ground (found with the
demo's own `pick`, straight down) is at least --min-ground metres, puts the
camera --altitude metres over that ground on a random heading, pitched
--pitch degrees down, settles the view headless and prints one line a view:
settled ms, first frame ms, chunks, triangles per pixel (listed and
rasterised), peak RSS MB, and the pose to reproduce it.

    cargo build --release -p nebula-demo
    python3 docs/random-views.py target/release/nebula-demo --count 6 \
        --altitude 1000 --pitch 10 --size 1280x720

Extra demo flags go after `--` (e.g. `-- --view lod`); with `-- --background
255,0,255` every view is crack-checked and its crack pixels printed (a sweep
of 48 such views on 2026-11-29 found one pinhole: README, "A pinhole in a
view nobody picked"). Pictures and reports are written to --out.
"""

import argparse
import json
import math
import os
import random
import subprocess
import sys
import tempfile

RADIUS = 6_371_000.0


def ground_radius(demo, world, up):
    """The radius of the first solid voxel straight down along `up`."""
    eye = [c * (RADIUS + 12_000.0) for c in up]
    below = [c * (RADIUS - 12_000.0) for c in up]
    out = subprocess.run(
        [demo, "--planet", "earth", "--world", world, "--camera-pos=" + ",".join(f"{c:.3f}" for c in eye),
         "--look-at=" + ",".join(f"{c:.3f}" for c in below), "pick"],
        capture_output=True, text=True, check=True).stdout
    hit = json.loads(out)
    if not hit.get("hit"):
        return None
    return math.sqrt(sum(c * c for c in hit["point"]))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def unit(v):
    length = math.sqrt(sum(c * c for c in v))
    return [c / length for c in v]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("demo")
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--count", type=int, default=6)
    parser.add_argument("--altitude", type=float, default=1000.0, help="metres over the ground")
    parser.add_argument("--pitch", type=float, default=10.0, help="degrees down")
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--min-ground", type=float, default=0.0, help="metres: 0 keeps land only")
    parser.add_argument("--out", default=os.path.join(tempfile.gettempdir(), "nebula-random-views"))
    # Demo flags after `--` go to every run as they are.
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    args = parser.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    os.makedirs(args.out, exist_ok=True)
    world = os.path.join(args.out, "pick.redb")
    rng = random.Random(args.seed)
    shown = 0
    while shown < args.count:
        # Away from the poles, as the render tests' random places are.
        up = unit([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.6, 0.6)])
        heading = math.radians(rng.uniform(0, 360))
        ground = ground_radius(args.demo, world, up)
        if ground is None or ground - RADIUS < args.min_ground:
            continue
        east = unit(cross([0.0, 0.0, 1.0], up))
        north = cross(up, east)
        ahead = [math.cos(heading) * n + math.sin(heading) * e for n, e in zip(north, east)]
        eye = [c * (ground + args.altitude) for c in up]
        pitch = math.radians(args.pitch)
        look = [p + 1000.0 * (a * math.cos(pitch) - u * math.sin(pitch)) for p, a, u in zip(eye, ahead, up)]
        pose = ["--camera-pos=" + ",".join(f"{c:.3f}" for c in eye), "--look-at=" + ",".join(f"{c:.3f}" for c in look)]
        name = os.path.join(args.out, f"view-{args.seed}-{shown}")
        subprocess.run([args.demo, "--planet", "earth", "--headless", "--size", args.size, *pose,
                        "--screenshot", name + ".png", "--report", name + ".json", *extra],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        with open(name + ".json") as file:
            report = json.load(file)
        # Occlusion culling's figures where it ran (with a GPU, or --occlusion-culling on).
        culled = (report.get("occlusion_culling") or {}).get("rasterised_triangles_per_pixel", report["triangles_per_pixel"])
        # Crack pixels where the view was drawn over a sentinel (`-- --background R,G,B`).
        cracks = report.get("crack_pixels")
        cracked = "" if cracks is None else f"{cracks} crack pixels {report.get('crack_samples', [])}, "
        print(f"view {shown}: ground {ground - RADIUS:.0f} m, settled {report['settled_ms']:.0f} ms, "
              f"first frame {report['first_frame_ms']:.0f} ms, {report['chunks']} chunks, "
              f"{report['triangles_per_pixel']:.2f} triangles/px listed, {culled:.2f} rasterised, "
              f"peak RSS {report['peak_rss_bytes'] / 1e6:.0f} MB, {cracked}"
              f"--size {args.size} {' '.join(pose)}", flush=True)
        shown += 1


if __name__ == "__main__":
    main()
