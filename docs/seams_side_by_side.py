"""The seam strategies side by side (`--seams skirts|constrained|stitched`)
on the same Earth views and a low flight, 640x400, lavapipe is enough:

    python3 docs/seams_side_by_side.py target/release/nebula-demo [OUT_DIR] [STRATEGY,...]

Each view is rendered settled over a sentinel background (crack pixels,
chunks, triangles, skirt triangles, settle time, chunks meshed, peak
memory, the largest LOD difference between drawn neighbours), and again
in the skirts debug view, whose skirt pixels are counted. The flight
(300 m/s, 100 m over land, 8 s) is crack-checked in every frame. Prints a
Markdown table and writes the pictures and reports to OUT_DIR. Camera
heights are found with the demo's `pick` straight down.
"""
import json
import math
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from contact_sheet import read_png  # noqa: E402
from ground_flight import RADIUS, along, dot, ground_radius, norm  # noqa: E402

SENTINEL = (255, 0, 255)
STRATEGIES = ["skirts", "constrained", "stitched"]


def pose(demo, direction, height, heading, pitch_deg):
    """A camera `height` m over the ground at `direction`, looking towards
    `heading` (made tangent) `pitch_deg` below the horizon."""
    up = norm(direction)
    heading = norm(along(heading, up, -dot(heading, up)))
    eye = [c * (ground_radius(demo, up) + height) for c in up]
    p = math.radians(pitch_deg)
    look = along(eye, along([h * math.cos(p) for h in heading], up, -math.sin(p)), 1000.0)
    return eye, look


def skirt_pixels(path):
    """Pixels of the skirts view's skirt colour (as the render tests count them)."""
    width, height, rgb = read_png(path)
    count = 0
    for k in range(width * height):
        r, g, b = rgb[3 * k], rgb[3 * k + 1], rgb[3 * k + 2]
        if (r, g, b) != SENTINEL and r > 2 * g + 8 and b > 2 * g:
            count += 1
    return count


def run(demo, args, out_dir, name):
    report = os.path.join(out_dir, name + ".json")
    subprocess.run([demo, "--planet", "earth", "--headless", "--size", "640x400", *args, "--report", report],
                   check=True, capture_output=True)
    return json.load(open(report))


def main():
    demo = sys.argv[1]
    out_dir = sys.argv[2] if len(sys.argv) > 2 else "target/seams-side-by-side"
    strategies = sys.argv[3].split(",") if len(sys.argv) > 3 else STRATEGIES
    os.makedirs(out_dir, exist_ok=True)
    land = norm([6219094.00, 1243818.80, 621909.40])
    east = norm([0.3, -1.0, 0.5])
    edge = norm([1.0, 1.0, 0.3])
    corner = norm([1.0, -1.0, 1.0])
    views = {
        "land 1 km, 10 deg down": pose(demo, land, 1000.0, east, 10.0),
        "cube edge, 100 m, 15 deg down": pose(demo, edge, 100.0, [-1.0, 1.0, 0.0], 15.0),
        "cube corner, 150 m, 20 deg down": pose(demo, corner, 150.0, [1.0, 1.0, 0.0], 20.0),
        "land 1.5 km, grazing 8 deg": pose(demo, land, 1500.0, east, 8.0),
        "12 deg lens, 500 m, 3 deg down": pose(demo, land, 500.0, east, 3.0),
        "cave mouth (README picture)": ([-277443.46, -2030223.41, 6032750.88], [-277521.50, -2030234.56, 6032735.09]),
    }
    rows = []
    for name, (eye, look) in views.items():
        fov = "12" if name.startswith("12 deg") else "75" if name.startswith("cave") else "60"
        camera = [f"--camera-pos={','.join(f'{c:.2f}' for c in eye)}",
                  f"--look-at={','.join(f'{c:.2f}' for c in look)}", "--fov", fov]
        for seams in strategies:
            tag = f"{len(rows):02d}-{seams}"
            r = run(demo, [*camera, "--seams", seams, "--background", "255,0,255",
                           "--screenshot", os.path.join(out_dir, tag + ".png")], out_dir, tag)
            skirts_png = os.path.join(out_dir, tag + "-skirts.png")
            run(demo, [*camera, "--seams", seams, "--background", "255,0,255", "--view", "skirts",
                       "--screenshot", skirts_png], out_dir, tag + "-skirts")
            rows.append((name, seams, r, skirt_pixels(skirts_png)))
            print(name, seams, r["crack_pixels"], r["triangles"], r["skirt_triangles"], file=sys.stderr)
    print("| view | seams | crack px | chunks | triangles | skirt triangles drawn / held | skirt px | "
          "max LOD diff | settled | chunks meshed | peak RSS |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, seams, r, pixels in rows:
        print(f"| {name} | {seams} | {r['crack_pixels']} | {r['chunks']:,} | {r['triangles']:,} | "
              f"{r['skirt_triangles']:,} / {r['skirt_triangles_held']:,} | {pixels:,} | {r['max_drawn_lod_diff']} | "
              f"{r['settled_ms'] / 1000:.1f} s | {r['chunks_meshed']:,} | {r['peak_rss_bytes'] / 1e6:.0f} MB |")
    # A low flight, every frame crack-checked.
    flight = os.path.join(out_dir, "flight-300ms.json")
    subprocess.run([sys.executable, os.path.join(os.path.dirname(__file__), "ground_flight.py"), demo, flight,
                    ",".join(str(c * RADIUS) for c in land), "0.3,-1,0.5", "8", "300", "100"],
                   check=True, capture_output=True)
    print()
    print("| 300 m/s flight, 100 m up, 8 s at 10 fps | seams | crack px (all frames) | chunks median | "
          "triangles median | skirt triangles median | unsettled median / max | chunks meshed | step ms median |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seams in strategies:
        report = os.path.join(out_dir, f"flight-{seams}.json")
        subprocess.run([demo, "--planet", "earth", "--headless", "--size", "640x400", "--flight", flight, "--fps",
                        "10", "--seams", seams, "--background", "255,0,255", "--report", report],
                       check=True, capture_output=True)
        r = json.load(open(report))
        s, frames = r["summary"], r["frames"]
        cracks = sum(f["crack_pixels"] or 0 for f in frames)
        meshed = f"{r['chunks_meshed']:,} ({r['chunks_remeshed_for_seams']:,} for seams)"
        print(f"| | {seams} | {cracks} in {len(frames)} frames | {s['chunks']['median']:,.0f} | "
              f"{s['triangles']['median']:,.0f} | {s['skirt_triangles']['median']:,.0f} | "
              f"{s['unsettled']['median']:.0f} / {s['unsettled']['max']:.0f} | {meshed} | "
              f"{s['step_ms']['median']:.1f} |")


if __name__ == "__main__":
    main()
