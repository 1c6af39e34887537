#!/usr/bin/python3
"""Reads a hapco-sim --vtk series with VTK's own XML readers (what ParaView uses) and checks it.

usage: check_vtk_series.py DIR EXPECTED_STEPS...
Checks: the .pvd lists obstacle, tool and contacts files for each expected step; every file
reads without error; the bodies have tetrahedral cells and finite displacement/force arrays;
the contact points carry normals, forces and states in {0, 1, 2}; the contact forces on the
tool sum to the opposite of those on the obstacle (action = reaction, read back from files).
"""
import math
import os
import sys
import xml.etree.ElementTree as ET

from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
from vtkmodules.util.numpy_support import vtk_to_numpy


def read(path):
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(path)
    reader.Update()
    if reader.GetErrorCode() != 0:
        raise SystemExit(f"VTK could not read {path}")
    return reader.GetOutput()


def main():
    folder, steps = sys.argv[1], [int(s) for s in sys.argv[2:]]
    entries = ET.parse(os.path.join(folder, "hapco.pvd")).getroot().findall("./Collection/DataSet")
    by_step = {}
    for entry in entries:
        by_step.setdefault(int(float(entry.get("timestep"))), []).append(entry.get("file"))
    if sorted(by_step) != steps:
        raise SystemExit(f"pvd lists steps {sorted(by_step)}, expected {steps}")
    for step, files in by_step.items():
        if len(files) != 3:
            raise SystemExit(f"step {step}: expected 3 files, got {files}")
        totals = {}
        for name in files:
            grid = read(os.path.join(folder, name))
            points = grid.GetNumberOfPoints()
            if points == 0:
                raise SystemExit(f"{name}: no points")
            data = grid.GetPointData()
            if name.startswith("contacts"):
                states = vtk_to_numpy(data.GetArray("state"))
                if not set(states.tolist()) <= {0, 1, 2}:
                    raise SystemExit(f"{name}: bad states {set(states.tolist())}")
                normals = vtk_to_numpy(data.GetArray("normal"))
                if abs(abs(normals).sum(axis=1).max() - 1) > 1e-9 and abs((normals ** 2).sum(axis=1) - 1).max() > 1e-9:
                    raise SystemExit(f"{name}: normals are not unit vectors")
            else:
                cell_types = {grid.GetCellType(i) for i in range(grid.GetNumberOfCells())}
                if not cell_types <= {10, 24}:
                    raise SystemExit(f"{name}: unexpected cell types {cell_types}")
                u = vtk_to_numpy(data.GetArray("displacement_m"))
                f = vtk_to_numpy(data.GetArray("contact_force_n"))
                if u.shape != (points, 3) or not all(math.isfinite(x) for x in u.ravel()):
                    raise SystemExit(f"{name}: bad displacement array")
                totals[name.split("_")[0]] = f.sum(axis=0)
        balance = totals["tool"] + totals["obstacle"]
        scale = max(1.0, float(abs(totals["tool"]).max()))
        if abs(balance).max() > 1e-9 * scale:
            raise SystemExit(f"step {step}: tool and obstacle contact forces do not balance: {balance}")
        print(f"step {step}: 3 files read by VTK, contact force on tool {totals['tool']} N")
    print("ok")


if __name__ == "__main__":
    main()
