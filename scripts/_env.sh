# Sourced by demo.sh and test.sh: use the active virtual environment, else create/activate .venv
# in the repository, then install Samba (editable) with the extras given as $1 (e.g. "[dev]").
if [ -z "${VIRTUAL_ENV:-}" ]; then
    [ -x .venv/bin/python ] || python3 -m venv .venv
    # shellcheck disable=SC1091
    source .venv/bin/activate
fi
python -m pip install -q --upgrade pip >/dev/null
python -m pip install -q -e ".${1:-}"
