"""Guards that survive `jax.jit`, `jax.vmap` and `jax.grad`.

Parameter checks (`jaxbelt._checks`) raise at construction when values are concrete. When they
are traced, `traced_checks(*modules)` re-runs every `__check_init__` of the modules (and of the
modules inside them) and collects each check as `(ok, message)`, `ok` a boolean array.
`guard(value, checks, throw)` then attaches them to the values a caller consumes:

- `throw=True`: `eqx.error_if(value, ~ok, message)` — the program raises at run time, naming the
  parameter and its range, whatever part of the result the caller keeps (under `vmap`, if any
  element is bad);
- `throw=False`: the bad elements are set to NaN and reported through the returned flag.
"""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import collecting, is_concrete

def _modules(tree):
    out = []

    def visit(x):
        if isinstance(x, eqx.Module):
            out.append(x)
            for f in dataclasses.fields(x):
                visit(getattr(x, f.name, None))
        elif isinstance(x, (list, tuple)):
            for y in x:
                visit(y)
        elif isinstance(x, dict):
            for y in x.values():
                visit(y)

    visit(tree)
    return out


def traced_checks(*trees) -> list:
    """`[(ok, message)]` of the parameter checks of every module in `trees` whose values are traced.

    Concrete modules were checked when they were built and add nothing here.
    """
    if is_concrete(trees):
        return []
    with collecting() as found:
        for m in _modules(trees):
            if is_concrete(m):
                continue
            for klass in type(m).__mro__:
                check = klass.__dict__.get("__check_init__")
                if check is not None:
                    check(m)
    return found


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _checked(x, pred, message):
    return eqx.error_if(x, pred, message)


@_checked.defjvp
def _checked_jvp(message, primals, tangents):
    x, pred = primals
    tx, _ = tangents
    # The tangent is scaled by a guarded 1: the backward pass of `grad` needs that factor, so the
    # check runs even when the caller keeps only the gradient (a check on the primal output alone
    # would be removed as dead code in `jit(grad(f))`).
    one = eqx.error_if(jnp.ones((), dtype=x.dtype), pred, message)
    return eqx.error_if(x, pred, message), tx * one


def error_if(value, pred, message: str):
    """`eqx.error_if` on every inexact leaf of `value` that also guards derivatives.

    Under `jax.grad`/`jax.jacfwd` the check runs in the derivative program too, so an invalid
    value raises whether the caller keeps the value, its gradient or both.
    """
    pred = jnp.asarray(pred)

    def one(x):
        if isinstance(x, (jax.Array, np.ndarray)) and jnp.issubdtype(x.dtype, jnp.inexact) and x.size:
            return _checked(x, pred, message)
        return x

    return jax.tree_util.tree_map(one, value)


def all_ok(checks):
    """Conjunction of the checks' flags (True when there are none)."""
    ok = jnp.array(True)
    for c, _ in checks:
        ok = ok & c
    return ok


def guard(value, checks, throw: bool = True):
    """Attach `checks` to the pytree `value`: raise at run time (`throw`) or NaN the bad values.

    Returns `(value, ok)`.
    """
    ok = all_ok(checks)
    if not checks:
        return value, ok
    if throw:
        for c, msg in checks:
            value = error_if(value, ~c, msg)
        return value, ok
    return nan_where(value, ok), ok


def nan_where(value, ok):
    """`value` with every inexact leaf set to NaN where `ok` is False (ok broadcasts from the left)."""

    def one(x):
        if not (isinstance(x, jax.Array) or hasattr(x, "dtype")) or not jnp.issubdtype(x.dtype, jnp.inexact):
            return x
        o = jnp.reshape(ok, jnp.shape(ok) + (1,) * (jnp.ndim(x) - jnp.ndim(ok))) if jnp.ndim(x) >= jnp.ndim(ok) else ok
        return jnp.where(o, x, jnp.nan)

    return jax.tree_util.tree_map(one, value)
