#!/usr/bin/python3
"""Plots the CSVs of hapco_paper_study (docs/data/paper_*.csv, stability_*.csv) into
docs/figures/paper_*.png and stability_*.png. Run by scripts/reproduce-paper-figures.

    /usr/bin/python3 scripts/plot_paper_figures.py --data docs/data --out docs/figures
"""
import argparse
import csv
import os
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PHASES = ["press", "slide+x", "slide+y", "slide-x", "lift"]
STYLE = {
    "local-uzawa": dict(color="tab:blue", label="local Uzawa"),
    "global-uzawa-gs": dict(color="tab:red", label="global Uzawa, Gauss-Seidel (paper)"),
    "global-uzawa-jacobi": dict(color="tab:gray", label="global Uzawa, Jacobi"),
    "global-uzawa-jacobi-rho0.1": dict(color="tab:olive", label="global Uzawa, Jacobi, 0.1 ρ"),
    "local-uzawa-rho-per-contact": dict(color="tab:cyan", label="local Uzawa, per-contact ρ"),
    "reference": dict(color="black", label="reference (local Uzawa 1e-12 m)"),
}


def read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def phase_marks(ax, phases_of_step):
    """Vertical lines at the phase boundaries, phase names on top."""
    bounds = []
    last = None
    for step, phase in phases_of_step:
        if phase != last:
            bounds.append((step, phase))
            last = phase
    end = phases_of_step[-1][0]
    for i, (step, phase) in enumerate(bounds):
        if i > 0:
            ax.axvline(step - 0.5, color="k", lw=0.8, ls=":")
        nxt = bounds[i + 1][0] if i + 1 < len(bounds) else end + 1
        ax.text((step + nxt) / 2, 1.01, f"({phase + 1}) {PHASES[phase]}", transform=ax.get_xaxis_transform(),
                ha="center", va="bottom", fontsize=8)


def fig67(data, out):
    rows = read(os.path.join(data, "paper_fig67_iterations.csv"))
    series = defaultdict(list)
    for r in rows:
        series[(r["tol_m"], r["solver"])].append(r)
    for number, tol in (("6", "1e-06"), ("7", "1e-07")):
        fig, ax = plt.subplots(figsize=(11, 5))
        first = None
        for solver in STYLE:
            run = series.get((tol, solver))
            if not run:
                continue
            first = first or run
            steps = [int(r["step"]) for r in run]
            outer = [max(1, int(r["outer"])) for r in run]
            total = sum(int(r["outer"]) for r in run)
            nc = sum(r["status"] != "converged" for r in run)
            st = STYLE[solver]
            ax.plot(steps, outer, color=st["color"], lw=1.2,
                    label=f'{st["label"]}: {total} sweeps' + (f", {nc} steps NOT converged" if nc else ""))
            bad = [(s, o) for s, o, r in zip(steps, outer, run) if r["status"] != "converged"]
            if bad:
                ax.plot(*zip(*bad), "x", color=st["color"], ms=6)
        phase_marks(ax, [(int(r["step"]), int(r["phase"])) for r in first])
        ax.set_yscale("log")
        ax.set_xlabel("haptic step (device increment P/10 = 0.1 mm)")
        ax.set_ylabel("outer iterations k per step (log)")
        ax.set_title(f"Fig. {number} reproduced: benchmark 1, μ = 0.3, Uzawa error ‖Δr‖/ρ < {float(tol):g} m, "
                     "cold start r0 = 0, ρ = min 1/W_ii\n(× = step not converged: iteration cap 5000; "
                     "Jacobi loses the contact after its failed steps, 0 contacts afterwards)", fontsize=10, pad=18)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, loc="lower center", ncol=2)
        fig.tight_layout()
        fig.savefig(os.path.join(out, f"paper_fig{number}_iterations.png"), dpi=110)
        plt.close(fig)


def fig8(data, out):
    summary = read(os.path.join(data, "paper_fig8_cpu_vs_tol.csv"))
    per_step = read(os.path.join(data, "paper_fig8_cpu_per_step.csv"))
    fig, (a, b) = plt.subplots(1, 2, figsize=(14, 5), gridspec_kw=dict(width_ratios=[1, 1.6]))
    by = defaultdict(list)
    for r in summary:
        by[r["solver"]].append(r)
    for solver, rows in by.items():
        st = STYLE[solver]
        tol = [float(r["tol_m"]) for r in rows]
        cpu = [float(r["total_cpu_s"]) for r in rows]
        nc = [int(r["not_converged"]) for r in rows]
        label = st["label"] + (" (fails: 20 steps not converged, then no contact)" if max(nc) else "")
        a.plot(tol, cpu, "o-", color=st["color"], label=label)
    a.set_xscale("log")
    a.set_yscale("log")
    a.invert_xaxis()
    a.set_xlabel("Uzawa error ε = ‖Δr‖/ρ (m)  → more precise")
    a.set_ylabel("total CPU time of the 310 steps (s, log)")
    a.set_title("CPU time vs precision (benchmark 1, μ = 0.6)", fontsize=10)
    a.grid(True, which="both", alpha=0.3)
    a.legend(fontsize=8)
    runs = defaultdict(list)
    for r in per_step:
        runs[r["solver"]].append(r)
    first = None
    for solver, rows in runs.items():
        st = STYLE[solver]
        first = first or rows
        b.plot([int(r["step"]) for r in rows], [max(float(r["cpu_us"]), 1.0) / 1000 for r in rows],
               color=st["color"], lw=1, label=st["label"])
    phase_marks(b, [(int(r["step"]), int(r["phase"])) for r in first])
    b.set_yscale("log")
    b.set_xlabel("haptic step")
    b.set_ylabel("CPU time per step (ms, log)")
    b.set_title("per step at Uzawa error 1e-6 m (the paper's 1e-4 cm)", fontsize=10, pad=18)
    b.grid(True, which="both", alpha=0.3)
    b.legend(fontsize=8)
    fig.suptitle("Fig. 8 reproduced: benchmark 1, μ = 0.6, cold start, ρ = min 1/W_ii (thread CPU time, "
                 "2-core shared machine)", fontsize=11)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "paper_fig8_cpu.png"), dpi=110)
    plt.close(fig)


def fig9(data, out):
    summary = read(os.path.join(data, "paper_fig9_benchmark2.csv"))
    forces = read(os.path.join(data, "paper_fig9_forces.csv"))
    fig, axes = plt.subplots(2, 2, figsize=(14, 9))
    by = defaultdict(list)
    for r in summary:
        by[r["solver"]].append(r)
    panels = [("total_outer", "total outer iterations (310 steps, log)", True),
              ("not_converged", "steps not converged (of 310)", False),
              ("max_force_error_rel", "max ‖F − F_ref‖ / max ‖F_ref‖ (log)", True)]
    for ax, (key, label, log) in zip([axes[0, 0], axes[0, 1], axes[1, 0]], panels):
        for solver, rows in by.items():
            st = STYLE[solver]
            ax.plot([float(r["mu"]) for r in rows], [max(float(r[key]), 1e-7) for r in rows], "o-",
                    color=st["color"], label=st["label"])
        ax.set_xlabel("friction coefficient μ")
        ax.set_ylabel(label)
        if log:
            ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    ax = axes[1, 1]
    for solver in STYLE:
        rows = [r for r in forces if r["solver"] == solver and r["mu"] == "0.3"]
        if not rows:
            continue
        st = STYLE[solver]
        ax.plot([int(r["step"]) for r in rows], [float(r["fz_n"]) for r in rows], color=st["color"],
                lw=2.5 if solver == "reference" else 1, ls="--" if solver == "reference" else "-",
                label=st["label"])
    first = [r for r in forces if r["solver"] == "reference" and r["mu"] == "0.3"]
    phase_marks(ax, [(int(r["step"]), int(r["phase"])) for r in first])
    ax.set_xlabel("haptic step")
    ax.set_ylabel("normal contact force F_z on the tool (N)")
    ax.set_title("μ = 0.3: force along the trajectory", fontsize=10, pad=18)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle("Fig. 9 reproduced: benchmark 2 (obstacle clamped at x = 0 only), Uzawa error 1e-6 m, "
                 "cold start, ρ = min 1/W_ii", fontsize=11)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "paper_fig9_benchmark2.png"), dpi=110)
    plt.close(fig)


SOLVER_COLORS = {"local-uzawa": "tab:blue", "global-uzawa-gs": "tab:red", "global-uzawa-jacobi": "tab:gray"}


def stability(data, out):
    rows = read(os.path.join(data, "stability_summary.csv"))
    sweeps = [("rho", "ρ scale (× paper ρ = min 1/W_ii), μ = 0.3", True),
              ("mu", "friction coefficient μ (benchmark 1)", False),
              ("increment", "device increment (× 0.1 mm per step)", True)]
    fig, axes = plt.subplots(len(sweeps), 2, figsize=(14, 12))
    for row, (sweep, xlabel, logx) in enumerate(sweeps):
        sel = [r for r in rows if r["sweep"] == sweep]
        groups = defaultdict(list)
        for r in sel:
            bench = r["case"].split()[0]
            groups[(bench, r["config"], r["solver"])].append(r)
        for (bench, config, solver), rs in sorted(groups.items()):
            color = SOLVER_COLORS[solver]
            ls = "-" if config == "default" else "--"
            marker = "o" if bench == "benchmark1" else "s"
            x = [float(r["value"]) if sweep != "rho" else float(r["rho_scale"]) for r in rs]
            label = f"{solver} {config} {bench}"
            axes[row, 0].plot(x, [int(r["not_converged"]) for r in rs], ls=ls, marker=marker, color=color,
                              label=label, alpha=0.8)
            axes[row, 1].plot(x, [max(float(r["max_force_error_rel"]), 1e-6) for r in rs], ls=ls,
                              marker=marker, color=color, label=label, alpha=0.8)
        for col in (0, 1):
            ax = axes[row, col]
            ax.set_xlabel(xlabel)
            if logx:
                ax.set_xscale("log")
            ax.grid(True, which="both", alpha=0.3)
        axes[row, 0].set_ylabel("steps not converged")
        axes[row, 1].set_ylabel("max ‖F − F_ref‖ / max ‖F_ref‖ (log)")
        axes[row, 1].set_yscale("log")
        if sweep == "increment":
            for col in (0, 1):
                axes[row, col].axvline(10, color="k", ls=":", lw=1)
                axes[row, col].text(10, 0.5, " press increment ≥ 1 mm =\n collision max_penetration_m:\n"
                                    " the tool passes through\n (all methods, reference too)",
                                    transform=axes[row, col].get_xaxis_transform(), fontsize=7)
    axes[0, 0].legend(fontsize=7, ncol=2)
    fig.suptitle("Stability sweeps (coarse meshes; solid = default config: warm start, ε₁ 1e-6 m, ε₂ 1e-7 m; "
                 "dashed = paper config: cold start, ε₁ = ε₂ = 1e-6 m;\n● benchmark 1, ■ benchmark 2; "
                 "iteration caps 1000 outer / 100 inner)", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "stability_sweeps.png"), dpi=100)
    plt.close(fig)

    # Contact next to the obstacle's ends: grouped bars.
    sel = [r for r in rows if r["sweep"] == "end"]
    cases = list(dict.fromkeys(r["case"] for r in sel))
    configs = [(c, s) for c in ("default", "paper") for s in SOLVER_COLORS]
    fig, axes = plt.subplots(1, 2, figsize=(14, 5.5))
    width = 0.8 / len(configs)
    for i, (config, solver) in enumerate(configs):
        nc, err = [], []
        for case in cases:
            r = next(r for r in sel if r["case"] == case and r["config"] == config and r["solver"] == solver)
            nc.append(int(r["not_converged"]))
            err.append(max(float(r["max_force_error_rel"]), 1e-6))
        xs = [k + (i - len(configs) / 2 + 0.5) * width for k in range(len(cases))]
        kw = dict(width=width, color=SOLVER_COLORS[solver], hatch="" if config == "default" else "//",
                  edgecolor="k", lw=0.3, label=f"{solver} {config}")
        axes[0].bar(xs, nc, **kw)
        axes[1].bar(xs, err, **kw)
    for ax in axes:
        ax.set_xticks(range(len(cases)))
        ax.set_xticklabels([c.replace(" increment", "\nincrement") for c in cases], rotation=30, ha="right",
                           fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].set_ylabel("steps not converged")
    axes[1].set_ylabel("max ‖F − F_ref‖ / max ‖F_ref‖ (log)")
    axes[1].set_yscale("log")
    axes[0].legend(fontsize=8)
    fig.suptitle("Contact next to the obstacle's ends (benchmark 1: both clamped; benchmark 2: left clamped, "
                 "right free), μ = 0.3, coarse meshes", fontsize=11)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "stability_ends.png"), dpi=100)
    plt.close(fig)

    # Force traces of the ρ sweep on benchmark 2.
    traces = read(os.path.join(data, "stability_traces.csv"))
    fig, axes = plt.subplots(1, 3, figsize=(16, 5), sharey=True)
    ref = [r for r in traces if r["config"] == "reference"]
    for ax, solver in zip(axes, SOLVER_COLORS):
        ax.plot([int(r["step"]) for r in ref], [float(r["fz_n"]) for r in ref], "k--", lw=2.5,
                label="reference")
        for rho, color in (("1", "tab:green"), ("3", "tab:orange"), ("10", "tab:purple")):
            rs = [r for r in traces if r["config"] == "default" and r["solver"] == solver and r["rho_scale"] == rho]
            if rs:
                nc = sum(r["status"] != "converged" for r in rs)
                ax.plot([int(r["step"]) for r in rs], [float(r["fz_n"]) for r in rs], color=color, lw=1,
                        label=f"ρ × {rho}: {nc} steps not converged")
        phase_marks(ax, [(int(r["step"]), int(r["phase"])) for r in ref])
        ax.set_title(f"{solver}, default config", fontsize=10, pad=18)
        ax.set_xlabel("haptic step")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("normal contact force F_z (N)")
    fig.suptitle("Benchmark 2, μ = 0.3 (coarse mesh): what failure looks like along the trajectory", fontsize=11)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "stability_rho_traces.png"), dpi=100)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", required=True)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    for name, fn in (("paper_fig67_iterations.csv", fig67), ("paper_fig8_cpu_vs_tol.csv", fig8),
                     ("paper_fig9_benchmark2.csv", fig9), ("stability_summary.csv", stability)):
        if os.path.exists(os.path.join(args.data, name)):
            fn(args.data, args.out)
            print(f"plotted {name}")
        else:
            print(f"skipped {name} (not found)")


if __name__ == "__main__":
    main()
