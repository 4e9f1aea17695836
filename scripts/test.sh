#!/usr/bin/env bash
# The README's test command. On a fresh machine: creates .venv (unless a virtual environment is
# active), installs Samba with its test extras, installs Debian's chromium for the browser test
# when running as root in CI, then runs the whole test suite. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=scripts/_env.sh
source scripts/_env.sh "[dev]"
if [ "${CI:-}" = "true" ] && [ "$(id -u)" = 0 ] && ! command -v chromium >/dev/null 2>&1; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
        || echo "chromium could not be installed: the browser tests will be skipped" >&2
fi
export OPENBLAS_NUM_THREADS=1 OPENCV_LOG_LEVEL=ERROR
# pytest exits 5 when it collects no test: that is a failure here, as is any other non-zero code
python -m pytest tests "$@"
