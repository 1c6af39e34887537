#!/usr/bin/python3
"""Charts for docs/contact-benchmark.md from the CSV of `contact_bench --csv FILE`.

  contact_time_vs_tolerance.png: time to reach fc3d 1e-4 / 1e-6 / 1e-8 against m, per solver,
                                 log-log (cold start solid, warm start dashed; a solver that
                                 did not reach the tolerance within the cap is left out).
  contact_sweep_ratio.png:       time of one sweep / time of one dense W·r, per solver and m.

Usage: /usr/bin/python3 scripts/plot_contact_benchmark.py bench.csv [out_dir]
(out_dir defaults to docs/figures next to this script).
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ORDER = ["local-uzawa", "global-uzawa-gs", "global-uzawa-jacobi", "reference",
         "siconos-nsgs", "siconos-dsfp"]
COLOURS = {"local-uzawa": "tab:red", "global-uzawa-gs": "tab:blue",
           "global-uzawa-jacobi": "tab:cyan", "reference": "tab:gray",
           "siconos-nsgs": "tab:green", "siconos-dsfp": "tab:olive"}


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    here = os.path.dirname(os.path.abspath(__file__))
    out_dir = sys.argv[2] if len(sys.argv) > 2 else os.path.join(here, "..", "docs", "figures")
    os.makedirs(out_dir, exist_ok=True)
    with open(sys.argv[1], newline="") as f:
        rows = list(csv.DictReader(f))
    solve = [r for r in rows if r["kind"] == "solve"]
    sweep = [r for r in rows if r["kind"] == "sweep"]
    load = rows[0]["load_start"] if rows else "?"
    solvers = [s for s in ORDER if any(r["solver"] == s for r in rows)]

    tols = sorted({float(r["tolerance"]) for r in solve}, reverse=True)
    fig, axes = plt.subplots(1, len(tols), figsize=(5 * len(tols), 4.5), sharey=True)
    if len(tols) == 1:
        axes = [axes]
    for ax, tol in zip(axes, tols):
        for s in solvers:
            for start, style in (("cold", "-"), ("warm", "--")):
                pts = sorted((int(r["m"]), float(r["seconds"])) for r in solve
                             if r["solver"] == s and r["start"] == start
                             and float(r["tolerance"]) == tol and r["converged"] == "1")
                if pts:
                    ax.plot([p[0] for p in pts], [p[1] for p in pts], style, marker="o",
                            color=COLOURS.get(s), label=f"{s} ({start})")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("contacts m")
        ax.set_title(f"fc3d error < {tol:g}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("CPU time to tolerance, s (median)")
    axes[-1].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Time to tolerance (elastic slab + curved punch); load avg at start {load}")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "contact_time_vs_tolerance.png"), dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for s in solvers:
        pts = sorted((int(r["m"]), float(r["ratio"])) for r in sweep if r["solver"] == s)
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", color=COLOURS.get(s),
                    label=s)
    ax.axhline(1.5, color="k", ls=":", label="goal 1.5 x W·r")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("contacts m")
    ax.set_ylabel("one sweep / one dense W·r (same run)")
    ax.set_title(f"Sweep cost vs the W·r memory floor; load avg at start {load}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "contact_sweep_ratio.png"), dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
