"""Writes a flight file for `nebula-demo --flight`: a great circle at a
constant speed and height over the ground (found with the demo's `pick`
straight down at each keyframe), looking ahead and a little down.

    python3 docs/ground_flight.py DEMO OUT.json START_X,Y,Z HEADING_X,Y,Z SECONDS [SPEED] [HEIGHT]

docs/flight-1kms-land.json:
    python3 docs/ground_flight.py target/release/nebula-demo docs/flight-1kms-land.json \\
        6219094.00,1243818.80,621909.40 0.3,-1,0.5 30
docs/flight-1kms-mountains.json:
    python3 docs/ground_flight.py target/release/nebula-demo docs/flight-1kms-mountains.json \\
        -2853425.89,5698159.83,-144616.37 -1,-0.5,1 30
"""
import json
import math
import subprocess
import sys

RADIUS = 6371000.0  # the Earth preset's
STEP_S = 0.5


def norm(v):
    length = math.sqrt(sum(c * c for c in v))
    return [c / length for c in v]


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def along(a, b, s=1.0):
    return [x + s * y for x, y in zip(a, b)]


def ground_radius(demo, direction):
    top = ",".join(str(c * (RADIUS + 12000.0)) for c in direction)
    out = subprocess.run([demo, "--planet", "earth", f"--camera-pos={top}", "--look-at=0,0,0", "pick"],
                         capture_output=True, text=True, check=True).stdout
    hit = json.loads(out)
    return math.sqrt(dot(hit["point"], hit["point"])) if hit["hit"] else RADIUS


def main():
    demo, out = sys.argv[1], sys.argv[2]
    up = norm([float(x) for x in sys.argv[3].split(",")])
    heading = [float(x) for x in sys.argv[4].split(",")]
    heading = norm(along(heading, up, -dot(heading, up)))
    seconds = float(sys.argv[5])
    speed = float(sys.argv[6]) if len(sys.argv) > 6 else 1000.0
    height = float(sys.argv[7]) if len(sys.argv) > 7 else 300.0
    points = []
    for k in range(int(seconds / STEP_S) + 2):
        angle = speed * STEP_S * k / RADIUS
        d = along([c * math.cos(angle) for c in up], heading, math.sin(angle))
        points.append((k * STEP_S, [c * (ground_radius(demo, d) + height) for c in d], d))
    keys = []
    for (t, pos, d), (_, ahead, _) in zip(points, points[1:]):
        forward = norm(along(ahead, pos, -1.0))
        look = along(along(pos, forward, 1000.0), d, -150.0)
        keys.append({"t": t, "pos": pos, "look_at": look})
    with open(out, "w") as f:
        json.dump(keys, f, indent=1)
    print(len(keys), "keyframes")


if __name__ == "__main__":
    main()
