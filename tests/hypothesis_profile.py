"""The hypothesis settings and shared strategies of the bad-input suites (tests/test_fuzz.py, tests/test_property.py).

A database-less, derandomized profile: the same examples on every run (CI is reproducible); no explain phase
(it writes no patch files)."""

import math

import equinox as eqx
import jax
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st

settings.register_profile(
    "jaxbelt-bad-input",
    derandomize=True,
    database=None,
    deadline=None,
    print_blob=True,
    phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink],
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture],
)
_PROFILE = settings.get_profile("jaxbelt-bad-input")


def examples(n):
    """`@settings` of these suites with `n` examples."""
    return settings(_PROFILE, max_examples=n)


# What an `eqx.error_if` raises at run time (see tests/test_guarantees.py): match the message.
RUNTIME = (eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError, ValueError)

nan, inf = math.nan, math.inf
NONFINITE = st.sampled_from([nan, inf, -inf])
