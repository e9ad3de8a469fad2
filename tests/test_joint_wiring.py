"""Every stage takes a joint description file (issue 37 §2, and §4's bellow check per law).

* the paper's joint file reproduces today's FEM: its law gives the same UFL forms as the
  (E, nu) neo-Hookean forms fem.physics.problem wrote before joint files (written out here again,
  independently), and a solve with it equals the solve with those forms to 1e-12 mm on a
  4 mm mesh, in the displacement and the mixed formulation;
* one bellow solve per law (neo-Hookean, Mooney-Rivlin, Yeoh, Ogden, with the paper's
  small-strain moduli mu0 = 4.094 MPa, nu = 0.49; 4 mm mesh, mixed u-p, where a solve
  takes one load step) converges and keeps the y-mirror symmetry
  (P, F1, F2, M) -> (-P, F1, -F2, -M) to 1e-6 mm;
* the campaign manifest: the paper's joint records nothing new (the committed manifests'
  configs are reproduced), another joint records its description and digest, a resume
  with another joint is refused naming --joint and both joints, the mirror check rebuilds
  the joint from the manifest;
* the surrogate checkpoint carries its joint (old checkpoints: the paper's) and the
  predictor refuses a model of another joint than the finger file names;
* finger files: a joint part may name its joint file (relative to the finger file), its
  length and law follow it, the dict round trip keeps it; committed files are unchanged;
* bad --joint files (and a finger naming one) exit 2 with one line, writing nothing, on
  every command line that takes them.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from contract.finger import FingerFileError, finger_from_dict, finger_to_dict, load_finger
from contract.joint import DEFAULT_JOINT, joint_digest, load_joint, parse_joint

ROOT = Path(__file__).resolve().parents[1]
PAPER_TEXT = DEFAULT_JOINT.read_text()
#: Laws with the paper's small-strain shear modulus mu0 = 12.2 / (2 * 1.49) = 4.094 MPa
#: (and nu = 0.49): their bellows bend alike at small strain and part at large strain.
MU0 = 12.2 / (2 * 1.49)
LAWS = {
    "neo-hookean": 'law = "neo-hookean"\nE = 12.2',
    "mooney-rivlin": f'law = "mooney-rivlin"\nC10 = 1.6\nC01 = {MU0 / 2 - 1.6!r}',
    "yeoh": f'law = "yeoh"\nC10 = {MU0 / 2!r}\nC20 = -0.03\nC30 = 0.004',
    "ogden": f'law = "ogden"\nmu = [3.0, {MU0 - 3.0!r}]\nalpha = [1.8, 6.0]',
}


def joint_text(law: str = "neo-hookean", name: str = "paper", **replace) -> str:
    """The paper's joint file with another law, name and ``key = value`` lines replaced
    (keys of any table, e.g. pressure_mpa="0.05", count="8"; size="4.0" meshes tetrahedra
    of that size instead of the file's hexahedra)."""
    text = re.sub(r'law = "neo-hookean"\nE = 12.2[^\n]*', LAWS[law], PAPER_TEXT)
    if "size" in replace:
        text, n = re.subn(r"^divisions = [^\n]*\nhex_size = [^\n]*$", "size = 0", text, flags=re.M)
        assert n == 1
    text = text.replace('name = "paper"', f'name = "{name}"')
    if "count" in replace:     # the bulge table is one value per chord of the paper's 10 anchors
        text = text[:text.index("[outline]")]
    for key, value in replace.items():
        text, n = re.subn(rf"^{key} = [^\n]*$", f"{key} = {value}", text, flags=re.M)
        assert n == 1, key
    return text


def test_joint_files_of_the_tests_are_what_they_say():
    """Each law's file has mu0 = 4.094 MPa and nu = 0.49; the renamed paper keeps its digest."""
    for law in LAWS:
        m = parse_joint(joint_text(law)).material
        assert m.law == law and m.mu0 == pytest.approx(MU0, rel=1e-12) and m.poisson == 0.49
    assert joint_digest(parse_joint(joint_text(name="copy"))) == joint_digest(load_joint())


# ---------------------------------------------------------------------- FEM
dolfinx = pytest.importorskip("dolfinx")
import ufl  # noqa: E402
from mpi4py import MPI  # noqa: E402

from contract.spec import mirror  # noqa: E402
from fem.mesh.geometry import JointGeometry  # noqa: E402
from fem.solvers.load_path import LoadPathSolver  # noqa: E402
from fem.solvers.joint import JointSolver, Load  # noqa: E402

COARSE = 4.0   # mm


def todays_internal(problem) -> ufl.Form:
    """The paper joint's internal virtual work as fem.physics.problem wrote it before joint files:
    neo-Hookean (E, nu) = (12.2 MPa, 0.49) body, (100 x 12.2 MPa, 0.3) cap, written out
    from psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2 (mixed: the perturbed
    Lagrangian with -p ln J - p^2 / (2 lambda))."""
    md = problem.mesh_data
    dx = ufl.Measure("dx", domain=md.mesh, subdomain_data=md.cell_tags, metadata={"quadrature_degree": 2})
    test = ufl.TestFunction(problem.V)
    mixed = problem.formulation == "mixed"
    u, p = ufl.split(problem.u) if mixed else (problem.u, None)
    F = ufl.variable(ufl.Identity(3) + ufl.grad(u))

    def density(E, nu):
        mu, lmbda = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
        J = ufl.det(F)
        if mixed:
            return mu / 2 * (ufl.tr(F.T * F) - 3) - mu * ufl.ln(J) - p * ufl.ln(J) - p ** 2 / (2 * lmbda)
        return mu / 2 * (ufl.tr(F.T * F) - 3) - mu * ufl.ln(J) + lmbda / 2 * ufl.ln(J) ** 2

    if mixed:
        Pi = density(12.2, 0.49) * dx(1) + density(100.0 * 12.2, 0.3) * dx(2)
        return ufl.derivative(Pi, problem.u, test)
    work = lambda E, nu, region: ufl.inner(ufl.diff(density(E, nu), F), ufl.grad(test)) * region
    return work(12.2, 0.49, dx(1)) + work(100.0 * 12.2, 0.3, dx(2))


@pytest.mark.fem
@pytest.mark.parametrize("formulation", ["displacement", "mixed"])
def test_paper_joint_file_reproduces_todays_solve(formulation):
    """The paper's joint file through fem.physics.materials: the same internal form (UFL
    signature) as today's (E, nu) forms, and the same anchors and cap rotation to 1e-12
    mm / rad at a load that bends the joint by ~17 deg."""
    joint = load_joint()
    geometry = JointGeometry(**{**joint.geometry_kwargs(), "mesh_size": COARSE, "divisions": 0, "hex_size": None})
    solver = JointSolver.for_joint(joint, MPI.COMM_SELF, geometry, formulation=formulation)
    today = todays_internal(solver.problem)
    assert solver.problem.internal.signature() == today.signature()
    load = Load(0.05, 0.5, -0.5, -10.0)
    ours = solver.solve(load)
    solver.problem = dataclasses.replace(solver.problem, internal=today)
    solver.solver = LoadPathSolver(solver.problem, solver.config)
    theirs = solver.solve(load)
    assert ours.converged and theirs.converged and abs(math.degrees(ours.cap_rotation)) > 10
    assert np.abs(ours.anchors - theirs.anchors).max() <= 1e-12
    assert abs(ours.cap_rotation - theirs.cap_rotation) <= 1e-12


@pytest.mark.fem
@pytest.mark.parametrize("law", list(LAWS))
def test_bellow_of_every_law_converges_and_keeps_mirror_symmetry(law):
    """One bellow solve per law and its y-mirror (4 mm mesh, the joint file's mixed u-p
    formulation): both converge, the anchors are mirrored to 1e-6 mm (measured <= 4e-12)
    and phi_end to 1e-8 rad, and the joint bends by more than 10 deg (measured 18-19.4)."""
    joint = parse_joint(joint_text(law, name=law, size=repr(COARSE), formulation='"mixed"'))
    solver = JointSolver.for_joint(joint, MPI.COMM_SELF)
    assert solver.formulation == "mixed" and solver.material.law == law
    load = np.array([0.05, 0.5, -0.5, -10.0])
    r1 = solver.solve(Load.from_array(load))
    r2 = solver.solve(Load.from_array(load * [-1, 1, -1, -1]))
    assert r1.converged and r2.converged, (r1.reason, r2.reason)
    _, a_m, _ = mirror(load[None], r1.anchors[None])
    np.testing.assert_allclose(r2.anchors, a_m[0], atol=1e-6, rtol=0)
    assert r2.phi_end == pytest.approx(-r1.phi_end, abs=1e-8)
    assert abs(math.degrees(r1.phi_end)) > 10
    assert solver.mesh_info()["nodes"] > 1000


@pytest.mark.fem
def test_contact_penalty_scales_with_the_modulus():
    """Neo-Hookean statics are homogeneous in E at fixed nu: a joint of E / 2 under half the
    loads takes the same deformation, provided its valley contact scales with E as well
    (fem.physics.problem.contact_penalty_for). At a box corner, where valleys close (4 mm mesh), the
    anchors agree to 1e-8 mm; keeping the paper's 100 MPa/mm on the soft joint
    instead moves them by more than 1e-3 mm."""
    from fem.solvers.load_path import SolverConfig

    stiff = parse_joint(joint_text(size=repr(COARSE)))
    soft = parse_joint(joint_text(name="soft", size=repr(COARSE)).replace("\nE = 12.2", "\nE = 6.1", 1))
    assert soft.material.youngs_modulus == 6.1
    load = np.array([0.3, 3.0, -3.0, -100.0])                # a box corner, bent ~70 deg

    def solve(joint, a, **kw):
        solver = JointSolver.for_joint(joint, MPI.COMM_SELF, **kw)
        result = solver.solve(Load.from_array(a))
        assert result.converged
        return result.anchors, min(g.min() for g in solver.contact.gaps(solver.u).values())

    (ref, gap), (scaled, _) = solve(stiff, load), solve(soft, load / 2)
    fixed, _ = solve(soft, load / 2, config=SolverConfig(contact_penalty=200.0))   # 100 MPa/mm on E = 6.1
    assert gap < 0                                         # valleys closed: the penalty acts
    assert np.abs(scaled - ref).max() <= 1e-8
    assert np.abs(fixed - ref).max() > 1e-3


# ---------------------------------------------------------------------- manifest
from workflow.campaign import campaign_config, check_compatible, unit_walk  # noqa: E402
from workflow.shards import Manifest, ShardError  # noqa: E402
from workflow.store import recorded_joint  # noqa: E402


def _config(joint=None, **kw):
    from fem.options import joint_geometry
    from types import SimpleNamespace

    # the 1.8 mm reference sets' paper-fidelity mesh, as their campaigns pass it (--mesh-size 1.8)
    geometry = joint_geometry(SimpleNamespace(mesh_size=1.8, wall_mesh_size=None), joint or load_joint())
    return campaign_config(geometry, kw.get("unit_size", 16), 0.1, 8, "displacement", joint)


def test_paper_manifests_unchanged_and_another_joint_recorded():
    """The paper's joint (and a renamed copy) gives the 1.8 mm reference heldout manifest's
    config exactly (results/data/heldout_h1.8), so that campaign resumes; another joint adds its description and digest, and
    workflow.store.recorded_joint rebuilds it (digest and law) from the config alone."""
    committed = Manifest.load(ROOT / "results/data/heldout_h1.8").config
    assert _config() == committed and _config(parse_joint(joint_text(name="copy"))) == committed
    assert check_compatible(ROOT / "results/data/heldout_h1.8", committed, 2, 256) is not None
    yeoh = parse_joint(joint_text("yeoh", name="yeoh", pressure_mpa="0.2"))
    config = _config(yeoh)
    assert config["joint_sha256"] == joint_digest(yeoh) and "name" not in config["joint"]
    assert config["input_box"] == [0.2, 3.0, 3.0, 100.0] and config["material"]["law"] == "yeoh"
    back = recorded_joint(json.loads(json.dumps(config)))
    assert joint_digest(back) == joint_digest(yeoh) and back.material == yeoh.material
    assert joint_digest(recorded_joint(committed)) == joint_digest(load_joint())
    # the walk spans the joint's box: same unit, scaled P
    np.testing.assert_allclose(unit_walk(2, 0, 8, 0.1, box=yeoh.input_box)[:, 0],
                               unit_walk(2, 0, 8, 0.1)[:, 0] * (0.2 / 0.3), rtol=1e-14, atol=0)


def test_resume_with_another_joint_is_refused(tmp_path):
    """A campaign folder of one joint refuses a run of another, either way, with one line
    naming --joint and both joints; the same joint under another name resumes."""
    yeoh = parse_joint(joint_text("yeoh", name="yeoh"))
    paper_dir, yeoh_dir = tmp_path / "paper", tmp_path / "yeoh"
    for folder, joint in ((paper_dir, None), (yeoh_dir, yeoh)):
        folder.mkdir()
        Manifest(seed=1, config=_config(joint), shards=(), samples_requested=4, units_total=1).save(folder)
    with pytest.raises(ShardError) as err:
        check_compatible(paper_dir, _config(yeoh), 1, 4, yeoh)
    text = str(err.value)
    assert "\n" not in text and "--joint 'yeoh'" in text and "the paper's joint" in text
    assert joint_digest(yeoh)[:12] in text
    with pytest.raises(ShardError, match=rf"campaign of joint sha256 {joint_digest(yeoh)[:12]}, not of "
                                         r"--joint 'paper' \(the paper's joint\)"):
        check_compatible(yeoh_dir, _config(), 1, 4, load_joint())
    renamed = parse_joint(joint_text("yeoh", name="renamed"))
    assert check_compatible(yeoh_dir, _config(renamed), 1, 4, renamed) is not None


def test_paper_joint_predicate_lives_with_the_joint():
    """contract.joint.is_paper_joint: true for the paper's file under any name and mesh,
    false for one changed number (anchors.count 8)."""
    from contract.joint import is_paper_joint

    assert is_paper_joint(parse_joint(joint_text(name="copy", size="4.0")))
    assert not is_paper_joint(parse_joint(joint_text(count="8")))


def test_dataset_holds_the_joints_anchor_count(tmp_path):
    """A joint of 8 anchors through the campaign (2 samples, 6 mm mesh): its shards hold
    anchors (n, 8, 2) and Jacobians (n, 16, 4) (workflow.shards.anchor_count from the
    manifest's joint), and the FEM agrees with the paper's 10-anchor campaign of the same
    walk and mesh where the material points coincide: anchor 4 of 8 and anchor 5 of 10 are
    X = L/2, anchors 8 and 10 are X = L (to 1e-9 mm; the Jacobian rows to 1e-9 relative).
    A shard of 10 anchors under that config, and a recorded count that is not a whole
    number, are refused with one line."""
    from workflow import shards

    write_joint(tmp_path, "eight", joint_text(name="eight", count="8"))
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMP_NUM_THREADS": "1"}
    data = {}
    for name, joint in (("eight", ["--joint", str(tmp_path / "eight.toml")]), ("paper", [])):
        run = subprocess.run([sys.executable, "-m", "workflow.campaign", "--samples", "2", "--seed", "5",
                              "--unit-size", "2", "--mesh-size", "6", "--formulation", "displacement",
                              "--fresh-check-every", "0", "--quiet",
                              "--out", str(tmp_path / name), *joint], cwd=ROOT, env=env, capture_output=True,
                             text=True, timeout=300)
        assert run.returncode == 0, run.stderr[-2000:]
        data[name], manifest = shards.load_dataset(tmp_path / name)
        assert shards.anchor_count(manifest.config) == (8 if name == "eight" else 10)
    eight, paper = data["eight"], data["paper"]
    assert eight["anchors"].shape == (2, 8, 2) and eight["jacobian"].shape == (2, 16, 4)
    np.testing.assert_array_equal(eight["inputs"], paper["inputs"])
    for i8, i10 in ((3, 4), (7, 9)):
        np.testing.assert_allclose(eight["anchors"][:, i8], paper["anchors"][:, i10], rtol=0, atol=1e-9)
        rows8, rows10 = eight["jacobian"][:, 2 * i8:2 * i8 + 2], paper["jacobian"][:, 2 * i10:2 * i10 + 2]
        np.testing.assert_allclose(rows8, rows10, rtol=0, atol=1e-9 * np.abs(rows10).max())
    assert np.abs(eight["anchors"][:, 7] - eight["anchors"][:, 6]).max() > 1.0   # 8 anchors, 5.7 mm apart
    config = Manifest.load(tmp_path / "eight").config
    with pytest.raises(ShardError, match=r"'anchors' has shape \(2, 10, 2\), expected \(2, 8, 2\)"):
        shards.write_shard(tmp_path / "x.npz", paper, {"config": config})
    bad = json.loads(json.dumps(config))
    bad["joint"]["anchors"]["count"] = 8.5
    with pytest.raises(ShardError, match=r"anchors\.count = 8\.5 is not a whole number"):
        shards.anchor_count(bad)
    assert not (tmp_path / "x.npz").exists()


# ---------------------------------------------------------------------- checkpoint, finger
def write_joint(folder: Path, name: str, text: str) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


FINGER = """format = "softjoint-finger/1"
name = "{name}"
[[part]]
kind = "joint"
weight = 0.09
contact = false
{joint1}
[[part]]
kind = "rigid"
length = 60.0
weight = 0.04
[[part]]
kind = "joint"
weight = 0.09
{joint2}
"""


def finger_file(folder: Path, name: str, joint1: str = "", joint2: str = "") -> Path:
    path = folder / f"{name}.toml"
    path.write_text(FINGER.format(name=name, joint1=joint1, joint2=joint2))
    return path


def test_finger_joint_parts_name_their_joint_files(tmp_path):
    """A joint part's ``joint`` file, relative to the finger file: its length and law
    follow it, the part dict shows the file and its digest, the dict round trip rebuilds
    it; the committed fingers describe themselves as before (no joint keys); a bad joint
    file is one FingerFileError line naming the part and the file's key."""
    sub = tmp_path / "joints"
    sub.mkdir()
    write_joint(sub, "long", joint_text("yeoh", name="long", length="60.0"))
    path = finger_file(tmp_path, "mixed", joint2='joint = "joints/long.toml"')
    finger = load_finger(path)
    assert finger.parts[2].length == 60.0 and finger.parts[0].length == 45.45
    assert finger.length == 45.45 + 60.0 + 60.0
    assert finger.parts[2].spec.material.law == "yeoh" and finger.parts[0].spec.name == "paper"
    summary = finger.summary()["parts"]
    assert summary[2]["joint"] == "joints/long.toml" and "joint" not in summary[0]
    assert summary[2]["joint_sha256"] == joint_digest(finger.parts[2].joint)
    d = json.loads(json.dumps(finger_to_dict(finger)))
    assert finger_from_dict(d) == finger and finger_to_dict(finger_from_dict(d)) == d
    for committed in [ROOT / "contract/fingers/paper.toml", *sorted((ROOT / "tests/data/fingers").glob("*.toml"))]:
        try:
            parts = finger_to_dict(load_finger(committed))["parts"]
        except FingerFileError:
            continue        # the bad files of tests/test_bad_input.py
        assert all(set(p) <= {"kind", "weight", "contact", "length", "height", "width", "contact_points"}
                   for p in parts)
    write_joint(sub, "bad", joint_text(E="nan"))
    with pytest.raises(FingerFileError) as err:
        load_finger(finger_file(tmp_path, "bad", joint1='joint = "joints/bad.toml"'))
    assert "\n" not in str(err.value)
    assert re.search(r"part 1 \(joint\): joint = 'joints/bad.toml': .*material\.E = nan is not a finite number",
                     str(err.value))


def test_predictor_refuses_a_model_of_another_joint(tmp_path):
    """A surrogate checkpoint carries its joint (surrogate.model.checkpoint_joint); the
    committed checkpoint, written before, is the paper's; predictor.model.joint.load_joint with
    a finger refuses, in one line naming both joints, a model whose joint is not the one
    every joint part names, and accepts the matching pair."""
    torch = pytest.importorskip("torch")
    from predictor.model.joint import AnalyticJoint, check_finger
    from predictor.model.joint import load_joint as load_model
    from surrogate.model import JointSurrogate, ModelConfig, load_surrogate, save_checkpoint

    soft = parse_joint(joint_text("yeoh", name="soft"))
    write_joint(tmp_path, "soft", joint_text("yeoh", name="soft"))
    soft_finger = load_finger(finger_file(tmp_path, "soft_finger", 'joint = "soft.toml"', 'joint = "soft.toml"'))
    half = load_finger(finger_file(tmp_path, "half", joint2='joint = "soft.toml"'))
    paper_finger = load_finger()
    norm = {"input_scale": soft.input_box.tolist(), "output_mean": [1.0] * 20, "output_scale": [1.0] * 20}
    net = JointSurrogate(ModelConfig(hidden=(8,)), norm).double()
    path = tmp_path / "soft.pt"
    save_checkpoint(path, net, {}, {}, {}, soft)
    assert joint_digest(load_surrogate(path).joint) == joint_digest(soft)
    model = load_model(str(path), soft_finger)
    assert model.joint.material.law == "yeoh"
    for finger in (paper_finger, half):
        with pytest.raises(ValueError) as err:
            load_model(str(path), finger)
        text = str(err.value)
        assert "\n" not in text and "'soft'" in text and "'paper'" in text and joint_digest(soft)[:12] in text
    committed = ROOT / "results/surrogate/improved.pt"
    if committed.is_file():
        assert joint_digest(load_model(str(committed), paper_finger).joint) == joint_digest(load_joint())
        with pytest.raises(ValueError, match="joint 1 of finger 'soft_finger' is 'soft'"):
            load_model(str(committed), soft_finger)
    check_finger(AnalyticJoint(), paper_finger)
    with pytest.raises(ValueError, match="joint 2 of finger 'half'"):
        check_finger(AnalyticJoint(), half)
    assert torch.equal(load_surrogate(path)(torch.zeros(1, 4, dtype=torch.float64)),
                       net(torch.zeros(1, 4, dtype=torch.float64)).detach())


def test_finger_fem_takes_each_joints_law_and_box(tmp_path):
    """fem.solvers.finger's per-joint law and pressure limit (no mesh): a finger mixing the paper's
    joint with a Yeoh joint of the same shape gives each joint its own law and box; a joint of
    another shape is meshed in its own shape with the finger's mesh settings
    (FingerGeometry.joint_at), and a mesh joint of another shape than the first joint's is
    refused (it would be ignored)."""
    from fem.physics.finger import joint_laws
    from fem.mesh.geometry import pressure_limits
    from fem.mesh.geometry import FingerGeometry
    from fem.physics.problem import Material

    write_joint(tmp_path, "yeoh", joint_text("yeoh", name="yeoh", pressure_mpa="0.05"))
    write_joint(tmp_path, "long", joint_text(name="long", length="60.0"))
    finger = load_finger(finger_file(tmp_path, "mix", joint2='joint = "yeoh.toml"'))
    laws = joint_laws(finger)
    assert laws[0] == load_joint().material and laws[2].law == "yeoh"
    assert joint_laws(finger, Material())[2] == Material().law()
    np.testing.assert_array_equal(pressure_limits(finger), [0.3, 0.05])
    assert FingerGeometry(finger, JointGeometry()).same_shape
    other = load_finger(finger_file(tmp_path, "other", joint2='joint = "long.toml"'))
    geo = FingerGeometry(other, JointGeometry(mesh_size=4.0, divisions=0, hex_size=None))
    assert not geo.same_shape and geo.as_dict()["joints"][1]["length"] == 60.0
    assert (geo.joint_at(0).length, geo.joint_at(2).length, geo.joint_at(2).mesh_size) == (JointGeometry().length, 60.0, 4.0)
    with pytest.raises(ValueError, match="joint.length = 60.0 is not the finger's first joint's"):
        FingerGeometry(other, JointGeometry(length=60.0))


# ---------------------------------------------------------------------- command lines
def _rows(tmp: Path) -> list[tuple[str, list[str], str]]:
    """(module, args, needle) of every bad --joint (or finger naming a bad joint) row."""
    write_joint(tmp, "bad", joint_text(E="nan"))
    write_joint(tmp, "narrow", joint_text(name="narrow", pressure_mpa="0.05"))
    write_joint(tmp, "yeoh", joint_text("yeoh", name="yeoh"))
    bad_finger = finger_file(tmp, "badf", joint1='joint = "bad.toml"')
    narrow_finger = finger_file(tmp, "narrowf", joint1='joint = "narrow.toml"')
    E_nan = "material.E = nan is not a finite number (allowed [0.001, 1000] MPa)"
    yeoh_sha = joint_digest(parse_joint(joint_text("yeoh")))[:12]
    return [
        ("fem.cli.solve", ["--joint", f"{tmp}/bad.toml"], E_nan),
        ("fem.cli.solve", ["--joint", f"{tmp}/none.toml"], f"cannot read joint file {tmp}/none.toml"),
        ("fem.cli.solve", ["--joint", f"{tmp}/narrow.toml", "--p", "0.1"],
         "P = 0.1 is outside the training box (1 of 1 input(s) affected; allowed |P| <= 0.05 MPa"),
        ("fem.cli.render", ["--joint", f"{tmp}/bad.toml", "--out", f"{tmp}/x.png"], E_nan),
        ("workflow.campaign", ["--samples", "4", "--seed", "1", "--joint", f"{tmp}/bad.toml",
                               "--out", f"{tmp}/d"], E_nan),
        ("workflow.campaign", ["--samples", "256", "--unit-size", "16", "--seed", "2", "--joint",
                               f"{tmp}/yeoh.toml", "--out", "results/data/heldout"],
         f"results/data/heldout holds a campaign of the paper's joint, not of --joint 'yeoh' "
         f"(joint sha256 {yeoh_sha}); rerun with the --joint it was made with"),
        ("fem.cli.finger", ["--finger", str(bad_finger)], f"part 1 (joint): joint = 'bad.toml': {tmp}/bad.toml: {E_nan}"),
        ("fem.cli.finger", ["--finger", str(narrow_finger), "--p1", "0.1"], "--p1: 0.1 is outside [-0.05, 0.05] MPa"),
        ("fem.studies.finger_cases", ["--finger", str(bad_finger), "--out", f"{tmp}/f"], E_nan),
    ]


def _git_status() -> str:
    return subprocess.run(["git", "status", "--porcelain"], cwd=ROOT, capture_output=True, text=True).stdout


def test_bad_joint_files_exit_2_with_one_line(tmp_path):
    """Every row in one Python process (tests/data/run_cli_rows.py): exit 2, one stderr
    line holding the needle, no traceback, and nothing written (the folder holds only the
    inputs, the repository's status is unchanged)."""
    rows = _rows(tmp_path)
    inputs = sorted(os.listdir(tmp_path))
    before = _git_status()
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMP_NUM_THREADS": "1", "PYVISTA_OFF_SCREEN": "true"}
    run = subprocess.run([sys.executable, str(ROOT / "tests/data/run_cli_rows.py")], cwd=ROOT, env=env,
                         input=json.dumps([[m, a] for m, a, _ in rows]), capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    for (module, args, needle), res in zip(rows, json.loads(run.stdout)):
        lines = [line for line in res["stderr"].splitlines() if line.strip()]
        assert res["returncode"] == 2, (module, args, res)
        assert len(lines) == 1 and "Traceback" not in res["stderr"], (module, args, res["stderr"])
        assert needle in lines[0], (module, args, lines[0])
    assert sorted(os.listdir(tmp_path)) == inputs
    assert _git_status() == before
