"""An added catalogue effect that fits only with a parameter of its own at a bound is
kept in the model but not named (issue 69, item 4): ``DiscoveryResult.stand_ins``."""

from __future__ import annotations

from types import SimpleNamespace

from pneubayes.discovery.report_text import report_markdown as _report
from pneubayes.discovery.result import DiscoveryResult
from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.effects.sensor_lag import SensorLag
from pneubayes.effects.spool_lag import SpoolLag
from pneubayes.model import Model

EVIDENCE = {"inclusion_probability": 0.9, "t_max": 6.0, "best_term": "reading lag 1 ms"}


def _result(model, params, names, posterior=None):
    final = SimpleNamespace(model=model, params=params, heldout_rmse_Pa=600.0)
    accepted = tuple({"name": n, "evidence": EVIDENCE, "score_gain": 50.0,
                      "score_p_value": 0.001, "rmse_before_Pa": 900.0,
                      "rmse_after_Pa": 600.0} for n in names)
    return DiscoveryResult(settings=DiscoverySettings(), base=final, final=final,
                           accepted=accepted, ledger=(), maps=(), searches=(),
                           params=params, estimate="refined", noise_floor_Pa=500.0,
                           range_Pa=4.5e5, span_Pa=4e5, posterior_summary=posterior)


def _params(model, **values):
    return {**{n: 1.0 for n in Model().parameter_names}, "dead_volume_m3": 2e-6,
            **model.neutral_values(), **values}


def test_an_effect_at_a_bound_of_its_own_is_kept_as_a_stand_in_not_named():
    model = Model().with_effect(SensorLag(form="pressure_dependent"))
    params = _params(model, sensor_time_constant_s=0.006, sensor_pressure_exponent=2.996)
    result = _result(model, params, ["sensor_lag"])
    (hit,) = result.stand_ins()["sensor_lag"]
    assert hit["parameter"] == "sensor_pressure_exponent" and hit["bound"] == "upper"
    doc = result.to_dict()
    assert doc["effects"] == []
    (entry,) = doc["stand_ins"]
    assert entry["name"] == "sensor_lag" and entry["at_bounds"] == [hit]
    assert entry["parameters"]["sensor_pressure_exponent"] == {"estimate": 2.996}
    assert result.effect_names == ["sensor_lag"]  # (still in the model)
    text = _report({**doc, "recordings": ["a.csv"]}, result, {})
    assert "Kept as stand-ins, not named" in text
    assert "sensor_pressure_exponent at its upper bound 3" in text
    from pneubayes.cli.discover import summary_lines

    (line,) = summary_lines(doc)
    assert line.startswith("  ~ sensor_lag: kept as a stand-in, not named")
    assert summary_lines({"effects": []}) == ["  no missing effect is supported"]


def test_an_effect_inside_its_bounds_or_switched_off_is_named():
    model = Model().with_effect(SensorLag(form="pressure_dependent"))
    inside = _params(model, sensor_time_constant_s=0.006, sensor_pressure_exponent=1.0)
    doc = _result(model, inside, ["sensor_lag"]).to_dict()
    assert [e["name"] for e in doc["effects"]] == ["sensor_lag"] and doc["stand_ins"] == []
    # a parameter at the bound that switches its effect off (neutral) is no strain
    lag = Model().with_effect(SpoolLag(form="first_order"))
    off = _params(lag, spool_time_constant_s=0.0)
    assert _result(lag, off, ["spool_lag"]).stand_ins() == {}


def test_with_a_posterior_the_interval_decides():
    model = Model().with_effect(SensorLag(form="pressure_dependent"))
    params = _params(model, sensor_time_constant_s=0.006, sensor_pressure_exponent=2.9)
    near = {"sensor_time_constant_s": {"median": 0.006, "q05": 0.005, "q95": 0.007},
            "sensor_pressure_exponent": {"median": 2.9, "q05": 2.7, "q95": 2.99}}
    assert _result(model, params, ["sensor_lag"], near).stand_ins() != {}
    clear = dict(near, sensor_pressure_exponent={"median": 2.0, "q05": 1.5, "q95": 2.5})
    assert _result(model, params, ["sensor_lag"], clear).stand_ins() == {}


def test_a_parameter_at_its_physical_limit_is_no_strain():
    """Heat transfer's coupling at 1 is the energy equation itself (its ``limit``), not a
    form stretched to its bound; its exchange rate at the upper bound still is."""
    from pneubayes.effects.heat_transfer import HeatTransfer

    model = Model().with_effect(HeatTransfer())
    full = _params(model, heat_transfer_rate_per_s=12.0, heat_transfer_coupling=1.0)
    doc = _result(model, full, ["heat_transfer"]).to_dict()
    assert [e["name"] for e in doc["effects"]] == ["heat_transfer"] and doc["stand_ins"] == []
    pinned = _params(model, heat_transfer_rate_per_s=100.0, heat_transfer_coupling=1.0)
    (hit,) = _result(model, pinned, ["heat_transfer"]).stand_ins()["heat_transfer"]
    assert hit["parameter"] == "heat_transfer_rate_per_s" and hit["bound"] == "upper"
