"""Joint surrogate R = sur(P, F1, F2, M): inputs (..., 4) [MPa, N, N, N·mm] -> anchors (..., k, 2) mm.

k and the input box are the joint's (its file's ``[anchors] count`` and ``[input_box]``; the
paper's: 10 and contract.spec.INPUT_BOX): a dataset's manifest gives them to training, and
a checkpoint carries them (ModelConfig.n_anchors, ModelConfig.input_box) with its joint.

Public API (the gripper predictor uses load_surrogate and ModelError):
    load_surrogate(path)   frozen float64 nn.Module, batched, differentiable in its inputs;
                           model.with_cap(x) -> (anchors (..., k, 2) mm, distal cap
                           rotation (...) rad) in one pass where model.has_cap_rotation
    ModelError             (ValueError) missing, damaged, foreign or inconsistent
                           checkpoint, one-line message
    check_box(x, box=model.input_box)   refuses inputs outside the training box or not
                           finite (OutOfBoxError, a ValueError); contract.spec owns the check
    phi_end(anchors)       end orientation from the last two anchors, rad (numpy or torch,
                           autograd kept); from contract.spec
    ModelConfig, JointSurrogate, KNN

Modules: data (load/split/augment/normalise), model (network + integrity-checked
checkpoint), knn (baseline), train, evaluate, predict, sweep (CLIs: python -m
surrogate.<name> --help), synthetic (an analytic rod dataset for tests and development;
not FEM data; also a CLI), checkpoint (the checkpoint container, shared with the predictor).
Importing this package never imports dolfinx or the predictor.
"""

from contract.spec import OutOfBoxError, check_box, phi_end
from surrogate.knn import KNN
from surrogate.model import JointSurrogate, ModelConfig, ModelError, load_surrogate

__all__ = ["load_surrogate", "ModelError", "check_box", "OutOfBoxError", "phi_end",
           "ModelConfig", "JointSurrogate", "KNN"]
