#!/usr/bin/env bash
# A screenshot of the rerun viewer showing a recording, on a machine without a display:
# rerun's own web viewer (rerun --web-viewer, WebGL) served on localhost and drawn by
# headless Chromium (Debian: apt-get install chromium).
#
#   bash docs/rerun_screenshot.sh RECORDING.rrd OUT.png [WIDTHxHEIGHT] [SECONDS]
#
# SECONDS (default 30) is how long the page runs before the picture is taken: the
# viewer loads the recording and plays it from the start, so the 3D view shows the
# robot where the recording stands by then. The viewer listens on ports 9090 (HTTP)
# and 9876 (gRPC), which must be free.
set -euo pipefail
rrd=$1 out=$2 size=${3:-1600x1000} seconds=${4:-30}
[ -f "$rrd" ] || { echo "error: $rrd: no such recording" >&2; exit 2; }
browser=$(command -v chromium || command -v chromium-browser || true)
[ -n "$browser" ] || { echo "error: no chromium on PATH (apt-get install chromium)" >&2; exit 2; }
XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp} rerun --web-viewer --renderer webgl "$rrd" \
    >/dev/null 2>&1 &
viewer=$!
trap 'kill $viewer 2>/dev/null || true' EXIT
for _ in $(seq 50); do  # the web server answers within a few seconds
  curl -sf -o /dev/null http://127.0.0.1:9090 && break
  sleep 0.2
done
profile=$(mktemp -d)
"$browser" --headless --no-sandbox --use-gl=angle --use-angle=swiftshader \
    --enable-unsafe-swiftshader --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync \
    --user-data-dir="$profile" --window-size="${size/x/,}" \
    --virtual-time-budget=$((seconds * 1000)) --screenshot="$out" \
    "http://127.0.0.1:9090?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A9876%2Fproxy&renderer=webgl" \
    >/dev/null 2>&1
rm -rf "$profile"
echo "$out"
