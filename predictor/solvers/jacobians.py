"""Batched Jacobians of the gesture residual r(x; P) (predictor.solvers.graphs.residual_fn):
J = dr/dx (B, 2n, n) and dr/dP (B, n, J) for n = 3J unknowns, by central differences of
the recorded residual or exactly by one reverse-mode pass (``jacobian_fn`` picks).
"""
from __future__ import annotations

import functools

import torch

from contract.spec import INPUT_BOX
from predictor.solvers.graphs import residual_fn, traced_residual_fn
from predictor.model.statics import PENALTY_WEIGHT, GripperProblem, box_scale


def jacobian_fn(problem: GripperProblem, pressure: bool = True, kind: str = "auto"):
    """The batched Jacobian the solver uses: jac(x (B, n), p (B, J)) -> (J (B, 2n, n),
    r (B, 2n), dr/dP (B, n, J), None unless ``pressure``). kind: auto, exact or
    differences.

    Without an object the residual is smooth (the surrogate's SiLU network and the chain's
    trigonometry): central differences of the traced residual (``_difference_jacobian``),
    ~10x faster than reverse mode for one query. With an object it has kinks (contact
    onset, stick/slip): a difference that straddles one averages the two sides, and LM then
    stalls at grasps on the stick/slip boundary (a three-joint grasp did), so the exact
    reverse-mode Jacobian (``autograd_jacobian``) is used there.
    """
    if kind not in ("auto", "exact", "differences"):
        raise ValueError(f"unknown jacobian {kind!r}: use auto, exact or differences")
    if kind == "differences" or (kind == "auto" and problem.obstacle is None):
        return _difference_jacobian(traced_residual_fn(problem), pressure)
    return autograd_jacobian(residual_fn(problem))


def autograd_jacobian(r_fn):
    """Exact batched Jacobian by one reverse pass over n = 3J copies of each sample.

    Copy k of sample b only feeds output row k, so the gradient of sum_k r[b, k, k]
    with respect to copy k is row k of dr/dx: J (B, n, n) of the equilibrium rows in
    one forward + one backward of an nB batch (docs/decisions.md §11: not vmap(jacfwd)). The
    penalty rows are elementwise in x, so their Jacobian is diagonal and written out.
    The same pass gives dr/dP (B, n, J) for the ramp's tangent predictor.
    """

    def jac(x: torch.Tensor, p: torch.Tensor, dp: bool = True):   # dr/dP comes with the same pass
        B, n = x.shape
        with torch.enable_grad():
            xr = x.detach().repeat_interleave(n, 0).requires_grad_(True)
            pr = p.detach().repeat_interleave(n, 0).requires_grad_(True)
            r = r_fn(xr, pr).reshape(B, n, 2 * n)
            g, gp = torch.autograd.grad(torch.diagonal(r[..., :n], dim1=1, dim2=2).sum(), (xr, pr))
        return torch.cat((g.reshape(B, n, n), _penalty_jacobian(x)), 1), r[:, 0].detach(), gp.reshape(B, n, p.shape[1])

    return jac


def _difference_jacobian(r_fn, pressure: bool = True, rel_step: float = 1e-6):
    """Batched Jacobian by central differences in one inference-mode pass.

    For each sample, the residual is evaluated at x and at x ± h_k e_k, P ± h_P e_j
    (1 + 2n + 2J rows of one batch; without ``pressure`` the P rows are skipped and dr/dP
    is None), with h_k = rel_step × (1 N, 1 N, 100 N·mm) and h_P = rel_step × 0.3 MPa.
    For a smooth residual truncation (h²) and round-off (eps/h) errors are both ~1e-10
    relative, far below what Newton's quadratic convergence needs. ``jac(x, p, dp=False)``
    skips the P rows too, and ``jac.dp(x, p)`` gives dr/dP alone (2J rows a sample): LM
    iterates without it and takes it once at its last iterate, not 2J of 1 + 2n + 2J rows
    on every iterate.
    """

    hp = rel_step * INPUT_BOX[0]

    def jac(x: torch.Tensor, p: torch.Tensor, dp: bool = True):
        B, n = x.shape
        m = p.shape[1] if pressure and dp else 0
        hx, offsets = difference_offsets(n, rel_step)
        ep = hp * torch.eye(p.shape[1], dtype=x.dtype)[:m]   # (m, J)
        X = torch.cat((x[:, None] + offsets, x[:, None].expand(B, 2 * m, n)), 1)
        P = torch.cat((p[:, None].expand(B, 1 + 2 * n, p.shape[1]), p[:, None] + ep, p[:, None] - ep), 1)
        with torch.inference_mode():
            R = r_fn(X.reshape(-1, n), P.reshape(B * (1 + 2 * n + 2 * m), -1)).reshape(B, -1, 2 * n)
        R = R.clone()                     # leave inference mode: the caller writes into it
        g = (R[:, 1:1 + n, :n] - R[:, 1 + n:1 + 2 * n, :n]).transpose(1, 2) / (2 * hx)
        gp = (R[:, 1 + 2 * n:1 + 2 * n + m, :n] - R[:, 1 + 2 * n + m:, :n]).transpose(1, 2) / (2 * hp) if m else None
        return torch.cat((g, _penalty_jacobian(x)), 1), R[:, 0], gp

    def jac_p(x: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        # dr/dP (B, n, J) alone (2J rows a sample): LM needs it at its last iterate only
        B, n = x.shape
        ep = hp * torch.eye(p.shape[1], dtype=x.dtype)
        P = torch.cat((p[:, None] + ep, p[:, None] - ep), 1)
        with torch.inference_mode():
            R = r_fn(x.repeat_interleave(2 * p.shape[1], 0), P.reshape(-1, p.shape[1])).reshape(B, 2, -1, 2 * n)
        return ((R[:, 0, :, :n] - R[:, 1, :, :n]).transpose(1, 2) / (2 * hp)).clone()

    jac.dp = jac_p if pressure else None
    return jac


@functools.lru_cache(maxsize=8)
def difference_offsets(n: int, rel_step: float, central: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """(h (n,), offsets (1 + 2n or 1 + n, n)): the steps h_k = rel_step × (1 N, 1 N, 100
    N·mm) and the rows 0, +h_k e_k (and -h_k e_k when ``central``) at which a difference
    quotient evaluates the residual; cached (read only), as every LM Jacobian asks for them."""
    h = rel_step * box_scale(n)[1]
    rows = (torch.zeros(1, n, dtype=h.dtype), torch.diag(h)) + ((-torch.diag(h),) if central else ())
    return h, torch.cat(rows)


def _penalty_jacobian(x: torch.Tensor) -> torch.Tensor:
    """d(range penalty)/dx (B, n, n): diagonal, PENALTY_WEIGHT sign(x)/scale outside the box."""
    box, scale = box_scale(x.shape[1])
    return torch.diag_embed(PENALTY_WEIGHT * torch.sign(x) * (x.abs() > box).to(x.dtype) / scale)
