#!/usr/bin/env bash
# The README's main command. On a fresh machine: creates .venv (unless a virtual environment is
# active), installs Samba, reconstructs the sample take shipped in the package, then runs the
# live demo (4 simulated motes + server + browser viewer on http://127.0.0.1:8080) until Ctrl-C.
# Extra arguments go to samba-demo (e.g. --duration 30).
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=scripts/_env.sh
source scripts/_env.sh ""
export OPENBLAS_NUM_THREADS=1
echo "== samba-reconstruct on the sample take (the first run compiles the solver: about a minute)"
samba-reconstruct sample --out sample_joints.npz
echo "== samba-demo: open http://127.0.0.1:8080 ; Ctrl-C to stop"
samba-demo --http 127.0.0.1:8080 "$@"
