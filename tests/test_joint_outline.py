"""The bulge of a pressurised joint's cells, from the joint FEM to the predictor's outline
(issue 56: fem.studies.joint_outline, the joint file's [outline], predictor.model.gripper).

* the joint file's [outline] round-trips, is refused with one line when malformed, and
  leaves the joint's digest as it is (no dataset or checkpoint goes stale);
* the committed table of the paper's joint is the committed study's, to its 3 decimals;
* the outline's half-heights: the table's values at every tabled pressure (vertex m the
  larger of chords m - 1 and m), 0 at P = 0, linear between, the pressurised side by the
  sign of P, mirror-symmetric (P -> -P swaps the faces);
* the bulged outline is the band moved by exactly those heights along each vertex normal;
* the predictor against the production finger FEM at (0.3, -0.3) MPa with gravity, where
  joint 2's pressurised cells carry the plane X = 0: the band's fingertip is 5.55 mm off,
  the bulged outline's 0.31 mm (frozen FEM case, results/validation/finger_fem);
* the study's offset of a material point from the deformed centre line is exact for a rigid
  motion of the straight joint (every offset is the reference y), and, on a coarse FEM
  joint, the pressurised side bulges, more at a higher pressure, and P -> -P mirrors it.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from contract.joint import JointFileError, joint_digest, joint_from_dict, joint_to_dict, load_joint, parse_joint

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "contract" / "joints" / "paper.toml"


def _without_outline(text: str) -> str:
    return text[: text.index("[outline]")]


def test_outline_round_trips_and_leaves_the_digest():
    joint = load_joint()
    assert joint.outline is not None and len(joint.outline[0]) == 7
    assert joint_from_dict(joint_to_dict(joint)) == joint
    bare = parse_joint(_without_outline(PAPER.read_text()), "bare.toml")
    assert bare.outline is None
    assert joint_digest(bare) == joint_digest(joint)


@pytest.mark.parametrize("table,why", [
    ("pressures = [0.1, 0.1]\nbulge = [[0]*10]\nother = [[0]*10]", "pressures"),
    ("pressures = [0.1]\nbulge = [[0.0, 0.1]]\nother = [[0.0, 0.1]]", "bulge must be 1 lists"),
    ("pressures = [0.1]\nbulge = [[10.0, 0, 0, 0, 0, 0, 0, 0, 0, 0]]\nother = [[0, 0, 0, 0, 0, 0, 0, 0, 0, 0]]",
     "height/2"),
    ("pressures = [0.1]\nbulge = [[0, 0, 0, 0, 0, 0, 0, 0, 0, 0]]", "missing 'other'"),
])
def test_a_malformed_outline_is_refused_in_one_line(table, why):
    text = _without_outline(PAPER.read_text()) + "[outline]\n" + table.replace("[0]*10", "[" + ", ".join(["0"] * 10) + "]")
    with pytest.raises(JointFileError) as exc:
        parse_joint(text, "j.toml")
    assert why in str(exc.value) and "\n" not in str(exc.value) and str(exc.value).startswith("j.toml: ") and "outline" in str(exc.value)


def test_the_paper_joints_table_is_the_committed_study():
    """paper.toml holds, to the character, the table the committed study prints."""
    from contract.joint import outline_table
    from fem.artefacts import outline_of

    record = json.loads((ROOT / "results" / "fem" / "joint_outline.json").read_text())
    table = outline_table(*outline_of(record))
    assert table in PAPER.read_text()
    pressures, bulge, other = load_joint().outline
    assert pressures == tuple(r["P_MPa"] for r in record["bulge_mm"])
    for row, b, o in zip(record["bulge_mm"], bulge, other):
        assert np.allclose(b, row["pressurised_mm"], atol=5e-4, rtol=0)
        assert np.allclose(o, row["other_mm"], atol=5e-4, rtol=0)
    # the study's own mirror check: P -> -P swaps the sides to round-off
    assert np.allclose(record["mirror"]["pressurised_mm"], record["bulge_mm"][-1]["pressurised_mm"], atol=1e-9)


def _vertex_table(chords):
    """Vertex m's value: the larger of chords m - 1 and m (the ends: their one chord)."""
    c = np.asarray(chords)
    return np.maximum(np.concatenate(([c[0]], c)), np.concatenate((c, [c[-1]])))


def test_half_heights_are_the_table_at_its_pressures_and_linear_between():
    from predictor.model.gripper import GripperParams, band_half_heights

    params = GripperParams(outline="bulged")
    pressures, bulge, other = load_joint().outline
    H2 = params.layout.joint_half_height
    for k, P in enumerate(pressures):
        h = band_half_heights(torch.tensor([[P, -P]], dtype=torch.float64), params.bulge, H2)[0]
        # joint 1 at +P: the outer face (+nu) is pressurised; joint 2 at -P: the inner face
        assert np.allclose(h[0, 1] - H2, _vertex_table(bulge[k]), atol=1e-12)
        assert np.allclose(h[0, 0] - H2, _vertex_table(other[k]), atol=1e-12)
        assert np.allclose(h[1, 0] - H2, _vertex_table(bulge[k]), atol=1e-12)
        assert np.allclose(h[1, 1] - H2, _vertex_table(other[k]), atol=1e-12)
    zero = band_half_heights(torch.zeros(1, 2, dtype=torch.float64), params.bulge, H2)
    assert torch.equal(zero, torch.full_like(zero, H2))
    mid = 0.5 * (pressures[2] + pressures[3])
    h = band_half_heights(torch.tensor([[mid, mid]], dtype=torch.float64), params.bulge, H2)[0, 0, 1] - H2
    assert np.allclose(h, 0.5 * (_vertex_table(bulge[2]) + _vertex_table(bulge[3])), atol=1e-12)
    p = torch.tensor([[0.13, -0.27]], dtype=torch.float64)
    assert torch.equal(band_half_heights(-p, params.bulge, H2), band_half_heights(p, params.bulge, H2).flip(2))


def test_bulged_outline_is_the_band_moved_along_each_normal():
    from predictor.model.gripper import GripperParams, band_size, finger_pose, outline_vertices
    from predictor.model.joint import AnalyticJoint

    p = torch.tensor([[0.2, -0.25]], dtype=torch.float64)
    tau = torch.tensor([[[0.1, -0.2, 5.0], [0.0, 0.3, -4.0]]], dtype=torch.float64)
    band, bulged = (GripperParams(outline=o) for o in ("band", "bulged"))
    pose_b, pose_u = (finger_pose(AnalyticJoint(), prm, p, tau) for prm in (band, bulged))
    assert torch.equal(pose_b.joints, pose_u.joints)
    Vb, Vu = (outline_vertices(q, band.layout) for q in (pose_b, pose_u))
    n1 = band_size(band.finger) // 2
    H2 = band.layout.joint_half_height
    for j in range(2):
        rows = slice(2 * n1 * j, 2 * n1 * (j + 1))
        shift = (Vu[0, rows] - Vb[0, rows]).norm(dim=-1)
        heights = pose_u.band[0, j] - H2          # (2, n + 1): inner, outer
        assert torch.allclose(shift, heights.abs().reshape(-1), atol=1e-12)
    assert torch.equal(Vu[0, 4 * n1:], Vb[0, 4 * n1:])      # the rigid parts' corners stay


def test_a_bulged_poses_heights_follow_its_rows_and_survive_the_mirror():
    """The band heights are sizes: the mirror keeps them, masked() NaNs the failed rows,
    rows() and with_rows() take them with their samples."""
    from predictor.model.gripper import GripperParams, finger_pose
    from predictor.model.joint import AnalyticJoint

    p = torch.tensor([[0.2, -0.25], [-0.1, 0.3], [0.0, 0.05]], dtype=torch.float64)
    pose = finger_pose(AnalyticJoint(), GripperParams(outline="bulged"), p, torch.zeros(3, 2, 3, dtype=torch.float64))
    assert pose.band.shape == (3, 2, 2, 11)
    assert torch.equal(pose.mirrored().band, pose.band)
    ok = torch.tensor([True, False, True])
    masked = pose.masked(ok).band
    assert bool(masked[1].isnan().all()) and torch.equal(masked[ok], pose.band[ok])
    rows = torch.tensor([False, True, False])
    assert torch.equal(pose.rows(rows).band, pose.band[1:2])
    other = finger_pose(AnalyticJoint(), GripperParams(outline="bulged"), -p, torch.zeros(3, 2, 3, dtype=torch.float64))
    swapped = pose.with_rows(rows, other.rows(rows)).band
    assert torch.equal(swapped[1], other.band[1]) and torch.equal(swapped[~rows], pose.band[~rows])


def test_bulged_outline_meets_the_finger_fem_where_the_cells_carry_the_plane():
    """Production finger FEM, gravity (0.3, -0.3) MPa with the plane (2,823 s on one core):
    joint 2's plane-facing chamber is pressurised and its cells carry the plane."""
    from predictor import load_gripper, solve_gesture

    fem = json.loads((ROOT / "results/validation/finger_fem/gravity_0.3_-0.3_hex2s3_plane.json").read_text())
    errors = {}
    for outline in ("band", "bulged"):
        s = solve_gesture(load_gripper(outline=outline), 0.3, -0.3).summary()
        errors[outline] = (math.dist(s["tip"], fem["tip"]), s["tip_angle_deg"] - fem["tip_angle_deg"])
    assert errors["band"][0] > 5.0 and abs(errors["band"][1]) > 1.5      # measured 5.55 mm, -1.93 deg
    assert errors["bulged"][0] < 0.5 and abs(errors["bulged"][1]) < 0.3  # measured 0.31 mm, -0.13 deg


def test_offsets_of_a_rigid_motion_are_the_reference_heights():
    pytest.importorskip("dolfinx")
    from fem.studies.joint_outline import normal_offsets

    rng = np.random.default_rng(0)
    L, n = 45.45, 10
    X = np.column_stack([rng.uniform(0, L, 500), rng.uniform(-10, 10, 500), rng.uniform(0, 7, 500)])
    a, t = 0.7, np.array([3.0, -2.0])
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    x = X.copy()
    x[:, :2] = X[:, :2] @ R.T + t
    anchors = (np.column_stack([np.arange(1, n + 1) * L / n, np.zeros(n)]) @ R.T) + t
    # the proximal centre is fixed at the origin in the study: move it with the body
    off, chord = normal_offsets(X, x - np.r_[t, 0.0], anchors - t, L)
    assert np.allclose(off, X[:, 1], atol=1e-12)
    assert np.array_equal(chord, np.minimum((X[:, 0] // (L / n)).astype(int), n - 1))


@pytest.mark.fem
def test_coarse_joint_bulges_on_its_pressurised_side_and_mirrors():
    """hex1:4 mixed joint (coarse; ~20 s): measured 1.31 mm at 0.1 MPa and 3.27 mm at
    0.3 MPa on the pressurised side's most bulged chord, the other side within 0.03 mm
    of the band there; P -> -P swaps the sides to round-off."""
    pytest.importorskip("dolfinx")
    from fem.mesh.geometry import JointGeometry
    from fem.solvers.joint import JointSolver, Load
    from fem.studies.joint_outline import bulges

    joint = load_joint()
    kw = {**joint.geometry_kwargs(), "divisions": 1, "hex_size": 4.0}
    solver = JointSolver(JointGeometry(**kw), material=joint.material, formulation="mixed")
    H2, L = joint.shape.height / 2, joint.shape.length
    seen = []
    for P in (0.1, 0.3):
        assert solver.solve(Load(P), continuation=True).converged
        seen.append(bulges(solver, H2, L))
    (low, _), (high, other) = seen
    assert 0.5 < low.max() < high.max() < 5.0
    assert (high > low).all()
    assert solver.solve(Load(-0.3)).converged
    m_plus, m_minus = bulges(solver, H2, L)
    assert np.allclose(m_minus, high, atol=1e-8) and np.allclose(m_plus, other, atol=1e-8)
