"""Physics tests of the FEM joint solver (coarse meshes; DOLFINx on one rank, and mpirun).

Exact references: the Bisshopp-Drucker elastica and the roll-up circle for the beam, the
y-mirror symmetry of docs/physics.md, u = 0 at zero load, and the linearised response
(tangent solves) for small loads.
"""

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("dolfinx")
import dolfinx.fem  # noqa: E402
from mpi4py import MPI  # noqa: E402

from fem.studies import validation  # noqa: E402
from fem.physics.contact import ValleyContact  # noqa: E402
from fem.studies.elastica import cantilever_tip, rollup_tip  # noqa: E402
from fem.mesh.geometry import TAGS, JointGeometry, anchor_points  # noqa: E402
from fem.mesh.build import create_mesh  # noqa: E402
from fem.solvers.joint import JointSolver, Load, SolverConfig  # noqa: E402
from contract.spec import INPUT_BOX, OutOfBoxError  # noqa: E402
from fem_checks import COARSE_TET, assert_matrix_free_tangent, assert_mirror_symmetric  # noqa: E402

pytestmark = pytest.mark.fem
#: a coarse tetrahedral joint in P2 displacement (JointGeometry's default mesh is the production hexahedra)
COARSE = COARSE_TET
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def joint():
    return JointSolver(COARSE, MPI.COMM_SELF, formulation="displacement")


@pytest.mark.parametrize("alpha, u, w, theta", [(0.5, 0.01592, 0.16214, 0.2445),
                                                 (1.0, 0.05643, 0.30172, 0.4614),
                                                 (2.0, 0.16064, 0.49346, 0.7818)])
def test_elastica_reference_values(alpha, u, w, theta):
    """Bisshopp-Drucker table (issue 2): u/L, w/L, theta to the printed 4-5 digits."""
    exact = cantilever_tip(alpha)
    assert exact["u_over_L"] == pytest.approx(u, abs=1e-5)
    assert exact["w_over_L"] == pytest.approx(w, abs=1e-5)
    assert exact["theta"] == pytest.approx(theta, abs=1e-4)


def test_cantilever_matches_elastica():
    """3D beam (L/h = 50, nu = 0) under a dead tip load, alpha = 3: tip within 1.5 % of L."""
    out = validation.cantilever(3.0, comm=MPI.COMM_SELF)
    assert out["error_over_L"] < 0.015
    assert out["theta"] == pytest.approx(out["exact"]["theta"], abs=0.02)


def test_rollup_full_circle_is_a_pure_couple():
    """Pure end moment M = 2 pi EI / L rolls the beam into a full circle: the tip returns
    to the clamp (x = y = 0) within 2 % of L and the cap turns by 2 pi. A dead couple
    would act as M cos(phi) and could not close the circle."""
    out = validation.rollup(2 * math.pi, comm=MPI.COMM_SELF)
    assert out["error_over_L"] < 0.02
    assert out["theta"] == pytest.approx(2 * math.pi, abs=0.03)
    assert rollup_tip(2 * math.pi)["x_over_L"] == pytest.approx(0.0, abs=1e-12)


def test_zero_load_gives_zero_displacement(joint):
    """u = 0 solves R(u) = 0 exactly at zero load: no Newton iteration, anchors at X_i."""
    r = joint.solve(Load())
    assert r.converged and r.iterations == 0
    np.testing.assert_array_equal(r.anchors, anchor_points(COARSE.length)[:, :2])
    assert r.phi_end == 0.0


def test_mirror_symmetry(joint):
    """(R, P, F1, F2, M) -> (R diag(1,-1), -P, F1, -F2, -M) on a mirror-symmetric mesh:
    anchors agree to solver tolerance (1e-6 mm), and so do the sensitivities. The load
    bends the joint by ~60 deg, so the valley contact is active on one side."""
    assert_mirror_symmetric(joint, np.array([0.1, 1.5, 2.0, 100.0]))


def test_the_matrix_free_tangent_is_the_assembled_tangent(joint):
    """GMRES's operator, the tangent applied matrix-free (fem.solvers.load_path.TangentAction), is
    the assembled tangent K of the P2 displacement form (a blocked space: three dofs a
    node) with its Dirichlet rows and columns: K x agrees to 1e-13 of |K x| for a random x
    that is nonzero on the constrained dofs, at a state with closed valley pairs."""
    assert_matrix_free_tangent(joint, Load(M=100.0))


def test_contact_keeps_valley_walls_apart(joint):
    """M = 100 N·mm closes the top valleys. Without contact the facing walls overlap by
    0.3 mm on this mesh; with the penalty (100 MPa/mm) the overlap is the contact pressure
    over the penalty, < 0.02 mm, the walls touch (gap < 0.05 mm), and the contact
    stiffens the joint (smaller end rotation)."""
    free = JointSolver(COARSE, MPI.COMM_SELF, config=SolverConfig(contact_penalty=0.0), formulation="displacement")
    gaps = ValleyContact(free.V, free.mesh_data.facet_tags, COARSE, 0.0).gaps
    r_free = free.solve(Load(M=100.0))
    r = joint.solve(Load(M=100.0))
    assert r.converged and r_free.converged
    closest = min(g.min() for g in gaps(joint.u).values())
    assert -0.02 < closest < 0.05
    assert min(g.min() for g in gaps(free.u).values()) < -0.2
    assert 0.5 < r.phi_end < r_free.phi_end - math.radians(0.5)


def test_small_loads_match_linearised_response(joint):
    """For a small load lambda*e the displacement is lambda*K0^-1 f + O(lambda^2): the
    anchor displacements over lambda converge to the tangent solve at u = 0 with rate 1."""
    joint.solve(Load())
    J0 = joint.sensitivities()
    X = anchor_points(COARSE.length)[:, :2].reshape(-1)
    e = INPUT_BOX
    errors = []
    for lam in (2e-3, 1e-3):
        r = joint.solve(Load.from_array(lam * e * [1, 1, 1, -1]))
        du = (r.anchors.reshape(-1) - X) / lam
        lin = J0 @ (e * [1, 1, 1, -1])
        errors.append(np.abs(du - lin).max() / np.abs(lin).max())
    assert errors[1] < 0.02
    rate = math.log(errors[0] / errors[1], 2)
    assert 0.8 < rate < 1.3, errors


def test_out_of_box_load_is_refused(joint):
    """|P| = 0.5 > 0.3 MPa is extrapolation: refused unless explicitly allowed, and then
    recorded. A NaN load is refused before any Newton step, even when allowed."""
    with pytest.raises(OutOfBoxError, match=r"P = 0.5 is outside the training box"):
        joint.solve(Load(P=0.5))
    r = joint.solve(Load(P=0.31), allow_extrapolation=True)
    assert r.converged and r.extrapolated
    back = joint.solve(Load(P=0.3), continuation=True)     # one small step back into the box
    assert back.converged and not back.extrapolated
    factorisations = joint.factorisations
    with pytest.raises(OutOfBoxError, match=r"P = nan is not a finite number"):
        joint.solve(Load(P=math.nan), allow_extrapolation=True)
    assert joint.factorisations == factorisations


def _cli(args, ranks=1):
    cmd = [sys.executable, "-m", "fem.cli.solve", *args]
    if ranks > 1:   # -q: without it mpirun adds its own 9-line banner on a non-zero exit
        cmd = ["mpirun", "-q", "--oversubscribe", "-n", str(ranks), *cmd]
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMP_NUM_THREADS": "1"}
    return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)


def test_cli_refuses_out_of_box_with_one_line():
    """python -m fem.cli.solve --m 150: exit status 2 and a one-line reason on stderr."""
    p = _cli(["--m", "150", "--mesh-size", "4"])
    assert p.returncode == 2
    assert p.stderr.strip().count("\n") == 0 and "M = 150 is outside the training box" in p.stderr


@pytest.mark.mpi
def test_cli_bad_input_under_mpirun_is_one_line():
    """mpirun -n 2 python -m fem.cli.solve --p nan / --p 0.5: every rank exits 2 at once (no
    mesh, no hang), and only rank 0 prints the one error line."""
    for args, needle in ((["--p", "nan"], "'nan' is not a finite number"),
                         (["--p", "0.5", "--mesh-size", "4"], "P = 0.5 is outside the training box")):
        p = _cli(args, ranks=2)
        assert p.returncode == 2, p.stderr
        lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and needle in lines[0], p.stderr
        assert p.stdout == ""


@pytest.mark.mpi
def test_two_ranks_match_serial():
    """The same case under mpirun -n 2 gives the serial anchors to solver tolerance, and
    the serial Jacobian to the sensitivity tolerance (so the distributed tangent, contact
    blocks included, is the serial one); the valley contact is active (its pairs straddle
    the two ranks' partitions)."""
    args = ["--p", "0.1", "--f2", "2", "--m", "100", "--mesh-size", "4", "--formulation", "displacement", "--json",
            "--jacobian"]
    serial, parallel = _cli(args), _cli(args, ranks=2)
    assert serial.returncode == 0, serial.stderr
    assert parallel.returncode == 0, parallel.stderr
    a, b = (json.loads(p.stdout) for p in (serial, parallel))
    assert b["ranks"] == 2
    np.testing.assert_allclose(a["anchors_mm"], b["anchors_mm"], atol=1e-6)
    J = np.array(a["jacobian"])
    assert J.shape == (20, 4) and np.abs(J[:, 3]).max() > 0
    scale = np.abs(J).max(axis=0)     # per input column: mm/MPa, mm/N, mm/N, mm/(N·mm)
    np.testing.assert_allclose(np.array(b["jacobian"]) / scale, J / scale, atol=1e-5)


def test_wall_refinement_puts_two_elements_through_the_wall():
    """wall_mesh_size = wall/2 = 0.6 mm at h = 4 mm: the tetrahedra with a face on the top
    chamber's wall shrink from a median longest edge of 2.9 mm (p95 4.1) to 0.85 mm (p95
    1.0); a tetrahedron's longest edge is ~1.4x its size, so ~0.6 mm elements, two through
    the 1.2 mm wall. Bounds: median <= 0.9 mm, p95 <= 1.35 mm (unrefined: median > 2 mm)."""

    def wall_edges(geo):
        md = create_mesh(geo, MPI.COMM_SELF)
        m, tags = md.mesh, md.facet_tags
        m.topology.create_connectivity(2, 3)
        cells = np.unique(np.concatenate([m.topology.connectivity(2, 3).links(f)
                                          for f in tags.find(TAGS["top_chamber"])]))
        x = m.geometry.x[m.geometry.dofmap.array.reshape(-1, 4)[cells]]   # (n, 4, 3) vertices
        edges = [np.linalg.norm(x[:, i] - x[:, j], axis=1) for i in range(4) for j in range(i)]
        return np.max(edges, axis=0)

    coarse, refined = wall_edges(COARSE), wall_edges(JointGeometry(mesh_size=4.0, wall_mesh_size=0.6, divisions=0, hex_size=None))
    assert np.median(coarse) > 2.0
    assert np.median(refined) <= 0.9 and np.percentile(refined, 95) <= 1.35


def test_richardson_recovers_a_known_order_and_limit():
    """Exact solution f(h) = f* + C h^p on the meshes h = 2.4, 2.4/r, 2.4/r^2 (r = sqrt 2):
    the observed order is p and the extrapolated value f*, for a scalar (p = 2) and a vector
    (p = 1.5, every component the same order). Oscillating changes (f2 - f1 and f3 - f2 of
    opposite sign, growing) are not asymptotic: the finest value is returned, no order."""
    from fem.studies.mesh_study import richardson

    r = math.sqrt(2.0)
    hs = [2.4, 2.4 / r, 2.4 / r ** 2]
    out = richardson(*[60.0 + 0.3 * h ** 2 for h in hs], r)
    assert out["asymptotic"] and abs(out["order"] - 2.0) < 1e-12 and abs(out["extrapolated"] - 60.0) < 1e-12
    star, C = np.array([36.6, 23.3]), np.array([0.1, -0.05])
    out = richardson(*[star + C * h ** 1.5 for h in hs], r)
    assert abs(out["order"] - 1.5) < 1e-12
    np.testing.assert_allclose(out["extrapolated"], star, atol=1e-12)
    out = richardson(59.0, 59.5, 58.0, r)
    assert not out["asymptotic"] and out["extrapolated"] == 58.0


def test_richardson_on_nested_hexahedra_of_two_three_and_four_divisions():
    """Exact solution f(h) = f* + C h^p on h = 1/2, 1/3, 1/4 (fem.mesh.hexahedra's nested meshes,
    ratios 1.5 and 4/3, not one ratio): the observed order is p (2.5 and 0.7 here) and the
    extrapolated value f*; the constant-ratio formula would give neither. A change that
    grows under refinement has no order in ORDER_RANGE and is not asymptotic."""
    from fem.studies.mesh_study import richardson

    hs = [1 / 2, 1 / 3, 1 / 4]
    for p in (2.5, 0.7):
        out = richardson(*[7.0 - 3.0 * h ** p for h in hs], hs[0] / hs[1], hs[1] / hs[2])
        assert out["asymptotic"] and abs(out["order"] - p) < 1e-9 and abs(out["extrapolated"] - 7.0) < 1e-9
        assert abs(richardson(*[7.0 - 3.0 * h ** p for h in hs], 1.5)["order"] - p) > 0.05
    out = richardson(1.0, 1.1, 1.3, 1.5, 4 / 3)
    assert not out["asymptotic"] and out["extrapolated"] == 1.3


def test_mesh_study_error_of_the_production_mesh_against_the_extrapolation():
    """A synthetic study whose results follow f(h) = f* + C h^2 exactly (anchors shifted by
    C h^2 along x, phi_end and cap rotation by 0.1 h^2 deg) on a sqrt(2) chain of four mixed
    meshes, the production mesh 2.4:1.2 in it, and the paper's 1.8 mm displacement mesh
    (a constant 0.5 mm, 1 deg off): the chain is found without the other formulation, both
    triples observe order 2, the extrapolation is f*, the production error is C 2.4^2 in
    anchors and 0.1 2.4^2 deg in both angles, the paper's error its offset."""
    from fem.studies import mesh_study

    X = anchor_points(JointGeometry().length)[:, :2]
    star = X + np.array([5.0, 2.0])
    n = len(mesh_study.LOADS)

    def mesh(h, w, formulation="mixed", offset=None):
        e = h ** 2                 # W scales with H inside the family
        shift, angle = ([0.01 * e, 0.0], 0.1 * e) if offset is None else ([offset, 0.0], 1.0)
        cases = [{"anchors": (star + shift).tolist(), "phi_end_deg": 60.0 + angle,
                  "cap_rotation_deg": 58.0 + angle} for _ in range(n)]
        return {"key": f"{h}:{w}:{formulation}", "mesh": f"{h}:{w}", "element": "tet", "sizes": [h, w or h],
                "formulation": formulation, "nodes": int(1e5 / (h * (w or h))), "cases": cases}

    r = math.sqrt(2.0)
    chain = [mesh(2.4 * r, 1.2 * r), mesh(2.4, 1.2), mesh(2.4 / r, 1.2 / r), mesh(1.2, 0.6)]
    paper = mesh(1.8, None, "displacement", offset=0.5)
    out = mesh_study.analyse(chain + [paper], chain[1]["key"], paper["key"])
    assert out["asymptotic"] and out["reference"] == "richardson"
    assert out["family"] == [m["mesh"] for m in chain]
    assert len(out["orders"]) == 2
    for triple in out["orders"]:
        np.testing.assert_allclose(triple["anchors"] + triple["phi_end_deg"], 2.0, atol=1e-9)
    e = out["production_error"]
    assert abs(e["anchor_mm"] - 0.01 * 2.4 ** 2) < 1e-9 and abs(e["tip_mm"] - 0.01 * 2.4 ** 2) < 1e-9
    assert abs(e["phi_end_deg"] - 0.1 * 2.4 ** 2) < 1e-9 and abs(e["cap_rotation_deg"] - 0.1 * 2.4 ** 2) < 1e-9
    assert not out["production_met"]            # 0.576 deg > 0.3 deg
    assert abs(out["paper_error"]["anchor_mm"] - 0.5) < 1e-9 and abs(out["paper_error"]["phi_end_deg"] - 1.0) < 1e-9
    out = mesh_study.analyse(chain + [paper], chain[3]["key"], paper["key"])
    # the finest: 0.0144 mm of |(5, 2)| = 5.385 mm (0.27 %), 0.144 deg: within 1 % and 0.3 deg
    assert out["production_met"] and abs(out["production_error"]["anchor_percent"] - 1.44 / 29 ** 0.5) < 1e-9
    # out of the asymptotic range (a wiggle on the finest mesh): the finest mesh is the reference
    chain[3]["cases"][0]["phi_end_deg"] += 5.0
    out = mesh_study.analyse(chain + [paper], chain[1]["key"], paper["key"])
    assert not out["asymptotic"] and out["reference"] == "finest mesh" and not out["production_met"]


def test_mesh_study_finds_the_hexahedral_family_of_the_production_mesh():
    """Synthetic records f(n) = f* + C n^-3 on hex2, hex3, hex4 (fem.mesh.hexahedra's nested
    divisions, h = 1/n) beside a tetrahedral sqrt(2) chain of other values: with hex2 as
    the production mesh the family is the hexahedra (never a chain across the two kinds),
    the order 3 at every load, and hex2's error exactly C / 8 against f*."""
    from fem.studies import mesh_study

    X = anchor_points(JointGeometry().length)[:, :2]
    star, n_loads = X + np.array([5.0, 2.0]), len(mesh_study.LOADS)

    def mesh(mesh_text, element, h, C):
        cases = [{"anchors": (star + [C * h ** 3, 0.0]).tolist(), "phi_end_deg": 60.0 + 10 * C * h ** 3,
                  "cap_rotation_deg": 58.0} for _ in range(n_loads)]
        return {"key": mesh_text, "mesh": mesh_text, "element": element, "sizes": [h, h], "formulation": "mixed",
                "nodes": int(1e4 / h ** 3), "cases": cases}

    hexes = [mesh(f"hex{n}", "hex", 1 / n, 0.8) for n in (2, 3, 4)]
    tets = [mesh(f"{h:g}", "tet", h, -0.3) for h in (2.4, 2.4 / 2 ** 0.5, 1.2)]
    out = mesh_study.analyse(tets + hexes, "hex2")
    assert out["family"] == ["hex2", "hex3", "hex4"] and out["element"] == "hex" and out["asymptotic"]
    np.testing.assert_allclose(out["orders"][0]["anchors"] + out["orders"][0]["phi_end_deg"], 3.0, atol=1e-9)
    assert abs(out["production_error"]["anchor_mm"] - 0.8 / 8) < 1e-9
    assert abs(out["production_error"]["phi_end_deg"] - 1.0) < 1e-9
    # two hexahedral meshes are no family: no extrapolation (an empty list, which the
    # format accepts), the finest hex mesh is the reference
    out = mesh_study.analyse(tets + hexes[:2], "hex2")
    assert out["family"] is None and out["extrapolation"] == [] and out["reference"] == "finest mesh"


def test_a_problem_composed_from_the_pieces_is_solved_by_the_same_solver():
    """The seam between physics and solver: a problem written here from fem.physics.problem's
    pieces, the beam's neo-Hookean body (nu = 0) under a uniform dead transverse load q
    (N/mm, a body force q/A along +y on the half-model, A = b h) that no builder of the
    project declares, handed to LoadPathSolver. In the linear regime (tip deflection 1 %
    of L) the tip deflection is Euler-Bernoulli's w = q L^4 / (8 EI) within 1 %, and the
    solver's sensitivity dw/dq agrees with w/q to 1e-3 (the O(q) nonlinearity)."""
    from fem.solvers.load_path import LoadPathSolver, SolverConfig
    from fem.physics.problem import (LoadTerm, Problem, clamp_and_symmetry, deformation_gradient,
                                     displacement_space, elastic_work)

    geo = validation.DEFAULT_BEAM
    E, L, A = validation.E_BEAM, geo.length, geo.width * geo.thickness
    EI = validation.bending_stiffness(geo)
    q = 0.01 * L * 8 * EI / L ** 4                    # w = L / 100
    md = create_mesh(geo, MPI.COMM_SELF)
    u, v, dx, _ = displacement_space(md, 2, 2)
    F = deformation_gradient(u)
    internal = (elastic_work(F, v, E, 0.0, dx(TAGS["solid"]))
                + elastic_work(F, v, E, 0.0, dx(TAGS["distal_cap"])))
    weight = LoadTerm(dolfinx.fem.Constant(md.mesh, 0.0), -(1.0 / A) * v[1] * dx(TAGS["solid"]), 0)
    bcs = tuple(clamp_and_symmetry(u.function_space, md.facet_tags))
    problem = Problem(md, u, internal, (weight,), np.array([q]), bcs, np.array([[L, 0.0, 0.0]]))
    solver = LoadPathSolver(problem, SolverConfig(first_step=1.0))
    path = solver.follow(np.zeros(1), np.array([q]))
    assert path.converged and path.load_steps == 1
    w = solver.probe_displacements()[0, 1]
    assert w == pytest.approx(q * L ** 4 / (8 * EI), rel=0.01)
    assert solver.sensitivities()[0, 1, 0] == pytest.approx(w / q, rel=1e-3)
