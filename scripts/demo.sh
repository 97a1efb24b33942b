#!/usr/bin/env bash
# The product's main job for a newcomer: set-up, Release build, then start
# palpate-server in the background, run palpate-client against it for a few
# seconds (a force ramp on the best real-time scene, scenes/hertz_cube_haptic.json:
# within 1 % of the converged reference, served at 1 kHz) and stop the server,
# printing the client's table (time, commanded force, indentation, contact force, the
# Hertz depth of that force, the difference) and the rate the server held.
#
#   scripts/demo.sh                 # the server demo (~10 s after the build)
#   scripts/demo.sh --viewer        # the server with the browser viewer: prints the URL to
#                                   # open, serves until Ctrl-C
#   scripts/demo.sh --headless      # the same client on a headless session (force steps to rest)
#   scripts/demo.sh --verify [ARGS] # the Hertz verification sweep (palpate-verify)
#   SCENE=palpation_lump scripts/demo.sh --viewer   # any scene of scenes/ by name
#
# Environment: BUILD_DIR (default build), SCENE (default hertz_cube_haptic), PORT (default
# 7420), WEB (the viewer's ADDR:PORT, default 127.0.0.1:8080; 0.0.0.0:8080 to be reached
# from other machines), SECONDS_RUN (default 5), RAMP (default 100 N).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
SCENE=${SCENE:-hertz_cube_haptic}
[[ -f scenes/$SCENE.json ]] || { echo "demo.sh: no scene scenes/$SCENE.json (SCENE is a name under scenes/)" >&2; exit 2; }
echo "== building (Release) in $BUILD_DIR"
BUILD_DIR=$BUILD_DIR BUILD_TYPE=Release scripts/build.sh >/dev/null

if [[ "${1:-}" == "--verify" ]]; then
  shift
  echo "== palpate-verify on scenes/$SCENE.json"
  exec "$BUILD_DIR/bin/palpate-verify" --scene "scenes/$SCENE.json" "$@"
fi

PORT=${PORT:-7420}
SECONDS_RUN=${SECONDS_RUN:-5}
RAMP=${RAMP:-100}
WEB=${WEB:-127.0.0.1:8080}
LOG=$(mktemp -t palpate-server.XXXXXX.log)
http=()
[[ "${1:-}" == "--viewer" ]] && http=(--http "$WEB")
echo "== palpate-server on 127.0.0.1:$PORT (log: $LOG)"
"$BUILD_DIR/bin/palpate-server" --listen "127.0.0.1:$PORT" "${http[@]}" --scene "scenes/$SCENE.json" --rate 1000 \
  >"$LOG" 2>&1 &
SERVER_PID=$!
trap 'kill -TERM $SERVER_PID 2>/dev/null || true; wait $SERVER_PID 2>/dev/null || true' EXIT
for _ in $(seq 600); do  # wait for "listening on" (at most 60 s: the server builds its default scene first)
  grep -q "listening on" "$LOG" && break
  kill -0 $SERVER_PID 2>/dev/null || { cat "$LOG"; exit 1; }
  sleep 0.1
done
grep -q "listening on" "$LOG" || { echo "server did not start"; cat "$LOG"; exit 1; }

if [[ "${1:-}" == "--viewer" ]]; then
  url=$(grep -o "http://[^ ]*" "$LOG" | head -1)
  echo "== the viewer of scenes/$SCENE.json: open $url in a browser"
  echo "   (each page opens its own session; ?session=ID watches one read-only, ?scene=NAME opens another scene;"
  echo "   Ctrl-C stops the server)"
  wait $SERVER_PID
  exit
elif [[ "${1:-}" == "--headless" ]]; then
  echo "== palpate-client --headless: forces applied one after the other, each stepped to rest"
  "$BUILD_DIR/bin/palpate-client" --connect "127.0.0.1:$PORT" --scene "$SCENE" --headless --forces 10.36,29.30,53.83,82.88
else
  echo "== palpate-client: force ramp 0 -> $RAMP N over $SECONDS_RUN s, streamed at 20 Hz"
  "$BUILD_DIR/bin/palpate-client" --connect "127.0.0.1:$PORT" --scene "$SCENE" --ramp "$RAMP" \
    --seconds "$SECONDS_RUN" --rate 20
fi
echo "== (a dynamic ramp lags the quasi-static Hertz depth; scripts/demo.sh --headless compares at rest)"
