#!/bin/sh
# Re-record every reference bag listed in bags/manifest.yaml (or only some: --only NAME ...), check
# that each new recording replays bit-identically, and update the manifest. Run after an INTENDED
# change of results, then commit bags/. Needs the venv (make setup); no ROS, no network.
set -e
cd "$(dirname "$0")/.."
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
export NUMBA_CACHE_DIR="${NUMBA_CACHE_DIR:-$PWD/.cache/numba}"
exec "${PYTHON:-.venv/bin/python}" -m flexmb.cli bag regenerate --dir bags "$@"
