#!/bin/sh
# Regenerate the reference recordings of bags/ (see bags/README.md). Run from anywhere:
#   bags/make_bags.sh            (uses .venv/bin/conveyor-twin of this checkout)
#   CONVEYOR_TWIN=conveyor-twin bags/make_bags.sh
# Scheduled commands make the recorded messages depend only on the software: rerunning at the
# same commit gives the same messages (file bytes differ only in the creation time and the
# recorder's counters). The markers bag runs in realtime, so that the micro node publishes every
# due marker array (a busy machine may still skip one).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
ct=${CONVEYOR_TWIN:-$here/../.venv/bin/conveyor-twin}

"$ct" run --mode fast --duration 4 --seed 1 --markers-rate 0 --quiet \
    --record "$here/default_4s.mcap" \
    --command 200:belt:main=1.2 1500:actuator:pusher=0.2 2500:belt:main=0.6

"$ct" run --mode realtime --duration 2 --seed 7 --markers-rate 30 --quiet \
    --record "$here/default_markers_2s.mcap" --record-compression zstd \
    --command 300:actuator:stopper=0.008 1000:actuator:stopper=0 1200:belt:main=1.0
