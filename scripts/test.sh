#!/usr/bin/env bash
# The README's test command: install Samba with its test extras into the active Python
# environment, then run the whole test suite. pytest's "no tests collected" (exit 5) is an error.
set -euo pipefail
cd "$(dirname "$0")/.."
python -m pip install -q -e ".[dev]"
export OPENBLAS_NUM_THREADS=1 OPENCV_LOG_LEVEL=ERROR
python -m pytest tests "$@"
