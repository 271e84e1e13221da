"""The Gauss-Legendre rule of the pseudo-polynomials' residual integrals, shared by the designs
(`jaxbelt.shaping.pseudo`) and the residual curves (`jaxbelt.shaping.residual`): the rule on [0, 1], kept per size,
and the node count of a move (host decisions from concrete values; numpy only)."""

import functools

import numpy as np

#: the node count of `rule_nodes`: `NODES_PER_RAD` per radian of the highest $\omega T$ plus `NODES_EXTRA`, rounded
#: up to a power of two from `MIN_NODES` to `MAX_NODES` (one Gauss-Legendre rule)
NODES_PER_RAD = 0.75
NODES_EXTRA = 64
MIN_NODES = 512
MAX_NODES = 4096
#: the one `MAX_NODES` rule resolves $\omega T$ up to this (measured: 5e-13 of $\int_0^1 u^{\gamma-2}e^{i\omega Tu}du$
#: at $\omega T$ = 7500 for $\gamma$ = 2 and 3.5, 2e-9 at 9000); above it the rule is composite (`PANEL_NODES`)
SINGLE_MAX_OMEGA_T = 7000.0
#: a composite rule's panels: `PANEL_NODES` Gauss-Legendre nodes on each of K panels of v that share the phase
#: $\omega T v^4$ equally (boundaries $(j/K)^{1/4}$), at most `PANEL_RAD` radians each (measured: 800 rad per 512-node
#: panel resolve the integrals to rounding, 1e-10 of their value, at $\omega T$ = 7000-30000), K a power of two
PANEL_NODES = 512
PANEL_RAD = 600.0
#: the most nodes a composite rule takes ($\omega T$ up to 64 x 600 = 38400 rad: a 1 kHz mode in a 6 s move); a
#: residual curve holds (modes x factors x nodes) complex numbers: 0.5 GB for 2 modes x 512 (padded) factors at this
#: size, 5x that with a damping range (`design_move(damping=)` judges 5 damping ratios per mode)
MAX_COMPOSITE_NODES = 64 * PANEL_NODES
#: the most $\omega T$ [rad] a rule resolves (`MAX_COMPOSITE_NODES` / `PANEL_NODES` panels of `PANEL_RAD`); above it the
#: residual curves take the integrals' asymptotic closed form (`jaxbelt.shaping.residual`), exact to rounding there
REACH_OMEGA_T = MAX_COMPOSITE_NODES // PANEL_NODES * PANEL_RAD


@functools.cache
def gauss_legendre_01(n_nodes: int):
    r"""The `n_nodes`-point Gauss-Legendre rule on [0, 1], `(nodes, weights)`, read-only: kept per size (numpy's
    `leggauss` solves an eigenproblem, 30 ms at 512 nodes, 0.14 s at 1024, and a design takes the rule five times).

    Above `MAX_NODES` (a multiple of `PANEL_NODES`, from `rule_nodes`) the composite rule of K = n / `PANEL_NODES`
    panels of v with boundaries $(j/K)^{1/4}$ (equal shares of the phase $\omega T v^4$), each with the
    `PANEL_NODES`-point rule: one rule of that size would cost minutes to build and resolve no more."""
    n_nodes = int(n_nodes)
    if n_nodes > MAX_NODES:
        if n_nodes % PANEL_NODES:
            raise ValueError(
                f"gauss_legendre_01: a composite rule's size must be a multiple of {PANEL_NODES}; got {n_nodes}"
            )
        k = n_nodes // PANEL_NODES
        vp, wp = gauss_legendre_01(PANEL_NODES)
        edges = (np.arange(k + 1) / k) ** 0.25
        h = np.diff(edges)
        v, w = (edges[:-1, None] + h[:, None] * vp[None, :]).ravel(), (h[:, None] * wp[None, :]).ravel()
        v.setflags(write=False)
        w.setflags(write=False)
        return v, w
    x, w = np.polynomial.legendre.leggauss(n_nodes)
    v, w = 0.5 * (x + 1.0), 0.5 * w
    v.setflags(write=False)
    w.setflags(write=False)
    return v, w


def rule_nodes(max_omega_t: float) -> int:
    """$0.75\\,\\omega T + 64$ nodes rounded up to a power of two, at least `MIN_NODES` = 512, at most `MAX_NODES`,
    for the integrands $e^{i\\omega T u}$ under $u = v^4$ of a move of `max_omega_t` = the largest $\\omega T$ of the
    modes (measured against a 4096-node rule, `pseudo.design_nodes`: 5e-13 wherever $0.55\\,\\omega T$ nodes are
    given). One size serves a wide range of move times (512 nodes up to $\\omega T$ = 597).

    Above $\\omega T$ = `SINGLE_MAX_OMEGA_T` (where one `MAX_NODES` rule stops resolving the integrands): the size of
    a composite rule (`gauss_legendre_01`), `PANEL_NODES` x K, K the power of two (16 or more) that keeps each panel
    within `PANEL_RAD` radians. Raises ValueError beyond `MAX_COMPOSITE_NODES`' reach: no silent loss of accuracy."""
    wt = float(max_omega_t)
    if wt > SINGLE_MAX_OMEGA_T:
        k = 16
        while k * PANEL_RAD < wt and k * PANEL_NODES < MAX_COMPOSITE_NODES:
            k *= 2
        if k * PANEL_RAD < wt:
            raise ValueError(
                f"residual of a pseudo-polynomial move: a mode's omega*T = {wt:.6g} rad (2 pi x its frequency x the "
                f"move time) is above {REACH_OMEGA_T:.6g} rad, the most its "
                "quadrature resolves; shorten the move or leave that mode out of the axis"
            )
        return k * PANEL_NODES
    need = int(NODES_PER_RAD * wt + NODES_EXTRA)
    n = MIN_NODES
    while n < need and n < MAX_NODES:
        n *= 2
    return n
