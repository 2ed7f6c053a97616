#!/usr/bin/env bash
# Create or reuse the project's virtual environment and install flexure_sim into it.
# Usage: source scripts/venv.sh   (sets VENV, PATH, AMENT_PREFIX_PATH)
# FLEXURE_VENV overrides the location (default: <repo>/.venv).
# The ros2 command-line tools (not on PyPI) are installed from wheels when their folder exists:
# FLEXURE_ROS2CLI, default <repo>/../shared/ros2cli (see its README); tests that need `ros2`
# say so when it is absent.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${FLEXURE_VENV:-$REPO/.venv}"
PY="${PYTHON:-python3}"
stamp="$VENV/.flexure_requirements.sha"
ROS2CLI="${FLEXURE_ROS2CLI:-$REPO/../shared/ros2cli}"
reqs=(-r "$REPO/requirements.txt")
wheels=()
if [ -f "$ROS2CLI/requirements.txt" ] && compgen -G "$ROS2CLI/*.whl" >/dev/null; then
  ROS2CLI="$(cd "$ROS2CLI" && pwd)"
  reqs+=(-r "$ROS2CLI/requirements.txt")
  wheels=("$ROS2CLI"/*.whl)
fi
want="$(cat "$REPO/requirements.txt" ${wheels[@]+"$ROS2CLI/requirements.txt"} | sha256sum | cut -d' ' -f1)"
want="$want $(printf '%s\n' ${wheels[@]+"${wheels[@]}"} | sha256sum | cut -d' ' -f1)"
if [ ! -x "$VENV/bin/python" ]; then
  echo "[venv] creating $VENV" >&2
  "$PY" -m venv "$VENV"
fi
if [ "$(cat "$stamp" 2>/dev/null || true)" != "$want" ]; then
  echo "[venv] installing requirements into $VENV" >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
  # One resolver run for both lists: ros2cli pins empy, which colcon also uses.
  "$VENV/bin/python" -m pip install --quiet "${reqs[@]}" >&2
  if [ ${#wheels[@]} -gt 0 ]; then
    echo "[venv] installing the ros2 command-line tools from $ROS2CLI" >&2
    "$VENV/bin/python" -m pip install --quiet --no-deps "${wheels[@]}" >&2
  fi
  echo "$want" > "$stamp"
fi
# Install the package itself (not editable: data_files put the ros2-run launcher under
# <prefix>/lib/flexure_sim and the package marker in the ament index).
echo "[venv] installing flexure_sim from $REPO" >&2
"$VENV/bin/python" -m pip install --quiet --no-deps --force-reinstall "$REPO" >&2
export VENV
export PATH="$VENV/bin:$PATH"
export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
set +euo pipefail
