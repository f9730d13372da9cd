#!/usr/bin/python3
"""Findings of the quadruplex study with contact (docs/validation.md), from its CSVs.

usage: quadruplex_findings.py DIR

DIR holds contact_r<R>.csv of scripts/quadruplex_study (the study config/studies/quadruplex_contact.yaml).
Prints, per radius: the contact onset v and the force there, the stiffness just before and after it,
the first slack cable, the ultimate state (largest force) and the largest overlap.
"""
import csv
import glob
import os
import sys


def read(path):
    with open(path, newline="") as f:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]


def slope(rows, i, j):
    return (rows[j]["actuation_force"] - rows[i]["actuation_force"]) / (rows[j]["actuation"] - rows[i]["actuation"])


def main(argv):
    if len(argv) != 1:
        sys.exit(__doc__)
    paths = sorted(glob.glob(os.path.join(argv[0], "contact_r*.csv")))
    if not paths:
        sys.exit(f"quadruplex_findings: no contact_r*.csv in {argv[0]}")
    print("| Rs (m) | contact onset v (m) | height there (m) | stiffness before / after onset (kN/m) "
          "| first slack cable at v (m) | largest force (kN) at v (m) | largest overlap (µm) |")
    print("|---|---|---|---|---|---|---|")
    for path in paths:
        radius = os.path.basename(path)[len("contact_r") : -len(".csv")]
        rows = read(path)
        on = next((i for i, r in enumerate(rows) if r["active_contacts"] > 0), None)
        slack = next((r["actuation"] for r in rows if r["slack_cables"] > 0), None)
        top = max(range(len(rows)), key=lambda i: rows[i]["actuation_force"])
        overlap = max(0.0, -min(r["min_gap"] for r in rows))
        if on is None:
            print(f"| {radius} | none | | | | | |")
            continue
        k = 8  # load steps either side of the onset for the secant stiffness
        before = slope(rows, max(0, on - 1 - k), on - 1) / 1e3
        after = slope(rows, on, min(len(rows) - 1, on + k)) / 1e3
        print(f"| {radius} | {rows[on]['actuation']:.4f} | {rows[on]['height']:.4f} | {before:.2f} / {after:.1f} "
              f"| {slack if slack is None else f'{slack:.4f}'} | {rows[top]['actuation_force'] / 1e3:.1f} at "
              f"{rows[top]['actuation']:.4f} | {overlap * 1e6:.0f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
