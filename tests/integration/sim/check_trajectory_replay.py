"""hapco-sim --trajectory replays given poses: fed the scene's own trajectory (the dx,dy,dz
columns of a default run) it must give the same forces, and a malformed file must be refused
with FILE:LINE. Usage: check_trajectory_replay.py HAPCO_SIM SCENE WORKDIR"""
import csv, subprocess, sys

sim, scene, work = sys.argv[1:4]
subprocess.run([sim, scene, "--csv", f"{work}/default.csv", "--quiet"], check=True, stdout=subprocess.DEVNULL)
default = list(csv.DictReader(open(f"{work}/default.csv")))
with open(f"{work}/trajectory.csv", "w") as f:
    f.write("x_m,y_m,z_m\n")
    for r in default:
        f.write(f"{r['dx_m']},{r['dy_m']},{r['dz_m']}\n")
subprocess.run([sim, scene, "--trajectory", f"{work}/trajectory.csv", "--csv", f"{work}/replay.csv", "--quiet"],
               check=True, stdout=subprocess.DEVNULL)
replay = list(csv.DictReader(open(f"{work}/replay.csv")))
assert len(replay) == len(default) == 310, (len(replay), len(default))
worst = 0.0
for a, b in zip(default, replay):
    assert b["phase"] == "file"
    for k in ("device_fx_n", "device_fy_n", "device_fz_n"):
        fa, fb = float(a[k]), float(b[k])
        worst = max(worst, abs(fa - fb) / max(abs(fa), abs(fb), 1e-3))
# The CSV prints positions with 9 significant digits, so the replayed poses differ from the
# scene's by < 1e-9 m: forces agree to ~1e-6 relative, not bit for bit.
assert worst < 1e-5, worst
with open(f"{work}/bad.csv", "w") as f:
    f.write("x_m,y_m,z_m\n0,0,-0.0001\n0,nan,0\n")
bad = subprocess.run([sim, scene, "--trajectory", f"{work}/bad.csv"], capture_output=True, text=True)
assert bad.returncode == 1 and "bad.csv:3:" in bad.stderr, (bad.returncode, bad.stderr)
print(f"replay of {len(replay)} steps: largest relative force difference {worst:.3g}")
print("ok")
