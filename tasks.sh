#!/usr/bin/env bash
# One entry point for the README's commands:
#   bash tasks.sh demo    set up (first time) and run the main job: the double-pendulum
#                         derivation demo, then `lagjax run foucault-pendulum`
#   bash tasks.sh test    set up (first time) and run the test suite
#   bash tasks.sh integration
#                         the integration checks: every notebook and the benchmark
#                         scripts' quick modes, each in a fresh process (CI's second step)
#   bash tasks.sh bench   set up with the benchmark extras and run the benchmarks
# Set-up creates ./.venv with the package installed in editable mode; it is
# re-run whenever pyproject.toml is newer than the environment's stamp.
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
VENV=.venv

setup() {
    local extras=$1 stamp="$VENV/.stamp-$1"
    if [ ! -x "$VENV/bin/python" ]; then
        "$PY" -m venv "$VENV"
    fi
    if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
        "$VENV/bin/python" -m pip install --quiet --upgrade pip
        "$VENV/bin/python" -m pip install --quiet -e ".[$extras]"
        touch "$stamp"
    fi
}

cmd=${1:-}
shift || true
case "$cmd" in
    demo)
        setup test
        "$VENV/bin/python" -m lagjax.cli.demo
        exec "$VENV/bin/lagjax" run foucault-pendulum "$@" ;;
    # Two pytest workers by default (the CI machine has 2 cores); LAGJAX_TEST_WORKERS=0
    # runs in one process. Whole files per worker: module fixtures (benchmark runs) and
    # a file's jitted functions are built once, not once on each worker.
    test) setup test; exec "$VENV/bin/python" -m pytest -n "${LAGJAX_TEST_WORKERS:-2}" --dist loadfile "$@" ;;
    integration)
        setup test
        exec "$VENV/bin/python" -m pytest -n "${LAGJAX_TEST_WORKERS:-2}" --dist loadfile -m integration "$@" ;;
    bench) setup "test,bench"; exec "$VENV/bin/python" -m benchmarks.derivation_overhead "$@" ;;
    *) echo "usage: bash tasks.sh {demo|test|integration|bench} [args...]" >&2; exit 2 ;;
esac
