#!/usr/bin/env bash
# The Python client's tests: a venv (target/py-venv), the pinned toolchain (requirements-test.txt),
# the package built from clients/python (its gRPC stubs generated from proto/ at build time), then
# pytest against a real server binary (SUBLEVEL_BIN, else the newer of target/{release,debug}/sublevel,
# built with `cargo build --locked --bin sublevel` when neither exists). Exits non-zero on a failure.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT="$PWD"
VENV="${SUBLEVEL_PY_VENV:-$ROOT/target/py-venv}"
PYTHON="${PYTHON:-python3}"
REQ="$ROOT/clients/python/requirements-test.txt"

if [ ! -x "$VENV/bin/python" ]; then
  echo "python client: creating $VENV" >&2
  if ! "$PYTHON" -m venv "$VENV"; then
    # Debian's system Python ships venv separately.
    rm -rf "$VENV"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq python3-venv
    "$PYTHON" -m venv "$VENV"
  fi
fi
PY="$VENV/bin/python"
# The toolchain, once per change of requirements-test.txt.
STAMP="$VENV/.sublevel-requirements-test.txt"
if ! cmp -s "$REQ" "$STAMP"; then
  echo "python client: installing $(grep -v '^#' "$REQ" | tr '\n' ' ')" >&2
  "$PY" -m pip install --quiet --disable-pip-version-check -r "$REQ"
  cp "$REQ" "$STAMP"
fi
# The package itself, rebuilt every run so the stubs follow proto/ (grpcio-tools from the venv).
"$PY" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation --force-reinstall "$ROOT/clients/python"

if [ -z "${SUBLEVEL_BIN:-}" ] && [ ! -x target/release/sublevel ] && [ ! -x target/debug/sublevel ]; then
  echo "python client: building the server binary" >&2
  cargo build --locked --bin sublevel
fi

if [ -n "${SUBLEVEL_BIN:-}" ]; then
  SUBLEVEL_BIN="$(realpath "$SUBLEVEL_BIN")"
  export SUBLEVEL_BIN
fi
cd "$ROOT/clients/python"
exec "$PY" -m pytest -p no:cacheprovider -q tests "$@"
