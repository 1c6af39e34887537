#!/usr/bin/python3
"""Hertz validation chart (docs/validation.md): force against indentation of hapco-sim runs of
tests/data/scenes/hertz.txtpb, with Hertz's F = 4/3 E* R^1/2 d^3/2 for the half-space and for
the block (its clamped base at depth H: the half-space needs d + c F, c = (3 - 2nu)(1 + nu) /
(2 pi E H)), and the relative error of each run against the block's Hertz curve.

usage: plot_hertz.py OUT.png LABEL=RUN.csv [LABEL=RUN.csv ...]
  RUN.csv: hapco-sim --csv of the Hertz scene (columns dz_m, fz_n).
"""
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# tests/data/scenes/hertz.txtpb
E_BLOCK, NU_BLOCK, E_SPHERE, NU_SPHERE = 1.0e6, 0.3, 2.0e8, 0.3  # Pa, -
RADIUS_M, DEPTH_OF_BASE_M = 0.010, 0.050
E_STAR = 1.0 / ((1 - NU_BLOCK**2) / E_BLOCK + (1 - NU_SPHERE**2) / E_SPHERE)
BASE_COMPLIANCE = (3 - 2 * NU_BLOCK) * (1 + NU_BLOCK) / (2 * math.pi * E_BLOCK * DEPTH_OF_BASE_M)


def hertz_force(depth_m):
    return 4.0 / 3.0 * E_STAR * math.sqrt(RADIUS_M) * max(depth_m, 0.0) ** 1.5


def block_force(depth_m):
    """F with hertz_force(d + c F) = F (fixed point; c F is a few % of d)."""
    force = hertz_force(depth_m)
    for _ in range(50):
        force = hertz_force(depth_m + BASE_COMPLIANCE * force)
    return force


def main():
    if len(sys.argv) < 3 or any("=" not in a for a in sys.argv[2:]):
        raise SystemExit(__doc__)
    out = sys.argv[1]
    fig, (ax_force, ax_error) = plt.subplots(1, 2, figsize=(11, 4.2))
    depths = [k * 1e-6 for k in range(0, 401)]
    ax_force.plot([d * 1e3 for d in depths], [hertz_force(d) for d in depths], "k-", lw=1.5, label="Hertz, half-space")
    ax_force.plot([d * 1e3 for d in depths], [block_force(d) for d in depths], "k--", lw=1.2, label="Hertz, block (clamped base)")
    for arg in sys.argv[2:]:
        label, path = arg.split("=", 1)
        rows = list(csv.DictReader(open(path)))
        d = [-float(r["dz_m"]) for r in rows]
        f = [float(r["fz_n"]) for r in rows]
        ax_force.plot([x * 1e3 for x in d], f, "o-", ms=2.5, lw=0.8, label=label)
        ax_error.plot([x * 1e3 for x in d if x >= 5e-5], [100 * (y - block_force(x)) / block_force(x) for x, y in zip(d, f) if x >= 5e-5],
                      "o-", ms=2.5, lw=0.8, label=label)
    ax_force.set_xlabel("indentation d (mm)")
    ax_force.set_ylabel("normal force F (N)")
    ax_force.set_title("Sphere R = 10 mm into a thick block, frictionless")
    ax_force.grid(alpha=0.3)
    ax_force.legend(fontsize=8)
    ax_error.axhline(0, color="k", lw=0.8)
    ax_error.set_xlabel("indentation d (mm)")
    ax_error.set_ylabel("F error vs Hertz for the block (%)")
    ax_error.set_title("Error by mesh (contact element = mesh_size / 16)")
    ax_error.grid(alpha=0.3)
    ax_error.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
