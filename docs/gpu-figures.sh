#!/bin/bash
# Frame figures on a real GPU at 1920x1080 (SIZE=WxH for another size;
# issue 22): each README Earth view settled once (its report), then flown
# from scratch held still for 6 s at 60 fps with nothing read back, its
# figures over the frames once settled (frame_ms = step + draw waited
# for: 1000 / frame_ms is the frame rate); and the two 1 km/s flights at
# 60 fps, over every frame, and the mountain one again without occlusion
# culling. About 4 minutes on an H100/H200.
#
# Usage: docs/gpu-figures.sh DEMO OUT
#   DEMO: a release nebula-demo (strip it to carry it: 14 MB instead of 96)
#   OUT:  a folder for the reports (one JSON per run, plus summary.txt)
set -u
demo=${1:?nebula-demo binary}
out=${2:?output folder}
mkdir -p "$out"
cd "$(dirname "$0")/.."
size=${SIZE:-1920x1080}
earth="--planet earth --headless --size $size"
summary() { # medians and 95th percentiles over the settled frames (or all)
    python3 - "$1" "$2" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
frames = r["frames"]
if sys.argv[2] == "settled":
    frames = [f for f in frames if f["stand_ins"] == 0 and f["jobs_in_flight"] == 0] or frames
def spread(key):
    xs = sorted(key(f) for f in frames if key(f) is not None)
    return "%.2f / %.2f" % (xs[len(xs) // 2], xs[min(len(xs) - 1, len(xs) * 95 // 100)]) if xs else "-"
figures = {
    "frame_ms": lambda f: f["step_ms"] + f["draw_ms"], "gpu_ms": lambda f: f["gpu_ms"],
    "encode_ms": lambda f: f["encode_ms"], "step_ms": lambda f: f["step_ms"], "chunks": lambda f: f["chunks"],
    "triangles": lambda f: f["triangles"], "rasterised": lambda f: f.get("rasterised_triangles"),
}
print(sys.argv[1].split("/")[-1], r["adapter"], "%d %s frames" % (len(frames), sys.argv[2]),
      *("%s %s" % (k, spread(v)) for k, v in figures.items()),
      "peak RSS %d MB" % ((r.get("peak_rss_bytes") or 0) >> 20), sep=" | ")
PY
}
while read -r name pos look; do
    # Settled once (the report's settled_ms, triangles), then held.
    timeout 120 "$demo" $earth --camera-pos="$pos" --look-at="$look" \
        --screenshot "$out/$name.png" --report "$out/$name-shot.json" > /dev/null 2>&1 || echo "$name: shot failed"
    python3 -c "import json,sys; p=[float(v) for v in sys.argv[1].split(',')]; l=[float(v) for v in sys.argv[2].split(',')]
print(json.dumps([{'t': t, 'pos': p, 'look_at': l} for t in (0, 6)]))" "$pos" "$look" > "$out/$name-hold.json"
    timeout 120 "$demo" $earth --flight "$out/$name-hold.json" --fps 60 --report "$out/$name-hold-report.json" \
        > /dev/null 2>&1 || echo "$name: hold failed"
    summary "$out/$name-hold-report.json" settled
done <<'VIEWS' | tee "$out/summary.txt"
orbit 7830681,29224500,-2647007 0,0,0
sea-4.2km 4410030.3170,4409605.7733,1322945.4135 4409940.2146,4409648.5657,1322938.3171
land-1km 6219094.00,1243818.80,621909.40 6219057.74,1243911.98,621907.71
mountains-2.5km -2853425.89,5698159.83,-144616.37 -2921362.76,5660036.65,-77821.85
peak-300m -2901622.70,5671976.61,-85292.75 -2914136.06,5667132.35,-85311.50
coast-150m -1207367.81,6252140.34,211236.78 -1207648.18,6253592.19,155658.21
VIEWS
for flight in ${FLIGHTS-land mountains}; do
    timeout 150 "$demo" $earth --flight "docs/flight-1kms-$flight.json" --fps 60 \
        --report "$out/flight-$flight.json" > /dev/null 2>&1 || echo "flight $flight failed"
    summary "$out/flight-$flight.json" all | tee -a "$out/summary.txt"
done
# Occlusion culling (on by default with a GPU) against none: GPU time and
# memory over the mountain flight (on lavapipe culled frames grew the
# process by about 1.8 MB each; does a real driver?).
timeout 150 "$demo" $earth --flight docs/flight-1kms-mountains.json --fps 60 --occlusion-culling off \
    --report "$out/flight-mountains-no-culling.json" > /dev/null 2>&1 || echo "flight without culling failed"
summary "$out/flight-mountains-no-culling.json" all | tee -a "$out/summary.txt"
