#!/usr/bin/python3
"""Charts of hapco-loadtest results (docs/load-and-network.md).

  plot_loadtest.py run --csv-dir DIR
      one run: DIR/roundtrip-cdf.png (round trip CDF per client), DIR/forces.png (rendered vs
      server force and the passivity energy of the first client)
  plot_loadtest.py capacity --csv CAPACITY.csv --runs-dir DIR --out PREFIX
      PREFIX-roundtrip.png (p50/p99/p99.9 vs N), PREFIX-missed.png (missed % vs N),
      PREFIX-server.png (server pose received to answered, queueing included, and CPU vs N), PREFIX-cdf.png (round trip CDF per N,
      from DIR/n<N>/roundtrip.csv)
  plot_loadtest.py table --capacity CAPACITY.csv | --network NETWORK.csv
      the markdown tables of docs/load-and-network.md, from the CSVs
  plot_loadtest.py network --csv NETWORK.csv --runs-dir DIR --out PREFIX
      PREFIX-delay.png (stability vs delay), PREFIX-loss.png (stability vs loss),
      PREFIX-traces.png (force traces at 0 / 5 / 20 ms, from DIR/<case>/ticks-*.csv)
"""
import argparse
import csv
import glob
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

plt.rcParams.update({"figure.dpi": 90, "font.size": 9})


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def num(row, key):
    try:
        return float(row[key])
    except (KeyError, ValueError):
        return math.nan


def cdf(ax, values, label):
    values = sorted(values)
    if not values:
        return
    n = len(values)
    ax.plot([v / 1000.0 for v in values], [(i + 1) / n for i in range(n)], label=label, lw=1)


def roundtrips(path):
    by_client = {}
    for row in read_csv(path):
        by_client.setdefault(row["client"], []).append(float(row["round_trip_us"]))
    return by_client


def save(fig, path, dpi=None):
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    print("wrote", path)


def force_panel(ax_f, ax_e, ticks_path, t_begin=None, t_end=None, title=""):
    rows = read_csv(ticks_path)
    t = [num(r, "time_s") for r in rows]
    if t_begin is None:
        t_begin, t_end = t[0], t[-1]
    sel = [i for i, x in enumerate(t) if t_begin <= x <= t_end]
    tt = [t[i] for i in sel]
    for axis, colour in (("z", "C0"), ("x", "C1")):
        ax_f.plot(tt, [num(rows[i], "server_f%s_n" % axis) for i in sel], color=colour, lw=2.5, alpha=0.35,
                  label="server F%s (for the tick's pose)" % axis)
        ax_f.plot(tt, [num(rows[i], "f%s_n" % axis) for i in sel], color=colour, lw=0.9, label="rendered F%s" % axis)
    stale = [tt[k] for k, i in enumerate(sel) if rows[i]["stale"] == "1"]
    if stale:
        ax_f.plot(stale, [0.0] * len(stale), "r|", ms=6, label="stale ticks")
    ax_f.set_ylabel("force, N")
    ax_f.set_title(title)
    ax_f.legend(fontsize=7, loc="upper right")
    if ax_e is not None:
        ax_e.plot(tt, [num(rows[i], "energy_j") * 1000 for i in sel], color="k", lw=1)
        ax_e.axhline(0, color="r", lw=0.6)
        ax_e.set_ylabel("passivity E, mJ")
        ax_e.set_xlabel("time since the client started, s")


def plot_run(args):
    d = args.csv_dir
    rt = roundtrips(os.path.join(d, "roundtrip.csv"))
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for client, values in sorted(rt.items()):
        cdf(ax, values, client)
    ax.set_xscale("log")
    ax.set_xlabel("round trip (pose sampled -> force arrived), ms")
    ax.set_ylabel("fraction of forces")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    save(fig, os.path.join(d, "roundtrip-cdf.png"))
    ticks = sorted(glob.glob(os.path.join(d, "ticks-*.csv")))
    if ticks:
        fig, (a, b) = plt.subplots(2, 1, figsize=(7, 5), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
        force_panel(a, b, ticks[0], title=os.path.basename(ticks[0]))
        save(fig, os.path.join(d, "forces.png"))


def plot_capacity(args):
    rows = read_csv(args.csv)
    # One series per server: hapco (the contact physics) and floor (--physics none), if run.
    servers = []
    for r in rows:
        if r.get("server", "hapco") not in servers:
            servers.append(r.get("server", "hapco"))
    by_server = {k: [r for r in rows if r.get("server", "hapco") == k] for k in servers}
    # An N that failed is run once more (scripts/loadtest-capacity) and the second run decides:
    # chart that one.
    for k, rs in by_server.items():
        last = {}
        for r in rs:
            last[r["clients"]] = r
        by_server[k] = list(last.values())
    styles = {"hapco": "-", "floor": "--"}

    fig, ax = plt.subplots(figsize=(5, 3.2))
    for k, rs in by_server.items():
        n = [num(r, "clients") for r in rs]
        for key, label, marker in (("rt_p50_us", "p50", "o"), ("rt_p99_us", "p99", "s"), ("rt_p999_us", "p99.9", "^")):
            ax.plot(n, [num(r, key) / 1000 for r in rs], marker + styles.get(k, ":"), label="%s %s" % (k, label))
    ax.axhline(1.0, color="grey", lw=0.6, ls="--")
    ax.set_yscale("log")
    ax.set_xlabel("clients N (benchmark 1, 1 kHz each)")
    ax.set_ylabel("round trip, ms")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    save(fig, args.out + "-roundtrip.png")

    fig, ax = plt.subplots(figsize=(5, 3.2))
    for k, rs in by_server.items():
        n = [num(r, "clients") for r in rs]
        ax.plot(n, [num(r, "lost_pct") for r in rs], "o" + styles.get(k, ":"), label="%s: lost (missed + never answered)" % k)
        ax.plot(n, [num(r, "missed_pct") for r in rs], "s" + styles.get(k, ":"), label="%s: servo ticks missed" % k)
    ax.axhline(1.0, color="r", lw=0.8, label="1 % limit")
    ax.set_xlabel("clients N")
    ax.set_ylabel("% of ticks")
    ax.set_ylim(bottom=0)
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    save(fig, args.out + "-missed.png")

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax2 = ax.twinx()
    for k, rs in by_server.items():
        n = [num(r, "clients") for r in rs]
        ax.plot(n, [num(r, "server_step_p50_us") for r in rs], "o" + styles.get(k, ":"), label="%s step p50" % k)
        ax.plot(n, [num(r, "server_step_p99_us") for r in rs], "s" + styles.get(k, ":"), label="%s pose-to-answer p99" % k)
        ax2.plot(n, [num(r, "server_cpu") for r in rs], "k^" + styles.get(k, ":"), label="%s CPU (cores)" % k)
    ax.set_xlabel("clients N")
    ax.set_ylabel("server: pose received to answered (queueing included), us")
    ax.grid(True, alpha=0.3)
    ax2.set_ylabel("server CPU, cores")
    ax2.set_ylim(bottom=0)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=6, loc="upper left")
    save(fig, args.out + "-server.png")

    fig, ax = plt.subplots(figsize=(5, 3.2))
    for r in by_server.get("hapco", rows):
        n_clients = int(num(r, "clients"))
        path = os.path.join(args.runs_dir, "hapco-n%d" % n_clients, "roundtrip.csv")
        if not os.path.exists(path):
            path = os.path.join(args.runs_dir, "n%d" % n_clients, "roundtrip.csv")
        if os.path.exists(path):
            values = [v for vs in roundtrips(path).values() for v in vs]
            cdf(ax, values, "N = %d" % n_clients)
    ax.set_xscale("log")
    ax.set_xlabel("round trip, ms (all clients, hapco)")
    ax.set_ylabel("fraction of forces")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    save(fig, args.out + "-cdf.png")


def plot_network(args):
    rows = read_csv(args.csv)

    def series(x_key, fixed):
        sel = [r for r in rows if all(abs(num(r, k) - v) < 1e-9 for k, v in fixed.items())]
        return sorted(sel, key=lambda r: num(r, x_key))

    panels = (("tracking_rms_n", "tracking error rms, N"), ("hf_ratio", "HF ratio (rendered / server)"),
              ("passivity_min_j", "passivity min E, J"), ("stale_ticks", "stale ticks"))
    for x_key, fixed_sets, xlabel, name in (
            ("delay_ms", [({"loss_pct": 0, "jitter_ms": 0}, "no loss, no jitter"),
                          ({"loss_pct": 0, "jitter_ms": 1}, "jitter 1 ms"),
                          ({"loss_pct": 1, "jitter_ms": 0}, "loss 1 %")], "one-way delay, ms", "delay"),
            ("loss_pct", [({"delay_ms": 0, "jitter_ms": 0}, "no delay"),
                          ({"delay_ms": 5, "jitter_ms": 0}, "delay 5 ms")], "loss per direction, %", "loss")):
        fig, axes = plt.subplots(1, 4, figsize=(11, 2.8))
        modes = sorted(set(r["mode"] for r in rows))
        for ax, (key, label) in zip(axes, panels):
            for k, (fixed, legend) in enumerate(fixed_sets):
                for mode in modes:
                    s = [r for r in series(x_key, fixed) if r["mode"] == mode]
                    if len(s) >= 1:
                        ax.plot([num(r, x_key) for r in s], [num(r, key) for r in s],
                                "o-" if mode == "kinematic" else "s--", color="C%d" % k,
                                label="%s, %s" % (legend, mode))
            ax.set_xlabel(xlabel)
            ax.set_title(label, fontsize=8)
            ax.grid(True, alpha=0.3)
            if key == "passivity_min_j":
                ax.axhline(0, color="r", lw=0.6)
        axes[0].legend(fontsize=7)
        save(fig, "%s-%s.png" % (args.out, name))

    cases = [c for c in ("d0_j0_l0", "d5_j0_l0", "d20_j0_l0") if os.path.isdir(os.path.join(args.runs_dir, c))]
    if cases:
        fig, axes = plt.subplots(len(cases), 1, figsize=(7, 2.2 * len(cases)), sharex=True)
        if len(cases) == 1:
            axes = [axes]
        for ax, case in zip(axes, cases):
            ticks = sorted(glob.glob(os.path.join(args.runs_dir, case, "ticks-*.csv")))
            if ticks:
                force_panel(ax, None, ticks[0], 0.0, 1.3, title="%s (%s)" % (case, os.path.basename(ticks[0])))
        axes[-1].set_xlabel("time since the client started, s")
        save(fig, args.out + "-traces.png", dpi=70)

    # Hand mode: the device moves under the rendered force, so delay can drive it.
    cases = [c for c in ("d0_j0_l0_hand", "d1_j0_l0_hand", "d2_j0_l0_hand", "d5_j0_l0_hand")
             if os.path.isdir(os.path.join(args.runs_dir, c))]
    if cases:
        fig, axes = plt.subplots(len(cases), 1, figsize=(7, 2.2 * len(cases)), sharex=True)
        if len(cases) == 1:
            axes = [axes]
        for ax, case in zip(axes, cases):
            ticks = sorted(glob.glob(os.path.join(args.runs_dir, case, "ticks-*.csv")))
            if not ticks:
                continue
            rows = [r for r in read_csv(ticks[0]) if num(r, "time_s") <= 1.3]
            t = [num(r, "time_s") for r in rows]
            ax.plot(t, [num(r, "server_fz_n") for r in rows], color="C0", lw=2.5, alpha=0.35, label="server Fz")
            ax.plot(t, [num(r, "fz_n") for r in rows], color="C0", lw=0.9, label="rendered Fz")
            ax.set_ylabel("force, N")
            ax2 = ax.twinx()
            ax2.plot(t, [num(r, "z_m") * 1000 for r in rows], color="k", lw=0.8, label="device z")
            ax2.set_ylabel("z, mm")
            e = [num(r, "energy_j") for r in rows]
            ax.set_title("%s: passivity E at 1.3 s = %.3f J" % (case, e[-1] if e else math.nan), fontsize=8)
            h1, l1 = ax.get_legend_handles_labels()
            h2, l2 = ax2.get_legend_handles_labels()
            ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper right")
        axes[-1].set_xlabel("time since the client started, s")
        save(fig, args.out + "-traces-hand.png", dpi=70)


def table(args):
    if args.capacity:
        print("| server | N | lost | servo missed | round trip p50 / p99 / p99.9 | server pose-to-answer p50 / p99 | server CPU | timeouts | load before / after |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in read_csv(args.capacity):
            print("| %s | %d | %.2f %% | %.2f %% | %.2f / %.2f / %.1f ms | %.0f / %.0f µs | %.2f | %d | %s / %s |" % (
                r.get("server", "hapco"), num(r, "clients"), num(r, "lost_pct"), num(r, "missed_pct"), num(r, "rt_p50_us") / 1000,
                num(r, "rt_p99_us") / 1000, num(r, "rt_p999_us") / 1000, num(r, "server_step_p50_us"),
                num(r, "server_step_p99_us"), num(r, "server_cpu"), num(r, "server_losses"),
                r.get("load1_before", "-"), r.get("load1_after", "-")))
    if args.network:
        rows = read_csv(args.network)
        cases = []
        for r in rows:
            key = (r["delay_ms"], r["jitter_ms"], r["loss_pct"])
            if key not in cases:
                cases.append(key)
        print("| one-way delay / jitter / loss | round trip p50 | lost (kin / hand) | servo missed (kin / hand) | "
              "tracking rms (kin / hand) | HF ratio (kin / hand) | passivity min E (kin / hand) | timeouts (kin / hand) |")
        print("|---|---|---|---|---|---|---|---|")
        for key in cases:
            k = next((r for r in rows if (r["delay_ms"], r["jitter_ms"], r["loss_pct"]) == key and r["mode"] == "kinematic"), None)
            h = next((r for r in rows if (r["delay_ms"], r["jitter_ms"], r["loss_pct"]) == key and r["mode"] == "hand"), None)

            def pair(fmt, col):
                return " / ".join(fmt % num(x, col) if x else "-" for x in (k, h))
            first = k or h
            print("| %s / %s / %s | %.2f ms | %s | %s | %s | %s | %s | %s |" % (
                key[0], key[1], key[2], num(first, "rt_p50_us") / 1000, pair("%.1f %%", "lost_pct"),
                pair("%.2f %%", "missed_pct"), pair("%.2f N", "tracking_rms_n"), pair("%.2f", "hf_ratio"),
                pair("%.3g J", "passivity_min_j"), pair("%d", "server_losses")))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="what", required=True)
    r = sub.add_parser("run")
    r.add_argument("--csv-dir", required=True)
    c = sub.add_parser("capacity")
    c.add_argument("--csv", required=True)
    c.add_argument("--runs-dir", required=True)
    c.add_argument("--out", required=True)
    n = sub.add_parser("network")
    n.add_argument("--csv", required=True)
    n.add_argument("--runs-dir", required=True)
    n.add_argument("--out", required=True)
    t = sub.add_parser("table")
    t.add_argument("--capacity")
    t.add_argument("--network")
    args = p.parse_args()
    {"run": plot_run, "capacity": plot_capacity, "network": plot_network, "table": table}[args.what](args)


if __name__ == "__main__":
    sys.exit(main())
