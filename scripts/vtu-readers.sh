#!/usr/bin/env bash
# The result frames in the readers users have (tests/vtu/readers.py says what it asserts):
# meshio 5.3.5, which refused the frames' String field array before, and pyvista (VTK's XML
# reader, as ParaView). The volume frames of `pe solve` and board-sim's surface frames, on
# the built-in scene (coarse), long enough for the probe to move the tissue; and `pe solve`'s
# frames of a tetrahedral and a hexahedron-and-prism beam.
#
# Installs what it needs: meshio, pyvista, vtk and numpy (pinned) in a virtual environment
# under the target dir, only if missing.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET_DIR=${TARGET_DIR:-${CARGO_TARGET_DIR:-$ROOT/target}}
OUT=$TARGET_DIR/vtu-readers
rm -rf "$OUT" && mkdir -p "$OUT"
export RUST_BACKTRACE=0

PKGS=(meshio==5.3.5 pyvista==0.44.2 vtk==9.3.1 numpy==1.26.4)
VENV=$TARGET_DIR/vtu-venv
if ! python3 -c 'import ensurepip' 2>/dev/null; then
    echo "vtu-readers: installing python3-venv"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
fi
if ! "$VENV/bin/python" -c 'import importlib.metadata as m, sys; sys.exit(m.version("meshio") != "5.3.5" or m.version("pyvista") != "0.44.2")' 2>/dev/null; then
    echo "vtu-readers: installing ${PKGS[*]} in $VENV"
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q "${PKGS[@]}"
fi

source scripts/host-bins.sh

# The probe first touches the tissue near step 876 (see .ci/run): 1200 steps, the scene's
# output interval (pe solve) and the graphics frames the host received (board-sim).
"$PE" solve --builtin --level coarse --steps 1200 --vtk "$OUT/solve" >/dev/null
"$SIM" builtin --level coarse --steps 1200 --quiet --out "$OUT/sim" >/dev/null
# Tetrahedra (VTK_TETRA) and hexahedra with prisms (VTK_WEDGE), as pe solve writes them.
"$PE" solve tests/scenes/beam_tet.toml --vtk "$OUT/tet" >/dev/null
"$PE" solve tests/scenes/beam_mixed.toml --vtk "$OUT/mixed" >/dev/null
"$VENV/bin/python" tests/vtu/readers.py "$OUT/solve" "$OUT/sim/frames" "$OUT/tet:tetra" "$OUT/mixed:hexahedron,wedge"
