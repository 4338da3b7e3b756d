"""Issue 12 diagnosis: the slow healthy tool change checked with the true parameters against the validated,
tachometer and true plant speed (see the stop note). python benchmarks/diag_model_check_speed.py"""
import numpy as np, tempfile
from feeddrive.cosim.monitor import MEASUREMENTS, MonitorConfig, MonitorPipeline, centred_speed
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.estimator.history import History
from feeddrive.estimator.mismatch import check_model
TRUTH = {"R": 0.6, "L": 4.0e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}
H=1e-4
Z={"noise":0.0}
sc = scenario_from_dict({"name": "slow", "axis": "X", "step": H,
  "plant": {"fmu": "builtin", "parameters": TRUTH},
  "sensors": {"seed": 1, "current": [{"noise": 0.05}, {"noise": 0.05}]},
  "nc": {"program": [{"dwell": {"time": 0.2}}, {"tool_change": {"position": 0.1, "v_max": 0.02, "accel": 0.2, "time": 0.3}}]},
  "monitor": {"db": ":memory:", "speed_threshold": 2.0}})
r = run_scenario(sc, tempfile.mkdtemp()+"/o", plots=False)
rows = np.flatnonzero(r.signals["nc.state"] == 1)
signals = {k: r.signals[f"sensors.{k}"][rows] for k in MEASUREMENTS}
signals["w_enc"] = centred_speed(signals["theta_enc"], signals["w_enc"], H, MonitorConfig().encoder_window_s)
with History(":memory:") as history:
    trace = MonitorPipeline(MonitorConfig(speed_threshold=2.0), history, "X").process(signals, H, 0.0, 1, 0.0)
v = trace.validation
plant_w = r.signals["plant.speed"][rows] if "plant.speed" in r.signals else None
print([k for k in r.signals if k.startswith("plant.")])
for name, w in (("validated w", v.w), ("tach", signals["w_tach"]), ("plant w", plant_w)):
    if w is None: continue
    mm = check_model(v.u, v.i, w, H, TRUTH, MonitorConfig().filter, 0.01, noise={"current":1e-3,"speed":1e-3}, noise_dof=1e5)
    c = mm.checks["speed"]
    print(name, "speed indep F=%.2f p=%.2g rms=%.3g" % (c.tests["independence"].statistic, c.tests["independence"].p_value, c.rms),
          "current indep F=%.2f" % mm.checks["current"].tests["independence"].statistic)
    if plant_w is not None: print("   max |w - plant w| =", np.abs(w-plant_w).max())
est = {k: p["value"] for k, p in trace.result["parameters"].items()}
cov, names = trace.estimate.covariance, trace.estimate.names
for name, w in (("validated w", v.w), ("tach", signals["w_tach"])):
    mm = check_model(v.u, v.i, w, H, est, MonitorConfig().filter, 0.01, covariance=cov, names=names,
                     noise={"current":0.025,"speed":0.035}, noise_dof=1e5)
    print("estimated,", name, {k: round(c.tests["independence"].p_value, 4) for k, c in mm.checks.items()}, "passed", mm.passed)
