"""Joint models: (P, F1, F2, M) -> 10 anchor points of one bellow joint.

Data flow: ``inputs (..., 4) = [P MPa, F1 N, F2 N, M N·mm]`` -> ``anchors (..., 10, 2) mm``
in the joint frame of docs/physics.md (x along the undeformed axis from the proximal face,
y in the bending plane, proximal centre at the origin). Both implementations are torch,
float64, batched over any leading shape and differentiable in every input, so the
equilibrium solver can take exact autograd Jacobians through them.

``AnalyticJoint`` is the stand-in (``--model analytic``) and the test oracle (its anchors
have a closed form). It is a planar
beam of length L = 45.45 mm cut into 10 segments (one per anchor interval, h = L/10);
``AnalyticJoint.for_joint(spec)`` is the same beam with another joint description's
length L and anchor count n (h = L/n), standing for that joint.
Segment k (midpoint s_k) has constant curvature

    kappa_k = (M - c_p·P + F2·(L - s_k)) / EI                          [1/mm]

i.e. the bending moment of the dead end loads taken about the undeformed section
(linear moment law), with exact large-rotation kinematics: the segment is a circular arc,
start angle a_k = sum_{j<k} kappa_j·h, chord

    Δr_k = (1 + F1/EA) · h · sinc(kappa_k h / 2) · (cos(a_k + kappa_k h/2), sin(...)),

and r_i = sum_{k<=i} Δr_k. Sign of the pressure moment: P > 0 pressurises the top (+y)
chamber, the top bellow lengthens, so the joint bends towards -y (clockwise); hence the
``-c_p·P``. The model keeps the docs/physics.md mirror symmetry
(R·diag(1,-1), -P, F1, -F2, -M) exactly.

Stand-in stiffnesses (chosen, not measured; documented here so reports can quote them):
- EI = 3000 N·mm²: a 100 N·mm end couple bends the joint by 100·45.45/3000 = 1.52 rad.
- c_p = 333 N·mm/MPa (≈ chamber area 120 mm² × lever 2.8 mm): |P| = 0.3 MPa gives a
  100 N·mm pressure couple, i.e. a free end angle of 87°; 0.1 MPa gives 29°, the tens of
  degrees a pneumatic bellow joint reaches. Gravity (≈0.2 N at ≈100 mm) droops ≈ 10°.
- EA = 300 N: the bellow is axially soft, 3 N stretches it by 1 % (0.45 mm).

Cap kinematics (issue 14, predictor.model.gripper): ``anchors_and_cap(inputs)`` also returns the
rotation (rad) of the joint's distal cap face, the section the next rigid part is bonded
to. AnalyticJoint: the exact end-section angle of its beam, a_10 + kappa_10·h (the start
angle of the last segment plus its turn). SurrogateJoint: the surrogate's cap-rotation
head (``module.with_cap``) when the checkpoint has one (``module.has_cap_rotation``),
otherwise a one-line ValueError (use tangent kinematics).

Joint descriptions (contract.joint, docs/joints.md). Every joint model is a model of one
joint description, ``model.joint``: a surrogate's is the one its checkpoint carries
(surrogate.model.checkpoint_joint; absent in checkpoints written before joint files: the
paper's), the analytic stand-in's is the paper's. A finger file names the joint of each
joint part (contract.finger; absent: the paper's), and ``check_finger`` refuses, with one
line, a model whose joint is not the one every joint part of the finger names (compared
by contract.joint.joint_digest): ``load_joint(spec, finger)`` loads and checks in one call.

The joint's contract (length, anchors, input box, phi_end) is contract.spec's for the
paper's joint; this module only implements it.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

import torch

from contract import joint as joint_file
from contract.files import sha256_file
from contract.finger import FingerSpec
from contract.joint import JointSpec, joint_digest
from contract.spec import JOINT_LENGTH, N_ANCHORS
from predictor.defaults import ANALYTIC, joint_spec


class JointModel:
    """Interface: ``joint(inputs)`` maps (..., 4) [P MPa, F1 N, F2 N, M N·mm] (float64)
    to anchors (..., 10, 2) mm in the joint frame, differentiably."""

    length: float = JOINT_LENGTH
    name: str = "joint"

    def __call__(self, inputs: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    @property
    def joint(self) -> JointSpec:
        """The joint description this model stands for (module docstring): the paper's."""
        return joint_file.load_joint()

    @property
    def has_cap_rotation(self) -> bool:
        """Whether ``anchors_and_cap`` is available (cap kinematics)."""
        return False

    def anchors_and_cap(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(anchors (..., 10, 2) mm, cap rotation (...) rad) of inputs (..., 4) in one pass."""
        raise ValueError(no_cap_message(self.name))

    def astype(self, dtype: torch.dtype) -> "JointModel":
        """This joint model evaluating inputs of ``dtype`` (float32 for batched throughput;
        float64, the default, for the solvers). A model whose formulas follow their inputs'
        dtype is returned as it is."""
        return self


def no_cap_message(name: str) -> str:
    return f"joint model {name} has no cap-rotation head: use --kinematics tangent"


@dataclass(frozen=True)
class AnalyticJoint(JointModel):
    """Segment-wise constant-curvature beam (module docstring has the equations).

    EI in N·mm², c_p in N·mm/MPa (pressure couple per MPa), EA in N, L in mm.
    """

    EI: float = 3000.0
    c_p: float = 333.0
    EA: float = 300.0
    length: float = JOINT_LENGTH
    name: str = "analytic"
    #: The joint description it stands for (None: the paper's); ``for_joint`` sets it.
    description: JointSpec | None = None

    @classmethod
    def for_joint(cls, spec: JointSpec) -> "AnalyticJoint":
        """The stand-in beam with the length and anchor count of the joint ``spec`` (and
        the paper's stand-in stiffnesses EI, c_p, EA): a joint model of that description,
        e.g. to test a finger of another joint without training a surrogate."""
        return cls(length=spec.length, name=f"analytic:{spec.name}", description=spec)

    @property
    def joint(self) -> JointSpec:
        return self.description if self.description is not None else joint_file.load_joint()

    @property
    def anchors(self) -> int:
        """Anchor count n (10 for the paper's joint); segment length h = L/n."""
        return self.description.anchors if self.description is not None else N_ANCHORS

    def __call__(self, inputs: torch.Tensor) -> torch.Tensor:
        return self._beam(inputs)[0]

    @property
    def has_cap_rotation(self) -> bool:
        return True

    def anchors_and_cap(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self._beam(inputs)

    def _beam(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(anchors (..., n, 2), end-section angle (...) = a_n + kappa_n·h)."""
        P, F1, F2, M = inputs.unbind(-1)
        n = self.anchors
        h = self.length / n
        s_mid = (torch.arange(n, dtype=inputs.dtype) + 0.5) * h  # (n,)
        kappa = (M - self.c_p * P)[..., None] + F2[..., None] * (self.length - s_mid)
        kappa = kappa / self.EI  # (..., n) 1/mm
        turn = kappa * h
        start = torch.cumsum(turn, -1) - turn  # angle at each segment start
        mid = start + 0.5 * turn
        # sinc(x) = sin(x)/x for the chord of an arc; torch.sinc is the normalised one.
        chord = (1.0 + F1 / self.EA)[..., None] * h * torch.sinc(0.5 * turn / math.pi)
        steps = torch.stack((chord * torch.cos(mid), chord * torch.sin(mid)), -1)
        return torch.cumsum(steps, -2), start[..., -1] + turn[..., -1]


class SurrogateJoint(JointModel):
    """The FEM-trained surrogate (issue 4) loaded from a checkpoint file.

    Wraps ``surrogate.load_surrogate(path)`` (an nn.Module in float64, (..., 4) ->
    (..., 10, 2) mm). Its parameters are frozen: the predictor differentiates through
    the network with respect to its inputs only.
    """

    def __init__(self, path: str | Path):
        from surrogate import load_surrogate  # the predictor -> surrogate direction only

        path = Path(path)
        self.module = load_surrogate(path).double().eval()  # ModelError (ValueError), one line
        for p in self.module.parameters():
            p.requires_grad_(False)
        # The content digest ties what was built on this joint (the NN predictors) to
        # this exact checkpoint: a retrained file under the same name is another joint.
        self.name = f"surrogate:{path.name}@{sha256_file(path)[:12]}"
        self.length = self.module.joint.length

    @property
    def joint(self) -> JointSpec:
        """The joint description the checkpoint was trained on."""
        return self.module.joint

    def __call__(self, inputs: torch.Tensor) -> torch.Tensor:
        return self.module(inputs)

    @property
    def has_cap_rotation(self) -> bool:
        # The cap-rotation head is issue 14's; older checkpoints have none.
        return bool(getattr(self.module, "has_cap_rotation", False))

    def anchors_and_cap(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if not self.has_cap_rotation:
            raise ValueError(no_cap_message(self.name))
        return self.module.with_cap(inputs)

    def astype(self, dtype: torch.dtype) -> "SurrogateJoint":
        """A copy whose network (weights and normalisation) is in ``dtype``, same name."""
        other = copy.copy(self)
        other.module = copy.deepcopy(self.module).to(dtype)
        return other


def check_finger(model: JointModel, finger: FingerSpec) -> None:
    """ValueError (one line) unless every joint part of ``finger`` names the joint
    description ``model`` was made for (module docstring; compared by digest)."""
    want = joint_digest(model.joint)
    for j, k in enumerate(finger.joints):
        named = finger.parts[k].spec
        if joint_digest(named) != want:
            where = finger.parts[k].joint_file or "no joint file: the paper's joint"
            raise ValueError(f"joint model {model.name} was trained on joint {model.joint.name!r} (sha256 "
                             f"{want[:12]}), but joint {j + 1} of finger {finger.name!r} is {named.name!r} "
                             f"({where}, sha256 {joint_digest(named)[:12]}): use a model of that joint")


def load_joint(spec: str | None, finger: FingerSpec | None = None) -> JointModel:
    """``"analytic"`` -> AnalyticJoint(); a checkpoint path -> SurrogateJoint; None -> the
    default surrogate (predictor.defaults: found from the package, never the working
    directory). With ``finger``, the model must be of the joint its joint parts name
    (check_finger).

    Raises ValueError (surrogate.ModelError is one) with a one-line reason, also when the
    default surrogate is missing (the analytic joint is only used when named).
    """
    spec = joint_spec(spec)
    model = AnalyticJoint() if spec == ANALYTIC else SurrogateJoint(spec)
    if finger is not None:
        check_finger(model, finger)
    return model
