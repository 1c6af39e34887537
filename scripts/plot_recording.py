#!/usr/bin/python3
"""Charts of one HapCo recording (CSV from hapco-report): force over time, contacts by state
over time, and the round-trip histogram when the recording comes from an online run.

usage: plot_recording.py STEPS.csv OUT_DIR
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    rows = list(csv.DictReader(open(sys.argv[1])))
    out = sys.argv[2]
    if not rows:
        raise SystemExit("the recording holds no steps")
    step = [int(r["step"]) for r in rows]
    fig, ax = plt.subplots(figsize=(9, 4))
    for axis, color in zip("xyz", ("tab:red", "tab:green", "tab:blue")):
        ax.plot(step, [float(r[f"f{axis}_n"]) for r in rows], color=color, label=f"F{axis}")
    ax.set_xlabel("step")
    ax.set_ylabel("contact force on the tool (N)")
    ax.set_title("Force over the run")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "force.png"), dpi=110)

    fig, ax = plt.subplots(figsize=(9, 4))
    states = [[int(r[k]) for r in rows] for k in ("separating", "sticking", "sliding")]
    ax.stackplot(step, *states, labels=("separating", "sticking", "sliding"),
                 colors=("#bbbbbb", "#2c7fb8", "#f03b20"))
    ax.set_xlabel("step")
    ax.set_ylabel("contacts")
    ax.set_title("Contacts by state")
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "contact_states.png"), dpi=110)

    trips = [1e6 * float(r["round_trip_s"]) for r in rows if float(r["round_trip_s"]) > 0]
    fig, ax = plt.subplots(figsize=(6, 4))
    if trips:
        ax.hist(trips, bins=60, color="tab:purple")
        ax.set_xlabel("round trip (us)")
        ax.set_ylabel("samples")
        ax.set_title(f"Round trip, {len(trips)} samples")
    else:
        ax.text(0.5, 0.5, "offline recording: no round trips", ha="center", va="center")
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "round_trip.png"), dpi=110)
    print(f"charts: {out}/force.png, contact_states.png, round_trip.png")


if __name__ == "__main__":
    main()
