#!/usr/bin/env bash
# The main job: the built-in micropositioning stage, driven by a 1.35 um step, simulated
# and reported. Sets up its own virtual environment on first use.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/venv.sh
flexure-sim simulate microstage --drive step:1.35e-6 --static
echo
flexure-sim simulate microstage --drive step:1.35e-6 --duration 0.05
