#!/usr/bin/env python3
"""Chart of scripts/multirate-tradeoff: force error against CPU time per pose (docs/load-and-network.md)."""
import argparse
import csv

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--csv", required=True, help="summary CSV of multirate_study --summary")
    parser.add_argument("--out", required=True, help="PNG to write")
    args = parser.parse_args()
    with open(args.csv, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit("plot_multirate: no rows in " + args.csv)
    series = {}
    for r in rows:
        if int(r["physics_every"]) == 1:
            continue
        speed = ("scene path" if r["path"] == "scene" else
                 "top face, %g mm/s" % (float(r["spacing_m"]) * 1e6))
        key = (speed, float(r["max_model_distance_m"]))
        series.setdefault(key, []).append(r)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharex=True)
    for (speed, distance), rs in sorted(series.items()):
        rs.sort(key=lambda r: int(r["physics_every"]))
        x = [float(r["time_ratio"]) for r in rs]
        style = "-o" if distance < 3e-4 else "--s"
        for ax, column in zip(axes, ("rms_error_pct_of_peak", "max_error_pct_of_peak")):
            line, = ax.plot(x, [float(r[column]) for r in rs], style, ms=4,
                            label="%s, %.1f mm" % (speed, distance * 1e3))
            for r, xi in zip(rs, x):
                ax.annotate(r["physics_every"], (xi, float(r[column])), fontsize=6,
                            xytext=(2, 2), textcoords="offset points", color=line.get_color())
    axes[0].set_ylabel("force error, RMS over the path, % of peak")
    axes[1].set_ylabel("force error, worst pose, % of peak")
    for ax in axes:
        ax.set_xlabel("CPU time per pose / a step on every pose (labels: K)")
        ax.grid(True, alpha=0.3)
    axes[1].legend(fontsize=6, title="path, model distance", title_fontsize=6)
    fig.suptitle("multirate answering (hapco-server --physics-every K), benchmark 1", fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=130)
    print("wrote " + args.out)


if __name__ == "__main__":
    main()
