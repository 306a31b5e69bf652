#!/usr/bin/env bash
# OpenIGTLink check: an independent client (pyigtl from PyPI, pinned below) drives the probe
# of a running `pe live --builtin --level coarse` with TRANSFORM messages and checks the
# tool force (POINT) rises, the surface (POLYDATA) has the surface's node count and moves,
# and an unknown device gets an error STRING while the connection goes on
# (tests/igtl/client.py says what it asserts and why). The server is stopped at the end,
# whatever happens (trap).
#
# Installs what it needs: pyigtl, crcmod and numpy (pinned) in a virtual environment under
# the target dir, only if missing. Env: OUT (default $TARGET_DIR/igtl-check: the server's
# log and the client's output), HTTP_PORT and IGTL_PORT (default: free ports).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET_DIR=${TARGET_DIR:-${CARGO_TARGET_DIR:-$ROOT/target}}
OUT=${OUT:-$TARGET_DIR/igtl-check}
rm -rf "$OUT" && mkdir -p "$OUT"
export RUST_BACKTRACE=0

PYIGTL=(pyigtl==0.3.4 crcmod==1.7 numpy==2.4.6)
VENV=$TARGET_DIR/igtl-venv
# (pyigtl 0.3.4's own __version__ says 0.3.2: ask the installed distribution.)
# Debian's python3 has venv only with python3-venv (ensurepip).
if ! python3 -c 'import ensurepip' 2>/dev/null; then
    echo "igtl-check: installing python3-venv"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
fi
if ! "$VENV/bin/python" -c 'import importlib.metadata as m, sys; sys.exit(m.version("pyigtl") != "0.3.4")' 2>/dev/null; then
    echo "igtl-check: installing ${PYIGTL[*]} in $VENV"
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q "${PYIGTL[@]}"
fi

source scripts/host-bins.sh

free_port() {
    python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}
HTTP_PORT=${HTTP_PORT:-$(free_port)}
IGTL_PORT=${IGTL_PORT:-$(free_port)}

# Standard input is /dev/null for a background job: pe live then runs until SIGINT (sent by
# the trap) or --duration (a bound should the trap not run).
"$PE" live --builtin --level coarse --listen "127.0.0.1:$HTTP_PORT" --igtl-port "$IGTL_PORT" \
    --duration 300 >"$OUT/pe-live.out" 2>"$OUT/pe-live.err" &
PE_PID=$!
stop_server() {
    if kill -0 "$PE_PID" 2>/dev/null; then
        kill -INT "$PE_PID" 2>/dev/null || true
        for _ in $(seq 50); do
            kill -0 "$PE_PID" 2>/dev/null || break
            sleep 0.1
        done
        kill -KILL "$PE_PID" 2>/dev/null || true
    fi
    wait "$PE_PID" 2>/dev/null || true
}
trap stop_server EXIT

# The server is ready when its OpenIGTLink port takes a connection.
for i in $(seq 600); do
    if ! kill -0 "$PE_PID" 2>/dev/null; then
        echo "igtl-check: pe live ended before listening:" >&2
        cat "$OUT/pe-live.err" >&2
        exit 1
    fi
    (exec 3<>"/dev/tcp/127.0.0.1/$IGTL_PORT") 2>/dev/null && break
    [ "$i" = 600 ] && { echo "igtl-check: nothing listens on $IGTL_PORT after 60 s" >&2; exit 1; }
    sleep 0.1
done

echo "igtl-check: pe live --builtin --level coarse on 127.0.0.1:$HTTP_PORT, OpenIGTLink on $IGTL_PORT"
if ! "$VENV/bin/python" tests/igtl/client.py --port "$IGTL_PORT" 2>&1 | tee "$OUT/client.out"; then
    echo "igtl-check: the client failed; pe live's log:" >&2
    tail -n 30 "$OUT/pe-live.err" >&2
    exit 1
fi
stop_server
grep -E "client [0-9]+ .*(left|refused)|OpenIGTLink" "$OUT/pe-live.err" | head -n 10 || true
echo "igtl-check: OK"
