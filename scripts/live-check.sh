#!/usr/bin/env bash
# Live check: the trainer page in a real browser. Starts `pe live --builtin --level coarse`
# on a free local port, loads http://127.0.0.1:PORT/ in Debian's chromium (headless,
# WebGL2 through SwiftShader) driven by Playwright (tests/browser/live-check.mjs), drags
# the probe onto the right tube with real mouse events, and asserts from what the page
# received (window.peLive) that the tube moved, the far organs much less, the force bar
# rose and surface frames came at >= 25 Hz. Keeps a screenshot: $OUT/trainer.png.
#
# Installs what it needs when missing: chromium (apt), Node.js and npm (apt), and
# playwright-core (npm, pinned in tests/browser/package-lock.json; it drives
# /usr/bin/chromium and downloads no browser).
# Env: OUT (default $CARGO_TARGET_DIR/live or target/live), PE (a built pe to use instead
# of building one), LEVEL (the built-in level served, default coarse) and THREADS (solver
# threads, default 1): `LEVEL=medium THREADS=2` measures the built-in medium scene live
# (the server's summary, with the real-time factor and the pose-to-force latency, ends
# $OUT/server.log); LIVE_ARGS adds pe live options (e.g. `--plan DIR`: the model pe plan
# finds for real time where the full one cannot keep up, docs/live.md).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export RUST_BACKTRACE=0
TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
OUT=${OUT:-$TARGET_DIR/live}
mkdir -p "$OUT"

MISSING=()
[ -x /usr/bin/chromium ] || MISSING+=(chromium)
command -v node >/dev/null 2>&1 || MISSING+=(nodejs)
command -v npm >/dev/null 2>&1 || MISSING+=(npm)
if [ ${#MISSING[@]} -gt 0 ]; then
    echo "live-check: installing ${MISSING[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${MISSING[@]}" >/dev/null
fi
BROWSER=$ROOT/tests/browser
WANT=$(node -e 'console.log(require(process.argv[1]).packages["node_modules/playwright-core"].version)' \
    "$BROWSER/package-lock.json")
HAVE=$(node -e 'try { console.log(require(process.argv[1]).version) } catch { console.log("none") }' \
    "$BROWSER/node_modules/playwright-core/package.json")
if [ "$HAVE" != "$WANT" ]; then
    echo "live-check: installing playwright-core $WANT (npm ci)"
    (cd "$BROWSER" && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error)
fi

# The page's own modules first (no browser): instrument motions, frame decoding, normals.
node --test "$BROWSER/" >"$OUT/page-tests.log" 2>&1 || { cat "$OUT/page-tests.log" >&2; exit 1; }
grep -E '^# (pass|fail)' "$OUT/page-tests.log" | tr '\n' ' ' | sed 's/^/live-check: page modules: /; s/$/\n/'

if [ -z "${PE:-}" ]; then
    source scripts/host-bins.sh
fi

PORT=$(node -e 'const s = require("net").createServer().listen(0, "127.0.0.1", () => {
    console.log(s.address().port); s.close(); })')
LOG=$OUT/server.log
echo "live-check: pe live --builtin --level ${LEVEL:-coarse} on 127.0.0.1:$PORT (log: $LOG)"
# Standard input from /dev/null (pe live ends when a watched terminal or pipe closes) and
# --duration as a backstop: the trap below stops it first. One solver thread: the coarse
# scene runs faster on one, and the browser's software WebGL needs the other core.
"$PE" live --builtin --level "${LEVEL:-coarse}" --listen "127.0.0.1:$PORT" --igtl-port 0 --duration 900 \
    --threads "${THREADS:-1}" ${LIVE_ARGS:-} \
    </dev/null >"$LOG" 2>&1 &
SERVER=$!
# Ctrl-C (SIGINT) ends pe live with its summary; a server that has not ended after 5 s is
# killed.
stop_server() {
    if kill -0 "$SERVER" 2>/dev/null; then
        kill -INT "$SERVER" 2>/dev/null || true
        for _ in $(seq 50); do
            kill -0 "$SERVER" 2>/dev/null || break
            sleep 0.1
        done
        kill -KILL "$SERVER" 2>/dev/null || true
    fi
    wait "$SERVER" 2>/dev/null || true
}
trap stop_server EXIT

# The server builds the scene first: wait until it answers (or has died).
READY=0
for _ in $(seq 1 600); do
    if ! kill -0 "$SERVER" 2>/dev/null; then
        echo "live-check: pe live exited before serving:" >&2
        cat "$LOG" >&2
        exit 1
    fi
    if node -e 'require("http").get(process.argv[1], (r) => process.exit(r.statusCode === 200 ? 0 : 1))
        .on("error", () => process.exit(1))' "http://127.0.0.1:$PORT/" 2>/dev/null; then
        READY=1
        break
    fi
    sleep 0.2
done
if [ $READY -ne 1 ]; then
    echo "live-check: pe live does not answer on 127.0.0.1:$PORT after 2 minutes:" >&2
    tail -n 40 "$LOG" >&2
    exit 1
fi

set +e
node "$BROWSER/live-check.mjs" "http://127.0.0.1:$PORT/" "$OUT"
STATUS=$?
set -e
if [ $STATUS -ne 0 ]; then
    echo "live-check: the server's log ($LOG):" >&2
    tail -n 40 "$LOG" >&2
    exit $STATUS
fi
