"""Where the predictor finds its default models: never the working directory.

The committed artefacts live under the results folder of the repository this package
belongs to, ``ROOT/results`` with ROOT = the folder above ``predictor/``; the
environment variable SOFTJOINT_RESULTS names another results folder (e.g. an installed
copy's). Every tool and the Python API resolve a default model here:

    surrogate (the joint model):  RESULTS/surrogate/improved.pt
    NN predictors:                RESULTS/predictor/{gravity,contact}_nn.pt

A default that is missing is an error (ValueError, one line naming the file and the
ways out); the analytic stand-in joint is used only when asked for by name
(``ANALYTIC``). Pure path logic: no torch import.
"""
from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS_ENV = "SOFTJOINT_RESULTS"
ANALYTIC = "analytic"


def results_dir() -> Path:
    """The results folder: $SOFTJOINT_RESULTS when set, else ROOT/results."""
    env = os.environ.get(RESULTS_ENV)
    return Path(env).expanduser() if env else ROOT / "results"


def default_surrogate() -> Path:
    """The committed joint surrogate, results_dir()/surrogate/improved.pt."""
    return results_dir() / "surrogate" / "improved.pt"


def default_nn_dir() -> Path:
    """The folder of the committed NN predictors, results_dir()/predictor."""
    return results_dir() / "predictor"


def joint_spec(model: str | None) -> str:
    """The joint model to load: ``model`` itself (a checkpoint path or "analytic"), or,
    for None, the default surrogate. ValueError (one line) when that default is missing:
    the analytic joint is never a silent substitute."""
    if model is not None:
        return str(model)
    path = default_surrogate()
    if not path.is_file():
        raise ValueError(f"default joint model {path} not found: give --model PATH (model= in the API), "
                         f"--model {ANALYTIC}, or set {RESULTS_ENV} to a results folder")
    return str(path)
