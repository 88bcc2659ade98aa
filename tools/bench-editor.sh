#!/usr/bin/env bash
# Editor benchmark (docs/editor.md, "Benchmark"): frames/s and edit latency while editing
# continuously with real input. Starts a private Xvfb, opens `voxdag editor SCENE` at 1280x720
# without vsync (dynamic render scale on) with --stats-json OUT, holds the left button over the
# middle of the window with xdotool while moving the pointer back and forth (one edit per frame),
# releases, quits with Esc and prints the stats line. An autosave of SCENE left by an earlier run
# is not offered (--recover no): its prompt would take the press.
#
# usage: tools/bench-editor.sh SCENE.vdag OUT.json [TOOL] [RADIUS] [SECONDS]
#   TOOL: paint (default) | sphere-add | ... (`voxdag editor --tool`); RADIUS: 32; SECONDS: 20
# env: VOXDAG (binary, default target/release/voxdag), BENCH_DISPLAY (default :71),
#      EDITOR_ARGS (more editor flags, e.g. "--render-mode pt"),
#      VK_ICD_FILENAMES (lavapipe: /usr/share/vulkan/icd.d/lvp_icd.x86_64.json)
set -euo pipefail
scene=${1:?usage: tools/bench-editor.sh SCENE.vdag OUT.json [TOOL] [RADIUS] [SECONDS]}
out=${2:?usage: tools/bench-editor.sh SCENE.vdag OUT.json [TOOL] [RADIUS] [SECONDS]}
tool=${3:-paint}
radius=${4:-32}
seconds=${5:-20}
bin=${VOXDAG:-target/release/voxdag}
display=${BENCH_DISPLAY:-:71}

Xvfb "$display" -screen 0 1600x1000x24 -nolisten tcp >/dev/null 2>&1 &
xvfb=$!
editor=
cleanup() {
    [ -n "$editor" ] && kill "$editor" 2>/dev/null || true
    kill "$xvfb" 2>/dev/null || true
}
trap cleanup EXIT
export DISPLAY=$display
for _ in $(seq 1 100); do xdpyinfo >/dev/null 2>&1 && break; sleep 0.1; done

status=$(mktemp -u /tmp/bench-editor-status.XXXXXX)
"$bin" editor "$scene" --size 1280x720 --no-vsync --tool "$tool" --radius "$radius" \
    --material 3 --recover no --stats-json "$out" --status-file "$status" ${EDITOR_ARGS:-} &
editor=$!
id=
for _ in $(seq 1 1200); do
    id=$(xdotool search --name "voxdag editor" 2>/dev/null | head -n 1 || true)
    [ -n "$id" ] && break
    kill -0 "$editor" 2>/dev/null || { echo "the editor exited before its window opened" >&2; exit 1; }
    sleep 0.5
done
[ -n "$id" ] || { echo "no editor window" >&2; exit 1; }
# Wait for the scene to load and 3 frames to pass (first pass timings for the dynamic scale),
# then for the hover hit under the pointer.
frame() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['$1'])" "$status" 2>/dev/null || echo none; }
xdotool mousemove --window "$id" 640 360
for _ in $(seq 1 2400); do
    f=$(frame frame)
    [ "$f" != none ] && [ "$f" -ge 3 ] && [ "$(frame hover)" != None ] && break
    sleep 0.25
done
xdotool mousedown 1
end=$((SECONDS + seconds))
while [ "$SECONDS" -lt "$end" ]; do
    for dx in 0 24 48 24 0 -24 -48 -24; do
        xdotool mousemove --window "$id" $((640 + dx)) $((360 + dx / 3))
        sleep 0.2
    done
done
xdotool mouseup 1
sleep 1
# Esc asks about the unsaved edits; D discards them (and their autosave).
xdotool windowfocus --sync "$id" key --delay 200 Escape d
wait "$editor"
editor=
rm -f "$status"
