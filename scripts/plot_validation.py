#!/usr/bin/python3
"""Charts for docs/validation.md from the CSV of hapco-fem-validate.

usage: scripts/plot_validation.py validation.csv [--out docs/figures]

Writes validation_error_vs_dofs.png and validation_error_vs_time.png (log-log, Tet4 and Tet10).
Solid lines: relative error of the tip deflection against Timoshenko beam theory. Dashed lines:
error against the converged 3D value, estimated by Richardson extrapolation of the three finest
Tet10 meshes (nested meshes, so the compliance grows monotonically towards it). The gap
between the two is the modelling difference between the clamped 3D bar and the beam.
"""
import argparse
import csv
import math
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_rows(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in ("nx", "ny", "nz", "dofs", "free_dofs", "factor_nonzeros"):
            r[k] = int(r[k])
        for k in ("tip_deflection_m", "beam_theory_m", "relative_error", "assembly_s",
                  "factorization_s", "solve_s"):
            r[k] = float(r[k])
    return rows


def richardson_limit(rows):
    """Limit of d(n) = d_inf - C n^-p from the three finest Tet10 meshes (n = cells along x)."""
    tet10 = sorted((r for r in rows if r["order"] == "Tet10"), key=lambda r: r["nx"])[-3:]
    if len(tet10) < 3:
        return None, None
    (n1, d1), (n2, d2), (n3, d3) = [(r["nx"], r["tip_deflection_m"]) for r in tet10]
    target = (d2 - d1) / (d3 - d2)

    def ratio(p):
        return (n1 ** -p - n2 ** -p) / (n2 ** -p - n3 ** -p)

    lo, hi = 0.1, 8.0  # ratio(p) increases with p: bisect
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if ratio(mid) < target:
            lo = mid
        else:
            hi = mid
    p = 0.5 * (lo + hi)
    c = (d3 - d2) / (n2 ** -p - n3 ** -p)
    return d3 + c * n3 ** -p, p


def plot(rows, limit, x_key, x_label, path, title):
    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=130)
    styles = {"Tet4": ("tab:orange", "s"), "Tet10": ("tab:blue", "o")}
    for order, (color, marker) in styles.items():
        sel = sorted((r for r in rows if r["order"] == order), key=lambda r: r["dofs"])
        if not sel:
            continue
        xs = [x_key(r) for r in sel]
        ax.loglog(xs, [100 * abs(r["relative_error"]) for r in sel], color=color, marker=marker,
                  label=f"{order} vs beam theory")
        if limit is not None:
            ax.loglog(xs, [100 * abs(r["tip_deflection_m"] - limit) / limit for r in sel],
                      color=color, marker=marker, linestyle="--", mfc="none",
                      label=f"{order} vs converged 3D (discretization only)")
        for r in sel:
            if order == "Tet10" and (r["nx"], r["ny"]) == (20, 4):
                ax.annotate("default 20x4x4", (x_key(r), 100 * abs(r["relative_error"])),
                            textcoords="offset points", xytext=(4, -14), fontsize=8)
    ax.axhline(2.0, color="gray", linewidth=1, linestyle=":")
    ax.text(ax.get_xlim()[0] * 1.1, 2.15, "2 % tolerance", color="gray", fontsize=8)
    ax.set_xlabel(x_label)
    ax.set_ylabel("|relative error of tip deflection| (%)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    print("wrote", path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "docs",
                                                      "figures"))
    args = parser.parse_args()
    rows = read_rows(args.csv)
    if not rows:
        raise SystemExit(f"{args.csv}: no rows")
    args.out = os.path.normpath(args.out)
    os.makedirs(args.out, exist_ok=True)
    limit, p = richardson_limit(rows)
    if limit is not None:
        beam = rows[0]["beam_theory_m"]
        print(f"Richardson 3D limit {limit:.6e} m (observed order p = {p:.2f} in 1/n), "
              f"{100 * (limit - beam) / beam:+.3f} % vs beam theory {beam:.6e} m")
    title = "Red bar cantilever (0.10 x 0.02 x 0.02 m, E = 3 MPa, nu = 0.3), tip shear load"
    plot(rows, limit, lambda r: r["dofs"], "degrees of freedom",
         os.path.join(args.out, "validation_error_vs_dofs.png"), title)
    plot(rows, limit, lambda r: r["assembly_s"] + r["factorization_s"] + r["solve_s"],
         "time: assembly + factorization + one solve (s)",
         os.path.join(args.out, "validation_error_vs_time.png"), title)


if __name__ == "__main__":
    main()
