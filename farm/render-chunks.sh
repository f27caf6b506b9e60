#!/bin/sh
# Renders a frame range in chunks, one `logsh render` process per chunk, and keeps going
# when a chunk fails; exits 1 at the end if any did. Rerun it to fill in what failed:
# finished frames are skipped.
#
#   farm/render-chunks.sh SCENE_DIR OUT_DIR FIRST LAST [CHUNK] [-- more logsh flags]
set -u
if [ $# -lt 4 ]; then
    echo "usage: $0 SCENE_DIR OUT_DIR FIRST LAST [CHUNK] [-- logsh render flags]" >&2
    exit 2
fi
scene=$1 out=$2 first=$3 last=$4
shift 4
chunk=10
if [ $# -gt 0 ] && [ "$1" != "--" ]; then chunk=$1; shift; fi
if [ $# -gt 0 ] && [ "$1" = "--" ]; then shift; fi
logsh=${LOGSH:-logsh}

failed=""
start=$first
while [ "$start" -le "$last" ]; do
    end=$((start + chunk - 1))
    [ "$end" -gt "$last" ] && end=$last
    if ! "$logsh" render "$scene" --frames "$start-$end" --out "$out" --skip-existing --progress lines "$@"; then
        failed="$failed $start-$end"
    fi
    start=$((end + 1))
done
if [ -n "$failed" ]; then
    echo "chunks with failed frames:$failed (rerun this command to retry them)" >&2
    exit 1
fi
