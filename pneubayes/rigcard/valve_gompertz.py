"""Valve kind ``gompertz``: the paper's proportional valve, two ports mapped by eq. 11.

Card keys: the ten names of the thin-port core (``inlet_offset_m2`` ... ``exhaust_d_V``),
each known or a prior; a key left out keeps the core's default prior. The command is
in the unit the card's ``command`` declares (c in 1/unit, d in the unit).
"""

from __future__ import annotations

from pneubayes.effects.thin_port import ThinPort
from pneubayes.errors import RigCardError
from pneubayes.rigcard.component import RigComponent, register
from pneubayes.rigcard.values import Unknown, quantity

_CORE = {p.name: p for p in ThinPort().parameters() if p.name != "dead_volume_m3"}


@register
class GompertzValve(RigComponent):
    role, kind = "valve", "gompertz"
    quantities = tuple((n, p.unit, p.description, "") for n, p in _CORE.items())
    slots_written = tuple(_CORE)

    @classmethod
    def from_table(cls, table, where):
        stray = sorted(set(table) - set(_CORE) - {"kind"})
        if stray:
            raise RigCardError(f"{where}: unknown key(s) {stray} for kind 'gompertz'; its "
                               f"keys are {sorted(_CORE)}")
        values = {}
        given = tuple(n for n in _CORE if n in table)
        for n, p in _CORE.items():
            v = quantity(table, n, where, required=False,
                         default=Unknown(p.prior, p.lower, p.upper))
            if not isinstance(v, Unknown) and not p.lower <= v <= p.upper:
                # a known value outside the core's bounds is the user's to state; the
                # signs of c keep the maps monotone in the right direction
                if n in ("inlet_c_per_V", "exhaust_c_per_V") and (v > 0) != (p.lower > 0):
                    raise RigCardError(f"{where} key {n!r}: must be "
                                       f"{'> 0' if p.lower > 0 else '< 0'}, got {v!r}")
            values[n] = v
        out = cls(values)
        out.given = given
        return out

    #: the keys the card gave (the others take the core's default priors)
    given: tuple = ()

    def without_exhaust(self, where):
        given = [n for n in self.given if n.startswith("exhaust_") and self.values[n] != 0.0]
        if given:
            raise RigCardError(f"{where}: the rig's exhaust is a separate valve (its "
                               f"'exhaust' table); leave this valve's exhaust keys {given} "
                               "out (or 0)")
        out = type(self)({n: (0.0 if n.startswith("exhaust_") else v)
                          for n, v in self.values.items()})
        out.given = self.given
        return out

    def lower_all(self, values, rig):
        return dict(values)
