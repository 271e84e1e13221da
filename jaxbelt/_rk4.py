"""The classical fourth-order Runge-Kutta method as a diffrax solver (`simulate(..., method="rk4")`).

A module of its own so that `jaxbelt.solve` imports diffrax only when an ODE is integrated: the
closed forms of the linear scenes never load it.
"""

from __future__ import annotations

from typing import ClassVar

import diffrax
import numpy as np


class RK4(diffrax.AbstractERK):
    """The classical fourth-order Runge-Kutta method as a diffrax solver (fixed step, no error estimate).

    Incerti (2014) checks the modal solution with it at a 0.1 ms step, Incerti (2012) integrates the
    four-bar with it at 1 ms. `simulate(..., method="rk4", dt=...)` uses it with a constant step;
    the output times are read off the cubic Hermite interpolant between steps.
    """

    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.ButcherTableau(
        c=np.array([0.5, 0.5, 1.0]),
        b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
        b_error=np.zeros(4),
        a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])),
    )
    interpolation_cls: ClassVar = diffrax.ThirdOrderHermitePolynomialInterpolation.from_k

    def order(self, terms):
        return 4
