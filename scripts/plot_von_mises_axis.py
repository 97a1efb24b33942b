#!/usr/bin/python3
"""The von Mises field of an exported state against Hertz's on the contact axis.

usage: /usr/bin/python3 scripts/plot_von_mises_axis.py BODY_VTU FORCE_N RADIUS_M YOUNG_PA POISSON OUT_PNG
BODY_VTU: a body_K.vtu of palpate-verify --vtk DIR --vtk-ascii (the text format; this
reader does not decode the binary one). Plots von_mises of the particles within 4 cm of
the tool's axis (x = y = 0) against their depth below the undeformed top face z = 0, with
the half-space solution on the axis (zeta = z / a, a = (3 F R / 4 E*)^(1/3),
p0 = 3 F / (2 pi a^2)):
    sigma_r / p0 = -(1 + nu) (1 - zeta atan(1 / zeta)) + 1 / (2 (1 + zeta^2)),
    sigma_z / p0 = -1 / (1 + zeta^2),   von Mises = |sigma_z - sigma_r|,
and prints both maxima and their depths.
"""
import re
import sys

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def array(text, name):
    m = re.search(r'Name="%s"[^>]*format="ascii">(.*?)</DataArray>' % name, text, re.S)
    if m is None:
        sys.exit("%s: no ascii DataArray %s (write it with --vtk-ascii)" % (sys.argv[1], name))
    return np.array(m.group(1).split(), float)


def main():
    if len(sys.argv) != 7:
        sys.exit(__doc__)
    path, force, radius, young, nu, out = sys.argv[1], *map(float, sys.argv[2:6]), sys.argv[6]
    text = open(path).read()
    x = array(text, "Points").reshape(-1, 3)
    rest = x - array(text, "displacement").reshape(-1, 3)
    vm = array(text, "von_mises")
    near = np.hypot(rest[:, 0], rest[:, 1]) < 0.04
    depth = -rest[near, 2]
    e_star = young / (1 - nu**2)
    a = (3 * force * radius / (4 * e_star)) ** (1 / 3)
    p0 = 3 * force / (2 * np.pi * a**2)
    z = np.linspace(1e-4 * a, 5 * a, 400)
    zeta = z / a
    sigma_r = -(1 + nu) * (1 - zeta * np.arctan(1 / zeta)) + 0.5 / (1 + zeta**2)
    sigma_z = -1 / (1 + zeta**2)
    hertz = np.abs(sigma_z - sigma_r) * p0
    plt.plot(depth, vm[near], "o", ms=4, label="particles within 4 cm of the axis (reference position)")
    plt.plot(z, hertz, "-", label="Hertz on the axis (half-space)")
    plt.xlabel("depth below the undeformed top face [m]")
    plt.ylabel("von Mises [Pa]")
    plt.title("%.2f N: a = %.3f m, p0 = %.0f Pa" % (force, a, p0))
    plt.legend()
    plt.grid(alpha=0.3)
    plt.savefig(out, dpi=90)
    i, j = np.argmax(hertz), np.argmax(vm[near])
    print("Hertz: max %.0f Pa at %.4f m (%.2f a); particles: max %.0f Pa at %.4f m" %
          (hertz[i], z[i], z[i] / a, vm[near][j], depth[j]))


main()
