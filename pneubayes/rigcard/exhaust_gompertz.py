"""Exhaust kind ``gompertz``: a separate exhaust valve on its own command column.

Its area is eq. 11 of its own command ``v`` (unit and range declared by the table's
``command``): ``offset + a exp(-b exp(-c (v + d)))`` with c > 0 (the exhaust opens as
its command grows). The simulator holds ``v`` between samples and does not delay it
(the inlet command's delay and lag effects act on the inlet valve only).

Card keys: ``command`` (``{unit, range}``, required), ``column`` (the recording's column
holding the command; default ``exhaust_command``) and the map's ``offset_m2``,
``a_m2``, ``b``, ``c_per_V``, ``d_V`` (c and d in the exhaust command's unit), each known
or a prior; a key left out takes the default prior below. Fitted, they are the
parameters ``exhaust_valve_a_m2``, ... . The valve table then has no exhaust of its own.
"""

from __future__ import annotations

from pneubayes.rigcard.component import register
from pneubayes.rigcard.exhaust_common import SeparateExhaust
from pneubayes.rigcard.values import Unknown

#: key -> (unit, description, sign, default prior)
_MAP = {
    "offset_m2": ("m^2", "area at a closed command", "nonnegative",
                  Unknown("uniform", 0.0, 1e-5)),
    "a_m2": ("m^2", "Gompertz amplitude (full opening less the offset)", "positive",
             Unknown("log-uniform", 1e-8, 1e-3)),
    "b": ("-", "Gompertz displacement", "positive", Unknown("log-uniform", 0.05, 50.0)),
    "c_per_V": ("1/unit", "Gompertz growth rate per unit of the exhaust command",
                "positive", Unknown("uniform", 0.5, 40.0)),
    "d_V": ("unit", "Gompertz command shift", "", Unknown("uniform", -1.5, 1.0)),
}


@register
class GompertzExhaust(SeparateExhaust):
    role, kind = "exhaust", "gompertz"
    quantities = tuple((k, u, d, s) for k, (u, d, s, _) in _MAP.items())
    defaults = {k: v[3] for k, v in _MAP.items()}
    parameter_names_by_key = {k: f"exhaust_valve_{k}" for k in _MAP}
    slots_written = ("exhaust_offset_m2", "exhaust_a_m2", "exhaust_b", "exhaust_c_per_V",
                     "exhaust_d_V", "exhaust_own_command")

    def lower_all(self, values, rig):
        out = {f"exhaust_{k}": values[k] for k in _MAP}
        out["exhaust_own_command"] = 1.0
        return out
