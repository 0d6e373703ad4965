"""Gas constants of the thin-port model (paper Table IV and appendix).

The paper gives C, Z, M, R and kappa but not the temperature; NOTES.md suggests
293.15 K. Everything derived (alpha, beta, theta, Rs) is computed from the
definitions in the appendix, never typed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class GasConstants:
    """Physical constants of air and the orifice (Table IV).

    Parameters
    ----------
    discharge_coefficient : float
        C, dimensionless (0.72).
    compressibility : float
        Z, dimensionless (0.99 for air).
    molar_mass_kg_per_mol : float
        M (0.029 kg/mol for air).
    gas_constant_J_per_mol_K : float
        Universal gas constant R (the paper uses 8.31).
    heat_capacity_ratio : float
        kappa (1.4 for air); also the process index n of eq. 5.
    temperature_K : float
        Upstream gas temperature T.
    """

    discharge_coefficient: float = 0.72
    compressibility: float = 0.99
    molar_mass_kg_per_mol: float = 0.029
    gas_constant_J_per_mol_K: float = 8.31
    heat_capacity_ratio: float = 1.4
    temperature_K: float = 293.15

    def __post_init__(self):
        for name in ("discharge_coefficient", "compressibility", "molar_mass_kg_per_mol",
                     "gas_constant_J_per_mol_K", "temperature_K"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"GasConstants.{name} must be finite and > 0, got {value!r}")
        if not (self.heat_capacity_ratio > 1.0 and math.isfinite(self.heat_capacity_ratio)):
            raise ValueError(
                f"GasConstants.heat_capacity_ratio must be > 1, got {self.heat_capacity_ratio!r}")

    @property
    def specific_gas_constant_J_per_kg_K(self) -> float:
        """Rs = R / M, J/(kg K)."""
        return self.gas_constant_J_per_mol_K / self.molar_mass_kg_per_mol

    @property
    def alpha_s_per_m(self) -> float:
        """Subsonic coefficient, alpha = C sqrt(2M/(ZRT) k/(k-1)), s/m (appendix)."""
        k = self.heat_capacity_ratio
        return self.discharge_coefficient * math.sqrt(
            2.0 * self.molar_mass_kg_per_mol
            / (self.compressibility * self.gas_constant_J_per_mol_K * self.temperature_K)
            * k / (k - 1.0))

    @property
    def beta_s_per_m(self) -> float:
        """Choked coefficient, beta = C sqrt(kM/(ZRT) (2/(k+1))^((k+1)/(k-1))), s/m."""
        k = self.heat_capacity_ratio
        return self.discharge_coefficient * math.sqrt(
            k * self.molar_mass_kg_per_mol
            / (self.compressibility * self.gas_constant_J_per_mol_K * self.temperature_K)
            * (2.0 / (k + 1.0)) ** ((k + 1.0) / (k - 1.0)))

    @property
    def theta(self) -> float:
        """Critical pressure ratio p_u/p_d = ((k+1)/2)^(k/(k-1)), about 1.893 (eq. 3)."""
        k = self.heat_capacity_ratio
        return ((k + 1.0) / 2.0) ** (k / (k - 1.0))

    @property
    def speed_of_sound_m_per_s(self) -> float:
        """c = sqrt(k Rs T), m/s, used by the tube-delay effect."""
        return math.sqrt(self.heat_capacity_ratio * self.specific_gas_constant_J_per_kg_K
                         * self.temperature_K)
