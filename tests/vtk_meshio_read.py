#!/usr/bin/python3
"""What an independent reader finds in palpate's VTK files (tests/vtk_meshio_test.cpp).

usage: /usr/bin/python3 tests/vtk_meshio_read.py FILE...

Each .vtu is read by Debian's meshio (python3-meshio; none of palpate's code), each .pvd by
Python's own XML parser. Prints one JSON object on stdout, keyed by the file as given:

  .vtu: {"points": [x0, y0, z0, x1, ...], "point_count": n,
         "cells": [{"type": meshio's name ("tetra", ...), "connectivity": [...]}, ...],
         "point_data": {name: {"shape": [...], "values": [flattened]}},
         "field_data": {name: {"shape": [...], "values": [flattened]}}}
  .pvd: {"datasets": [{"timestep": t, "part": p, "file": f}, ...]}

Floats go out as Python's repr (the shortest text that reads back to the same double), so
the C++ side compares bit for bit. Exit status 1 (a message on stderr) when a file cannot be
read: that is the finding the test reports.
"""
import json
import sys
import xml.etree.ElementTree as ET

import meshio
import numpy as np


def flat(array):
    a = np.asarray(array)
    return {"shape": list(a.shape), "values": a.ravel().tolist()}


def read_vtu(path):
    mesh = meshio.read(path)
    return {
        "points": np.asarray(mesh.points, dtype=np.float64).ravel().tolist(),
        "point_count": int(mesh.points.shape[0]),
        "cells": [{"type": block.type, "connectivity": np.asarray(block.data).ravel().tolist()}
                  for block in mesh.cells],
        "point_data": {name: flat(values) for name, values in mesh.point_data.items()},
        "field_data": {name: flat(values) for name, values in mesh.field_data.items()},
    }


def read_pvd(path):
    root = ET.parse(path).getroot()
    if root.get("type") != "Collection":
        raise ValueError(f"{path}: VTKFile type {root.get('type')!r}, not Collection")
    return {"datasets": [{"timestep": float(d.get("timestep")), "part": int(d.get("part")), "file": d.get("file")}
                         for d in root.iter("DataSet")]}


def main(files):
    out = {}
    for path in files:
        try:
            out[path] = read_pvd(path) if path.endswith(".pvd") else read_vtu(path)
        except Exception as e:  # a file meshio cannot read is the test's finding: say which and why
            print(f"vtk_meshio_read.py: {path}: {type(e).__name__}: {e}", file=sys.stderr)
            return 1
    json.dump(out, sys.stdout)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
