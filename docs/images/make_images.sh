#!/bin/sh
# Regenerate the pictures of docs/images/ (shown in the README). Run from anywhere:
#   docs/images/make_images.sh            (uses .venv/bin/conveyor-twin of this checkout)
#   CONVEYOR_TWIN=conveyor-twin docs/images/make_images.sh
# default_cell.png: the embedded default cell drawn to scale.
# deflector_jam.gif: the default cell fed at 500 parts/s (1200 spacers), recorded in fast mode
# (parts, light barriers, belts, actuators; parts every 20 ms), animated at 1.5x around the
# deflector where the parts queue for the gap at the right wall.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
ct=${CONVEYOR_TWIN:-$here/../../.venv/bin/conveyor-twin}
py=${PYTHON:-$here/../../.venv/bin/python}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$ct" plot default -o "$here/default_cell.png" --width 14 --dpi 90

"$py" - "$work/jam.yaml" <<'PY'
import sys

import yaml

from conveyor_twin.cell import default_cell_text

cell = yaml.safe_load(default_cell_text())
cell['cell']['name'] = 'deflector_jam'
cell['sources'][0]['rate'] = 500.0
cell['sources'][0]['max_parts'] = 1200
with open(sys.argv[1], 'w', encoding='utf-8') as f:
    yaml.safe_dump(cell, f, sort_keys=False)
PY

"$ct" run --cell "$work/jam.yaml" --mode fast --duration 7 --seed 1 --markers-rate 0 --quiet \
    --record "$work/jam.mcap" \
    --record-topics parts light_barriers belt_states actuator_states \
    --record-decimate parts=20 light_barriers=5 belt_states=5 actuator_states=20

"$ct" animate "$work/jam.mcap" -o "$here/deflector_jam.gif" --speed 1.5 --fps 8 \
    --view 1.6,4.0,-0.3,0.3 --width 8 --dpi 72 --quiet
ls -l "$here/default_cell.png" "$here/deflector_jam.gif"
