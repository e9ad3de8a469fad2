"""apps.material_fit: a joint file's law from a uniaxial tension test.

Exact solutions: stresses made from known coefficients (incompressible uniaxial nominal
stress, apps.material_fit's module docstring) give those coefficients back; the Yeoh
stability range is the root of dpsi/dI1 and its stretches solve l² + 2/l - 3 = x.
Frozen reference: results/joints/soft4/joint.toml's Yeoh coefficients are the fit of the
committed Dragon Skin 30 test (Marechal et al. 2021) below 100 % strain.
"""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from apps.material_fit import basis, fit, read_uniaxial, yeoh_stable_range
from contract.joint import load_joint

ROOT = Path(__file__).resolve().parents[1]
SOFT4 = ROOT / "results" / "joints" / "soft4"


@pytest.mark.parametrize("law, coef", [("neo-hookean", (0.1,)), ("mooney-rivlin", (0.2, -0.05)),
                                       ("yeoh", (0.09, 0.012, -0.001))])
def test_fit_recovers_exact_coefficients(law, coef):
    strain = np.linspace(0.02, 1.5, 40)
    lam = 1 + strain
    g = 2 * (lam - lam ** -2)
    x = lam ** 2 + 2 / lam - 3
    if law == "neo-hookean":
        stress = g * coef[0]
    elif law == "mooney-rivlin":
        stress = g * (coef[0] + coef[1] / lam)
    else:
        stress = g * (coef[0] + 2 * coef[1] * x + 3 * coef[2] * x ** 2)
    assert np.allclose(basis(law, lam) @ np.array(coef), stress, rtol=1e-14, atol=0)
    out = fit(law, strain, stress, 2.0, 0.49)
    got = out["material"]
    if law == "neo-hookean":       # the file's E = 2 mu (1 + nu), mu = 2 C10
        assert got["E"] == pytest.approx(4 * coef[0] * 1.49, rel=1e-12)
    else:
        assert [got[k] for k in ("C10", "C01", "C20", "C30") if k in got] == pytest.approx(coef, rel=1e-10)
    assert out["rms_relative_error"] < 1e-12 and out["samples"] == 40


def test_yeoh_stable_range_is_where_dpsi_di1_vanishes():
    c = (0.08656, 0.01380, -0.001466)
    x_max, (lo, hi) = yeoh_stable_range(*c)
    assert c[0] + 2 * c[1] * x_max + 3 * c[2] * x_max ** 2 == pytest.approx(0.0, abs=1e-14)
    for lam in (lo, hi):
        assert lam ** 2 + 2 / lam - 3 == pytest.approx(x_max, rel=1e-12)
    assert lo < 1 < hi
    assert yeoh_stable_range(0.1, 0.01, 0.0)[0] == np.inf      # no negative term: stable for all x


def test_soft4_coefficients_are_the_committed_test_fit():
    strain, stress = read_uniaxial(SOFT4 / "dragon_skin_30.csv")
    assert len(strain) == 312 and stress.max() == pytest.approx(4.161, abs=1e-3)   # MPa, at 711 % strain
    out = fit("yeoh", strain, stress, 1.0, 0.499)
    joint = load_joint(SOFT4 / "joint.toml").material.params
    for k in ("C10", "C20", "C30"):      # the file prints 4 significant digits
        assert out["material"][k] == pytest.approx(joint[k], rel=5e-4), k
    assert out["samples"] == 42 and out["stretch_range"] == pytest.approx([1.045, 1.977], abs=1e-3)
    assert out["rms_relative_error"] == pytest.approx(0.049, abs=5e-4)
    assert out["stable_x_max"] == pytest.approx(8.57, abs=5e-3)


def test_cli_prints_a_table_the_joint_file_reads(tmp_path):
    csv = SOFT4 / "dragon_skin_30.csv"
    r = subprocess.run([sys.executable, "-m", "apps.material_fit", "--csv", str(csv), "--law", "mooney-rivlin"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    joint = (SOFT4 / "joint.toml").read_text()
    table = [line for line in r.stdout.splitlines() if not line.startswith("#")]
    head, _, tail = joint.partition("[material]")
    rest = tail[tail.index("\n["):]                         # the tables after [material]
    (tmp_path / "j.toml").write_text(head + "\n".join(table) + "\n" + rest)
    m = load_joint(tmp_path / "j.toml").material
    j = json.loads(subprocess.run([sys.executable, "-m", "apps.material_fit", "--csv", str(csv), "--law",
                                   "mooney-rivlin", "--json"], cwd=ROOT, capture_output=True, text=True,
                                  timeout=60).stdout)
    assert m.law == "mooney-rivlin" and m.params["C10"] == pytest.approx(j["material"]["C10"], rel=1e-3)
    assert m.youngs_modulus == pytest.approx(j["E_small_strain_MPa"], rel=2e-3)
