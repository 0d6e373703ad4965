"""Settings dataclasses from nested tables: one tree, checked by the dataclasses."""

import pytest

from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.inference.fit import FitSettings
from pneubayes.inference.sampler_settings import SamplerSettings
from pneubayes.physics.sensor_filter import PressureFilter
from pneubayes.settings_tree import SettingsError, build, override
from pneubayes.simulation import SolverConfig


def test_a_nested_table_changes_only_the_keys_it_names():
    base = FitSettings(sampler=SamplerSettings(max_steps=4000))
    out = override(base, {"sampler": {"n_walkers": 48}, "refine_solver": {"rtol": 1e-7}})
    assert out.sampler == SamplerSettings(max_steps=4000, n_walkers=48)
    assert out.refine_solver.rtol == 1e-7
    assert out.refine_solver.atol_Pa == SolverConfig.refinement().atol_Pa
    assert out.sample_solver == base.sample_solver and base.sampler.n_walkers == 0


def test_values_are_checked_against_the_type_hints_without_guessing():
    cases = [({"horizon_s": "2"}, "f.horizon_s: expected a number"),
             ({"sg_polyorder": 3.0}, "f.sg_polyorder: expected an integer"),
             ({"sg_polyorder": True}, "f.sg_polyorder: expected an integer"),
             ({"sampler": {"seed": 1.5}}, "f.sampler.seed: expected an integer"),
             ({"horizon_s": float("inf")}, "f.horizon_s: expected a finite number"),
             ({"sampler": 3}, "f.sampler: expected a table of SamplerSettings"),
             ({"sampler": {"walkers": 3}}, "f.sampler.walkers: unknown key; SamplerSettings"),
             ({"sampler": {"max_steps": 0}}, "f.sampler: SamplerSettings.max_steps must be")]
    for table, why in cases:
        with pytest.raises(SettingsError) as err:
            override(FitSettings(), table, "f")
        assert why in str(err.value), (table, str(err.value))


def test_lists_become_tuples_and_optional_fields_take_a_table_or_stay_none():
    d = override(DiscoverySettings(), {"search": {"regimes": {}},
                                       "data": {"bounds": {"dead_volume_m3": [1e-7, 1e-5]}}})
    assert d.data.bounds == {"dead_volume_m3": [1e-7, 1e-5]}
    f = override(FitSettings(), {"pressure_filter": {"order": 2, "cutoff_Hz": 1000}})
    assert f.pressure_filter == PressureFilter(2, 1000.0)
    with pytest.raises(SettingsError, match="f.pressure_filter: .*cutoff_Hz"):
        override(FitSettings(), {"pressure_filter": {"order": 2}}, "f")
    assert build(PressureFilter, {"order": 1, "cutoff_Hz": 50.0}).order == 1
    from pneubayes.ablation.settings import Settings

    assert override(Settings(), {"fit_positions": [0.2, 0.4]}).fit_positions == (0.2, 0.4)
    with pytest.raises(SettingsError, match=r"s.fit_positions\[1\]: expected a number"):
        override(Settings(), {"fit_positions": [0.2, "x"]}, "s")
    with pytest.raises(SettingsError, match=r"s.fit_positions\[1\]: must be <= 1"):
        override(Settings(), {"fit_positions": [0.2, 1.4]}, "s")


def test_the_discovery_tree_is_a_few_tables_with_one_name_per_knob():
    """Every knob of the loop sits in one table of a dozen at most, and a ``--set``
    assignment reaches it by the same dotted name a settings file uses."""
    import dataclasses

    from pneubayes.settings_tree import assignment, table_of

    top = [f.name for f in dataclasses.fields(DiscoverySettings)]
    assert len(top) <= 12
    s = override(DiscoverySettings(), table_of(map(assignment, [
        "stages.pair_members=0", "forms.tube_line_form=line", "posterior.method=laplace",
        "fit.pressure_filter={order = 2, cutoff_Hz = 1000}", "search.solver.rtol=1e-6"])))
    assert s.stages.pair_members == 0 and s.forms.tube_line_form == "line"
    assert s.posterior.method == "laplace" and s.posterior.sampled
    assert s.fit.pressure_filter == PressureFilter(2, 1000.0)
    assert s.search.solver.rtol == 1e-6
    # the saved tree is the same table: read back, it is the same settings
    assert override(DiscoverySettings(), _plain(s.to_dict())) == s
    with pytest.raises(SettingsError, match="rounds.max_effects: given more than once"):
        table_of(map(assignment, ["rounds.max_effects=1", "rounds.max_effects=2"]))
    with pytest.raises(SettingsError, match="expected KEY=VALUE"):
        assignment("rounds.max_effects")


def _plain(doc):
    """A saved tree (``to_dict``) as a settings file's table: nested dicts, no Nones."""
    if isinstance(doc, dict):
        return {k: _plain(v) for k, v in doc.items() if v is not None}
    return list(doc) if isinstance(doc, tuple) else doc
