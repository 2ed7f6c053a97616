#!/usr/bin/env bash
# The main job, end to end: set up (or reuse) the virtual environment, start stage_node on the
# built-in micropositioning stage, drive it with the demo profile 0 -> 0.5 -> 1.0 -> 1.5 ->
# 2.0 um (the full stroke) -> 0, 20 ms of simulated time per level, record exactly that part
# of the run, stop the node with SIGINT, then show what the recording holds (flexure-sim
# info), the analysis of every step (flexure-sim analyse) and where the figures are
# (flexure-sim plot).
#
# The node runs in lockstep mode (simulated time, /clock) and the driver advances it tick by
# tick with ~/step, publishing each command between two ticks: every run gives the same
# numbers, however loaded the machine is (fast mode would apply commands whenever the busy
# node gets to them).
#
# Everything goes to runs/main_job/<UTC time>/ (override with MAIN_JOB_DIR):
#   stage/ (the recording: a rosbag2 bag directory, metadata.yaml + stage_0.mcap, which
#   ros2 bag info and rosbags open too), plots/*.png, stage_node.log, live.json (what the
#   driver saw live).
set -euo pipefail
cd "$(dirname "$0")/.."
t_start=$(date +%s%N)
source scripts/venv.sh
set -euo pipefail

# DDS on this machine only, in a domain of its own unless the caller chose one.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 1 ))}"
export MPLBACKEND=Agg
export RCUTILS_COLORIZED_OUTPUT=0

out="${MAIN_JOB_DIR:-runs/main_job/$(date -u +%Y%m%dT%H%M%S)}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
export ROS_LOG_DIR="$out/ros_log"
run="$out/stage"

echo "== stage_node: microstage, lockstep mode, 2 kHz ticks of 5 engine steps, ROS_DOMAIN_ID=$ROS_DOMAIN_ID"
stage_node --ros-args -p mechanism:=microstage -p time_mode:=lockstep -p publish_rate:=2000.0 \
  -p record:=false -p record_path:="$run" >"$out/stage_node.log" 2>&1 &
node_pid=$!

stop_node() {
  if kill -0 "$node_pid" 2>/dev/null; then
    kill -INT "$node_pid" 2>/dev/null || true
    for _ in $(seq 100); do kill -0 "$node_pid" 2>/dev/null || break; sleep 0.1; done
    if kill -0 "$node_pid" 2>/dev/null; then kill -KILL "$node_pid" 2>/dev/null || true; fi
  fi
  wait "$node_pid" 2>/dev/null
}
trap 'stop_node' EXIT

echo "== demo drive: steps to 25, 50, 75, 100 % of the stroke and back to 0, 20 ms each"
if ! python -m flexure_sim.node.apps.demo_drive --record --rest 0.01 --dwell 0.02 --json >"$out/live.json"; then
  echo "main_job: the demo drive failed; stage_node's log:" >&2
  tail -n 20 "$out/stage_node.log" >&2
  exit 1
fi
python - "$out/live.json" <<'EOF'
import json, sys
from flexure_sim.node.apps.demo_drive import format_live
print(format_live(json.load(open(sys.argv[1]))))
EOF

set +e
stop_node
node_rc=$?
set -e
trap - EXIT
if [ "$node_rc" -ne 0 ]; then
  echo "main_job: stage_node exited with status $node_rc; its log:" >&2
  tail -n 20 "$out/stage_node.log" >&2
  exit 1
fi

echo
echo "== flexure-sim info $run"
flexure-sim info "$run"
echo
echo "== flexure-sim analyse $run"
flexure-sim analyse "$run"
echo
echo "== flexure-sim plot $run -o $out/plots"
flexure-sim plot "$run" -o "$out/plots"
echo
t_end=$(date +%s%N)
echo "plots:     $out/plots/"
echo "recording: $run"
awk -v a="$t_start" -v b="$t_end" 'BEGIN { printf "main job finished in %.1f s\n", (b - a) / 1e9 }'
