"""Live exploration in a notebook: `explore(scene_or_model, **options)`, sliders on a scene's figure.

A controls engineer who opens a notebook drags a stiffness, a PID gain, an exponent or a mode frequency and
sees the curves move. `explore` builds that view for each of jaxbelt's scenes (the extra `jaxbelt[notebook]`,
which brings ipywidgets):

| scene | start from | sliders | curves | key numbers |
|---|---|---|---|---|
| `"startup"` (Incerti, 2014) | `BeltStartup`, a `Scene` | $k$, $c$, $J_2$, $\\gamma$, $V_{max}$ | current, pulley speeds, acceleration | peak current, final speed, belt mode |
| `"fourbar"` (Incerti, 2012) | `FourBarDrive`, `PID`, a `Scene` | $K_p$, $K_i$, $K_d$, $\\omega_0$ | motor speed, voltage, current | χ (eq. 22), peak voltage and current |
| `"shaping"` (Incerti, pseudo-polynomial) | `BeltPlatform`, `PseudoPolynomial` | $\\gamma_i$, $k$, $c$ | command and platform accelerations | $\\mathcal H$, $E(T)$, one L-BFGS step |
| `"spans"` (belt-vibration report) | `MovingString` | $T$, $\\rho$, $L$, $R_U$, $V/V_{cr}$ | $f_n(V)$ with pulley harmonics, mode 1 | $V_{cr}$, $f_n$ at $V$, exciting speeds |
| `"nonlinear"` (Moon & Wickert, 1997) | `NonlinearBelt` | $v_t$, $v_l$, $\\xi_1$ | response curve (stable, unstable) | fold speeds |
| `"axis"` (`design_move`) | `ModalAxis` | $f_i$, $\\zeta_i$, $T$ | residual % over frequency, accelerations | worst residual, recommendation |

The numbers are the library's own: each view calls the public functions (`simulate`, `fluctuation_index`,
`residual_energy`, `optimise_command`, `MovingString.natural_frequencies`, `exciting_speeds`, `response_curve`,
`design_move`, `tune_pid`). Slider ranges and units come from the parameters' declarations (`jaxbelt._params`):
the unit and the valid range of each model field, around the value the view starts from.

**Fast scenes** (start-up, four-bar χ, $\\mathcal H$ with one optimisation step, span frequencies) call the
library's compiled programs with the slider values as data (arrays): a new value compiles nothing (what the views
derive besides, the start-up's system matrix, the commands' accelerations, the span's arrays, are `jax.jit` programs
of this module with the values as traced arguments). The figure is redrawn in
place, by changing its lines' data (`Line2D.set_data`), never rebuilt; its canvas (`CachedAggCanvas`) keeps the
rendering of the axes, ticks and labels and renders only the curves over it while the axes' limits hold (the limits
follow the data stickily, `_fit`), since text is most of a full rendering's time. With ipympl (`%matplotlib widget`)
the figure is ipympl's canvas and `draw_idle()` redraws it. **Long scenes** (a `design_move`, a `response_curve`
continuation, a `tune_pid` run) compute in one background thread (kept for the process: a program's first call in a
new thread costs more) behind a progress indicator; a slider that moves on makes the computation in flight stale (its
result is dropped when it ends) and replaces the request queued behind it. (A `design_move` compiles again when a
frequency or the move time crosses one of its problem sizes: its frequency grid grows with $f\\,u\\,T$; a damping
ratio never does.)

`Explorer.update(**values)` sets sliders from code (what the tests and the benchmark do) and waits for the figure.

**In a browser** (ipywidgets 8 on noUiSlider) a slider snaps its value to its grid `min + k step` when shown and
sends the snapped value back. Each slider's grid holds the value it starts from (`_grid`), a value set from code
moves the grid to hold it and reaches the front-end as one message (`_set_slider`: range, step and value together),
and a value the front-end sends within half a step of the slider's is a rounding, ignored (`_slider_class`): opening a
view changes no number, and the tuned gains reach the browser as they are. Numbers show 4 significant digits (`SPEC`)
with their units; a failed computation leaves `values` NaN (no number from earlier values).
"""

from ._knobs import BYTES_PER_POINT as BYTES_PER_POINT
from ._knobs import Knob as Knob
from ._knobs import max_points as max_points
from ._sliders import MISSING_WIDGETS as MISSING_WIDGETS
from ._view import SPEC as SPEC
from ._view import WIDTH as WIDTH
from ._view import Explorer as Explorer
from ._view import explore as explore

__all__ = ["Explorer", "Knob", "explore"]
