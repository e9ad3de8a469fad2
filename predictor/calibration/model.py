"""Calibrating a gripper to measured gestures (issue 38; docs/calibration.md).

Parameters theta (``parameter_table``), each switchable (``fit`` names or groups):

    gain_Ji, offset_Ji (MPa), stiffness_Ji   joint i sees P_eff = (g·P + o)/s and loads tau/s
    weight_k (N)                             part k's weight (1-based chain index)
    mount_x (mm), mount_deg (deg)            the base mount's shift along X and turn
    frame_x, frame_y (mm), frame_deg (deg)   gripper frame -> measurement frame, rigid 2D

The stiffness scale uses the exact similarity of a hyperelastic joint whose energy scales
with its modulus E under follower pressure and dead loads: R(P, tau; s·E) = R(P/s, tau/s; E),
so the joint model is evaluated at ((g·P + o)/s, tau/s). A turn delta of the mount is a
rotation of the whole finger about its mount, equivalent to computing the finger at the
nominal mount with gravity turned by -delta: the residual below does that, so every
parameter enters as a tensor and autograd differentiates it.

Forward model, per observation b: the equilibrium x_b = tau_b (3J) solves
R(x_b, theta; P_b) = 0 (Equation 1 of predictor.model.statics: gravity loads, and for the
gripper the frictionless penalty of the plane X = 0 where the two mirror fingers meet;
the residual is the statics' scaled one, checked against GripperProblem.residual by the
tests), found by Newton steps with the autograd Jacobian. The observations say which
problem was measured (predictor.calibration.observations ``problem``): ``gripper`` (the default, the
plane on, as predictor.cli.gesture solves it) or ``finger`` (a lone finger, statics.apart).
The plane is where the gripper's symmetry puts it, X = 0 of the gripper frame: the
outline's vertices are mapped by the mount (below, without the camera frame), the
plane's forces found there (statics.plane_contact) and mapped back, p = B + Rot(-mount)·
(q - B - (mount_x, 0)), f = Rot(-mount)·f_q. The predicted measurements
m_b(x_b, theta) are the tip, its angle and marker points mapped to the measurement frame:
p_meas = Rot(frame) · (B + (mount_x, 0) + Rot(mount)·(p - B)) + frame_xy, B the mount.

The fit's Jacobian is exact, by the implicit function theorem at the converged
equilibrium: dx/dtheta = -(dR/dx)^-1 dR/dtheta, dm/dtheta = dm/dtheta|_x + dm/dx ·
dx/dtheta (no unrolled iterations; ``sensitivities``).

Data flow: finger + joint model -> CalibrationModel; Observations (predictor.calibration.observations)
-> ``design`` -> Design; theta -> ``equilibrium`` -> x -> ``predict`` / ``sensitivities``
-> predictor.calibration.fit (the least squares) -> predictor.calibration.file (the
calibrated finger file every tool reads: weights, mount, joint keys; the measurement
frame is the camera's, recorded only). Units: mm, N, N·mm, MPa, rad in code; degrees in names ending _deg and in JSON.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from contract.finger import FingerSpec, JointPart
from predictor.model.gripper import GripperParams, finger_pose, outline_vertices, rot
from predictor.model.joint import JointModel
from predictor.calibration.observations import GRIPPER, Observations
from predictor.model.statics import MOMENT_SCALE, ContactParams, plane_contact

NEWTON_TOL = 1e-10     # N (and N·mm/MOMENT_SCALE): the equilibrium's residual


@dataclass(frozen=True)
class Param:
    """One parameter: name, nominal value, bounds, unit and group (for --fit)."""

    name: str
    nominal: float
    lo: float
    hi: float
    unit: str
    group: str


def parameter_table(finger: FingerSpec) -> tuple[Param, ...]:
    """Every calibratable parameter of ``finger`` with its nominal value and bounds."""
    out = []
    joints = [p for p in finger.parts if p.kind == "joint"]
    for i, p in enumerate(joints, 1):
        out += [Param(f"gain_J{i}", p.pressure_gain, 0.5, 2.0, "", "gain"),
                Param(f"offset_J{i}", p.pressure_offset, -0.05, 0.05, "MPa", "offset"),
                Param(f"stiffness_J{i}", p.stiffness_scale, 0.5, 2.0, "", "stiffness")]
    for k, p in enumerate(finger.parts, 1):
        out.append(Param(f"weight_{k}", p.weight, 0.0, 2.0, "N", "weight"))
    out += [Param("mount_x", 0.0, -10.0, 10.0, "mm", "mount"), Param("mount_deg", 0.0, -10.0, 10.0, "deg", "mount"),
            Param("frame_x", 0.0, -50.0, 50.0, "mm", "frame"), Param("frame_y", 0.0, -50.0, 50.0, "mm", "frame"),
            Param("frame_deg", 0.0, -20.0, 20.0, "deg", "frame")]
    return tuple(out)


DEFAULT_FIT = ("gain", "offset", "stiffness")


def resolve_fit(names, table: tuple[Param, ...]) -> tuple[int, ...]:
    """Indices into ``table`` of the fitted names (a name or a group: gain, offset,
    stiffness, weight, mount, frame); ValueError (one line) for an unknown one."""
    known = {p.name for p in table}
    groups = {p.group for p in table}
    chosen = []
    for n in names:
        if n in known:
            chosen += [i for i, p in enumerate(table) if p.name == n]
        elif n in groups:
            chosen += [i for i, p in enumerate(table) if p.group == n]
        else:
            raise ValueError(f"--fit: unknown parameter {n!r} (names: {', '.join(p.name for p in table)}; "
                             f"groups: {', '.join(sorted(groups))})")
    chosen = tuple(dict.fromkeys(chosen))
    if not chosen:
        raise ValueError("--fit: no parameter chosen")
    return chosen


def identity_joints(finger: FingerSpec) -> FingerSpec:
    """``finger`` with every joint's calibration keys reset (the model applies them)."""
    parts = tuple(JointPart(p.weight, p.contact) if p.kind == "joint" else p for p in finger.parts)
    return dataclasses.replace(finger, parts=parts, calibration=None)


class ScaledJoint(JointModel):
    """The joint model evaluated at ((g·P + o)/s, F1/s, F2/s, M/s) per joint: g, o, s are
    (B, J) tensors; inputs (B, J, 4) as predictor.model.gripper.finger_pose passes them."""

    def __init__(self, inner: JointModel, gain: torch.Tensor, offset: torch.Tensor, scale: torch.Tensor):
        self.inner, self.name = inner, inner.name
        self.gain, self.offset, self.scale = gain, offset, scale

    def _inputs(self, inputs: torch.Tensor) -> torch.Tensor:
        p = (self.gain * inputs[..., 0] + self.offset) / self.scale
        return torch.cat((p[..., None], inputs[..., 1:] / self.scale[..., None]), -1)

    def __call__(self, inputs):
        return self.inner(self._inputs(inputs))

    @property
    def has_cap_rotation(self) -> bool:
        return self.inner.has_cap_rotation

    def anchors_and_cap(self, inputs):
        return self.inner.anchors_and_cap(self._inputs(inputs))


def _loads_of_parts(params: GripperParams) -> tuple[torch.Tensor, torch.Tensor]:
    """(part index (Kw,), share (Kw,)) of each weight load of the chain layout: the load
    is share × that part's weight (a split joint's two halves, 0.5 each)."""
    finger, layout = params.finger, params.layout
    rigid = [k for k, p in enumerate(finger.parts) if p.kind == "rigid"]
    joints = list(finger.joints)
    split = layout.joint_weight == "split"
    cand_part = rigid + joints + (joints if split else [])
    cand_share = [1.0] * len(rigid) + [0.5 if split else 1.0] * (len(joints) * (2 if split else 1))
    src = layout.weight_source.tolist()
    return (torch.tensor([cand_part[i] for i in src], dtype=torch.long),
            torch.tensor([cand_share[i] for i in src], dtype=torch.float64))


class CalibrationModel:
    """The parametrised forward model of one finger and joint model (module docstring)."""

    def __init__(self, joint: JointModel, finger: FingerSpec, kinematics: str = "cap", joint_weight: str = "split"):
        self.joint, self.finger = joint, finger
        self.params = GripperParams(identity_joints(finger), kinematics=kinematics, joint_weight=joint_weight)
        self.table = parameter_table(finger)
        self.index = {p.name: i for i, p in enumerate(self.table)}
        self.nominal = torch.tensor([p.nominal for p in self.table], dtype=torch.float64)
        self.load_part, self.load_share = _loads_of_parts(self.params)
        self.J = finger.n_joints
        self.mount = torch.tensor([0.5 * finger.base_gap, 0.0], dtype=torch.float64)
        self.contact = ContactParams()   # the plane X = 0's penalty, as predictor.cli.gesture's gripper

    def _joint_params(self, th):
        idx = [self.index[f"{g}_J{i}"] for i in range(1, self.J + 1) for g in ("gain", "offset", "stiffness")]
        v = th[:, idx].reshape(-1, self.J, 3)
        return v[..., 0], v[..., 1], v[..., 2]

    def pose(self, x: torch.Tensor, th: torch.Tensor, pressures: torch.Tensor):
        """FingerPose at the nominal mount (B) for tau = x (B, 3J), theta (B, n), P (B, J) MPa."""
        gain, offset, scale = self._joint_params(th)
        joint = ScaledJoint(self.joint, gain, offset, scale)
        return finger_pose(joint, self.params, pressures, x.reshape(-1, self.J, 3))

    def residual(self, x, th, pressures, gravity, plane: bool = True) -> torch.Tensor:
        """Scaled Equation-1 residual (B, 3J): [R_Fx, R_Fy N, R_M/MOMENT_SCALE] per joint,
        gravity (B,) float 1/0, computed at the nominal mount with gravity turned by -mount;
        ``plane``: the gripper (the fingers meet at X = 0), else the finger alone."""
        pose = self.pose(x, th, pressures)
        tau = x.reshape(-1, self.J, 3)
        layout = self.params.layout
        joints = pose.joints
        at_joints = ((joints[:, :, 1:].mean(2),) if layout.joint_weight == "lumped" else
                     (joints[:, :, 0], joints[:, :, -1]))
        pts = torch.cat((pose.segments.mean(2),) + at_joints, 1).index_select(1, layout.weight_source)
        n_parts = len(self.finger.parts)
        w_part = th[:, self.index["weight_1"]:self.index["weight_1"] + n_parts]
        w = w_part[:, self.load_part] * self.load_share * gravity[:, None]                 # (B, Kw) N
        turn = torch.deg2rad(th[:, self.index["mount_deg"]])
        down = rot(-turn, torch.tensor([0.0, -1.0], dtype=x.dtype).expand(x.shape[0], 2))   # (B, 2)
        frc = w[..., None] * down[:, None, :]
        mask = layout.weight_mask.to(x.dtype)
        if plane:
            p_pts, p_frc = self.plane_loads(pose, th)
            pts, frc = torch.cat((pts, p_pts), 1), torch.cat((frc, p_frc), 1)
            mask = torch.cat((mask, layout.plane_mask.to(x.dtype)), 1)
        f_sum = (mask[:, :, None] * frc[:, None]).sum(2)                                     # (B, J, 2)
        cross = pts[..., 0] * frc[..., 1] - pts[..., 1] * frc[..., 0]
        ends = joints[:, :, -1]
        m_sum = (mask * cross[:, None]).sum(-1) - (ends[..., 0] * f_sum[..., 1] - ends[..., 1] * f_sum[..., 0])
        res = torch.cat((rot(pose.theta, tau[..., :2]) - f_sum, ((tau[..., 2] - m_sum) / MOMENT_SCALE)[..., None]), -1)
        return res.reshape(x.shape[0], -1)

    def plane_loads(self, pose, th) -> tuple[torch.Tensor, torch.Tensor]:
        """The plane X = 0's Gauss points and forces (B, Kp, 2) mm, N on the outline of
        ``pose`` (computed at the nominal mount), in that frame (module docstring)."""
        q = self.to_gripper(outline_vertices(pose, self.params.layout), th)
        pc = plane_contact(pose, self.params, self.contact, q)
        turn = torch.deg2rad(th[:, self.index["mount_deg"]])[:, None]
        shift = torch.stack((th[:, self.index["mount_x"]], torch.zeros_like(th[:, 0])), -1)[:, None]
        return self.mount + rot(-turn, pc.points - self.mount - shift), rot(-turn, pc.forces)

    def to_gripper(self, p: torch.Tensor, th: torch.Tensor) -> torch.Tensor:
        """Points p (B, ..., 2) computed at the nominal mount -> the gripper frame (mm):
        B + (mount_x, 0) + Rot(mount_deg)·(p - B)."""
        extra = (1,) * (p.dim() - 2)
        turn = torch.deg2rad(th[:, self.index["mount_deg"]]).reshape(-1, *extra)
        shift = torch.stack((th[:, self.index["mount_x"]], torch.zeros_like(th[:, 0])), -1).reshape(-1, *extra, 2)
        return self.mount + shift + rot(turn, p - self.mount)

    def to_frame(self, p: torch.Tensor, th: torch.Tensor) -> torch.Tensor:
        """Points p (B, ..., 2) computed at the nominal mount -> measurement frame (mm)."""
        extra = (1,) * (p.dim() - 2)
        q = self.to_gripper(p, th)
        frame = torch.deg2rad(th[:, self.index["frame_deg"]]).reshape(-1, *extra)
        t = torch.stack((th[:, self.index["frame_x"]], th[:, self.index["frame_y"]]), -1).reshape(-1, *extra, 2)
        return rot(frame, q) + t

    def tip_angle_deg(self, pose, th) -> torch.Tensor:
        """The last part's direction (B,) deg in the measurement frame."""
        return (torch.rad2deg(pose.tip_angle) + th[:, self.index["mount_deg"]] + th[:, self.index["frame_deg"]])

    def part_point(self, pose, k: int, s: float) -> torch.Tensor:
        """(B, 2) the point s mm along part k (0-based) of the pose: rigid parts exactly,
        joints interpolated linearly between their anchors (at s = L·j/10)."""
        kind, poly = pose.part_polylines()[k]
        length = self.finger.parts[k].length
        n = poly.shape[1] - 1
        u = min(max(s / length * n, 0.0), float(n))
        j = min(int(u), n - 1)
        f = u - j
        return (1.0 - f) * poly[:, j] + f * poly[:, j + 1]


@dataclass
class Design:
    """Observations as tensors: pressures (B, J), gravity (B,), and the measured values
    y (N,) with sigma (N,), each scalar's observation obs (N,) and what it is ``what``
    (N tuples: ("x"|"y", part, s) or ("deg",)); ``plane``: the gripper was measured (the
    fingers meet at X = 0), else a lone finger."""

    pressures: torch.Tensor
    gravity: torch.Tensor
    y: np.ndarray
    sigma: np.ndarray
    obs: np.ndarray
    what: list
    tip_rows: list          # per observation: (row of x, row of y) of its tip or None
    plane: bool = True


def design(obs: Observations, finger: FingerSpec) -> Design:
    """The Design of ``obs`` (refuses observations with an object: one line)."""
    for i, o in enumerate(obs.items):
        if o.object is not None:
            raise ValueError(f"{obs.source}: observations[{i}] holds an object: the calibration fits gestures "
                             "without contact (gravity on or off); drop the object observations")
    y, sigma, ob, what, tips = [], [], [], [], []
    last = len(finger.parts) - 1
    for b, o in enumerate(obs.items):
        pts = ([(last, finger.parts[last].length, o.tip)] if o.tip else []) + [(m.part, m.s, (m.x, m.y, m.sigma))
                                                                             for m in o.markers]
        tips.append((len(y), len(y) + 1) if o.tip else None)
        for part, s, (px, py, sg) in pts:
            y += [px, py]
            sigma += [sg, sg]
            ob += [b, b]
            what += [("x", part, s), ("y", part, s)]
        if o.tip_angle is not None:
            y.append(o.tip_angle[0])
            sigma.append(o.tip_angle[1])
            ob.append(b)
            what.append(("deg",))
    return Design(torch.tensor([o.pressures for o in obs.items], dtype=torch.float64),
                  torch.tensor([1.0 if o.gravity else 0.0 for o in obs.items], dtype=torch.float64),
                  np.array(y), np.array(sigma), np.array(ob), what, tips, obs.problem == GRIPPER)


def predict(model: CalibrationModel, d: Design, x: torch.Tensor, th: torch.Tensor) -> torch.Tensor:
    """Predicted measurements (N,) for equilibria x (B, 3J) and theta (B, n)."""
    pose = model.pose(x, th, d.pressures)
    cache, out = {}, []
    deg = model.tip_angle_deg(pose, th)
    for b, w in zip(d.obs.tolist(), d.what):
        if w[0] == "deg":
            out.append(deg[b])
            continue
        key = w[1:]
        if key not in cache:
            cache[key] = model.to_frame(model.part_point(pose, *key), th)
        out.append(cache[key][b, 0 if w[0] == "x" else 1])
    return torch.stack(out)


def equilibrium(model: CalibrationModel, d: Design, th: torch.Tensor, x0: torch.Tensor | None = None,
                max_iter: int = 40) -> tuple[torch.Tensor, torch.Tensor]:
    """R(x, theta) = 0 per observation (B, 3J): Newton from x0 (default: 0 for a lone
    finger; the predictor's solver for the gripper, ``solved``: Newton from tau = 0 can land
    far across X = 0, where the plane's penalty is stiff); the rows it leaves unconverged
    are started again from ``solved`` (when they did not already start there). Returns
    (x (B, 3J), converged (B,) bool: max |R| <= NEWTON_TOL)."""
    th = th.detach()
    cold = x0 is None and d.plane
    if cold:
        x0 = solved(model, d, th)
    x, ok = _newton(model, d, th, x0, max_iter)
    if not cold and not bool(ok.all()):
        rows = (~ok).nonzero().flatten()
        sub = dataclasses.replace(d, pressures=d.pressures[rows], gravity=d.gravity[rows])
        xs, oks = _newton(model, sub, th[rows], solved(model, sub, th[rows]), max_iter)
        x, ok = x.clone(), ok.clone()
        x[rows], ok[rows] = xs, oks
    return x, ok


def _newton(model: CalibrationModel, d: Design, th: torch.Tensor, x0: torch.Tensor | None, max_iter: int):
    """Newton with backtracking on R(x, theta) = 0 from x0 (None: 0); (x, converged)."""
    B, n = d.pressures.shape[0], 3 * model.J
    x = torch.zeros(B, n, dtype=torch.float64) if x0 is None else torch.nan_to_num(x0.detach().clone())
    for _ in range(max_iter):
        r, jx = _residual_and_jacobian(model, d, x, th)
        norm = r.abs().amax(1)
        if bool((norm <= NEWTON_TOL).all()):
            break
        step = torch.linalg.solve(jx, -r[..., None])[..., 0]
        merit = r.norm(dim=1)   # |R|: the Newton step descends it (the max norm may not, near a kink)
        t = torch.ones(B, dtype=torch.float64)
        for _ in range(20):   # halve each row's step until its residual decreases
            with torch.no_grad():
                trial = model.residual(x + t[:, None] * step, th, d.pressures, d.gravity, d.plane).norm(dim=1)
            worse = ~(trial < merit) & (norm > NEWTON_TOL)
            if not bool(worse.any()):
                break
            t = torch.where(worse, 0.5 * t, t)
        x = x + torch.where(norm[:, None] > NEWTON_TOL, t[:, None] * step, torch.zeros_like(step))
    with torch.no_grad():
        ok = model.residual(x, th, d.pressures, d.gravity, d.plane).abs().amax(1) <= NEWTON_TOL
    return x, ok


def finger_at(model: CalibrationModel, theta: torch.Tensor) -> FingerSpec:
    """The finger file's description of parameters theta (n,): part weights, joint keys
    (gain, offset, stiffness scale), base_gap + 2·mount_x, base angle + mount_deg (the
    camera frame is no part of it)."""
    v = {p.name: float(theta[i]) for i, p in enumerate(model.table)}
    parts, j = [], 0
    for k, part in enumerate(model.finger.parts, 1):
        part = dataclasses.replace(part, weight=v[f"weight_{k}"])
        if part.kind == "joint":
            j += 1
            part = dataclasses.replace(part, pressure_gain=v[f"gain_J{j}"], pressure_offset=v[f"offset_J{j}"],
                                       stiffness_scale=v[f"stiffness_J{j}"])
        parts.append(part)
    return dataclasses.replace(model.finger, parts=tuple(parts), base_gap=model.finger.base_gap + 2.0 * v["mount_x"],
                               base_angle=model.finger.base_angle + np.radians(v["mount_deg"]), calibration=None)


def solved(model: CalibrationModel, d: Design, th: torch.Tensor) -> torch.Tensor:
    """Equilibria x (B, 3J) by the predictor's solver (predictor.solvers.solve, as predictor.cli.gesture:
    the plane's ramp where the fingers meet) of ``finger_at`` each row's theta, with or
    without gravity and the plane as ``d`` says; NaN where it does not converge. tau is
    in the joints' own frames, so the mount's turn leaves it unchanged."""
    from predictor.solvers.solve import solve
    from predictor.model.statics import GripperProblem, apart

    x = torch.full((d.pressures.shape[0], 3 * model.J), float("nan"), dtype=torch.float64)
    keys = [tuple(row) + (g,) for row, g in zip(th.tolist(), d.gravity.tolist())]
    for key in dict.fromkeys(keys):
        rows = torch.tensor([i for i, k in enumerate(keys) if k == key])
        params = GripperParams(finger_at(model, torch.tensor(key[:-1], dtype=torch.float64)),
                               kinematics=model.params.kinematics, joint_weight=model.params.joint_weight)
        problem = GripperProblem(model.joint, params, gravity=bool(key[-1]))
        res = solve(problem if d.plane else apart(problem), d.pressures[rows])
        x[rows] = torch.where(res.converged[:, None], res.tau.reshape(len(rows), -1), float("nan"))
    return x


def _residual_and_jacobian(model, d, x, th):
    """R (B, 3J) and dR/dx (B, 3J, 3J) by reverse mode (row b of R depends on x_b only)."""
    r, (rx,) = _rows_and_jacobians(model, d, x, (th.detach(),), 1)
    return r, rx


def _rows_and_jacobians(model, d, x, th: tuple, wrt: int):
    """R (B, n) at x (B, n), theta (th[0], (B, m)), and the Jacobians of R per row with
    respect to x and, with wrt = 2, theta: (B, n, n) and (B, n, m). One reverse pass: every
    row is evaluated n times in one batch (B·n rows; the residual is dispatch-bound, so
    a batch n times larger costs about as much), copy i of row b carrying R_i's seed."""
    B, n = x.shape
    xr = x.detach().repeat_interleave(n, 0).requires_grad_(True)
    tr = th[0].detach().repeat_interleave(n, 0).requires_grad_(wrt == 2)
    r = model.residual(xr, tr, d.pressures.repeat_interleave(n, 0), d.gravity.repeat_interleave(n, 0), d.plane)
    seed = torch.eye(n, dtype=r.dtype).repeat(B, 1)
    grads = torch.autograd.grad((r * seed).sum(), (xr, tr)[:wrt])
    return r.detach()[::n], tuple(g.reshape(B, n, -1) for g in grads)


def sensitivities(model: CalibrationModel, d: Design, x: torch.Tensor, theta: torch.Tensor, rates: bool = False):
    """(m (N,), dm/dtheta (N, n)) at the converged equilibria x (B, 3J) for the shared
    parameters theta (n,), by the implicit function theorem (module docstring); with
    ``rates`` also dx/dtheta (B, 3J, n) (the fit's Euler predictor of the next equilibria)."""
    B = x.shape[0]
    th = theta.detach()[None].repeat(B, 1).requires_grad_(True)   # one copy per observation
    xr = x.detach().requires_grad_(True)
    _, (rx, rt) = _rows_and_jacobians(model, d, xr, (th,), 2)           # (B, 3J, 3J), (B, 3J, n)
    dxdt = -torch.linalg.solve(rx, rt)                                   # (B, 3J, n)
    m = predict(model, d, xr, th)
    jac = torch.zeros(m.shape[0], th.shape[1], dtype=m.dtype)
    for rows in _independent_groups(d):
        # rows of distinct observations: one reverse pass gives each its own gradient
        gx, gt = torch.autograd.grad(m[rows].sum(), (xr, th), retain_graph=True, allow_unused=True)
        gx = torch.zeros_like(xr) if gx is None else gx
        gt = torch.zeros_like(th) if gt is None else gt
        b = torch.as_tensor(d.obs[rows])
        jac[rows] = gt[b] + (gx[b, None, :] @ dxdt[b])[:, 0]
    return (m.detach(), jac, dxdt.detach()) if rates else (m.detach(), jac)


def _independent_groups(d: Design) -> list[list[int]]:
    """Measurement rows grouped so that no two rows of a group belong to one observation
    (the k-th row of each observation that measures the same quantity)."""
    groups, seen = {}, {}
    for j, (b, w) in enumerate(zip(d.obs.tolist(), d.what)):
        k = seen[(b, w)] = seen.get((b, w), -1) + 1
        groups.setdefault((w, k), []).append(j)
    return list(groups.values())


if __name__ == "__main__":
    from contract.cli import not_a_command

    not_a_command("predictor.cli.calibrate")
