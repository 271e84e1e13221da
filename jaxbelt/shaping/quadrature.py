"""The Gauss-Legendre rule of the pseudo-polynomials' residual integrals, shared by the designs
(`jaxbelt.shaping.pseudo`) and the residual curves (`jaxbelt.shaping.residual`): the rule on [0, 1], kept per size,
and the node count of a move (host decisions from concrete values; numpy only)."""

import functools

import numpy as np

#: the node count of `rule_nodes`: `NODES_PER_RAD` per radian of the highest $\omega T$ plus `NODES_EXTRA`, rounded
#: up to a power of two from `MIN_NODES` to `MAX_NODES`
NODES_PER_RAD = 0.75
NODES_EXTRA = 64
MIN_NODES = 512
MAX_NODES = 4096


@functools.cache
def gauss_legendre_01(n_nodes: int):
    """The `n_nodes`-point Gauss-Legendre rule on [0, 1], `(nodes, weights)`, read-only: kept per size (numpy's
    `leggauss` solves an eigenproblem, 30 ms at 512 nodes, 0.14 s at 1024, and a design takes the rule five times)."""
    x, w = np.polynomial.legendre.leggauss(int(n_nodes))
    v, w = 0.5 * (x + 1.0), 0.5 * w
    v.setflags(write=False)
    w.setflags(write=False)
    return v, w


def rule_nodes(max_omega_t: float) -> int:
    """$0.75\\,\\omega T + 64$ nodes rounded up to a power of two, at least `MIN_NODES` = 512, at most `MAX_NODES`,
    for the integrands $e^{i\\omega T u}$ under $u = v^4$ of a move of `max_omega_t` = the largest $\\omega T$ of the
    modes (measured against a 4096-node rule, `pseudo.design_nodes`: 5e-13 wherever $0.55\\,\\omega T$ nodes are
    given). One size serves a wide range of move times (512 nodes up to $\\omega T$ = 597)."""
    need = int(NODES_PER_RAD * float(max_omega_t) + NODES_EXTRA)
    n = MIN_NODES
    while n < need and n < MAX_NODES:
        n *= 2
    return n
