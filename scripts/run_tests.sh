#!/usr/bin/env bash
# Run the whole test suite in the project's virtual environment (created on first use).
# Extra arguments go to pytest, e.g.  scripts/run_tests.sh -k stage -x
# The tests run on FLEXURE_TEST_WORKERS pytest-xdist workers (default 2; 0: in this process,
# for pdb or a run in strict collection order); test/conftest.py says how they are shared.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/venv.sh
# Keep DDS traffic on this machine and give each run its own domain (0..101 are valid
# with the default port mapping; 1..100 leaves room for parallel runs).
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 1 ))}"
export MPLBACKEND=Agg
echo "[tests] ROS_DOMAIN_ID=$ROS_DOMAIN_ID  python=$(command -v python)" >&2
exec python -m pytest --durations=25 -n "${FLEXURE_TEST_WORKERS:-2}" --dist loadgroup test "$@"
