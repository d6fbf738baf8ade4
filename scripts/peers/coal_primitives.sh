#!/usr/bin/env bash
# Builds and runs the coal peer timing bench for primitive pairs (scripts/peers/coal_primitives.cpp) on the
# cases written by scripts/peers/coal_primitives.py; prints JSON lines (coal's settings, then one per pair).
#   bash scripts/peers/coal_primitives.sh [CASES.csv]   (default: crates/query/tests/data/coal_primitives.csv)
# Needs g++ and Eigen (Debian: g++ libeigen3-dev, installed when missing) and coal's C++ library from its PyPI
# wheel: reuses the venv under ${COAL_WORK:-/tmp/coal-peer} (as the coal peer benchmark's run.sh does) and
# installs coal==3.0.3 into it when absent. The binary is built there too, with -O3 -march=native.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
cases=$(realpath "${1:-$root/crates/query/tests/data/coal_primitives.csv}")
work=${COAL_WORK:-${TMPDIR:-/tmp}/coal-peer}
mkdir -p "$work"
for pkg in g++ libeigen3-dev python3-venv; do
  dpkg -s "$pkg" >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq "$pkg" >/dev/null; }
done
[ -x "$work/venv/bin/python" ] || python3 -m venv "$work/venv"
prefix=$(ls -d "$work"/venv/lib/python3*/site-packages/cmeel.prefix 2>/dev/null || true)
if [ -z "$prefix" ] || [ ! -f "$prefix/include/coal/distance.h" ]; then
  "$work/venv/bin/pip" install -q coal==3.0.3 >&2
  prefix=$(ls -d "$work"/venv/lib/python3*/site-packages/cmeel.prefix)
fi
bin="$work/coal_primitives"
if [ ! -x "$bin" ] || [ "$here/coal_primitives.cpp" -nt "$bin" ]; then
  g++ -O3 -march=native -std=c++17 -w -I"$prefix/include" -I/usr/include/eigen3 "$here/coal_primitives.cpp" \
      -L"$prefix/lib" -lcoal -Wl,-rpath,"$prefix/lib" -o "$bin"
fi
exec "$bin" "$cases"
