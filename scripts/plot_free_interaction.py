#!/usr/bin/python3
"""Charts of the free-interaction study (tests/bench/free_interaction, docs/free-interaction.md).

usage: plot_free_interaction.py STUDY_DIR OUT_DIR

STUDY_DIR holds the per-path CSVs free_interaction_study writes; OUT_DIR receives
free_interaction_sweep.png (|F| along the 3 mm top-face sweep, both benchmarks, Tet4/Tet10,
with friction and frictionless), free_interaction_presses.png (|F| against depth) and
free_interaction_faces.png (force components of the end/side-face pushes and the path below
the end and back).
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def load(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows] for k in ("dx_m", "dy_m", "dz_m", "fx_n", "fy_n", "fz_n", "force_n")}


def finish(ax, title, xlabel, ylabel, log=True):
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend()


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    study, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), sharey=False)
    for ax, scene in zip(axes, ("benchmark1", "benchmark2")):
        for name, style in (("Tet4_top-sweep", "-"), ("Tet10_top-sweep", "--"), ("Tet4_top-sweep-frictionless", ":"),
                            ("reference_top-sweep", "k-")):
            path = os.path.join(study, f"{scene}_{name}.csv")
            if not os.path.exists(path):
                continue
            d = load(path)
            # the tool's left edge position along the bar: home at x = 40 mm
            x = [40 + 1e3 * v for v in d["dx_m"]]
            pressed = [i for i, z in enumerate(d["dz_m"]) if abs(z + 0.003) < 1e-9]
            ax.plot([x[i] for i in pressed], [d["force_n"][i] for i in pressed], style, lw=1,
                    label=name.replace("_top-sweep", "").replace("-frictionless", " mu=0")
                    .replace("reference", "refined reference"))
        finish(ax, f"{scene}: 3 mm deep slide over the whole top face, out and back",
               "tool's left edge x (mm); bar spans 0..100, tool 20 mm wide", "|F| on the tool (N)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "free_interaction_sweep.png"), dpi=110)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    for ax, scene in zip(axes, ("benchmark1", "benchmark2")):
        for press in ("press-mid", "press-clamp", "press-end"):
            path = os.path.join(study, f"{scene}_Tet4_{press}.csv")
            if not os.path.exists(path):
                continue
            d = load(path)
            n = len(d["dz_m"])
            depth = [-1e3 * z for z in d["dz_m"][n - 110:]]
            ax.plot(depth, d["force_n"][n - 110:], label=press)
        finish(ax, f"{scene}: straight presses to half the bar's thickness", "device travel below the top (mm)",
               "|F| (N)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "free_interaction_presses.png"), dpi=110)

    fig, axes = plt.subplots(2, 3, figsize=(14, 6.5))
    for row, scene in enumerate(("benchmark1", "benchmark2")):
        for col, path_name in enumerate(("push-end-face", "push-side-face", "below-end-and-back")):
            ax = axes[row][col]
            path = os.path.join(study, f"{scene}_Tet4_{path_name}.csv")
            if not os.path.exists(path):
                ax.set_visible(False)
                continue
            d = load(path)
            steps = range(1, len(d["fx_n"]) + 1)
            for key, label in (("fx_n", "Fx"), ("fy_n", "Fy"), ("fz_n", "Fz")):
                ax.plot(steps, d[key], label=label)
            finish(ax, f"{scene}: {path_name}", "step (0.1 mm)", "force on the tool (N)", log=False)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "free_interaction_faces.png"), dpi=110)


if __name__ == "__main__":
    main()
