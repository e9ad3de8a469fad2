"""The hyperelastic laws of fem.physics.materials against independent references.

* numpy: each closed form P(F) is the derivative of its energy (central finite
  differences), including F with repeated principal stretches; Ogden with exponents 2 and
  -2 is Mooney-Rivlin (C10 = mu_1 / 2, C01 = mu_2 / 2); a small uniaxial stretch gives
  the law's small-strain E and nu (contract.joint.MaterialLaw);
* UFL: the neo-Hookean energy, its stress and its mixed form are today's fem.physics.problem
  expressions (same form signature, so the same compiled code and the same data);
* FEM (fem.studies.materials_check, a 2 x 2 x 2 cube): every law's face reactions equal the
  closed-form P within 1e-6 on uniaxial, equibiaxial and shear states, the displacement
  and mixed formulations agree, the small-strain E and nu hold within 1e-4; the Ogden law
  (eigenvalues in closed form, regularised) is stress-free at F = I and its tangent there
  is the linear elasticity of its (mu0, K);
* the command line: bad input exits 2 with one line, and nothing is written.

The FEM tests take about 5 s once the forms are compiled (first run: about 2 min, the Ogden
Jacobian being the largest form).
"""
import json

import numpy as np
import pytest

from contract.joint import MaterialLaw
from fem.physics.materials import strain_energy, stress
from fem.studies.materials_check import CHECK_LAWS, SMALL_STRAIN_TARGET, TARGET_REL, main

RNG = np.random.default_rng(37)
STATES = {
    "random": np.eye(3) + 0.25 * RNG.standard_normal((3, 3)),
    "uniaxial": np.diag([1.4, 0.85, 0.85]),
    "equibiaxial": np.diag([1.2, 1.2, 0.7]),
    "near rest": np.eye(3) + 1e-3 * RNG.standard_normal((3, 3)),
}


def numerical_stress(m: MaterialLaw, F: np.ndarray, h: float = 1e-6) -> np.ndarray:
    P = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            dF = np.zeros((3, 3))
            dF[i, j] = h
            P[i, j] = (strain_energy(m, F + dF) - strain_energy(m, F - dF)) / (2 * h)
    return P


@pytest.mark.parametrize("state", STATES)
@pytest.mark.parametrize("law", CHECK_LAWS)
def test_closed_form_stress_is_the_derivative_of_the_energy(law, state):
    """Central differences (h = 1e-6, error ~ h^2 psi''' + 1e-16 psi / h): within 1e-7 of
    max |P| away from rest; near rest (|P| ~ 1e-3 E) within 1e-6."""
    m, F = CHECK_LAWS[law], STATES[state]
    P, P_fd = stress(m, F), numerical_stress(m, F)
    tol = 1e-6 if state == "near rest" else 1e-7
    assert np.abs(P - P_fd).max() <= tol * np.abs(P).max()


@pytest.mark.parametrize("state", STATES)
def test_ogden_with_exponents_2_and_minus_2_is_mooney_rivlin(state):
    """sum lb^2 = I1b and sum lb^-2 = I2b (lb1 lb2 lb3 = 1), so 2 mu / alpha^2 (...) with
    alpha = +-2 is C10 = mu_1 / 2, C01 = mu_2 / 2: the spectral form against the invariant
    form, energy and stress."""
    F = STATES[state]
    ogden = MaterialLaw("ogden", ((0.6, 0.2), (2.0, -2.0)), K=40.0)
    mr = MaterialLaw("mooney-rivlin", (0.3, 0.1), K=40.0)
    assert strain_energy(ogden, F) == pytest.approx(strain_energy(mr, F), rel=1e-12, abs=1e-15)
    assert np.abs(stress(ogden, F) - stress(mr, F)).max() <= 1e-12 * np.abs(stress(mr, F)).max()


@pytest.mark.parametrize("law", CHECK_LAWS)
def test_small_strain_limit_of_the_closed_form(law):
    """Uniaxial stress at stretch 1 + 1e-6 (lateral stretch from P22 = 0): P11 / strain is
    the reported E and the lateral contraction ratio its nu, within 1e-5 (the O(strain)
    nonlinearity is 1e-6)."""
    from fem.studies.materials_check import free_stretch

    m, e = CHECK_LAWS[law], 1e-6
    t = free_stretch(m, lambda t: np.diag([1 + e, t, t]), 1)
    P = stress(m, np.diag([1 + e, t, t]))
    assert P[0, 0] / e == pytest.approx(m.youngs_modulus, rel=1e-5)
    assert -(t - 1) / e == pytest.approx(m.poisson, rel=1e-5)


def test_neo_hookean_is_todays_energy():
    """fem.physics.problem's neo-Hookean energy, stress and mixed density have the same form
    signature as fem.physics.materials' for the paper's law (so identical generated code), and a
    different one for another nu (the comparison can fail)."""
    ufl = pytest.importorskip("ufl")
    from fem.physics.materials import energy, first_piola, mixed_energy
    from fem.physics.problem import lame, mixed_energy_density, neo_hookean_psi

    cell = ufl.tetrahedron
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", cell, 1))
    u = ufl.Coefficient(ufl.FunctionSpace(domain, ufl.VectorElement("Lagrange", cell, 2)))
    p = ufl.Coefficient(ufl.FunctionSpace(domain, ufl.FiniteElement("Lagrange", cell, 1)))
    v = ufl.TestFunction(u.ufl_function_space())
    F = ufl.variable(ufl.Identity(3) + ufl.grad(u))

    def signature(expr):
        return (expr * ufl.dx).signature()

    paper = CHECK_LAWS["neo-hookean"]
    today = neo_hookean_psi(F, *lame(12.2, 0.49))
    assert signature(energy(paper, F)) == signature(today)
    work = ufl.inner(first_piola(paper, F), ufl.grad(v))
    assert signature(work) == signature(ufl.inner(ufl.diff(today, F), ufl.grad(v)))
    assert signature(mixed_energy(paper, F, p)) == signature(mixed_energy_density(F, p, 12.2, 0.49))
    other = MaterialLaw("neo-hookean", (12.2,), nu=0.45)
    assert signature(energy(other, F)) != signature(today)
    with pytest.raises(ValueError, match="needs kappa > 0"):
        mixed_energy(MaterialLaw("neo-hookean", (12.2,), nu=0.0), F, p)


# ---------------------------------------------------------------------- FEM
@pytest.fixture(scope="module", params=list(CHECK_LAWS))
def checked(request):
    pytest.importorskip("dolfinx")
    from fem.studies.materials_check import check_law

    return request.param, check_law(CHECK_LAWS[request.param])


@pytest.mark.fem
def test_fem_reactions_match_the_closed_form(checked):
    """Each homogeneous test: both formulations' reactions within 1e-6 of max |P| of the
    closed form (measured <= 6e-9), the mixed pressure is -kappa ln J, the formulations
    agree, and Newton converged quadratically (<= 10 iterations from a random start)."""
    law, d = checked
    for name, t in d["tests"].items():
        assert t["max_rel_diff"] <= TARGET_REL, (law, name, t["max_rel_diff"])
        assert t["displacement"]["rel_diff"] <= TARGET_REL and t["mixed"]["rel_diff"] <= TARGET_REL
        assert t["mixed"]["pressure_rel_diff"] <= TARGET_REL
        assert t["formulations_rel_diff"] <= TARGET_REL
        assert max(t["displacement"]["newton_iterations"], t["mixed"]["newton_iterations"]) <= 10
    # the uniaxial state is one: its lateral faces carry no load (P22 = P33 = 0 by scipy)
    uni = np.array(d["tests"]["uniaxial"]["displacement"]["P_fem"])
    assert np.abs(uni[1:, 1:]).max() <= 1e-10 * uni[0, 0] and uni[0, 0] > 0


@pytest.mark.fem
def test_fem_small_strain_limit_is_the_laws_E_and_nu(checked):
    """The FEM's R_11 / 1e-6 at stretch 1 + 1e-6 is E, the lateral contraction nu, within
    1e-4 (measured ~1e-6, the nonlinearity)."""
    law, d = checked
    small = d["tests"]["small_strain"]
    assert small["E_rel_diff"] <= SMALL_STRAIN_TARGET and small["nu_rel_diff"] <= SMALL_STRAIN_TARGET
    assert small["E_fem"] == pytest.approx(CHECK_LAWS[law].youngs_modulus, rel=SMALL_STRAIN_TARGET)


@pytest.mark.fem
def test_ogden_at_rest_is_stress_free_with_the_linear_elastic_tangent():
    """At F = I (every eigenvalue repeated, where the unregularised eigenvalue formula is
    0/0) the Ogden cube's residual is 0 (to round-off) and its tangent equals a neo-Hookean cube's of the
    same small-strain E and nu: the linear elasticity of (mu0, K), to 1e-8 relative."""
    pytest.importorskip("dolfinx")
    from fem.studies.materials_check import HomogeneousCube

    ogden = CHECK_LAWS["ogden"]
    same = MaterialLaw("neo-hookean", (ogden.youngs_modulus,), nu=ogden.poisson)
    cubes = [HomogeneousCube(m, "displacement") for m in (ogden, same)]
    b, A = cubes[0].assemble()
    _, A_ref = cubes[1].assemble()
    assert np.isfinite(A).all() and np.abs(b).max() <= 1e-15     # N, round-off of mu0 ~ 0.4 MPa
    assert np.abs(A - A_ref).max() <= 1e-8 * np.abs(A_ref).max()
    rest = cubes[0].solve(np.eye(3))
    assert np.abs(rest.reactions).max() <= 1e-12


# ---------------------------------------------------------------------- command line
@pytest.mark.parametrize("argv, message", [
    (["--out", "{tmp}/no/such/m.json"], "folder {tmp}/no/such does not exist"),
    (["--out", "{tmp}/m.txt"], "expected a .json file"),
    (["--joint", "{tmp}/bad.toml"], "material: law = 'hooke', use one of"),
    (["--joint", "{tmp}/missing.toml"], "cannot read joint file"),
])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, argv, message):
    from contract.joint import DEFAULT_JOINT

    (tmp_path / "bad.toml").write_text(DEFAULT_JOINT.read_text().replace('"neo-hookean"', '"hooke"'))
    before = sorted(tmp_path.iterdir())
    with pytest.raises(SystemExit) as exit_:
        main([a.format(tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and message.format(tmp=tmp_path) in err, err
    assert sorted(tmp_path.iterdir()) == before


@pytest.mark.fem
def test_command_checks_a_joint_files_law(tmp_path, capsys):
    """--joint FILE checks that file's law only; the document passes its format."""
    pytest.importorskip("dolfinx")
    from contract.joint import DEFAULT_JOINT
    from fem.artefacts import MATERIALS

    out = tmp_path / "m.json"
    assert main(["--joint", str(DEFAULT_JOINT), "--out", str(out), "--quiet"]) == 0
    doc = MATERIALS.load(out)
    assert list(doc["laws"]) == ["neo-hookean"] and doc["target_met"] is True
    assert doc["worst_rel_diff"] <= TARGET_REL
    assert "neo-hookean: uniaxial" in capsys.readouterr().out
    assert json.loads(out.read_text())["laws"]["neo-hookean"]["E_small_strain"] == 12.2
