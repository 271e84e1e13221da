"""Independent references shared by the tests: numpy/scipy only, no jaxbelt solver code.

The start-up model enters only through its matrices A and B, which `test_startup.py` checks
entry by entry against eq. (10)-(11) of Incerti (2014).
"""

import numpy as np
import scipy.linalg as sl


def expm_reference(A, F, s, x0, ts):
    """States of $x' = A x + \\sum_j F_{:,j} e^{s_j t}$, $x(t_0) = x_0$ at `ts` ($t_0$ = ts[0]), by
    scipy's matrix exponential of the system augmented with the exponential generators."""
    A, F, s = np.asarray(A, float), np.asarray(F, float), np.asarray(s, float)
    n, m = F.shape
    Aa = np.zeros((n + m, n + m))
    Aa[:n, :n], Aa[:n, n:], Aa[n:, n:] = A, F, np.diag(s)
    ts = np.asarray(ts, dtype=float)
    t0 = float(ts[0])
    z0 = np.concatenate([np.asarray(x0, float), np.exp(s * t0)])
    return np.array([sl.expm(Aa * (t - t0)) @ z0 for t in ts])[:, :n]


def startup_reference(model, ts, v_max=24.0, gamma=None, x0=None):
    """Start-up states for $V = V_{max}(1 - e^{-t/\\gamma})$ (or a constant $V_{max}$ when gamma
    is None) and the model's constant load torque, from rest unless `x0` is given."""
    A, B = (np.asarray(a, dtype=float) for a in model.matrices())
    const = B[:, 0] * float(model.tau_r0) + float(v_max) * B[:, 1]
    x0 = np.zeros(A.shape[0]) if x0 is None else x0
    if gamma is None:
        return expm_reference(A, const[:, None], np.array([0.0]), x0, ts)
    F = np.stack([const, -float(v_max) * B[:, 1]], axis=1)
    return expm_reference(A, F, np.array([0.0, -1.0 / float(gamma)]), x0, ts)
