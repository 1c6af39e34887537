#!/usr/bin/python3
"""usage: check_sim_csv.py FILE STEPS — one row per step, finite values, every step converged,
a force that grows while pressing (once the bodies touch: a scene may start with a gap) and
vanishes after the final lift (back at the start height
the exact force is zero; the solver's stop test leaves a residual, allowed up to 1e-4 of the
peak force)."""
import csv
import math
import sys

rows = list(csv.DictReader(open(sys.argv[1])))
steps = int(sys.argv[2])
if [int(r["step"]) for r in rows] != list(range(1, steps + 1)):
    raise SystemExit(f"expected steps 1..{steps}, got {len(rows)} rows")
for r in rows:
    for key, value in r.items():
        if key not in ("phase", "status") and not math.isfinite(float(value)):
            raise SystemExit(f"step {r['step']}: {key} = {value}")
    if r["status"] != "converged":
        raise SystemExit(f"step {r['step']}: status {r['status']}")
press = [float(r["fz_n"]) for r in rows if r["phase"] == "press"]
if not any(f > 0 for f in press) or not all(b > a or a == b == 0 for a, b in zip(press, press[1:])):
    raise SystemExit("the normal force does not grow monotonically while pressing")
last = rows[-1]
peak = max(math.hypot(float(r["fx_n"]), float(r["fy_n"]), float(r["fz_n"])) for r in rows)
if math.hypot(float(last["fx_n"]), float(last["fy_n"]), float(last["fz_n"])) > 1e-4 * peak:
    raise SystemExit(f"force after the lift is not zero: {last['fx_n']} {last['fy_n']} {last['fz_n']}")
print(f"{len(rows)} steps, peak fz {max(float(r['fz_n']) for r in rows):.3f} N")
print("ok")
