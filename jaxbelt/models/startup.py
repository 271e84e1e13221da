"""Belt drive driven by a DC motor through a gear reducer: the start-up model of Incerti (2014).

State (eq. 12) $x = (\\vartheta_1, \\vartheta_2, \\dot\\vartheta_1, \\dot\\vartheta_2, I)$, input
(eq. 13) $u = (\\tau_{r0}, V(t))$, $\\dot x = A x + B u$ with A, B of eq. (10)-(11).

`BeltChain` generalises the drive to n belt stages in series (n + 1 shafts, 2(n + 1) + 1 states,
as the paper's conclusion suggests); `BeltStartup` is the paper's 2-DOF case (n = 1) with the
Table I values as defaults.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array as _arr
from .._checks import check_finite, check_nonnegative, check_positive, is_concrete
from ..commands import AbstractVoltageCommand
from .base import AbstractLinearModel, integrand, observable


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


class _BeltDriveBase(AbstractLinearModel):
    """Shared behaviour of the belt-drive start-up models (linear, voltage driven).

    Subclasses provide the shaft inertias `_inertias()` (n + 1) and the stage radii
    `_stage_radii()` (driving, driven; n each); the motor, load and belt fields (`jm`, `k`, `c`,
    `tau_r0`, `mu`, `z`, `R`, `L`, `km`) have the same names in every subclass.
    """

    input_types: ClassVar[tuple[type, ...]] = (AbstractVoltageCommand,)

    def _inertias(self):
        raise NotImplementedError

    def _stage_radii(self):
        raise NotImplementedError

    def _check_common(self, owner: str):
        check_positive("jm", self.jm, "kg m^2", owner)
        check_positive("k", self.k, "N/m", owner)
        check_nonnegative("c", self.c, "N s/m", owner)
        check_nonnegative("mu", self.mu, "N m s/rad", owner)
        # constant part of the load torque tau_r = tau_r0 + mu * omega (Incerti, 2014): any finite value
        check_finite("tau_r0", self.tau_r0, owner=owner)
        check_positive("z", self.z, "", owner)
        check_positive("R", self.R, "ohm", owner)
        check_positive("L", self.L, "H", owner)
        check_positive("km", self.km, "N m/A", owner)

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

    def vector_field(self, t, y, inp):
        A, B = self.matrices()
        return A @ y + B[:, 1] * inp(t) + B[:, 0] * self.tau_r0

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

    def accepts_output(self, name: str) -> bool:
        """Accelerations `alpha3`, `alpha4`, ... of longer chains (`alpha1`, `alpha2` are declared)."""
        return name.startswith("alpha") and name[5:].isdigit() and 1 <= int(name[5:]) <= self.n_shafts

    def output(self, name, t, y, inp):
        if name not in self.output_names() and self.accepts_output(name):
            return self._accel(t, y, inp)[int(name[5:]) - 1]
        return super().output(name, t, y, inp)

    @observable("alpha1")
    def _out_alpha1(self, t, y, inp):
        """Angular acceleration of pulley 1 $\\ddot\\vartheta_1$ [rad/s²] (Fig. 3g)."""
        return self._accel(t, y, inp)[0]

    @observable("alpha2")
    def _out_alpha2(self, t, y, inp):
        """Angular acceleration of pulley 2 $\\ddot\\vartheta_2$ [rad/s²] (Fig. 3h)."""
        return self._accel(t, y, inp)[1]

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


class BeltStartup(_BeltDriveBase):
    """2-DOF synchronous belt drive + gear reducer + permanent-magnet DC motor (Incerti, 2014).

    Equations of motion (eq. 6-8), with $J_1^* = J_1 + z^2 J_m$:

    $J_1^*\\ddot\\vartheta_1 + 2c r_1(r_1\\dot\\vartheta_1 - r_2\\dot\\vartheta_2)
      + 2k r_1(r_1\\vartheta_1 - r_2\\vartheta_2) = z k_m I$

    $J_2\\ddot\\vartheta_2 - 2c r_2(r_1\\dot\\vartheta_1 - r_2\\dot\\vartheta_2)
      - 2k r_2(r_1\\vartheta_1 - r_2\\vartheta_2) = -(\\tau_{r0} + \\mu\\dot\\vartheta_2)$

    $V(t) = R I + L\\dot I + z k_m\\dot\\vartheta_1$ (eq. 7)

    Parameters (SI; defaults are Table I of Incerti (2014)):

    | field | symbol | unit | default |
    |---|---|---|---|
    | `jm` | $J_m$ motor inertia | kg m² | 4e-4 |
    | `j1` | $J_1$ driving pulley inertia | kg m² | 0.018 |
    | `j2` | $J_2$ driven pulley + load inertia | kg m² | 0.25 |
    | `k` | belt branch stiffness | N/m | 120e3 |
    | `c` | belt branch damping | N s/m | 20 |
    | `r1`, `r2` | pulley radii | m | 0.08, 0.16 |
    | `tau_r0` | constant load torque | N m | 0 |
    | `mu` | viscous load coefficient | N m s/rad | 5 |
    | `z` | gear ratio $\\vartheta_m = z\\vartheta_1$ | – | 15 |
    | `R` | armature resistance | Ω | 0.15 |
    | `L` | armature inductance | H | 0.2e-3 |
    | `km` | torque / back-emf constant | N m/A | 0.09 |

    State: `theta1, theta2` [rad], `omega1, omega2` [rad/s], `current` [A].
    """

    jm: jnp.ndarray = eqx.field(converter=_arr, default=4e-4)
    j1: jnp.ndarray = eqx.field(converter=_arr, default=0.018)
    j2: jnp.ndarray = eqx.field(converter=_arr, default=0.25)
    k: jnp.ndarray = eqx.field(converter=_arr, default=120e3)
    c: jnp.ndarray = eqx.field(converter=_arr, default=20.0)
    r1: jnp.ndarray = eqx.field(converter=_arr, default=0.08)
    r2: jnp.ndarray = eqx.field(converter=_arr, default=0.16)
    tau_r0: jnp.ndarray = eqx.field(converter=_arr, default=0.0)
    mu: jnp.ndarray = eqx.field(converter=_arr, default=5.0)
    z: jnp.ndarray = eqx.field(converter=_arr, default=15.0)
    R: jnp.ndarray = eqx.field(converter=_arr, default=0.15)
    L: jnp.ndarray = eqx.field(converter=_arr, default=0.2e-3)
    km: jnp.ndarray = eqx.field(converter=_arr, default=0.09)

    state_names: ClassVar[tuple[str, ...]] = ("theta1", "theta2", "omega1", "omega2", "current")

    def __check_init__(self):
        o = "BeltStartup"
        check_positive("j1", self.j1, "kg m^2", o)
        check_positive("j2", self.j2, "kg m^2", o)
        check_positive("r1", self.r1, "m", o)
        check_positive("r2", self.r2, "m", o)
        self._check_common(o)

    def _inertias(self):
        return jnp.stack([self.j1, self.j2])

    def _stage_radii(self):
        return self.r1[None], self.r2[None]


class BeltChain(_BeltDriveBase):
    """n belt stages in series driven by a DC motor (generalisation of Incerti (2014)).

    Shafts 0..n; shaft 0 carries the motor through gear ratio `z`. Stage i (i = 0..n-1) joins
    shaft i (driving pulley radius `r_drive[i]`) and shaft i+1 (driven radius `r_driven[i]`) with
    two branches of stiffness `k[i]` [N/m] and damping `c[i]` [N s/m]. `inertias` [kg m²] has
    n + 1 entries (pulleys on each shaft); the load $\\tau_{r0} + \\mu\\dot\\vartheta_n$ acts on
    the last shaft. State: angles (n+1), speeds (n+1), current: 2n + 3 states.
    `BeltChain.from_startup(BeltStartup())` is the paper's 2-DOF drive.
    """

    array_fields: ClassVar[tuple[str, ...]] = ("inertias", "k", "c", "r_drive", "r_driven")

    inertias: jnp.ndarray = eqx.field(converter=_arr)
    k: jnp.ndarray = eqx.field(converter=_arr)
    c: jnp.ndarray = eqx.field(converter=_arr)
    r_drive: jnp.ndarray = eqx.field(converter=_arr)
    r_driven: jnp.ndarray = eqx.field(converter=_arr)
    jm: jnp.ndarray = eqx.field(converter=_arr, default=4e-4)
    tau_r0: jnp.ndarray = eqx.field(converter=_arr, default=0.0)
    mu: jnp.ndarray = eqx.field(converter=_arr, default=5.0)
    z: jnp.ndarray = eqx.field(converter=_arr, default=15.0)
    R: jnp.ndarray = eqx.field(converter=_arr, default=0.15)
    L: jnp.ndarray = eqx.field(converter=_arr, default=0.2e-3)
    km: jnp.ndarray = eqx.field(converter=_arr, default=0.09)

    def __check_init__(self):
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
        check_positive("inertias", self.inertias, "kg m^2", o)
        check_positive("r_drive", self.r_drive, "m", o)
        check_positive("r_driven", self.r_driven, "m", o)
        self._check_common(o)

    @classmethod
    def from_startup(cls, m: BeltStartup) -> BeltChain:
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
    def state_names(self) -> tuple[str, ...]:  # type: ignore[override]
        m = self.inertias.shape[0]
        return tuple(f"theta{i + 1}" for i in range(m)) + tuple(f"omega{i + 1}" for i in range(m)) + ("current",)

    def _inertias(self):
        return self.inertias

    def _stage_radii(self):
        return self.r_drive, self.r_driven


#: The eight time histories of Incerti (2014), Fig. 3, in the paper's panel order (a-h).
STARTUP_OUTPUTS = (
    "voltage",
    "current",
    "electric_power",
    "mechanical_power",
    "omega1",
    "omega2",
    "alpha1",
    "alpha2",
)


def startup_curves(model=None, gammas=(0.02, 0.04, 0.06), v_max=24.0, t_end=0.5, n_points=501, method="auto"):
    """The eight time histories of Incerti (2014), Fig. 3, for each voltage time constant, as numpy arrays.

    The motor voltage is $V(t) = V_{max}(1 - e^{-t/\\gamma})$ (Incerti, 2014, eq. 30) with
    `v_max` $V_{max}$ [V] and each $\\gamma$ of `gammas` [s]; the drive starts at rest and is
    simulated over $[0, t_{end}]$ [s] on `n_points` equally spaced times (one compiled program, run for
    each $\\gamma$; closed form by default, `method` as in `simulate`).

    Returns `(ts, curves)`: `ts` [s] of shape `(n_points,)` and `curves[name]` of shape
    `(len(gammas), n_points)` for each name of `STARTUP_OUTPUTS`: voltage [V], current [A],
    electric and mechanical power [W], pulley speeds [rad/s] and accelerations [rad/s²].
    Default model: `BeltStartup()` (Incerti, 2014, Table I).
    """
    from ..commands import ExponentialVoltage
    from ..scene import Scene
    from ..solve import simulate

    model = BeltStartup() if model is None else model
    ts = np.linspace(0.0, float(t_end), int(n_points))
    observe = tuple(n for n in STARTUP_OUTPUTS if n not in model.state_names)
    rows = []
    for g in np.atleast_1d(np.asarray(gammas, dtype=float)).tolist():
        sol = simulate(Scene(model, ExponentialVoltage(v_max, g), ts=ts, observe=observe), method=method)
        sol = jax.device_get(sol)  # the columns are read on the host (no program per column)
        rows.append([sol[n] for n in STARTUP_OUTPUTS])
    return ts, {n: np.stack([r[i] for r in rows]) for i, n in enumerate(STARTUP_OUTPUTS)}
