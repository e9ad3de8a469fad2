"""Timing of one calibration from 8 observations (issue 38: <= 10 s on this machine).

The timed calibration is docs/calibration.md §5's second command: the fit of the committed
measurement file docs/examples/observations.json (8 gestures of the committed surrogate's
lone finger with the recovery study's known changes, noise 0.3 mm / 0.3 deg; tip, tip
angle and one marker each) for ``FIT`` (gains, offsets, stiffness scales, the tip's
weight with its weighing as a prior, the camera frame: 10 parameters), ``STARTS`` starts
at most, values, stds, identifiability and the trust verdict: what the calibrated finger
file is written from. Not the recovery study's 11: with one marker per gesture the mount's
turn and the camera's are one direction (both unidentifiable), a fit the CLI refuses, and
a refused fit runs no leave-one-out, so its "with leave-one-out" time would time nothing
of it; ``bench_calibration`` refuses (ValueError, one line) a fit that is not trusted. The
CLI's default run adds the leave-one-out predictions (8 more fits, a check of the
calibration, not part of it: ``--no-loo``), timed beside it. The model and observations
are loaded once (a session that calibrates several grippers); each figure is the median
over ``repeats`` runs, wall and this process's CPU time, one torch thread. The load
averages before and after, and what the caller says ran beside it (``beside``), are
recorded: the machine is shared, so the wall time is the CPU time stretched by the load.
The measurement file's name and sha256 are recorded (a test checks they are the
committed example's).

Data flow: CalibrationModel + Observations -> ``bench_calibration`` -> dict
(results/bench/calibrate.json, predictor.artefacts.CALIBRATION_BENCH).
"""
from __future__ import annotations

import os
import statistics
import time

from predictor.calibration.model import CalibrationModel
from predictor.calibration.fit import Prior, calibrate
from predictor.calibration.recovery import PRIOR_STD, TRUTH
from predictor.defaults import ROOT
from predictor.calibration.observations import Observations

OBSERVATIONS = ROOT / "docs" / "examples" / "observations.json"
#: docs/calibration.md §5's fit of that file (groups of predictor.calibration.model), the weighing prior
FIT = ("gain", "offset", "stiffness", "weight_4", "frame")
STARTS = 3
REPEATS = 5
TARGET_S = 10.0


def _timed(model, obs, names, priors, loo: bool) -> tuple[float, float, object]:
    """(wall s, this process's CPU s, result) of one calibration."""
    t0, c0 = time.perf_counter(), time.process_time()
    res = calibrate(model, obs, names, priors, starts=STARTS, loo=loo)
    return time.perf_counter() - t0, time.process_time() - c0, res


def bench_calibration(model: CalibrationModel, obs: Observations, repeats: int = REPEATS, beside: str = "",
                      progress=None) -> dict:
    """Median wall and CPU times (s) of ``repeats`` calibrations of ``obs``, the fit
    alone and with its leave-one-out predictions (module docstring)."""
    names = list(FIT)
    priors = {k: Prior(TRUTH[k], sd) for k, sd in PRIOR_STD.items()}
    load_before = os.getloadavg()
    fit, fit_cpu, loo, loo_cpu = [], [], [], []
    for k in range(repeats):
        if progress:
            progress(f"run {k + 1} of {repeats}")
        wall, cpu, res = _timed(model, obs, names, priors, loo=False)
        if not res.trusted:   # a refused fit runs no leave-one-out: its "with" time would time nothing of it
            why = "; ".join(res.why or ["it did not converge"])
            raise ValueError(f"{obs.source}: the timed fit is not trusted ({why}): the bench times trusted fits only")
        fit.append(wall)
        fit_cpu.append(cpu)
        wall, cpu, res = _timed(model, obs, names, priors, loo=True)
        loo.append(wall)
        loo_cpu.append(cpu)
    med = statistics.median
    return {
        "observations": len(obs), "observations_sha256": obs.sha256, "observations_file": obs.source,
        "parameters": res.names, "priors_std": PRIOR_STD, "trusted": res.trusted,
        "reduced_chi2": res.reduced_chi2, "dof": res.dof, "starts": STARTS, "joint": model.joint.name,
        "repeats": repeats, "fit_s": fit, "fit_median_s": med(fit), "fit_cpu_median_s": med(fit_cpu),
        "with_loo_s": loo, "with_loo_median_s": med(loo), "with_loo_cpu_median_s": med(loo_cpu),
        "rms_after_mm": res.rms_after_mm, "loo_tip_error_mm": res.summary()["loo_tip_error_mm"],
        "torch_threads": 1, "cpus": os.cpu_count(), "load_average_before": list(load_before),
        "load_average_after": list(os.getloadavg()), "beside": beside, "target_s": TARGET_S}


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.calibrate bench")
