# Sourced by platform-up.sh and platform-down.sh: where the platform keeps its state, and
# which Python has the project installed (EOSP_PYTHON, else .venv, else python3).
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
STATE=${EOSP_PLATFORM_DIR:-$ROOT/.platform}
if [[ -n ${EOSP_PYTHON:-} ]]; then
    PY=$EOSP_PYTHON
elif [[ -x $ROOT/.venv/bin/python ]]; then
    PY=$ROOT/.venv/bin/python
else
    PY=$(command -v python3)
fi
export ROOT STATE PY
