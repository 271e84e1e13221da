"""Linear steady-state references for the non-linear belt (v_l = 0): frequency domain, no stepping.

Test references only: numpy, complex harmonic solves, no code path shared with the time
integration of `jaxbelt.nonlinear_sweep` (`jaxbelt.models.nonlinear.steady`). (The library's own linear response is
`jaxbelt.linear_runout_response`; tests/test_cross_scene.py compares the two scenes.)

- `modal_harmonic_pp(belt, speed)`: steady peak-to-peak displacement [m] of the *linearised
  N-mode Galerkin model with modal damping*: each mode block
  $\\dot z = [[-\\xi\\omega, \\omega], [-\\omega, -\\xi\\omega]] z + \\hat q e^{i\\Omega t}$ is solved
  as $\\hat z = (i\\Omega I - A)^{-1}\\hat q$.
- `string_exact_pp(belt, speed)`: the exact undamped steady state of the linear travelling string
  with harmonically moving ends (the closed form behind eq. 10 of Moon & Wickert (1997)): for each pulley,
  $W(x) = A e^{s_1 x} + B e^{s_2 x}$ with $s_1 = -i\\Omega/(1+v)$, $s_2 = i\\Omega/(1-v)$ (roots of
  $(1-v^2)s^2 - 2iv\\Omega s + \\Omega^2 = 0$) and $W$ equal to the pulley's complex run-out at its
  end and 0 at the other. It checks the forcing derived by the boundary-shift substitution.

With two pulley frequencies (unequal radii) the peak-to-peak of the quasi-periodic sum is taken
as its supremum $2(|W_0| + |W_1|)$.
"""

from __future__ import annotations

import numpy as np


def _params(belt, speed):
    v = float(speed) / float(belt.wave_speed)
    L = float(belt.span)
    r = np.asarray(belt.pulley_radii, dtype=float)
    e = np.asarray(belt.runout, dtype=float) / L
    Om = v * L / r
    return v, L, e, Om, float(belt.phase)


def _harmonics(belt, speed):
    """Per pulley: (Omega, boundary complex amplitude at x=0, at x=1, forcing callable F(x))."""
    v, L, e, Om, phi = _params(belt, speed)
    h0 = (Om[0], -1j * e[0], 0.0, lambda x: -1j * e[0] * Om[0] ** 2 * (1 - x) + 2 * v * e[0] * Om[0])
    p = np.exp(1j * phi)
    h1 = (Om[1], 0.0, -1j * e[1] * p, lambda x: p * (-1j * e[1] * Om[1] ** 2 * x - 2 * v * e[1] * Om[1]))
    return v, L, [h0, h1]


def _pp(belt, amps, Oms):
    if np.isclose(Oms[0], Oms[1], rtol=1e-12):
        return 2.0 * abs(amps[0] + amps[1]) * float(belt.span)
    return 2.0 * (abs(amps[0]) + abs(amps[1])) * float(belt.span)


def modal_harmonic_pp(belt, speed, at=0.01, n_modes=None, damping=None):
    """Peak-to-peak [m] at `at` [m] of the damped linear N-mode model in steady state (numpy)."""
    N = int(belt.n_modes if n_modes is None else n_modes)
    xi = float(belt.damping if damping is None else damping)
    v, L, harms = _harmonics(belt, speed)
    xg, wg = np.polynomial.legendre.leggauss(64 + 16 * N)
    x, w = 0.5 * (xg + 1), 0.5 * wg
    xm = float(at) / L
    amps, Oms = [], []
    for Om, b0, b1, F in harms:
        total = b0 * (1 - xm) + b1 * xm
        for n in range(1, N + 1):
            k = n * np.pi
            psi = np.sqrt(2) * np.sin(k * x) * np.exp(1j * k * v * x)
            om = k * (1 - v * v)
            mu = k * om
            Fx = F(x)
            # generalised forces of zeta^R, zeta^I for f = Re(F e^{i Om t}) (complex amplitudes)
            qr = -(om / mu) * np.sum(w * psi.imag * Fx)
            qi = (om / mu) * np.sum(w * psi.real * Fx)
            A = np.array([[-xi * om, om], [-om, -xi * om]])
            zr, zi = np.linalg.solve(1j * Om * np.eye(2) - A, np.array([qr, qi]))
            pm = np.sqrt(2) * np.sin(k * xm) * np.exp(1j * k * v * xm)
            total = total + zr * pm.real + zi * pm.imag
        amps.append(total)
        Oms.append(Om)
    return _pp(belt, amps, Oms)


def string_exact_pp(belt, speed, at=0.01):
    """Peak-to-peak [m] at `at` [m] of the exact undamped linear travelling string (numpy)."""
    v, L, harms = _harmonics(belt, speed)
    xm = float(at) / L
    amps, Oms = [], []
    for Om, b0, b1, _ in harms:
        s1, s2 = -1j * Om / (1 + v), 1j * Om / (1 - v)
        M = np.array([[1.0, 1.0], [np.exp(s1), np.exp(s2)]])
        A, B = np.linalg.solve(M, np.array([b0, b1], dtype=complex))
        amps.append(A * np.exp(s1 * xm) + B * np.exp(s2 * xm))
        Oms.append(Om)
    return _pp(belt, amps, Oms)
