"""Belt drive driven by a DC motor through a gear reducer: the start-up model of Incerti (2014).

State (eq. 12) $x = (\\vartheta_1, \\vartheta_2, \\dot\\vartheta_1, \\dot\\vartheta_2, I)$, input
(eq. 13) $u = (\\tau_{r0}, V(t))$, $\\dot x = A x + B u$ with A, B of eq. (10)-(11).

`BeltChain` generalises the drive to n belt stages in series (n + 1 shafts, 2(n + 1) + 1 states,
as the paper's conclusion suggests); `BeltStartup` is the paper's 2-DOF case (n = 1) with the
Table I values as defaults.
"""

import abc
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
from equinox import AbstractVar

from .._checks import is_concrete
from .._model import AbstractLinearModel, integrand, observable, observable_family
from .._params import FloatParam, document, param
from ..commands import AbstractVoltageCommand
from . import _ranges as _r
from ._ranges import ranged


def chain_matrices(jm, inertias, k, c, r_drive, r_driven, z, mu, R, L, km):
    """State matrices of an n-stage belt chain driven by a DC motor.

    Shaft 0 carries the motor (through the gear ratio z) and the first driving pulley; stage i
    links shaft i (radius `r_drive[i]`) to shaft i+1 (radius `r_driven[i]`); the load
    $\\tau_r = \\tau_{r0} + \\mu\\dot\\vartheta_n$ acts on the last shaft. Each stage has two
    branches of stiffness k and damping c, so $U = \\sum_i k_i\\delta_i^2$,
    $D = \\sum_i c_i\\dot\\delta_i^2$ with $\\delta_i = r^{d}_i\\vartheta_i - r^{n}_i\\vartheta_{i+1}$
    (Incerti, 2014, eq. 5). Returns `(A, B)` with shapes (2m+1, 2m+1) and (2m+1, 2), m = n + 1.
    """
    inertias = jnp.asarray(inertias, dtype=float)
    k = jnp.atleast_1d(jnp.asarray(k, dtype=float))
    c = jnp.atleast_1d(jnp.asarray(c, dtype=float))
    r_drive = jnp.atleast_1d(jnp.asarray(r_drive, dtype=float))
    r_driven = jnp.atleast_1d(jnp.asarray(r_driven, dtype=float))
    m = inertias.shape[0]
    n = m - 1
    if k.shape != (n,) or c.shape != (n,) or r_drive.shape != (n,) or r_driven.shape != (n,):
        raise ValueError(
            f"belt chain with {m} shafts needs {n} stages: k, c, r_drive, r_driven must have shape ({n},); "
            f"got {k.shape}, {c.shape}, {r_drive.shape}, {r_driven.shape}"
        )
    # g_i: elongation of stage i as a linear form of the shaft angles.
    G = jnp.zeros((n, m))
    idx = jnp.arange(n)
    G = G.at[idx, idx].set(r_drive).at[idx, idx + 1].set(-r_driven)
    K = 2.0 * (G.T * k) @ G
    C = 2.0 * (G.T * c) @ G
    C = C.at[n, n].add(mu)
    j_eff = inertias.at[0].add(z**2 * jm)  # J1* = J1 + z^2 Jm
    minv = 1.0 / j_eff
    e0 = jnp.zeros((m,)).at[0].set(1.0)
    A = jnp.zeros((2 * m + 1, 2 * m + 1))
    A = A.at[:m, m : 2 * m].set(jnp.eye(m))
    A = A.at[m : 2 * m, :m].set(-minv[:, None] * K)
    A = A.at[m : 2 * m, m : 2 * m].set(-minv[:, None] * C)
    A = A.at[m : 2 * m, 2 * m].set(minv * z * km * e0)
    A = A.at[2 * m, m].set(-z * km / L)
    A = A.at[2 * m, 2 * m].set(-R / L)
    B = jnp.zeros((2 * m + 1, 2))
    B = B.at[2 * m - 1, 0].set(-minv[n])
    B = B.at[2 * m, 1].set(1.0 / L)
    return A, B


class AbstractBeltDrive(AbstractLinearModel):
    """Shared behaviour of the belt-drive start-up models (linear, voltage driven).

    Subclasses give the shaft inertias `_inertias()` (n + 1) and the stage radii `_stage_radii()`
    (driving, driven; n each), and the motor, load and belt parameters declared here.
    """

    jm: AbstractVar[jnp.ndarray]
    k: AbstractVar[jnp.ndarray]
    c: AbstractVar[jnp.ndarray]
    tau_r0: AbstractVar[jnp.ndarray]
    mu: AbstractVar[jnp.ndarray]
    z: AbstractVar[jnp.ndarray]
    R: AbstractVar[jnp.ndarray]
    L: AbstractVar[jnp.ndarray]
    km: AbstractVar[jnp.ndarray]

    input_types: ClassVar[tuple[type, ...]] = (AbstractVoltageCommand,)

    @abc.abstractmethod
    def _inertias(self) -> jnp.ndarray:
        """The n + 1 shaft inertias [kg m²] (shaft 0 without the motor)."""

    @abc.abstractmethod
    def _stage_radii(self) -> tuple[jnp.ndarray, jnp.ndarray]:
        """Driving and driven pulley radii [m] of the n stages."""

    def initial_state(self, inp):
        """At rest, no current."""
        return jnp.zeros((self.n_states,))

    def input_checks(self, inp) -> list:
        return []

    def matrices(self):
        """`(A, B)` of eq. (10)-(11) (generalised to n stages)."""
        r_drive, r_driven = self._stage_radii()
        return chain_matrices(
            self.jm, self._inertias(), self.k, self.c, r_drive, r_driven, self.z, self.mu, self.R, self.L, self.km
        )

    @property
    def n_shafts(self) -> int:
        return (self.n_states - 1) // 2

    def _elongation_map(self):
        r"""G with belt elongations $\delta = G\vartheta$, one row per stage."""
        r_drive, r_driven = self._stage_radii()
        n = r_drive.shape[0]
        idx = jnp.arange(n)
        return jnp.zeros((n, n + 1)).at[idx, idx].set(r_drive).at[idx, idx + 1].set(-r_driven)

    def _j_eff(self):
        return self._inertias().at[0].add(self.z**2 * self.jm)  # J1* = J1 + z^2 Jm

    def linear_system(self):
        """`(A, b, c)`: $\\dot x = A x + b V(t) + c$, with $b$ the voltage column of B and
        $c = B_{:,0}\\,\\tau_{r0}$ the constant load torque (eq. 10-13)."""
        A, B = self.matrices()
        return A, B[:, 1], B[:, 0] * self.tau_r0

    def default_solver(self):
        import diffrax

        # The armature pole -R/L is far faster than the belt modes when L is small: an implicit
        # solver then takes steps at the belt's time scale instead of the electrical one.
        # Decided from concrete parameters at trace time (inside jit the matrices are built from
        # constants, so evaluate them eagerly); a traced model keeps the explicit default.
        if is_concrete(self):
            with jax.ensure_compile_time_eval():
                if self._stiffness_ratio() > 1e4:
                    return diffrax.Kvaerno5()
        return diffrax.Tsit5()

    def _stiffness_ratio(self) -> float:
        """Largest over smallest non-zero eigenvalue magnitude of A (the rigid-body 0 excluded)."""
        mag = np.abs(np.linalg.eigvals(np.asarray(self.matrices()[0])))
        nz = mag[mag > 1e-9 * mag.max()]
        return float(nz.max() / nz.min())

    @observable_family("alpha", size="n_shafts")
    def _out_alpha(self, t, y, inp):
        """Angular accelerations of the shafts $\\ddot\\vartheta_i$ [rad/s²]: `alpha1`, `alpha2` (Fig. 3g, 3h), ..."""
        return self._accel(t, y, inp)

    # --- derived outputs (one time) ---------------------------------------------------------
    def _accel(self, t, y, inp):
        m = self.n_shafts
        return self.vector_field(t, y, inp)[m : 2 * m]

    @observable("voltage")
    def _out_voltage(self, t, y, inp):
        return inp(t)

    @observable("electric_power")
    def _out_electric_power(self, t, y, inp):
        """Electric power at the motor terminals $V I$ [W] (Fig. 3c)."""
        return inp(t) * y[-1]

    @observable("mechanical_power")
    def _out_mechanical_power(self, t, y, inp):
        """Mechanical power at the motor shaft $k_m I \\cdot z\\dot\\vartheta_1$ [W] (Fig. 3d)."""
        return self.km * y[-1] * self.z * y[self.n_shafts]

    @observable("motor_speed")
    def _out_motor_speed(self, t, y, inp):
        """Motor shaft speed $z\\dot\\vartheta_1$ [rad/s]."""
        return self.z * y[self.n_shafts]

    @observable("kinetic_energy")
    def _out_kinetic_energy(self, t, y, inp):
        m = self.n_shafts
        return 0.5 * jnp.sum(self._j_eff() * y[m : 2 * m] ** 2)

    @observable("elastic_energy")
    def _out_elastic_energy(self, t, y, inp):
        d = self._elongation_map() @ y[: self.n_shafts]
        return jnp.sum(jnp.atleast_1d(self.k) * d**2)

    @observable("magnetic_energy")
    def _out_magnetic_energy(self, t, y, inp):
        return 0.5 * self.L * y[-1] ** 2

    # --- energy bookkeeping: integrands -----------------------------------------------------
    @integrand("electric_energy")
    def _rate_electric_energy(self, t, y, inp):
        return inp(t) * y[-1]

    @integrand("copper_loss")
    def _rate_copper_loss(self, t, y, inp):
        return self.R * y[-1] ** 2

    @integrand("damping_loss")
    def _rate_damping_loss(self, t, y, inp):
        m = self.n_shafts
        d = self._elongation_map() @ y[m : 2 * m]
        return 2.0 * jnp.sum(jnp.atleast_1d(self.c) * d**2)

    @integrand("load_work")
    def _rate_load_work(self, t, y, inp):
        w = y[2 * self.n_shafts - 1]
        return (self.tau_r0 + self.mu * w) * w


# The motor, load and belt parameters that both drives declare (written once, here).
def _jm():
    return ranged(4e-4, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_m$", doc="motor inertia", default_note="Table I")


def _tau_r0():
    return ranged(0.0, _r.TORQUE_N_M, unit="N m", symbol="$\\tau_{r0}$", doc="constant load torque", signed=True)


def _mu():
    return ranged(5.0, _r.VISCOUS_N_M_S, unit="N m s/rad", symbol="$\\mu$", doc="viscous load coefficient")


def _z():
    return ranged(15.0, _r.GEAR_RATIO, unit="–", symbol="$z$", doc="gear ratio $\\vartheta_m = z\\vartheta_1$")


def _R():
    return ranged(0.15, _r.RESISTANCE_OHM, unit="Ω", symbol="$R$", doc="armature resistance")


def _L():
    return ranged(0.2e-3, _r.INDUCTANCE_H, unit="H", symbol="$L$", doc="armature inductance")


def _km():
    return ranged(0.09, _r.MOTOR_CONSTANT, unit="N m/A", symbol="$k_m$", doc="torque / back-emf constant")


@document
class BeltStartup(AbstractBeltDrive):
    """2-DOF synchronous belt drive + gear reducer + permanent-magnet DC motor (Incerti, 2014).

    Equations of motion (eq. 6-8), with $J_1^* = J_1 + z^2 J_m$:

    $J_1^*\\ddot\\vartheta_1 + 2c r_1(r_1\\dot\\vartheta_1 - r_2\\dot\\vartheta_2)
      + 2k r_1(r_1\\vartheta_1 - r_2\\vartheta_2) = z k_m I$

    $J_2\\ddot\\vartheta_2 - 2c r_2(r_1\\dot\\vartheta_1 - r_2\\dot\\vartheta_2)
      - 2k r_2(r_1\\vartheta_1 - r_2\\vartheta_2) = -(\\tau_{r0} + \\mu\\dot\\vartheta_2)$

    $V(t) = R I + L\\dot I + z k_m\\dot\\vartheta_1$ (eq. 7)

    Parameters (SI; defaults are Table I of Incerti (2014)):

    {parameters}

    State: `theta1, theta2` [rad], `omega1, omega2` [rad/s], `current` [A].
    """

    jm: jnp.ndarray = _jm()
    j1: FloatParam = ranged(0.018, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_1$", doc="driving pulley inertia")
    j2: FloatParam = ranged(0.25, _r.INERTIA_KG_M2, unit="kg m²", symbol="$J_2$", doc="driven pulley + load inertia")
    k: FloatParam = ranged(120e3, _r.STIFFNESS_N_PER_M, unit="N/m", symbol="$k$", doc="stiffness of each belt branch")
    c: FloatParam = ranged(20.0, _r.DAMPING_N_S_PER_M, unit="N s/m", symbol="$c$", doc="damping of each belt branch")
    r1: FloatParam = ranged(0.08, _r.RADIUS_M, unit="m", symbol="$r_1$", doc="driving pulley radius")
    r2: FloatParam = ranged(0.16, _r.RADIUS_M, unit="m", symbol="$r_2$", doc="driven pulley radius")
    tau_r0: jnp.ndarray = _tau_r0()
    mu: jnp.ndarray = _mu()
    z: jnp.ndarray = _z()
    R: jnp.ndarray = _R()
    L: jnp.ndarray = _L()
    km: jnp.ndarray = _km()

    @property
    def state_names(self) -> tuple[str, ...]:
        return ("theta1", "theta2", "omega1", "omega2", "current")

    def _inertias(self):
        return jnp.stack([self.j1, self.j2])

    def _stage_radii(self):
        return self.r1[None], self.r2[None]


@document
class BeltChain(AbstractBeltDrive):
    """n belt stages in series driven by a DC motor (generalisation of Incerti (2014)).

    Shafts 0..n; shaft 0 carries the motor through gear ratio `z`. Stage i (i = 0..n-1) joins
    shaft i (driving pulley radius `r_drive[i]`) and shaft i+1 (driven radius `r_driven[i]`) with
    two branches of stiffness `k[i]` and damping `c[i]`. The load
    $\\tau_{r0} + \\mu\\dot\\vartheta_n$ acts on the last shaft. State: angles (n+1), speeds (n+1),
    current: 2n + 3 states. `BeltChain.from_startup(BeltStartup())` is the paper's 2-DOF drive.

    {parameters}
    """

    inertias: FloatParam = param(unit="kg m²", shape=None, doc="the n + 1 shaft inertias (pulleys on each shaft)")
    k: FloatParam = param(unit="N/m", shape=None, doc="branch stiffness of each stage, shape (n,)")
    c: FloatParam = param(unit="N s/m", check="nonnegative", shape=None, doc="branch damping of each stage, shape (n,)")
    r_drive: FloatParam = param(unit="m", shape=None, doc="driving pulley radius of each stage, shape (n,)")
    r_driven: FloatParam = param(unit="m", shape=None, doc="driven pulley radius of each stage, shape (n,)")
    jm: jnp.ndarray = _jm()
    tau_r0: jnp.ndarray = _tau_r0()
    mu: jnp.ndarray = _mu()
    z: jnp.ndarray = _z()
    R: jnp.ndarray = _R()
    L: jnp.ndarray = _L()
    km: jnp.ndarray = _km()

    def _check_relations(self):
        o = "BeltChain"
        if self.inertias.ndim != 1 or self.inertias.shape[0] < 2:
            raise ValueError(
                f"{o}: `inertias` must be a 1-D array of n + 1 >= 2 shaft inertias; got shape {self.inertias.shape}"
            )
        n = self.inertias.shape[0] - 1
        for name in ("k", "c", "r_drive", "r_driven"):
            if getattr(self, name).shape != (n,):
                raise ValueError(
                    f"{o}: `{name}` must have shape ({n},) for {n} stages; got {getattr(self, name).shape}"
                )

    @classmethod
    def from_startup(cls, m: BeltStartup) -> "BeltChain":
        return cls(
            inertias=jnp.stack([m.j1, m.j2]),
            k=m.k[None],
            c=m.c[None],
            r_drive=m.r1[None],
            r_driven=m.r2[None],
            jm=m.jm,
            tau_r0=m.tau_r0,
            mu=m.mu,
            z=m.z,
            R=m.R,
            L=m.L,
            km=m.km,
        )

    @property
    def state_names(self) -> tuple[str, ...]:
        m = self.inertias.shape[0]
        return tuple(f"theta{i + 1}" for i in range(m)) + tuple(f"omega{i + 1}" for i in range(m)) + ("current",)

    def _inertias(self):
        return self.inertias

    def _stage_radii(self):
        return self.r_drive, self.r_driven
