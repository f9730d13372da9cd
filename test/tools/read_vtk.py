#!/usr/bin/python3
"""Reads a tensegrity_run --vtk directory back with Python's own XML parser, checks that every file is
well formed VTK PolyData (counts, offsets, connectivity and array lengths agree) and prints, per step of
the collection, one JSON line: t, the points, and per cell its kind, force, radius, member and points;
with --csv instead one CSV line: t, the number of contact-point cells, the first point's x, y, z, then the
force of every strut cell. Exit 1 (with the reason on stderr) on anything malformed."""
import json
import os
import sys
import xml.etree.ElementTree as ET


def fail(message):
    print("read_vtk: " + message, file=sys.stderr)
    sys.exit(1)


def numbers(array, kind):
    return [kind(v) for v in (array.text or "").split()]


def read_piece(path):
    root = ET.parse(path).getroot()
    if root.tag != "VTKFile" or root.get("type") != "PolyData":
        fail(path + ": not a VTK PolyData file")
    piece = root.find("PolyData/Piece")
    n_points = int(piece.get("NumberOfPoints"))
    n_verts = int(piece.get("NumberOfVerts"))
    n_lines = int(piece.get("NumberOfLines"))
    pts = numbers(piece.find("Points/DataArray"), float)
    if len(pts) != 3 * n_points:
        fail("%s: %d coordinates for %d points" % (path, len(pts), n_points))
    points = [pts[3 * i:3 * i + 3] for i in range(n_points)]
    force = piece.find("PointData/DataArray[@Name='contact_force']")
    contact_force = numbers(force, float)
    if len(contact_force) != 3 * n_points:
        fail(path + ": contact_force does not have 3 components per point")
    cells = []
    for tag, count in (("Verts", n_verts), ("Lines", n_lines)):
        conn = numbers(piece.find(tag + "/DataArray[@Name='connectivity']"), int)
        offsets = numbers(piece.find(tag + "/DataArray[@Name='offsets']"), int)
        if len(offsets) != count:
            fail("%s: %d %s offsets for %d cells" % (path, len(offsets), tag, count))
        start = 0
        for end in offsets:
            ids = conn[start:end]
            if end < start or not ids or any(i < 0 or i >= n_points for i in ids):
                fail("%s: a %s cell with points %s out of 0..%d" % (path, tag, ids, n_points - 1))
            cells.append({"points": ids})
            start = end
        if start != len(conn):
            fail(path + ": connectivity longer than its offsets")
    for name, kind in (("kind", int), ("force", float), ("radius", float), ("member", int)):
        values = numbers(piece.find("CellData/DataArray[@Name='%s']" % name), kind)
        if len(values) != len(cells):
            fail("%s: %d %s values for %d cells" % (path, len(values), name, len(cells)))
        for cell, v in zip(cells, values):
            cell[name] = v
    return {"points": points, "contact_force": [contact_force[3 * i:3 * i + 3] for i in range(n_points)],
            "cells": cells}


def main():
    args = sys.argv[1:]
    csv = "--csv" in args
    args = [a for a in args if a != "--csv"]
    if len(args) != 1:
        fail("usage: read_vtk.py [--csv] DIR/run.pvd")
    pvd = args[0]
    root = ET.parse(pvd).getroot()
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        fail(pvd + ": not a VTK collection")
    for dataset in root.find("Collection"):
        step = read_piece(os.path.join(os.path.dirname(pvd), dataset.get("file")))
        step["t"] = float(dataset.get("timestep"))
        if not csv:
            print(json.dumps(step))
            continue
        kinds = [c["kind"] for c in step["cells"]]
        row = [step["t"], kinds.count(3)] + step["points"][0] + [c["force"] for c in step["cells"] if c["kind"] == 0]
        print(",".join(repr(v) for v in row))


if __name__ == "__main__":
    main()
