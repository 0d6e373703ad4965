"""A found closure as the source of an effect plug-in a user can name and edit.

:func:`effect_skeleton` writes a Python module defining an
:class:`~pneubayes.effects.Effect` that lowers onto the closure's slots with the found
terms fixed: its parameters carry the user's names (to be edited), bounds around the
fitted values and the fitted values as bench defaults. Registering it is one line in
``pneubayes.effects.CATALOGUE`` (or ``Model([FoundEffect()])`` directly).
"""

from __future__ import annotations

from pneubayes.effects.closure_terms import term_formula


def effect_skeleton(model, params: dict, class_name: str = "FoundEffect",
                    effect_name: str = "found_effect") -> str:
    """The module text of an effect plug-in for ``model``'s closure at ``params``.

    Parameters
    ----------
    model : Model
        A model with a ``closure`` component.
    params : dict
        Its fitted parameter values.
    class_name, effect_name : str
        The class's and the catalogue's name for the new effect (edit them).

    Returns
    -------
    str
        Python source; ``exec`` of it defines ``class_name``.
    """
    if not model.has("closure"):
        raise ValueError("effect_skeleton: the model has no closure (no found term)")
    closure = model.effect("closure")
    names, lines = {}, []
    for k, term in enumerate(closure.term_list()):
        lines.append(f"#   term {k}: {term_formula(term, k)}  (kg/s into the chamber)")
        names[f"term{k}_coefficient"] = f"closure_coefficient_{k}"
        for side in term.hinges():
            names[f"term{k}_threshold_{side}"] = f"closure_threshold_{k}_{side}"
    values = {mine: float(params[theirs]) for mine, theirs in names.items()}
    mapping = "\n".join(f"        {mine!r}: {theirs!r}," for mine, theirs in names.items())
    defaults = "\n".join(f"        {mine!r}: {v!r}," for mine, v in values.items())
    terms = closure.options()["terms"]
    return f'''"""{effect_name}: a mass flow into the chamber found by pneubayes discover.

Found as an open-form closure term (kg/s into the chamber):
{chr(10).join(lines)}
Edit the names, the descriptions and the bounds to say what it is; ``lower`` keeps
writing the closure's slots. Register it with one line in pneubayes.effects.CATALOGUE,
or use it directly: ``Model([{class_name}()])``.
"""

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.closure import Closure


class {class_name}(Effect):
    """A found mass flow into the chamber (edit this description)."""

    name = {effect_name!r}
    acts_on = Closure.acts_on
    #: The closure terms this effect is built from.
    TERMS = {terms!r}
    #: This effect's parameter -> the closure's.
    NAMES = {{
{mapping}
    }}

    def parameters(self):
        closure = {{p.name: p for p in Closure(terms=self.TERMS).parameters()}}
        return tuple(Parameter(mine, closure[theirs].unit, closure[theirs].lower,
                               closure[theirs].upper, closure[theirs].prior,
                               f"found: {{theirs}} (edit)", neutral=closure[theirs].neutral)
                     for mine, theirs in self.NAMES.items())

    def lower(self, values, rig):
        return Closure(terms=self.TERMS).lower(
            {{theirs: values[mine] for mine, theirs in self.NAMES.items()}}, rig)

    def bench_defaults(self):
        """The values discovery fitted."""
        return {{
{defaults}
        }}
'''


__all__ = ["effect_skeleton"]
