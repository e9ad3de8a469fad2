"""Hyperelastic laws as strain energies: UFL for the FEM, numpy closed forms for checks.

Units: MPa (= N/mm², energy per mm³); F dimensionless. A law is a
contract.joint.MaterialLaw (its parameters, small-strain moduli and the table of its
forms are in contract/joint.py's docstring). Every law is split as

    psi(F) = psi_dev(F) + kappa/2 (ln J)^2,        J = det F,  P = d psi / d F

* neo-Hookean: psi_dev = mu/2 (I1 - 3) - mu ln J, kappa = lambda, i.e. exactly
  fem.physics.problem.neo_hookean_psi (the same UFL expression, so the committed data is
  reproduced to the bit);
* Mooney-Rivlin, Yeoh, Ogden: psi_dev a function of the isochoric C_bar = J^(-2/3) F^T F
  (I1b = tr C_bar, I2b = ((tr C_bar)^2 - tr C_bar^2) / 2, Ogden's sum over its principal
  stretches lb_a^2 = eigenvalues of C_bar), kappa = K.

The mixed u-p form (fem.physics.problem's perturbed Lagrangian) is, for every law,

    Pi(F, p) = psi_dev(F) - p ln J - p^2 / (2 kappa)

stationary in p at p = -kappa ln J, where it equals psi (``mixed_energy``).

Ogden's principal stretches in UFL. The eigenvalues c_a of the symmetric C_bar come from
the closed form of the cubic: q = tr C_bar / 3, D = C_bar - q I, p = sqrt(tr D^2 / 6),
r = det D / (2 p^3), c_k = q + 2 p cos(acos(r) / 3 + 2 pi k / 3). It is singular where
eigenvalues coincide (p = 0 at F = I, |r| = 1 in uniaxial and equibiaxial states), though
sum_a f(c_a) is smooth there. Two changes make every derivative finite:

* p = sqrt(tr D^2 / 6 + DELTA^2): the c_k are then exactly the eigenvalues of a
  characteristic cubic whose p^2 invariant is raised by DELTA^2, so the power sums, and
  their derivatives, differ from the exact ones by O(DELTA^2) (DELTA = 1e-8: 1e-16);
* r -> (1 - R_MARGIN) clamp(r, -1, 1): keeps acos off its infinite slope at +-1; the
  clamp only trims round-off overshoot, and where it acts dr/dC = 0 exactly (|r| = 1 is
  r's maximum), so no derivative is lost; the margin moves det D by a relative 1e-12.

The numpy closed forms (``stress``, ``strain_energy``) are an independent re-implementation:
P written out from the invariants' derivatives, and for Ogden from numpy.linalg.eigh of the
left Cauchy-Green tensor b = F F^T (Kirchhoff stress tau = sum_a tau_a n_a n_a^T,
P = tau F^-T). fem.studies.materials_check compares the FEM with them.

Data flow: contract.joint.MaterialLaw -> energy / mixed_energy (UFL) -> fem.physics.problem's
internal work; -> stress (numpy) -> fem.studies.materials_check, tests.
"""

from __future__ import annotations

import math

import numpy as np
import ufl

from contract.joint import MaterialLaw

#: Regularisation of the eigenvalue formula's p (dimensionless, C_bar's units).
DELTA = 1e-8
#: Margin that keeps acos's argument inside (-1, 1).
R_MARGIN = 1e-12


# ---------------------------------------------------------------------- UFL
def principal_power_sums(C, exponents) -> list:
    """[sum_a c_a^e for e in exponents], c_a the eigenvalues of the symmetric 3x3 UFL C
    (module docstring: closed form, regularised)."""
    q = ufl.tr(C) / 3
    D = C - q * ufl.Identity(3)
    p = ufl.sqrt(ufl.tr(D * D) / 6 + DELTA ** 2)
    r = ufl.det(D) / (2 * p ** 3)
    r = (1 - R_MARGIN) * ufl.max_value(-1.0, ufl.min_value(1.0, r))
    phi = ufl.acos(r) / 3
    eigenvalues = [q + 2 * p * ufl.cos(phi + 2 * math.pi * k / 3) for k in range(3)]
    return [sum(c ** e for c in eigenvalues) for e in exponents]


def deviatoric_energy(material: MaterialLaw, F):
    """psi_dev(F) (MPa) of the module docstring; F a UFL 3x3 (a ``ufl.variable`` for P)."""
    J = ufl.det(F)
    if material.law == "neo-hookean":
        mu, _ = material.lame
        return mu / 2 * (ufl.tr(F.T * F) - 3) - mu * ufl.ln(J)
    p = material.params
    Cb = J ** (-2.0 / 3.0) * F.T * F
    if material.law == "ogden":
        sums = principal_power_sums(Cb, [a / 2 for a in p["alpha"]])
        return sum(2 * m / a ** 2 * (s - 3) for m, a, s in zip(p["mu"], p["alpha"], sums))
    I1b = ufl.tr(Cb)
    if material.law == "mooney-rivlin":
        I2b = (I1b ** 2 - ufl.tr(Cb * Cb)) / 2
        return p["C10"] * (I1b - 3) + p["C01"] * (I2b - 3)
    x = I1b - 3
    return p["C10"] * x + p["C20"] * x ** 2 + p["C30"] * x ** 3


def energy(material: MaterialLaw, F):
    """Strain energy density psi(F) = psi_dev + kappa/2 (ln J)^2 (MPa)."""
    return deviatoric_energy(material, F) + material.kappa / 2 * ufl.ln(ufl.det(F)) ** 2


def mixed_energy(material: MaterialLaw, F, p):
    """The perturbed Lagrangian psi_dev - p ln J - p^2 / (2 kappa) (MPa), p (MPa) the
    pressure; equals ``energy`` at its stationary point p = -kappa ln J. Needs kappa > 0."""
    kappa = material.kappa
    if kappa <= 0:
        raise ValueError(f"the mixed formulation needs kappa > 0 (nu > 0), not kappa = {kappa:g} MPa")
    return deviatoric_energy(material, F) - p * ufl.ln(ufl.det(F)) - p ** 2 / (2 * kappa)


def first_piola(material: MaterialLaw, F):
    """P = d psi / d F (MPa) of a UFL ``ufl.variable`` F."""
    return ufl.diff(energy(material, F), F)


# ---------------------------------------------------------------------- numpy closed forms
def _isochoric(F: np.ndarray):
    """(J, F^-T, I1b, dI1b/dF, I2b, dI2b/dF) of a 3x3 F."""
    J = np.linalg.det(F)
    FiT = np.linalg.inv(F).T
    C = F.T @ F
    I1 = np.trace(C)
    I2 = (I1 ** 2 - np.trace(C @ C)) / 2
    j23, j43 = J ** (-2.0 / 3.0), J ** (-4.0 / 3.0)
    dI1b = j23 * (2 * F - 2.0 / 3.0 * I1 * FiT)
    dI2b = j43 * (2 * (I1 * F - F @ C) - 4.0 / 3.0 * I2 * FiT)
    return J, FiT, j23 * I1, dI1b, j43 * I2, dI2b


def _ogden_kirchhoff(material: MaterialLaw, F: np.ndarray) -> np.ndarray:
    """Kirchhoff stress tau (MPa) of the Ogden law from the spectral form of b = F F^T."""
    p = material.params
    J = np.linalg.det(F)
    lam2, n = np.linalg.eigh(F @ F.T)
    lb = J ** (-1.0 / 3.0) * np.sqrt(lam2)
    tau = np.full(3, material.kappa * math.log(J))
    for m, a in zip(p["mu"], p["alpha"]):
        powers = lb ** a
        tau += 2 * m / a * (powers - powers.sum() / 3)
    return (n * tau) @ n.T


def stress(material: MaterialLaw, F) -> np.ndarray:
    """First Piola-Kirchhoff stress P(F) (3, 3) MPa, closed form (module docstring)."""
    F = np.asarray(F, dtype=float)
    law, p = material.law, material.params
    if law == "neo-hookean":
        mu, lmbda = material.lame
        J, FiT = np.linalg.det(F), np.linalg.inv(F).T
        return mu * (F - FiT) + lmbda * math.log(J) * FiT
    if law == "ogden":
        return _ogden_kirchhoff(material, F) @ np.linalg.inv(F).T
    J, FiT, I1b, dI1b, I2b, dI2b = _isochoric(F)
    volumetric = material.kappa * math.log(J) * FiT
    if law == "mooney-rivlin":
        return p["C10"] * dI1b + p["C01"] * dI2b + volumetric
    x = I1b - 3
    return (p["C10"] + 2 * p["C20"] * x + 3 * p["C30"] * x ** 2) * dI1b + volumetric


def strain_energy(material: MaterialLaw, F) -> float:
    """psi(F) (MPa), numpy: the energy ``stress`` is the derivative of."""
    F = np.asarray(F, dtype=float)
    law, p = material.law, material.params
    J = np.linalg.det(F)
    volumetric = material.kappa / 2 * math.log(J) ** 2
    if law == "neo-hookean":
        mu, _ = material.lame
        return mu / 2 * (np.trace(F.T @ F) - 3) - mu * math.log(J) + volumetric
    if law == "ogden":
        c = J ** (-2.0 / 3.0) * np.linalg.eigvalsh(F.T @ F)
        return sum(2 * m / a ** 2 * ((c ** (a / 2)).sum() - 3) for m, a in zip(p["mu"], p["alpha"])) + volumetric
    _, _, I1b, _, I2b, _ = _isochoric(F)
    if law == "mooney-rivlin":
        return p["C10"] * (I1b - 3) + p["C01"] * (I2b - 3) + volumetric
    x = I1b - 3
    return p["C10"] * x + p["C20"] * x ** 2 + p["C30"] * x ** 3 + volumetric
