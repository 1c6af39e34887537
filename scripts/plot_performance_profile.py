#!/usr/bin/python3
"""Dolan-More performance profiles (E. D. Dolan, J. J. More, "Benchmarking optimization
software with performance profiles", Math. Program. 91 (2002) 201-213).

usage: scripts/plot_performance_profile.py RESULTS.csv OUT_DIR [--title T]

RESULTS.csv (header row required, extra columns ignored):
  problem,solver,tolerance,seconds,converged,iterations,error
    problem     problem name (e.g. an FCLIB file)
    solver      solver name
    tolerance   the accuracy asked for; rows are grouped by its value (parsed as a float,
                so 1e-8 and 1.0e-08 are the same group), one profile per value
    seconds     CPU time to reach `tolerance` (s); used only when converged = 1
    converged   1 = reached the tolerance, 0 = did not (ratio = infinity)
    iterations  iterations used (reported as the median over the solved problems)
    error       final error (read, not used)
  A (problem, solver) pair missing at some tolerance counts as not solved. A pair given twice
  keeps its fastest converged row (a warning says so). Converged times below 1e-9 s are
  raised to 1e-9 s so that ratios stay finite.

For each tolerance: t_ps = seconds of solver s on problem p (infinite if not solved); a problem
no solver solved is dropped (counted in the table); r_ps = t_ps / min_s t_ps;
rho_s(tau) = |{p : r_ps <= tau}| / (number of problems kept). rho_s(1) is the fraction on which
s is fastest (ties count for every tied solver), rho_s(tau -> inf) the fraction it solves.

Writes OUT_DIR/performance_profile.png (one panel per tolerance, rho_s against tau on a log2
axis, step plot) and OUT_DIR/performance_profile.md, and prints the same markdown tables:
  solver | solved (count, fraction of kept problems) | fastest (fraction with r = 1) |
  median ratio (over kept problems, unsolved = inf) | median iterations (solved problems only)
"""
import argparse
import csv
import math
import os
import sys
from collections import OrderedDict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

REQUIRED = ("problem", "solver", "tolerance", "seconds", "converged", "iterations", "error")
TIME_FLOOR = 1e-9  # s
LINESTYLES = ("-", "--", "-.", ":")  # tied curves stay visible


def read_results(path):
    """{tolerance: {(problem, solver): (seconds or inf, iterations or None)}}, solvers, order."""
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
        if missing:
            sys.exit("%s: missing column(s) %s (need %s)" % (path, ", ".join(missing),
                                                              ",".join(REQUIRED)))
        data = OrderedDict()
        solvers = []
        problems = OrderedDict()
        for line, row in enumerate(reader, start=2):
            try:
                tol = float(row["tolerance"])
                conv = int(float(row["converged"]))
                if conv not in (0, 1):
                    raise ValueError("converged must be 0 or 1")
                secs = float(row["seconds"]) if conv else math.inf
                if conv and not (math.isfinite(secs) and secs >= 0):
                    raise ValueError("converged row needs a finite seconds >= 0")
                it_text = (row["iterations"] or "").strip()
                iters = float(it_text) if it_text and conv else None
            except (TypeError, ValueError) as err:
                sys.exit("%s:%d: %s" % (path, line, err))
            if conv and secs < TIME_FLOOR:
                secs = TIME_FLOOR
            prob, solver = row["problem"].strip(), row["solver"].strip()
            if solver not in solvers:
                solvers.append(solver)
            problems[prob] = True
            table = data.setdefault(tol, {})
            key = (prob, solver)
            if key in table:
                print("warning: %s:%d: %s / %s at tolerance %g given again; keeping the fastest"
                      " converged row" % (path, line, prob, solver, tol), file=sys.stderr)
                if secs >= table[key][0]:
                    continue
            table[key] = (secs, iters)
    if not data:
        sys.exit("%s: no rows" % path)
    return data, solvers


def profile(table, solvers):
    """Ratios (kept problems x solvers), kept problem names, dropped count, iterations."""
    probs = sorted({p for p, _ in table})
    t = np.array([[table.get((p, s), (math.inf, None))[0] for s in solvers] for p in probs])
    iters = [[table.get((p, s), (math.inf, None))[1] for s in solvers] for p in probs]
    best = t.min(axis=1)
    keep = np.isfinite(best)
    ratios = t[keep] / best[keep, None]
    kept_iters = [row for row, k in zip(iters, keep) if k]
    return ratios, [p for p, k in zip(probs, keep) if k], int(np.sum(~keep)), len(probs), \
        kept_iters


def fmt_ratio(x):
    return "inf" if not math.isfinite(x) else "%.3g" % x


def table_markdown(tol, ratios, kept, dropped, total, iters, solvers):
    n = len(kept)
    lines = ["### tolerance %g" % tol, "",
             "%d problems, %d solved by at least one solver (the profile is over these), %d "
             "solved by none (dropped)." % (total, n, dropped), "",
             "| solver | solved | fastest | median ratio | median iterations |",
             "|---|---|---|---|---|"]
    for j, s in enumerate(solvers):
        if n == 0:
            lines.append("| %s | 0 | - | - | - |" % s)
            continue
        col = ratios[:, j]
        solved = int(np.sum(np.isfinite(col)))
        fastest = int(np.sum(col == 1.0))
        med = float(np.median(col))  # inf when more than half unsolved
        it = [iters[k][j] for k in range(n) if math.isfinite(col[k]) and iters[k][j] is not None]
        lines.append("| %s | %d (%.0f%%) | %.0f%% (%d) | %s | %s |" % (
            s, solved, 100.0 * solved / n, 100.0 * fastest / n, fastest, fmt_ratio(med),
            ("%g" % float(np.median(it))) if it else "-"))
    return "\n".join(lines) + "\n"


def plot_panel(ax, tol, ratios, solvers, n):
    finite = ratios[np.isfinite(ratios)]
    tau_max = max(2.0, float(finite.max()) * 1.25) if finite.size else 2.0
    for s_index, name in enumerate(solvers):
        col = np.sort(ratios[:, s_index]) if n else np.array([])
        col = col[np.isfinite(col)]
        # rho(tau) = #{r <= tau} / n: right-continuous steps from tau = 1 to tau_max
        x = np.concatenate([[1.0], col, [tau_max]])
        y = np.concatenate([[np.sum(col <= 1.0)], np.arange(1, len(col) + 1), [len(col)]])
        ax.step(x, y / max(n, 1), where="post", label=name, linewidth=1.6,
                linestyle=LINESTYLES[s_index % len(LINESTYLES)])
    ax.set_xscale("log", base=2)
    ax.set_xlim(1.0, tau_max)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(r"$\tau$ (time ratio to the fastest solver)")
    ax.set_ylabel(r"$\rho_s(\tau)$ (fraction of problems)")
    ax.set_title("tolerance %g (%d problems)" % (tol, n))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower right", fontsize="small")


def main():
    ap = argparse.ArgumentParser(description="Dolan-More performance profiles")
    ap.add_argument("results")
    ap.add_argument("out_dir")
    ap.add_argument("--title", default="Performance profile (CPU time)")
    args = ap.parse_args()
    data, solvers = read_results(args.results)
    os.makedirs(args.out_dir, exist_ok=True)
    tols = sorted(data, reverse=True)  # loosest first
    fig, axes = plt.subplots(1, len(tols), figsize=(5.5 * len(tols), 4.4), squeeze=False)
    md = ["# %s" % args.title, "",
          "Dolan-More performance profiles from `%s`: r = t / (fastest t on that problem), "
          "unsolved = inf; fractions are of the problems solved by at least one solver." %
          os.path.basename(args.results), ""]
    for ax, tol in zip(axes[0], tols):
        ratios, kept, dropped, total, iters = profile(data[tol], solvers)
        md.append(table_markdown(tol, ratios, kept, dropped, total, iters, solvers))
        plot_panel(ax, tol, ratios, solvers, len(kept))
    fig.suptitle(args.title)
    fig.tight_layout()
    png = os.path.join(args.out_dir, "performance_profile.png")
    fig.savefig(png, dpi=130)
    text = "\n".join(md)
    with open(os.path.join(args.out_dir, "performance_profile.md"), "w") as fh:
        fh.write(text)
    print(text)
    print("wrote %s and performance_profile.md" % png, file=sys.stderr)


if __name__ == "__main__":
    main()
