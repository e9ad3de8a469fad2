"""A joint file's material law from a published uniaxial tension test (issue 37 §5).

    python -m apps.material_fit --csv FILE [--law yeoh] [--max-strain 1] [--nu 0.499] [--json]

Incompressible uniaxial tension, stretch l = 1 + e (e the engineering strain), first
invariant I1 = l² + 2/l, x = I1 - 3. The nominal (engineering) stress of each law of
contract.joint is linear in its coefficients (MPa):

    neo-hookean     P = 2 (l - l^-2) C10                      C10 = mu / 2
    mooney-rivlin   P = 2 (l - l^-2) (C10 + C01 / l)
    yeoh            P = 2 (l - l^-2) (C10 + 2 C20 x + 3 C30 x²)

so an ordinary least-squares solve over the test's samples with 0 < e < ``--max-strain``
gives them (Ogden's exponents enter nonlinearly: not fitted here). The joint's laws are
compressible with a volumetric term; ``--nu`` sets its small-strain Poisson ratio, which
the test (incompressible by assumption) cannot give. For neo-Hookean the file's parameter
is E = 2 mu (1 + nu).

Input: a CSV (``;`` or ``,``) with a header row naming the columns ``Engineering Strain``
and ``Engineering Stress (MPa)`` (the format of the Soft Robotics Materials Database,
Marechal et al. 2021; rows above the header, its metadata, are skipped). Output: the
``[material]`` table to paste into a joint file, and the fit's figures: samples and stretch
range used, RMS relative and absolute error, the law's small-strain E, and for Yeoh the
range of x (and of uniaxial stretch) where dpsi/dI1 = C10 + 2 C20 x + 3 C30 x² > 0, outside
which the law is unstable. results/joints/soft4/joint.toml's Yeoh coefficients are this
command on results/joints/soft4/dragon_skin_30.csv (tests/test_material_fit.py).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from contract import cli
from contract.joint import LAWS, MAX_NU, MaterialLaw, material_dict

STRAIN = "engineering strain"
STRESS = "engineering stress (mpa)"
FITTED = ("neo-hookean", "mooney-rivlin", "yeoh")


def read_uniaxial(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(engineering strain, engineering stress MPa), shape (n,) each, from a test's CSV
    (module docstring). Raises ValueError naming what is wrong."""
    text = Path(path).read_text(errors="strict")
    delimiter = ";" if text.count(";") > text.count(",") else ","
    rows = list(csv.reader(text.splitlines(), delimiter=delimiter))
    for i, row in enumerate(rows):
        names = [c.strip().lower() for c in row]
        if STRAIN in names and STRESS in names:
            a, b = names.index(STRAIN), names.index(STRESS)
            break
    else:
        raise ValueError(f"{path}: no header row with columns 'Engineering Strain' and 'Engineering Stress (MPa)'")
    data = [r for r in rows[i + 1:] if any(c.strip() for c in r)]
    try:
        e = np.array([float(r[a]) for r in data])
        s = np.array([float(r[b]) for r in data])
    except (ValueError, IndexError):
        raise ValueError(f"{path}: a row below the header has no numbers in the strain and stress columns") from None
    if not (np.isfinite(e).all() and np.isfinite(s).all()):
        raise ValueError(f"{path}: NaN or inf in the strain or stress column")
    return e, s


def basis(law: str, stretch: np.ndarray) -> np.ndarray:
    """The nominal stress per unit coefficient, shape (n, n_coefficients), MPa per MPa."""
    l = stretch
    g = 2 * (l - l ** -2)
    x = l ** 2 + 2 / l - 3
    if law == "neo-hookean":
        return g[:, None]
    if law == "mooney-rivlin":
        return np.stack([g, g / l], axis=1)
    return np.stack([g, 2 * g * x, 3 * g * x ** 2], axis=1)


def yeoh_stable_range(c10: float, c20: float, c30: float) -> tuple[float, tuple[float, float]]:
    """(the largest x_max with dpsi/dI1 > 0 on [0, x_max) (inf if none ends it), the
    uniaxial stretches (compression, tension) with I1 - 3 = x_max)."""
    roots = np.roots([3 * c30, 2 * c20, c10]) if c30 else np.roots([2 * c20, c10])
    positive = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-12 and r.real > 0]
    x_max = min(positive, default=np.inf)
    if not np.isfinite(x_max):
        return x_max, (0.0, np.inf)
    lam = sorted(r.real for r in np.roots([1.0, 0.0, -(3 + x_max), 2.0]) if abs(r.imag) < 1e-9 and r.real > 0)
    return float(x_max), (float(lam[0]), float(lam[-1]))


def fit(law: str, strain: np.ndarray, stress: np.ndarray, max_strain: float, nu: float) -> dict:
    """Least-squares coefficients of ``law`` on the samples with 0 < strain < max_strain,
    the [material] table (MaterialLaw) and the fit's figures (module docstring)."""
    use = (strain > 0) & (strain < max_strain)
    n_coef = len(LAWS[law])
    if use.sum() < n_coef + 1:
        raise ValueError(f"{use.sum()} samples with 0 < strain < {max_strain:g}: {law} needs at least {n_coef + 1}")
    lam, P = 1 + strain[use], stress[use]
    A = basis(law, lam)
    coef = np.linalg.lstsq(A, P, rcond=None)[0]
    model = A @ coef
    params = (4 * coef[0] * (1 + nu),) if law == "neo-hookean" else tuple(float(c) for c in coef)
    material = MaterialLaw(law, params, nu=nu)
    out = {"law": law, "material": material_dict(material), "samples": int(use.sum()),
           "stretch_range": [float(lam.min()), float(lam.max())],
           "rms_relative_error": float(np.sqrt(np.mean(((model - P) / P) ** 2))),
           "rms_error_MPa": float(np.sqrt(np.mean((model - P) ** 2))),
           "E_small_strain_MPa": material.youngs_modulus, "mu0_MPa": material.mu0}
    if law == "yeoh":
        x_max, stretches = yeoh_stable_range(*coef)
        out["stable_x_max"] = x_max
        out["stable_stretch_range"] = list(stretches)
    return out


def toml_table(result: dict) -> str:
    """The [material] table of a joint file (contract.joint) for the fit."""
    lines = ["[material]", f'law = "{result["law"]}"']
    lines += [f"{k} = {v:.4g}" for k, v in result["material"].items() if k != "law"]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m apps.material_fit", description=__doc__.split("\n\n")[0])
    ap.add_argument("--csv", required=True, help="the uniaxial test (module docstring's format)")
    ap.add_argument("--law", choices=FITTED, default="yeoh")
    ap.add_argument("--max-strain", type=cli.number(0.0, 20.0, "", open_lo=True), default=1.0,
                    help="fit the samples with engineering strain below this")
    ap.add_argument("--nu", type=cli.number(0.0, MAX_NU), default=0.499,
                    help="the law's small-strain Poisson ratio (the test cannot give it)")
    args = ap.parse_args(argv)
    with ap.errors():
        result = fit(args.law, *read_uniaxial(args.csv), args.max_strain, args.nu)
    if args.json:
        cli.print_json(result)
        return 0
    print(toml_table(result))
    print(f"# {result['samples']} samples, stretch {result['stretch_range'][0]:.3f} to "
          f"{result['stretch_range'][1]:.3f}; RMS error {100 * result['rms_relative_error']:.1f} % "
          f"({1e3 * result['rms_error_MPa']:.2f} kPa); small-strain E {result['E_small_strain_MPa']:.4g} MPa")
    if "stable_x_max" in result:
        lo, hi = result["stable_stretch_range"]
        print(f"# dpsi/dI1 > 0 while I1 - 3 < {result['stable_x_max']:.3g} (uniaxial stretch {lo:.2f} to {hi:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
