#!/usr/bin/python3
"""Network haptics: metrics and charts of scripts/loadtest-network --haptics (docs/network-haptics.md).

  network_haptics.py trajectory --out FILE        the hand intent (one row per tick, CSV)
  network_haptics.py analyse --runs-dir DIR --out CSV --figures PREFIX
  network_haptics.py plot --csv CSV --figures PREFIX    (the stability chart from the CSV)

The hand intent: hover 1 mm above the surface for 0.5 s (the device is connected before the user
presses: at a 200 ms round trip no answer, not even the surface ahead, can arrive sooner), press
towards 8 mm inside over 0.5 s, hold 1 s, slide 10 mm along +x over 1 s, hold 1 s, lift over
0.3 s, rest 0.2 s. The hand (a 300 N/m
spring, hapco-phantom --mode hand) drags the device along it; the rendered force pushes back.

Per run (DIR/<case>/<mode>/ticks-*.csv and summary.csv), against the reference run (mode
direct, round trip 0, no loss, no jitter: "the no-delay run of the same hand intent"):
  passivity_min_j       the observer's minimum (summary; >= -1e-4 J counts as passive)
  oscillation_mm        largest peak-to-peak device height over the last 0.6 s of each hold
  oscillation_hz        its frequency (zero crossings of the height minus its mean), 0 if < 0.05 mm
  force_rms_error_n/_pct  RMS over ticks of |F - F_ref| (N, % of the reference's peak |F|)
  force_peak_error_n/_pct the largest |F - F_ref|
  force_rms_error_normal_pct / _tangential_pct  the RMS error split into its z and xy parts (% of
                        the reference's peak): the normal force, and the friction
  sink_mm               how much deeper the device went than in the reference (deepest z)
  timeouts, dissipated_j, model_ticks, lost_pct   from the summary
"""
import argparse
import csv
import math
import os
import sys

TICK_S = 1e-3
START_Z, TARGET_Z, SLIDE_X = 0.001, -0.008, 0.010
PHASES = [  # (name, seconds)
    ("hover", 0.5), ("approach", 0.5), ("hold-press", 1.0), ("slide", 1.0), ("hold-slide", 1.0), ("lift", 0.3), ("rest", 0.2)]
HOLDS = ("hold-press", "hold-slide")
MODES = ["direct", "direct+passivity", "local-model", "local-model+passivity"]
FLOOR = "direct-repeat"  # direct again at round trip 0: the run-to-run floor of the force error


def smooth(s):
    """0..1 with zero slope at both ends (a hand does not jerk)."""
    return 0.5 - 0.5 * math.cos(math.pi * min(max(s, 0.0), 1.0))


def trajectory():
    rows, x, z, t0 = [], 0.0, START_Z, 0.0
    for name, seconds in PHASES:
        n = int(round(seconds / TICK_S))
        for k in range(1, n + 1):
            s = smooth(k / n)
            if name == "approach":
                z = START_Z + (TARGET_Z - START_Z) * s
            elif name == "slide":
                x = SLIDE_X * s
            elif name == "lift":
                z = TARGET_Z + (START_Z - TARGET_Z) * s
            rows.append((x, 0.0, z))
    return rows


def phase_windows():
    """(name, first tick, last tick) of each phase; tick 1 is the first pose."""
    out, tick = [], 1
    for name, seconds in PHASES:
        n = int(round(seconds / TICK_S))
        out.append((name, tick, tick + n - 1))
        tick += n
    return out


def read_ticks(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    ticks = {}
    for r in rows:
        if r["published"] != "1":
            continue
        ticks[int(r["tick"])] = (float(r["x_m"]), float(r["z_m"]),
                                 (float(r["fx_n"]), float(r["fy_n"]), float(r["fz_n"])))
    return ticks


def oscillation(ticks):
    worst_mm, worst_hz = 0.0, 0.0
    for name, first, last in phase_windows():
        if name not in HOLDS:
            continue
        zs = [ticks[t][1] for t in range(last - 599, last + 1) if t in ticks]
        if len(zs) < 100:
            continue
        p2p = (max(zs) - min(zs)) * 1e3
        if p2p > worst_mm:
            mean = sum(zs) / len(zs)
            crossings = sum(1 for a, b in zip(zs, zs[1:]) if (a - mean) * (b - mean) < 0)
            worst_mm = p2p
            worst_hz = crossings / 2 / (len(zs) * TICK_S) if p2p >= 0.05 else 0.0
    return worst_mm, worst_hz


def norm(v):
    return math.sqrt(sum(c * c for c in v))


def analyse(args):
    cases = []
    for case in sorted(os.listdir(args.runs_dir)):
        path = os.path.join(args.runs_dir, case)
        if not os.path.isfile(os.path.join(path, "case.txt")):
            continue
        with open(os.path.join(path, "case.txt")) as f:
            rt, loss, jitter, load = (float(v) for v in f.read().split())
        cases.append((rt, loss, jitter, load, path))
    cases.sort()
    reference = None
    for rt, loss, jitter, load, path in cases:
        if rt == 0 and loss == 0 and jitter == 0:
            reference = read_ticks(os.path.join(path, "direct", "ticks-nh-1.csv"))
    if reference is None:
        sys.exit("network_haptics.py: no reference run (round trip 0, mode direct)")
    ref_peak = max(norm(f) for _, _, f in reference.values())
    ref_deepest = min(z for _, z, _ in reference.values())
    out_rows = []
    for rt, loss, jitter, load, path in cases:
        for mode in MODES + [FLOOR]:
            ticks_path = os.path.join(path, mode, "ticks-nh-1.csv")
            summary_path = os.path.join(path, mode, "summary.csv")
            if not (os.path.isfile(ticks_path) and os.path.isfile(summary_path)):
                continue
            with open(summary_path) as f:
                summary = [r for r in csv.DictReader(f) if r["client"] == "all"][0]
            ticks = read_ticks(ticks_path)
            errors = [norm([a - b for a, b in zip(ticks[t][2], reference[t][2])]) for t in reference if t in ticks]
            normal_errors = [ticks[t][2][2] - reference[t][2][2] for t in reference if t in ticks]
            across_errors = [norm([ticks[t][2][0] - reference[t][2][0], ticks[t][2][1] - reference[t][2][1]])
                             for t in reference if t in ticks]
            split = lambda e: round(100 * math.sqrt(sum(v * v for v in e) / len(e)) / ref_peak, 2) if e else float("nan")
            rms = math.sqrt(sum(e * e for e in errors) / len(errors)) if errors else float("nan")
            peak = max(errors) if errors else float("nan")
            osc_mm, osc_hz = oscillation(ticks)
            deepest = min(z for _, z, _ in ticks.values())
            out_rows.append({
                "mode": mode, "round_trip_ms": rt, "loss_pct": loss, "jitter_ms": jitter,
                "passivity_min_j": float(summary["passivity_min_j"]),
                "passive": int(float(summary["passivity_min_j"]) >= -1e-4),
                "oscillation_mm": round(osc_mm, 4), "oscillation_hz": round(osc_hz, 2),
                "force_rms_error_n": round(rms, 4), "force_rms_error_pct": round(100 * rms / ref_peak, 2),
                "force_peak_error_n": round(peak, 4), "force_peak_error_pct": round(100 * peak / ref_peak, 2),
                "force_rms_error_normal_pct": split(normal_errors),
                "force_rms_error_tangential_pct": split(across_errors),
                "sink_mm": round((ref_deepest - deepest) * 1e3, 4),
                "timeouts": int(summary["server_losses"]), "dissipated_j": float(summary["passivity_dissipated_j"]),
                "model_ticks": int(summary["model_ticks"]), "lost_pct": float(summary["lost_pct"]),
                "peak_force_n": round(max(norm(f) for _, _, f in ticks.values()), 4),
                "reference_peak_force_n": round(ref_peak, 4), "load1": load,
            })
    with open(args.out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(out_rows[0].keys()))
        w.writeheader()
        w.writerows(out_rows)
    print(f"network_haptics.py: {len(out_rows)} rows -> {args.out}")
    plot(args, out_rows, cases, reference)


def plot(args, rows, cases, reference):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("network_haptics.py: matplotlib missing (apt-get install python3-matplotlib): no charts")
        return
    sweep = [r for r in rows if float(r["loss_pct"]) == 0 and float(r["jitter_ms"]) == 0]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for mode in MODES:
        pts = sorted(((float(r["round_trip_ms"]), r) for r in sweep if r["mode"] == mode), key=lambda p: p[0])
        if not pts:
            continue
        xs = [max(p[0], 0.5) for p in pts]
        axes[0].plot(xs, [float(p[1]["oscillation_mm"]) for p in pts], "o-", label=mode)
        axes[1].plot(xs, [float(p[1]["force_rms_error_pct"]) for p in pts], "o-", label=mode)
        axes[2].plot(xs, [min(float(p[1]["passivity_min_j"]), 0) for p in pts], "o-", label=mode)
    for ax, title, unit in ((axes[0], "sustained oscillation in the holds", "peak to peak, mm"),
                            (axes[1], "force error vs. the no-delay run", "RMS, % of peak force"),
                            (axes[2], "passivity observer minimum", "min E, J (0 = passive)")):
        ax.set_xscale("log")
        ax.set_xlabel("round trip, ms (0 shown at 0.5)")
        ax.set_ylabel(unit)
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[1].axhline(10, color="k", lw=0.8, ls="--")
    axes[2].set_yscale("symlog", linthresh=1e-5)
    axes[2].axhline(-1e-4, color="k", lw=0.8, ls="--")  # the passivity tolerance
    axes[2].set_ylim(-10, 0)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.figures + "-stability.png", dpi=110)
    plt.close(fig)
    if cases is None:
        print(f"network_haptics.py: chart {args.figures}-stability.png (traces need the runs)")
        return
    # Traces at 10 / 50 / 200 ms round trip: device height and force magnitude.
    wanted = [10, 50, 200]
    fig, axes = plt.subplots(2, len(wanted), figsize=(15, 6), sharex=True)
    for j, rt in enumerate(wanted):
        path = next((p for r, l, jt, ld, p in cases if r == rt and l == 0 and jt == 0), None)
        if path is None:
            continue
        for mode in MODES:
            tp = os.path.join(path, mode, "ticks-nh-1.csv")
            if not os.path.isfile(tp):
                continue
            ticks = read_ticks(tp)
            ts = sorted(ticks)
            axes[0][j].plot([t * TICK_S for t in ts], [ticks[t][1] * 1e3 for t in ts], lw=0.8, label=mode)
            axes[1][j].plot([t * TICK_S for t in ts], [norm(ticks[t][2]) for t in ts], lw=0.8, label=mode)
        ts = sorted(reference)
        axes[0][j].plot([t * TICK_S for t in ts], [reference[t][1] * 1e3 for t in ts], "k--", lw=0.8, label="no delay (direct)")
        axes[1][j].plot([t * TICK_S for t in ts], [norm(reference[t][2]) for t in ts], "k--", lw=0.8, label="no delay (direct)")
        axes[0][j].set_title(f"round trip {rt} ms")
        axes[0][j].set_ylabel("device height z, mm")
        axes[1][j].set_ylabel("|rendered force|, N")
        axes[1][j].set_xlabel("time, s")
        axes[0][j].set_ylim(-3, 2)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.figures + "-traces.png", dpi=110)
    plt.close(fig)
    print(f"network_haptics.py: charts {args.figures}-stability.png, {args.figures}-traces.png")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    t = sub.add_parser("trajectory")
    t.add_argument("--out", required=True)
    a = sub.add_parser("analyse")
    a.add_argument("--runs-dir", required=True)
    a.add_argument("--out", required=True)
    a.add_argument("--figures", required=True)
    c = sub.add_parser("plot", help="the stability chart again from the CSV alone")
    c.add_argument("--csv", required=True)
    c.add_argument("--figures", required=True)
    args = p.parse_args()
    if args.command == "trajectory":
        with open(args.out, "w") as f:
            f.write("x_m,y_m,z_m\n")
            f.write(f"0,0,{START_Z!r}\n")  # point 0: the start
            for x, y, z in trajectory():
                f.write(f"{x!r},{y!r},{z!r}\n")
    elif args.command == "plot":
        with open(args.csv) as f:
            plot(args, list(csv.DictReader(f)), None, None)
    else:
        analyse(args)


if __name__ == "__main__":
    main()
