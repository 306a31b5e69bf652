#!/usr/bin/env python3
"""Writes the turned box as legacy VTK (argument: the output path): the 10x5x5-cell,
0.2 x 0.1 x 0.1 m box of scenes/seed-box.toml at 10x5x5 cells, turned by 30 degrees
about x, so it is still clamped at x = 0 and every cell is a parallelepiped that is not
axis-aligned (the parallelepiped kernel; the unturned box takes the cuboid kernel).
Used by scripts/board-cost.sh and scripts/qemu-check.sh."""
import math
import sys

nx, ny, nz, size = 10, 5, 5, (0.2, 0.1, 0.1)
c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
pts = []
for k in range(nz + 1):
    for j in range(ny + 1):
        for i in range(nx + 1):
            x, y, z = i * size[0] / nx, j * size[1] / ny, k * size[2] / nz
            pts.append((x, c * y - s * z, s * y + c * z))


def at(i, j, k):
    return i + (nx + 1) * (j + (ny + 1) * k)


cells = [[at(i, j, k), at(i + 1, j, k), at(i + 1, j + 1, k), at(i, j + 1, k),
          at(i, j, k + 1), at(i + 1, j, k + 1), at(i + 1, j + 1, k + 1), at(i, j + 1, k + 1)]
         for k in range(nz) for j in range(ny) for i in range(nx)]
with open(sys.argv[1], "w") as f:
    f.write("# vtk DataFile Version 3.0\nturned box\nASCII\nDATASET UNSTRUCTURED_GRID\n")
    f.write("POINTS %d double\n" % len(pts))
    f.writelines("%.17g %.17g %.17g\n" % p for p in pts)
    f.write("CELLS %d %d\n" % (len(cells), 9 * len(cells)))
    f.writelines("8 " + " ".join(map(str, q)) + "\n" for q in cells)
    f.write("CELL_TYPES %d\n" % len(cells))
    f.writelines("12\n" for _ in cells)
