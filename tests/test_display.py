"""Rich displays and labelled data out (issue "Explore in a notebook", parts 2 and 3): the HTML tables of the
results and their `to_xarray` / `to_pandas` forms, checked against the results' own arrays (values, dimensions,
coordinates, units, the recommended row of a plan, escaping)."""

import dataclasses
import sys
from html.parser import HTMLParser

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbelt as jb
from jaxbelt._display import Display, Table, fmt

TS = jnp.linspace(0.0, 0.1, 11)
GAMMAS = jnp.array([0.02, 0.04, 0.06])


class _Tables(HTMLParser):
    """The rows of every `<table>` of an HTML text: `[(row attributes, [cell texts])]` per table."""

    def __init__(self, text):
        super().__init__()
        self.tables, self._row, self._cell = [], None, None
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self._row = (dict(attrs), [])
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._row is not None:
            self._row[1].append(self._cell)
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[-1].append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data


def _rows(text, table=-1):
    """The rows (cell texts) of table `table` of the HTML `text`, the header row first."""
    return [cells for _, cells in _Tables(text).tables[table]]


# --- the objects (cheap ones) ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sol():
    scene = jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, 0.02), ts=TS, observe=("electric_power",))
    return jb.simulate(scene)


@pytest.fixture(scope="module")
def batch():
    return jb.simulate(jb.Scene(jb.BeltStartup(), jb.ExponentialVoltage(24.0, GAMMAS), ts=TS))


@pytest.fixture(scope="module")
def plan():
    axis = jb.ModalAxis([6.0], [0.02])
    return jb.design_move(axis, 0.05, 0.7, v_max=0.3, a_max=1.2, include=("minimax", "ZV", "unshaped"))


@pytest.fixture(scope="module")
def curve():
    return jb.response_curve(jb.NonlinearBelt(), (7.5, 10.5), 1)


# --- Solution --------------------------------------------------------------------------------------------------
def test_solution_html_lists_states_and_outputs_with_units_and_values(sol):
    text = sol._repr_html_()
    fields = dict(_rows(text, 0))
    assert fields["model"] == "BeltStartup" and fields["success"] == "yes"
    assert fields["time span"] == "0 – 0.1 s"
    rows = _rows(text, 1)
    assert rows[0] == ["name", "kind", "unit", "shape", "min", "max", "final"]
    table = {r[0]: r for r in rows[1:]}
    assert list(table) == [*sol.state_names, "electric_power"]
    units = {"theta1": "rad", "omega2": "rad/s", "current": "A", "electric_power": "W"}
    for name, unit in units.items():
        v = np.asarray(sol[name])
        assert table[name][2] == unit
        assert table[name][3] == "11"
        assert table[name][4:] == [fmt(v.min()), fmt(v.max()), fmt(v[-1])]
    assert table["current"][1] == "state" and table["electric_power"][1] == "output"
    # the text form: the same numbers, one line per quantity
    lines = str(sol).splitlines()
    assert lines[0] == "jaxbelt Solution"
    current = next(ln.split() for ln in lines if ln.startswith("current"))
    assert current == ["current", "state", "A", "11", *table["current"][4:]]


def test_solution_of_a_batch_names_the_swept_parameter(batch):
    assert batch.batch is not None and batch.batch.name == "gamma" and batch.batch.unit == "s"
    fields = dict(_rows(batch._repr_html_(), 0))
    assert fields["batch"] == "gamma: 3 values, 0.02 – 0.06 s" and fields["success"] == "yes"


def test_solution_to_xarray(sol):
    pytest.importorskip("xarray")
    ds = sol.to_xarray()
    assert ds["current"].dims == ("t",)
    np.testing.assert_array_equal(ds["t"].values, np.asarray(sol.ts))
    assert ds["t"].attrs["units"] == "s"
    for name in (*sol.state_names, "electric_power"):
        np.testing.assert_array_equal(ds[name].values, np.asarray(sol[name]))
    assert ds["omega1"].attrs["units"] == "rad/s" and ds["electric_power"].attrs["units"] == "W"
    assert ds.attrs["model"] == "BeltStartup" and bool(ds["success"])


def test_solution_to_pandas(sol):
    pytest.importorskip("pandas")
    df = sol.to_pandas()
    assert df.index.name == "t" and list(df.columns) == [*sol.state_names, "electric_power"]
    np.testing.assert_array_equal(df.index.to_numpy(), np.asarray(sol.ts))
    for name in df.columns:
        np.testing.assert_array_equal(df[name].to_numpy(), np.asarray(sol[name]))
    assert df.attrs["units"]["current"] == "A" and df.attrs["units"]["t"] == "s"


def test_batched_solution_becomes_a_gamma_dimension(batch):
    pytest.importorskip("xarray")
    pytest.importorskip("pandas")
    ds = batch.to_xarray()
    assert ds["omega2"].dims == ("gamma", "t") and ds["success"].dims == ("gamma",)
    np.testing.assert_array_equal(ds["gamma"].values, np.asarray(GAMMAS))
    assert ds["gamma"].attrs["units"] == "s"
    np.testing.assert_array_equal(ds["omega2"].values, np.asarray(batch.omega2))
    np.testing.assert_array_equal(ds["omega2"].sel(gamma=0.04).values, np.asarray(batch.omega2)[1])
    df = batch.to_pandas()
    assert list(df.index.names) == ["gamma", "t"] and len(df) == 3 * TS.shape[0]
    np.testing.assert_array_equal(df["current"].to_numpy(), np.asarray(batch.current).ravel())
    assert df.loc[(0.06, float(TS[4])), "current"] == float(batch.current[2, 4])


def test_vmapped_solution_is_a_batch_dimension_unless_named(batch):
    """A `jax.vmap` over the time constant: the same values, a `batch` dimension, or `gamma` once named."""
    pytest.importorskip("xarray")
    model = jb.BeltStartup()
    sols = jax.vmap(lambda g: jb.simulate(jb.Scene(model, jb.ExponentialVoltage(24.0, g), ts=TS)))(GAMMAS)
    assert sols.batch is None and np.shape(sols.ts) == (3, TS.shape[0])
    ds = sols.to_xarray()
    assert ds["current"].dims == ("batch", "t")
    np.testing.assert_allclose(ds["current"].values, np.asarray(batch.current), rtol=1e-9, atol=1e-12)
    named = sols.to_xarray(batch=("gamma", GAMMAS, "s"))
    assert named["current"].dims == ("gamma", "t") and named["gamma"].attrs["units"] == "s"
    np.testing.assert_array_equal(named["gamma"].values, np.asarray(GAMMAS))
    with pytest.raises(ValueError, match="batch's length 3"):
        sols.to_xarray(batch=("gamma", GAMMAS[:2]))


# --- MovePlan --------------------------------------------------------------------------------------------------
def test_plan_html_is_the_ranked_table_with_the_best_row_marked(plan):
    text = plan._repr_html_()
    rows = _Tables(text).tables[-1]
    head, body = rows[0][1], rows[1:]
    assert head[1:4] == ["candidate", "T [s]", "worst [%]"]
    assert [cells[1] for _, cells in body] == [c.name for c in plan.table]
    for (attrs, cells), c in zip(body, plan.table):
        assert cells[2:5] == [fmt(c.move_time), fmt(c.worst_percent), fmt(c.mean_percent)]
        assert (attrs.get("class") == "jaxbelt-best") == (c is plan.best)
        assert (cells[0] == "★") == (c is plan.best)
    assert plan.best is not None and dict(_rows(text, 0))["recommended"] == plan.best.name
    assert str(plan) == plan.format_table()  # the text form is the CLI's table, as before


def test_plan_escapes_names(plan):
    first = dataclasses.replace(plan.table[0], name="<b>minimax</b> & co")
    odd = dataclasses.replace(plan, table=(first, *plan.table[1:]), best=first)
    text = odd._repr_html_()
    assert "<b>" not in text and "&lt;b&gt;minimax&lt;/b&gt; &amp; co" in text
    assert _Tables(text).tables[-1][1][1][1] == "<b>minimax</b> & co"  # the browser shows the name as written


def test_plan_to_pandas_and_xarray(plan):
    pytest.importorskip("pandas")
    xr = pytest.importorskip("xarray")
    df = plan.to_pandas()
    assert list(df.index) == [c.name for c in plan.table] and df.index.name == "candidate"
    assert df["best"].tolist() == [c is plan.best for c in plan.table]
    assert df["rank"].tolist() == list(range(1, len(plan.table) + 1))
    for col in ("move_time", "worst_percent", "mean_percent", "worst_m", "peak_v", "peak_a"):
        np.testing.assert_array_equal(df[col].to_numpy(), [getattr(c, col) for c in plan.table])
    np.testing.assert_array_equal(df["band5_low_mode1"].to_numpy(), [c.band_hz[0][0] for c in plan.table])
    assert df.attrs["units"]["worst_m"] == "m" and df.attrs["units"]["band5_high_mode1"] == "Hz"
    ds = plan.to_xarray()
    assert isinstance(ds, xr.Dataset) and ds["band5_high"].dims == ("candidate", "mode")
    np.testing.assert_array_equal(ds["worst_percent"].values, df["worst_percent"].to_numpy())
    np.testing.assert_array_equal(ds["reference_m"].values, plan.reference_m)
    assert ds.attrs["best"] == plan.best.name and ds["worst_m"].attrs["units"] == "m"


def test_plan_samples_as_labelled_data(plan):
    pytest.importorskip("pandas")
    pytest.importorskip("xarray")
    rate = 200.0
    t, x, v, a = (np.asarray(q) for q in plan.samples(rate, "ZV"))  # (the minimax design's correction is slower)
    df = plan.samples_to_pandas(rate, "ZV")
    assert df.index.name == "t" and list(df.columns) == ["x", "v", "a"]
    np.testing.assert_array_equal(df.index.to_numpy(), t)
    np.testing.assert_array_equal(df.to_numpy(), np.stack([x, v, a], axis=1))
    assert df.attrs["units"] == {"t": "s", "x": "m", "v": "m/s", "a": "m/s²"} and df.attrs["candidate"] == "ZV"
    ds = plan.samples_to_xarray(rate, "unshaped")
    t2, x2, *_ = plan.samples(rate, "unshaped")
    np.testing.assert_array_equal(ds["t"].values, np.asarray(t2))
    np.testing.assert_array_equal(ds["x"].values, np.asarray(x2))
    assert ds["a"].attrs["units"] == "m/s²" and ds["t"].attrs["units"] == "s"
    with pytest.raises(ValueError, match="rate_hz"):
        plan.samples_to_pandas(5.0)  # below Nyquist, refused as `to_csv` refuses it


# --- response curve --------------------------------------------------------------------------------------------
def test_response_curve_display_folds_and_stability(curve):
    text = curve._repr_html_()
    fields = dict(_rows(text, 0))
    folds = np.asarray(curve.folds)
    assert folds.size and fields["folds"] == ", ".join(fmt(f) for f in folds) + " m/s"
    st = np.asarray(curve.stable)
    assert fields["stable points"] == f"{int(st.sum())} of {st.size}"
    segments = _rows(text, 1)[1:]
    assert sum(int(r[3]) for r in segments) == st.size  # the runs cover every point
    assert [r[2] for r in segments][:1] == [fmt(bool(st[0]))]
    assert "ResponseCurve" in str(curve)


def test_response_curve_to_pandas_and_xarray(curve):
    pytest.importorskip("pandas")
    pytest.importorskip("xarray")
    df = curve.to_pandas()
    assert df.index.name == "speed"
    np.testing.assert_array_equal(df.index.to_numpy(), np.asarray(curve.speed))
    np.testing.assert_array_equal(df["pp"].to_numpy(), np.asarray(curve.pp))
    np.testing.assert_array_equal(df["stable"].to_numpy(), np.asarray(curve.stable))
    np.testing.assert_array_equal(df["amplitude1"].to_numpy(), np.asarray(curve.amplitude)[:, 0])
    assert df.attrs["units"]["pp"] == "m" and df.attrs["folds"] == np.asarray(curve.folds).tolist()
    ds = curve.to_xarray()
    assert ds["pp"].dims == ("point",) and ds["speed"].dims == ("point",) and ds["speed"].attrs["units"] == "m/s"
    np.testing.assert_array_equal(ds["speed"].values, np.asarray(curve.speed))
    np.testing.assert_array_equal(ds["amplitude"].values, np.asarray(curve.amplitude))
    np.testing.assert_array_equal(ds["coefficients"].values, np.asarray(curve.coefficients))
    np.testing.assert_array_equal(ds["folds"].values, np.asarray(curve.folds))
    assert list(ds["basis"].values) == ["1", "cos1", "sin1"] and ds["folds"].attrs["units"] == "m/s"


# --- optimisation, tuning and identification results -----------------------------------------------------------
def test_command_optimisation_result_display():
    res = jb.optimise_command(
        jb.BeltPlatform(), jb.PseudoPolynomial(jnp.array([3.0, 4.0, 5.0])), max_steps=2, progress=False
    )
    text = res._repr_html_()
    rows = {r[0]: r for r in _rows(text, 1)[1:]}
    assert rows["residual energy H"][1:] == [fmt(float(res.initial_value)), fmt(float(res.value)), "rad²/s⁴"]
    for i, g in enumerate(np.asarray(res.gammas)):
        assert rows[f"γ{i + 1}"][2] == fmt(g)
        assert rows[f"γ{i + 1}"][1] == fmt(np.asarray(res.gammas_history)[0, i])
    fields = dict(_rows(text, 0))
    assert fields["peak motor speed"] == f"{fmt(float(res.peak_speed))} rad/s"
    assert "γ1" in str(res)


def test_pid_tuning_result_display():
    pid = jb.PID(kp=80.0, ki=32.0, kd=0.015, omega_ref=30.0, v_limit=60.0)
    res = jb.tune_pid(jb.FourBarDrive(), pid, t0=0.375, t1=0.5, steps=2, progress=False)
    text = res._repr_html_()
    rows = {r[0]: r for r in _rows(text, 1)[1:]}
    assert rows["kp"] == ["kp", fmt(80.0), fmt(float(res.pid.kp)), "V/rad"]  # the ramped gain (multiplies t)
    assert rows["χ (exact)"][1:3] == [fmt(res.chi_initial), fmt(res.chi)]
    fields = dict(_rows(text, 0))
    assert fields["status"] == res.status and fields["peak |voltage|"] == f"{fmt(res.v_peak)} V"
    assert str(res).startswith("jaxbelt PIDTuneResult")


def test_identify_results_show_estimates_with_standard_errors():
    x = np.linspace(-1.0, 2.0, 40)
    y = 1.5 - 0.7 * x + 0.1 * np.random.default_rng(3).standard_normal(x.size)
    res = jb.identify(lambda p: p["a"] + p["b"] * x, {"a": 1.0, "b": -1.0}, y)
    rows = {r[0]: r for r in _rows(res._repr_html_(), 1)[1:]}
    for n in ("a", "b"):
        assert rows[n][1:3] == [fmt(float(res.params[n])), fmt(float(res.stderr[n]))]
    assert "standard error" in str(res)
    # identify_axis: a ModalAxis whose table holds the frequencies, damping ratios and their standard errors
    t = np.arange(2000) / 500.0
    decay = np.exp(-0.02 * 2 * np.pi * 7.0 * t) * np.cos(2 * np.pi * 7.0 * t)
    decay += 1e-3 * np.random.default_rng(0).standard_normal(t.size)
    axis = jb.identify_axis(t, decay, 1, offset=False)
    row = _rows(axis._repr_html_(), 1)[1]
    f, fs = float(axis.frequencies[0]), float(axis.frequency_std[0])
    z, zs = float(axis.damping_ratios[0]), float(axis.damping_std[0])
    assert row == ["1", fmt(f), fmt(fs), fmt(z), fmt(zs), "1"]


def test_text_is_escaped_in_html():
    shown = Display("a <b> & c", (("<x>", "<script>", "m"),), (Table(("<h>",), (("<i>",),), caption="<c>"),))
    text = shown.html()
    for raw in ("<b>", "<x>", "<script>", "<h>", "<i>", "<c>"):
        assert raw not in text and raw.replace("<", "&lt;").replace(">", "&gt;") in text
    res = jb.IdentifyResult({"<k>": 1.0}, {"<k>": 0.1}, np.eye(1), np.zeros(3), 0.1, 1.0, 2, 3, ("<k>",))
    assert "<k>" not in res._repr_html_() and "&lt;k&gt;" in res._repr_html_()


# --- the optional packages -------------------------------------------------------------------------------------
@pytest.mark.parametrize("module", ["pandas", "xarray"])
def test_missing_optional_package_names_the_extra(sol, module, monkeypatch):
    monkeypatch.setitem(sys.modules, module, None)  # `import pandas` raises ImportError
    call = sol.to_pandas if module == "pandas" else sol.to_xarray
    with pytest.raises(ImportError, match=r'pip install "jaxbelt\[notebook\]"'):
        call()
