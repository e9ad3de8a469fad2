"""Joint surrogate R = sur(P, F1, F2, M): inputs (..., 4) [MPa, N, N, N·mm] -> anchors (..., 10, 2) mm.

Public API (the gripper predictor uses load_surrogate and ModelError):
    load_surrogate(path)   frozen float64 nn.Module, batched, differentiable in its inputs
    ModelError             (ValueError) missing or corrupt checkpoint, one-line message
    check_box(x)           refuses inputs outside the training box (ExtrapolationError)
    phi_end(anchors)       end orientation atan2(y10 - y9, x10 - x9), rad
    ModelConfig, JointSurrogate, KNN

Modules: data (load/split/augment/normalise), model (network + checkpoint), knn (baseline),
train, evaluate, predict (CLIs: python -m surrogate.<name> --help), synthetic (an analytic
rod dataset for tests and development; not FEM data).
Importing this package never imports dolfinx or the predictor.
"""

from surrogate.data import ExtrapolationError, check_box
from surrogate.knn import KNN
from surrogate.model import JointSurrogate, ModelConfig, ModelError, load_surrogate, phi_end

__all__ = ["load_surrogate", "ModelError", "check_box", "ExtrapolationError", "phi_end",
           "ModelConfig", "JointSurrogate", "KNN"]
