"""Model composition, parameter handling, lowering and the model card."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from pneubayes.effects import Parameter, make_effect
from pneubayes.effects.base import Component
from pneubayes.effects.path import N_SLOTS, SLOT_INDEX, SLOT_NAMES
from pneubayes.errors import ModelCardError, ParameterError
from pneubayes.model import CARD_FORMAT, Model

EXAMPLE_CARD = {
    "format": "pneubayes-model/1", "effects": ["cylinder_leak"],
    "parameters": {"inlet_offset_m2": 2.9274e-08, "inlet_a_m2": 5.501e-07, "inlet_b": 3.539,
                   "inlet_c_per_V": 1.564, "inlet_d_V": 0.12, "exhaust_offset_m2": 2.6076e-08,
                   "exhaust_a_m2": 6.079e-07, "exhaust_b": 3.149, "exhaust_c_per_V": -1.365,
                   "exhaust_d_V": -0.1, "dead_volume_m3": 2.0e-07, "leak_area_m2": 3.04e-08}}
BASE_NAMES = ("inlet_offset_m2", "inlet_a_m2", "inlet_b", "inlet_c_per_V", "inlet_d_V",
              "exhaust_offset_m2", "exhaust_a_m2", "exhaust_b", "exhaust_c_per_V", "exhaust_d_V",
              "dead_volume_m3")
ALL = ["cylinder_leak", "tube_delay", "valve_deadzone", "supply_fluctuation", "heat_transfer",
       "spool_lag"]


def _card(**changes):
    card = json.loads(json.dumps(EXAMPLE_CARD))
    for k, v in changes.items():
        if v is _DELETE:
            del card[k]
        else:
            card[k] = v
    return card


_DELETE = object()


# ---------------------------------------------------------------- the example card
def test_example_card_parses():
    model, values = Model.from_card(EXAMPLE_CARD)
    assert model.effect_names == ("cylinder_leak",)
    assert model.effect("cylinder_leak").form == "orifice"
    assert model.parameter_names == BASE_NAMES + ("leak_area_m2",)
    assert values == EXAMPLE_CARD["parameters"]
    assert CARD_FORMAT == "pneubayes-model/1"
    # and it survives a round trip unchanged
    assert Model.from_card(model.to_card(values)) == (model, values)


def test_card_infers_the_laminar_leak_form():
    params = dict(EXAMPLE_CARD["parameters"])
    del params["leak_area_m2"]
    params["leak_conductance_kg_per_s_Pa2"] = 1e-16
    model, _ = Model.from_card(_card(parameters=params))
    assert model.effect("cylinder_leak").form == "laminar"


def test_a_heat_card_from_before_the_coupling_loads_as_it_meant():
    """A card with heat_transfer written before its coupling: the energy equation at an
    exchange > 0 (in its form: the convective one from its coefficient), eq. 5 at 0."""
    base = {k: v for k, v in EXAMPLE_CARD["parameters"].items() if k != "leak_area_m2"}
    for key, form in (("heat_transfer_rate_per_s", "rate"),
                      ("heat_transfer_coefficient_W_per_m2_K", "convective")):
        model, values = Model.from_card(_card(effects=["heat_transfer"],
                                              parameters={**base, key: 30.0}))
        assert model.effect("heat_transfer").form == form
        assert values["heat_transfer_coupling"] == 1.0
        _, off = Model.from_card(_card(effects=["heat_transfer"],
                                       parameters={**base, key: 0.0}))
        assert off["heat_transfer_coupling"] == 0.0
    _, given = Model.from_card(_card(effects=["heat_transfer"], parameters={
        **base, "heat_transfer_rate_per_s": 30.0, "heat_transfer_coupling": 0.4}))
    assert given["heat_transfer_coupling"] == 0.4


# ---------------------------------------------------------------- card errors
def _error(card) -> str:
    with pytest.raises(ModelCardError) as info:
        Model.from_card(card, source="MODEL.json")
    msg = str(info.value)
    assert "MODEL.json" in msg
    return msg


def test_card_wrong_format():
    msg = _error(_card(format="pneubayes-model/2"))
    assert "format" in msg and "pneubayes-model/2" in msg
    assert "format" in _error(_card(format=_DELETE))
    assert "JSON object" in _error(["not", "a", "dict"])


def test_card_unknown_effect():
    msg = _error(_card(effects=["cylinder_leak", "stiction"]))
    assert "stiction" in msg and "effects" in msg


def test_card_duplicate_effect():
    assert "cylinder_leak" in _error(_card(effects=["cylinder_leak", "cylinder_leak"]))


def test_card_missing_parameter():
    params = dict(EXAMPLE_CARD["parameters"])
    del params["inlet_b"]
    msg = _error(_card(parameters=params))
    assert "missing" in msg and "inlet_b" in msg


def test_card_unknown_parameter():
    params = dict(EXAMPLE_CARD["parameters"], tube_delay_s=0.003)
    msg = _error(_card(parameters=params))
    assert "tube_delay_s" in msg


def test_card_parameter_out_of_bounds():
    params = dict(EXAMPLE_CARD["parameters"], inlet_c_per_V=-1.0)  # inlet must grow with u
    msg = _error(_card(parameters=params))
    assert "inlet_c_per_V" in msg and "bounds" in msg


@pytest.mark.parametrize("bad", ["3.5", None, True, [3.5], float("nan"), float("inf")])
def test_card_non_numeric_parameter(bad):
    params = dict(EXAMPLE_CARD["parameters"], inlet_b=bad)
    msg = _error(_card(parameters=params))
    assert "inlet_b" in msg


@pytest.mark.parametrize("key,value", [("effects", "cylinder_leak"), ("parameters", [1, 2]),
                                       ("effect_options", [1])])
def test_card_wrong_types(key, value):
    assert key in _error(_card(**{key: value}))


def test_card_bad_effect_options():
    msg = _error(_card(effect_options={"cylinder_leak": {"colour": "red"}}))
    assert "cylinder_leak" in msg


def test_load_card_errors_name_the_file(tmp_path):
    missing = tmp_path / "nope.json"
    with pytest.raises(ModelCardError, match="nope.json"):
        Model.load_card(missing)
    broken = tmp_path / "broken.json"
    broken.write_text('{"format": "pneubayes-model/1",\n "effects": [}')
    with pytest.raises(ModelCardError, match=r"broken\.json.*line 2"):
        Model.load_card(broken)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(_card(format="x")))
    with pytest.raises(ModelCardError, match="bad.json"):
        Model.load_card(bad)


def test_save_and_load_card(tmp_path):
    model, values = Model.from_card(EXAMPLE_CARD)
    path = tmp_path / "m" / "MODEL.json"
    model.save_card(values, path)
    assert json.loads(path.read_text())["parameters"] == EXAMPLE_CARD["parameters"]
    assert Model.load_card(path) == (model, values)
    # overwriting is atomic and leaves no temporary files
    model.save_card(dict(values, inlet_b=4.0), path)
    assert Model.load_card(path)[1]["inlet_b"] == 4.0
    assert [p.name for p in path.parent.iterdir()] == ["MODEL.json"]


def test_card_keeps_effect_options():
    model = Model([make_effect("tube_delay", tube_diameter_m=0.004),
                   make_effect("cylinder_leak", form="laminar")])
    values = {p.name: p.lower for p in model.parameters}
    values.update(inlet_c_per_V=1.0, exhaust_c_per_V=-1.0)
    card = json.loads(json.dumps(model.to_card(values)))
    assert card["effect_options"]["tube_delay"] == {"tube_diameter_m": 0.004,
                                                    "air_viscosity_Pa_s": 1.81e-5,
                                                    "form": "transport"}
    again, vals = Model.from_card(card)
    assert again == model and again.effect("tube_delay").tube_diameter_m == 0.004
    # a card written before the tube had forms is the transport form
    del card["effect_options"]["tube_delay"]["form"]
    assert Model.from_card(card)[0] == model
    assert again != Model(["tube_delay", make_effect("cylinder_leak", form="laminar")])
    assert vals == model.as_dict(model.vector(values))


# ---------------------------------------------------------------- composition
def test_with_effect_and_without_round_trip():
    base = Model(["cylinder_leak"])
    bigger = base.with_effect("spool_lag").with_effect(make_effect("tube_delay"))
    assert bigger.effect_names == ("cylinder_leak", "tube_delay", "spool_lag")  # catalogue order
    assert bigger.without("tube_delay").without("spool_lag") == base
    assert bigger.without("cylinder_leak").parameter_names == BASE_NAMES + (
        "tube_delay_s", "spool_time_constant_s")
    assert base.with_effect("heat_transfer").without("heat_transfer") == base
    with pytest.raises(KeyError):
        base.without("spool_lag")


def test_duplicate_effect_raises():
    with pytest.raises(ValueError, match="cylinder_leak"):
        Model(["cylinder_leak", "cylinder_leak"])
    with pytest.raises(ValueError, match="cylinder_leak"):
        Model(["cylinder_leak"]).with_effect(make_effect("cylinder_leak", form="laminar"))
    with pytest.raises(ValueError):
        Model(["not_an_effect"])


def test_canonical_order_and_equality():
    a = Model(list(reversed(ALL)))
    b = Model(ALL)
    assert a == b and hash(a) == hash(b)
    assert a.parameter_names == b.parameter_names
    assert a.effect_names == tuple(ALL)
    assert Model(["cylinder_leak"]) != Model([make_effect("cylinder_leak", form="laminar")])
    assert a.n_parameters == 11 + 7  # (heat transfer: its rate and its coupling)
    assert len(set(a.parameter_names)) == a.n_parameters


# ---------------------------------------------------------------- parameter handling
def test_vector_as_dict_round_trip():
    model, values = Model.from_card(EXAMPLE_CARD)
    vec = model.vector(values)
    assert vec.shape == (12,) and vec[model.parameter_names.index("inlet_b")] == 3.539
    assert model.as_dict(vec) == values
    assert model.as_matrix(values).shape == (1, 12)
    assert model.as_matrix(np.stack([vec] * 3)).shape == (3, 12)
    with pytest.raises(ParameterError, match="missing"):
        model.vector({k: v for k, v in values.items() if k != "inlet_b"})
    with pytest.raises(ParameterError, match="unknown"):
        model.vector(dict(values, spool_time_constant_s=0.0))
    with pytest.raises(ParameterError):
        model.as_dict(vec[:-1])
    with pytest.raises(ParameterError):
        model.as_matrix(np.zeros((2, 5)))


def test_bounds_and_priors():
    model = Model(ALL)
    lo, hi = model.bounds
    assert lo.shape == hi.shape == (model.n_parameters,)
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)
    with pytest.raises(ValueError):
        lo[0] = 1.0  # read-only
    rng = np.random.default_rng(0)
    draws = np.array([[p.sample_prior(rng) for p in model.parameters] for _ in range(100)])
    assert model.out_of_bounds(draws) == []
    assert np.all(np.isfinite(model.log_prior(draws)))
    bad = draws[:2].copy()
    j = model.parameter_names.index("spool_time_constant_s")
    bad[1, j] = 1.0
    assert model.out_of_bounds(bad) == ["spool_time_constant_s"]
    lp = model.log_prior(bad)
    assert np.isfinite(lp[0]) and lp[1] == -np.inf
    with pytest.raises(ParameterError, match="spool_time_constant_s"):
        model.check_bounds(bad)
    bad[0, 0] = np.nan
    assert "inlet_offset_m2" in model.out_of_bounds(bad)


def test_log_uniform_prior_density():
    model = Model([])
    p = model.parameter("inlet_b")
    assert p.prior == "log-uniform"
    # log density -log(x): ratio of densities at 1 and 10 is 10
    assert p.log_prior(1.0) - p.log_prior(10.0) == pytest.approx(np.log(10.0), rel=1e-14)
    with pytest.raises(ParameterError):
        model.parameter("nope")


# ---------------------------------------------------------------- lowering
def test_base_lowering_is_the_identity_on_named_slots(rig):
    model, values = Model.from_card(EXAMPLE_CARD)
    slots = model.lower(values, rig)
    assert slots.shape == (1, N_SLOTS)
    for name in BASE_NAMES[:-1]:
        assert slots[0, SLOT_INDEX[name]] == values[name]
    assert slots[0, SLOT_INDEX["volume_m3"]] == values["dead_volume_m3"]
    assert slots[0, SLOT_INDEX["leak_orifice_area_m2"]] == values["leak_area_m2"]
    untouched = set(SLOT_NAMES) - set(BASE_NAMES[:-1]) - {"volume_m3", "leak_orifice_area_m2"}
    for name in untouched:
        assert slots[0, SLOT_INDEX[name]] == 0.0  # every slot's neutral value is 0


def test_lowering_is_row_wise(rig):
    model = Model(ALL)
    rng = np.random.default_rng(3)
    draws = np.array([[p.sample_prior(rng) for p in model.parameters] for _ in range(5)])
    together = model.lower(draws, rig)
    for b in range(5):
        assert np.array_equal(together[b], model.lower(draws[b], rig)[0])
    j = model.parameter_names.index("spool_time_constant_s")
    assert np.array_equal(together[:, SLOT_INDEX["spool_time_constant_s"]], draws[:, j])


class _ExtraVolume(Component):
    """A test component adding a volume to the chamber's (a slot another one writes)."""

    name = "extra_volume"
    acts_on = ("volume_m3",)
    writes = ("volume_m3",)

    def parameters(self):
        return (Parameter("extra_volume_m3", "m^3", 0.0, 1e-5, "uniform", "added"),)

    def lower(self, values, rig):
        return {slot: values["extra_volume_m3"] for slot in self.writes}


def test_lowering_sums_a_slot_two_components_write_and_checks_new_slots(rig):
    extra = _ExtraVolume()
    model = Model(["cylinder_leak"])
    model.base = model.base + (extra,)  # a second writer of volume_m3
    rng = np.random.default_rng(4)
    draws = np.array([[p.sample_prior(rng) for p in model.parameters] for _ in range(3)])
    slots = model.lower(draws, rig)
    dead = draws[:, model.parameter_names.index("dead_volume_m3")]
    added = draws[:, model.parameter_names.index("extra_volume_m3")]
    assert np.array_equal(slots[:, SLOT_INDEX["volume_m3"]], dead + added)
    leak = draws[:, model.parameter_names.index("leak_area_m2")]
    assert np.array_equal(slots[:, SLOT_INDEX["leak_orifice_area_m2"]], leak)
    assert slots.flags.c_contiguous and slots.shape == (3, N_SLOTS)
    # a lowering that starts writing an undeclared slot is caught though earlier calls
    # with the declared ones passed
    extra.writes = ("volume_m3", "compliance_m3_per_Pa")
    with pytest.raises(RuntimeError, match="extra_volume wrote slots it does not declare"):
        model.lower(draws, rig)


# ---------------------------------------------------------------- design meta-test
def test_import_does_not_pull_in_matplotlib():
    """One interpreter imports the core's modules together: the modules a set of imports
    loads include those each one loads alone, so none of them pulls matplotlib in (nor,
    for the ablation layer, dask: its scheduler is imported only when asked for)."""
    modules = ["pneubayes", "pneubayes.simulation", "pneubayes.effects", "pneubayes.model",
               "pneubayes.physics.orifice", "pneubayes.inference", "pneubayes.discovery",
               "pneubayes.io", "pneubayes.ablation"]
    code = (f"import sys, {', '.join(modules)}\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
            "('matplotlib', 'dask', 'distributed'))\n"
            "print(len(bad))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "0"


def test_card_rejects_options_of_an_unlisted_effect():
    import json

    from pneubayes.errors import ModelCardError
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset

    card = Model().to_card({**valve_preset("valve1").parameters(), "dead_volume_m3": 2e-7})
    card["effect_options"] = {"tube_delay": {"tube_diameter_m": 0.004}}
    with pytest.raises(ModelCardError, match="tube_delay"):
        Model.from_card(json.loads(json.dumps(card)), source="card.json")


def test_bound_overrides_replace_the_defaults_and_travel_with_the_model(tmp_path):
    m = Model([make_effect("cylinder_leak")], {"dead_volume_m3": (1e-5, 5e-3)})
    j = m.parameter_names.index("dead_volume_m3")
    assert m.bounds[0][j] == 1e-5 and m.bounds[1][j] == 5e-3
    assert m.parameter("dead_volume_m3").prior == Model().parameter("dead_volume_m3").prior
    assert m != Model([make_effect("cylinder_leak")])
    grown = m.with_effect("tube_delay")
    assert grown.bound_overrides == m.bound_overrides
    assert grown.without("tube_delay") == m
    both = grown.with_bounds({"tube_delay_s": (0.0, 0.1), "spool_time_constant_s": (0, 1)})
    assert both.bound_overrides["tube_delay_s"] == (0.0, 0.1)
    assert "spool_time_constant_s" not in both.bound_overrides  # not in this model
    assert "tube_delay_s" not in both.without("tube_delay").bound_overrides
    values = dict(m.neutral_values())
    values.update({n: float(0.5 * (lo + hi)) for n, lo, hi in
                   zip(m.parameter_names, *m.bounds)})
    m.save_card(values, tmp_path / "card.json")
    back, params = Model.load_card(tmp_path / "card.json")
    assert back == m and params["dead_volume_m3"] == pytest.approx(values["dead_volume_m3"])
    with pytest.raises(ParameterError, match=r"bounds for \['nope'\]"):
        _ = Model((), {"nope": (0.0, 1.0)}).parameters
    with pytest.raises(ValueError, match="lower < upper"):
        Model((), {"dead_volume_m3": (1e-3, 1e-5)})
    with pytest.raises(ParameterError, match="log-uniform prior needs lower > 0"):
        _ = Model((), {"inlet_a_m2": (0.0, 1e-5)}).parameters
    card = json.loads((tmp_path / "card.json").read_text())
    card["bounds"] = {"dead_volume_m3": [1e-3]}
    (tmp_path / "bad.json").write_text(json.dumps(card))
    with pytest.raises(ModelCardError, match=r"key 'bounds': 'dead_volume_m3' must be"):
        Model.load_card(tmp_path / "bad.json")
