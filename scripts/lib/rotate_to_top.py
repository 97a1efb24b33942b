#!/usr/bin/python3
"""Rotate a body about the origin so that the direction of a site S becomes +z (its top).

A site of a hemisphere centred at the origin (scripts/make_mesh.sh --dome) pressed along the
skin's normal is the same problem as the rotated body pressed straight down at its top: the
surface map of a dome (scripts/surface_map_study.sh --dome) presses each site that way, on
rotated copies of the scene's mesh and of the reference's meshes. The rotation is about the
axis S x z by the angle between S and z (none when S is on the z axis).

usage: rotate_to_top.py mesh IN.msh OUT.msh SX SY SZ    the gmsh 4.1 ASCII mesh IN rotated
       rotate_to_top.py point PX PY PZ SX SY SZ         prints the rotated point P (m)

Only node coordinates change (written with 17 significant digits); elements, tags and
physical groups are kept, so a rotated mesh has the same tetrahedra, volumes and groups.
"""
import math
import sys


def rotation(site):
    """The 3 x 3 matrix taking the direction of `site` to +z (Rodrigues)."""
    sx, sy, sz = site
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    if norm == 0:
        sys.exit("rotate_to_top.py: the site is the origin")
    nx, ny, nz = sx / norm, sy / norm, sz / norm
    s = math.hypot(nx, ny)  # sin of the angle; the axis is (ny, -nx, 0) / s
    if s < 1e-15:
        if nz > 0:
            return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        sys.exit("rotate_to_top.py: the site points straight down")
    kx, ky, c = ny / s, -nx / s, nz
    t = 1 - c
    return [[c + kx * kx * t, kx * ky * t, ky * s],
            [kx * ky * t, c + ky * ky * t, -kx * s],
            [-ky * s, kx * s, c]]


def apply(Q, p):
    return [sum(Q[i][j] * p[j] for j in range(3)) for i in range(3)]


def rotate_mesh(path_in, path_out, Q):
    lines = open(path_in).read().split("\n")
    if lines[lines.index("$MeshFormat") + 1].split()[0] != "4.1":
        sys.exit("rotate_to_top.py: %s: only gmsh 4.1 ASCII meshes" % path_in)
    i = lines.index("$Nodes")
    blocks = int(lines[i + 1].split()[0])
    k = i + 2
    for _ in range(blocks):
        dim, tag, parametric, n = (int(v) for v in lines[k].split())
        if parametric:
            sys.exit("rotate_to_top.py: %s: parametric node coordinates are not supported" % path_in)
        k += 1 + n
        for j in range(n):
            x = [float(v) for v in lines[k + j].split()[:3]]
            lines[k + j] = " ".join("%.17g" % v for v in apply(Q, x))
        k += n
    open(path_out, "w").write("\n".join(lines))


def main():
    a = sys.argv[1:]
    if len(a) == 6 and a[0] == "mesh":
        rotate_mesh(a[1], a[2], rotation([float(v) for v in a[3:6]]))
    elif len(a) == 7 and a[0] == "point":
        print(" ".join("%.12g" % v for v in apply(rotation([float(v) for v in a[4:7]]), [float(v) for v in a[1:4]])))
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
