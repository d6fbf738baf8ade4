# Sourced by the deploy/local test scripts: sets ROOT (the repository) and BIN (the `sublevel`
# binary: SUBLEVEL_BIN, else target/release, else target/debug), or exits 2 saying how to build it.
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
BIN="${SUBLEVEL_BIN:-}"
for b in "$ROOT/target/release/sublevel" "$ROOT/target/debug/sublevel"; do
  [ -n "$BIN" ] || { [ -x "$b" ] && BIN="$b"; }
done
[ -x "$BIN" ] || { echo "no sublevel binary: cargo build first (or set SUBLEVEL_BIN)"; exit 2; }
