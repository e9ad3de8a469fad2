"""Synthetic joint datasets from an analytic planar rod, for developing and testing the surrogate.

NOT FEM data. Every manifest this module writes says ``"source": "synthetic-rod"`` in its
config; never commit it as a campaign dataset.

Model (units mm, N, MPa, rad). A clamped, extensible Kirchhoff rod of length L = 45.45 mm
along x, cut into N straight segments of length h = L/N with angles theta_1..theta_N
(theta_0 = 0 at the clamp). Segment j has stretch

    lambda_j = 1 + e1 |P| + (F1 cos theta_j + F2 sin theta_j) / EA

and the nodes are r_k = sum_{j<=k} h lambda_j (cos theta_j, sin theta_j). Moment balance
at node k = 0..N-1 of the part distal to it, with dead end forces F = (F1, F2) at r_N and
the couple M:

    EI(P) [ (theta_{k+1} - theta_k) / h - kappa_P(P) ] = M + (x_N - x_k) F2 - (y_N - y_k) F1

with EI(P) = EI0 (1 + s1 |P|) (a pressurised chamber stiffens) and the pressure's free
curvature kappa_P(P) = -k1 P (1 + k2 |P|) (P > 0 inflates the +y chamber, which lengthens
and bends the joint towards -y). The pressure terms use |P|, so the response has a kink
at P = 0 like the two-chamber FEM. The model is exactly mirror-symmetric (docs/physics.md).

The N equations G(theta; u) = 0 are solved by Newton with load stepping, batched over
samples. The anchors are r_{iN/k}, i = 1..k (k = 10, or a joint's anchor count), and their
exact sensitivities follow from the implicit function theorem: d theta/du = -G_theta^{-1} G_u.

A dataset for another joint (``write_dataset(..., joint=spec)``): the rod takes the joint's
length, its anchor count (N rounded up to a multiple of k) and its input box (the inputs are
drawn in it), and the manifest records the joint as a campaign's does
(workflow.store.joint_record, with its [mesh] as the geometry), so the surrogate reads its
anchor count and box from it. The rod's stiffnesses stay the paper-sized defaults.

Usage: ``python -m surrogate.synthetic --out DIR --n 2560 --seed 1 [--json]`` (the shards
and manifest are written atomically by workflow.shards).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from contract import cli
from contract.spec import INPUT_BOX, JOINT_LENGTH, N_ANCHORS, N_INPUTS, phi_end
from workflow import shards
from workflow.store import joint_record


@dataclass(frozen=True)
class RodConfig:
    length_mm: float = JOINT_LENGTH
    segments: int = 50          # multiple of 10
    ei0_nmm2: float = 9000.0    # bending stiffness at P = 0, N·mm²
    ea_n: float = 400.0         # axial stiffness, N
    k1_per_mpa_mm: float = 0.064
    k2_per_mpa: float = 1.0
    e1_per_mpa: float = 0.10
    s1_per_mpa: float = 1.0
    load_steps: int = 4


def _stretch(theta: torch.Tensor, u: torch.Tensor, c: RodConfig) -> torch.Tensor:
    """Segment stretches (N,) for one sample: theta (N,) rad, u (4,)."""
    p, f1, f2 = u[0], u[1], u[2]
    return 1 + c.e1_per_mpa * p.abs() + (f1 * theta.cos() + f2 * theta.sin()) / c.ea_n


def _nodes(theta: torch.Tensor, u: torch.Tensor, c: RodConfig) -> torch.Tensor:
    """Node positions r_1..r_N (N, 2) mm for one sample."""
    h = c.length_mm / c.segments
    lam = _stretch(theta, u, c)
    seg = h * lam[:, None] * torch.stack([theta.cos(), theta.sin()], -1)
    return seg.cumsum(0)


def _residual(theta: torch.Tensor, u: torch.Tensor, c: RodConfig) -> torch.Tensor:
    """Moment balance G (N,) in N·mm at nodes 0..N-1 for one sample."""
    p, f1, f2, m = u
    h = c.length_mm / c.segments
    r = torch.cat([torch.zeros(1, 2, dtype=theta.dtype), _nodes(theta, u, c)])  # r_0..r_N
    th = torch.cat([torch.zeros(1, dtype=theta.dtype), theta])                   # theta_0..theta_N
    ei = c.ei0_nmm2 * (1 + c.s1_per_mpa * p.abs())
    kappa_p = -c.k1_per_mpa_mm * p * (1 + c.k2_per_mpa * p.abs())
    arm = r[-1] - r[:-1]
    return ei * ((th[1:] - th[:-1]) / h - kappa_p) - (m + arm[:, 0] * f2 - arm[:, 1] * f1)


def _anchors(theta: torch.Tensor, u: torch.Tensor, c: RodConfig, count: int) -> torch.Tensor:
    """Anchor points r_1..r_count (count, 2) mm for one sample."""
    step = c.segments // count
    return _nodes(theta, u, c)[step - 1::step]


def solve(inputs: np.ndarray, cfg: RodConfig = RodConfig(), tol: float = 1e-11, anchors: int = N_ANCHORS):
    """Solve the rod for a batch of inputs (n, 4) [P MPa, F1 N, F2 N, M N·mm].

    Returns (anchors (n, k, 2) mm, jacobian (n, 2k, 4) d anchors / d inputs,
    end rotation theta_N (n,) rad, Newton iterations (n,)), k = ``anchors``, which must
    divide cfg.segments (ValueError).
    """
    if cfg.segments % anchors:
        raise ValueError(f"{anchors} anchors do not divide the rod's {cfg.segments} segments")
    u_all = torch.as_tensor(inputs, dtype=torch.float64)
    n = len(u_all)
    res = torch.vmap(lambda t, u: _residual(t, u, cfg))
    g_theta = torch.vmap(torch.func.jacrev(lambda t, u: _residual(t, u, cfg), argnums=0))
    theta = torch.zeros(n, cfg.segments, dtype=torch.float64)
    iterations = 0
    for step in range(1, cfg.load_steps + 1):
        u = u_all * step / cfg.load_steps
        for _ in range(50):
            delta = torch.linalg.solve(g_theta(theta, u), -res(theta, u))
            theta = theta + delta
            iterations += 1
            if delta.abs().max() < tol:
                break
        else:
            raise RuntimeError("synthetic rod: Newton did not converge")
    jac_g = torch.vmap(torch.func.jacrev(lambda t, u: _residual(t, u, cfg), argnums=(0, 1)))
    g_t, g_u = jac_g(theta, u_all)
    dtheta_du = -torch.linalg.solve(g_t, g_u)                                    # (n, N, 4)
    jac_r = torch.vmap(torch.func.jacrev(lambda t, u: _anchors(t, u, cfg, anchors).reshape(-1), argnums=(0, 1)))
    r_t, r_u = jac_r(theta, u_all)
    jacobian = r_t @ dtheta_du + r_u
    points = torch.vmap(lambda t, u: _anchors(t, u, cfg, anchors))(theta, u_all)
    return (points.numpy(), jacobian.numpy(), theta[:, -1].numpy(),
            np.full(n, iterations, np.int64))


def for_joint(cfg: RodConfig, joint) -> RodConfig:
    """The rod of ``joint`` (module docstring): its length (mm) and segments rounded up to a
    multiple of its anchor count."""
    return replace(cfg, length_mm=joint.length, segments=math.ceil(cfg.segments / joint.anchors) * joint.anchors)


def write_dataset(root: str | Path, n: int, seed: int, shard_size: int = 256,
                  cfg: RodConfig = RodConfig(), joint=None) -> Path:
    """Sample n inputs uniformly in the box (seeded), solve, write shards + manifest to root.
    ``joint`` (a contract.joint.JointSpec, None: the paper's rod): the rod, box and anchors
    of that joint, recorded in the manifest (module docstring)."""
    root = Path(root)
    rng = np.random.default_rng(seed)
    box, count = (INPUT_BOX, N_ANCHORS) if joint is None else (joint.input_box, joint.anchors)
    cfg = cfg if joint is None else for_joint(cfg, joint)
    inputs = rng.uniform(-1, 1, (n, N_INPUTS)) * box
    config = {"source": "synthetic-rod", "rod": asdict(cfg)}
    if joint is not None:
        config |= {**joint_record(joint), "geometry": joint.geometry_kwargs(), "formulation": joint.formulation}
    entries = []
    for unit, start in enumerate(range(0, n, shard_size)):
        x = inputs[start:start + shard_size]
        t0 = time.perf_counter()
        anchors, jac, end_rot, its = solve(x, cfg, anchors=count)
        wall = (time.perf_counter() - t0) / len(x)
        arrays = shards.empty_arrays(count) | {
            "sample_id": np.arange(start, start + len(x), dtype=np.int64), "inputs": x,
            "anchors": anchors, "jacobian": jac, "phi_end": phi_end(anchors),
            "cap_rotation": end_rot, "newton_iterations": its,
            "wall_time_s": np.full(len(x), wall), "converged": np.ones(len(x), bool)}
        file = f"shards/unit-{unit:05d}.npz"
        meta = {"config": config, "seed": seed, "unit": unit, "git_commit": "synthetic"}
        sha = shards.write_shard(root / file, arrays, meta)
        entries.append(shards.ShardEntry(file=file, sha256=sha, n=len(x)))
    shards.Manifest(seed=seed, config=config, shards=tuple(entries)).save(root)
    return root


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.synthetic", description=__doc__.split("\n\n")[0])
    ap.add_output("--out", folder=True, required=True, help="dataset directory to write")
    ap.add_argument("--n", type=cli.number(1, 10**7, integer=True), default=2560,
                    help="number of samples")
    ap.add_argument("--seed", type=cli.number(0, 2**63 - 1, integer=True), default=1)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    with ap.errors():
        write_dataset(args.out, args.n, args.seed)
    seconds = time.perf_counter() - t0
    if args.json:
        cli.print_json({"out": args.out, "n": args.n, "seed": args.seed, "source": "synthetic-rod",
                        "time_s": seconds})
    else:
        print(f"wrote {args.n} synthetic samples to {args.out} in {seconds:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
