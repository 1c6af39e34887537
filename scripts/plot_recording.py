#!/usr/bin/python3
"""Charts of one HapCo recording (CSV from hapco-report): force over time, contacts by state
over time, and the round-trip histogram. One panel per client for recordings of several
clients (hapco-recorder); offline recordings (hapco-sim) have one client and no round trips.

usage: plot_recording.py STEPS.csv OUT_DIR
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

MAX_PANELS = 8  # clients drawn one panel each; further clients are listed in the title


def by_client(rows):
    groups = {}
    for r in rows:
        groups.setdefault(r.get("client_id", ""), []).append(r)
    return groups


def main():
    rows = list(csv.DictReader(open(sys.argv[1])))
    out = sys.argv[2]
    if not rows:
        raise SystemExit("the recording holds no steps")
    # Online recordings (pose sequences present): a common time axis, the server's clock.
    online = any(int(r.get("pose_sequence", "0") or 0) > 0 for r in rows)
    t0 = min(int(r["time_ns"]) for r in rows)

    def x_of(r):
        return (int(r["time_ns"]) - t0) * 1e-9 if online else int(r["step"])

    x_label = "time (s, server clock)" if online else "step"
    groups = by_client(rows)
    shown = list(groups)[:MAX_PANELS]
    extra = len(groups) - len(shown)
    suffix = f" ({extra} more clients not shown)" if extra > 0 else ""

    fig, axes = plt.subplots(len(shown), 1, figsize=(9, 2.2 + 2.3 * len(shown)), squeeze=False, sharex=True)
    for ax, client in zip(axes[:, 0], shown):
        rs = groups[client]
        x = [x_of(r) for r in rs]
        for axis, color in zip("xyz", ("tab:red", "tab:green", "tab:blue")):
            # A step written from the force alone (its frame was lost) has no contact force.
            y = [math.nan if r.get("contacts_missing") == "1" else float(r[f"f{axis}_n"]) for r in rs]
            ax.plot(x, y, color=color, label=f"contact F{axis}")
        device = [math.hypot(float(r["device_fx_n"]), float(r["device_fy_n"]), float(r["device_fz_n"])) for r in rs]
        ax.plot(x, device, color="black", linestyle="--", linewidth=0.8, label="|device force|")
        ax.set_ylabel("force (N)")
        ax.set_title(f"client {client}" if len(groups) > 1 else "Force over the run")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel(x_label)
    if len(groups) > 1:
        fig.suptitle("Force over the run" + suffix)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "force.png"), dpi=110)

    fig, axes = plt.subplots(len(shown), 1, figsize=(9, 2.2 + 2.3 * len(shown)), squeeze=False, sharex=True)
    for ax, client in zip(axes[:, 0], shown):
        rs = groups[client]
        x = [x_of(r) for r in rs]
        states = [[int(r[k]) for r in rs] for k in ("separating", "sticking", "sliding")]
        ax.stackplot(x, *states, labels=("separating", "sticking", "sliding"),
                     colors=("#bbbbbb", "#2c7fb8", "#f03b20"))
        ax.set_ylabel("contacts")
        ax.set_title(f"client {client}" if len(groups) > 1 else "Contacts by state")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel(x_label)
    if len(groups) > 1:
        fig.suptitle("Contacts by state" + suffix)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "contact_states.png"), dpi=110)

    fig, ax = plt.subplots(figsize=(6, 4))
    trips = {c: [1e6 * float(r["round_trip_s"]) for r in rs if float(r["round_trip_s"]) > 0]
             for c, rs in groups.items()}
    total = sum(len(v) for v in trips.values())
    if total > 0:
        for client in shown:
            if trips[client]:
                ax.hist(trips[client], bins=60, alpha=0.6 if len(groups) > 1 else 1.0,
                        label=client if len(groups) > 1 else None,
                        color=None if len(groups) > 1 else "tab:purple")
        ax.set_xlabel("round trip, pose sampled -> force arrived (us)")
        ax.set_ylabel("samples")
        ax.set_title(f"Round trip, {total} samples")
        if len(groups) > 1:
            ax.legend(fontsize=8)
    else:
        why = "offline recording" if not online else "the clients reported none"
        ax.text(0.5, 0.5, f"no round-trip times in this recording\n({why})", ha="center", va="center")
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "round_trip.png"), dpi=110)
    print(f"charts: {out}/force.png, contact_states.png, round_trip.png")


if __name__ == "__main__":
    main()
