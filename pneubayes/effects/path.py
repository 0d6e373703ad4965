"""Points on the signal path where the model's components act.

command -> [stiction] -> [delay] -> spool [lag: first order, speed-limited or second]
-> [dead band] -> ports
(Gompertz, eq. 11, and a switching valve's area proportional to its opening)
-> port mass flows (eqs. 1-3, supply and attenuation) [-> acoustic line]
+ extra flows (leaks, eq. 9) -> chamber (eq. 5: volume, pressure, temperature) -> sensor
[lag, first or second order] [calibration: zero offset and gain] (the rig's declared
anti-alias filter, :mod:`pneubayes.simulation.measurement`).

Each slot is one number per parameter set that the compiled simulator reads. Components
(the thin-port base and every effect) *lower* their named parameters onto slots; the
contributions of several components to one slot add up, and every slot's neutral value
is 0, so a model without an effect is exactly the model with that effect at zero
strength. The simulator never asks which effects are present.
"""

from __future__ import annotations

SLOTS: tuple[tuple[str, str], ...] = (
    # name, meaning (unit)
    ("inlet_offset_m2", "inlet Gompertz offset (m^2)"),
    ("inlet_a_m2", "inlet Gompertz a (m^2)"),
    ("inlet_b", "inlet Gompertz b (-)"),
    ("inlet_c_per_V", "inlet Gompertz c (1/V)"),
    ("inlet_d_V", "inlet Gompertz d (V)"),
    ("exhaust_offset_m2", "exhaust Gompertz offset (m^2)"),
    ("exhaust_a_m2", "exhaust Gompertz a (m^2)"),
    ("exhaust_b", "exhaust Gompertz b (-)"),
    ("exhaust_c_per_V", "exhaust Gompertz c (1/V)"),
    ("exhaust_d_V", "exhaust Gompertz d (V)"),
    ("volume_m3", "chamber volume at position 0, tube included (m^3)"),
    ("command_delay_s", "transport delay of the command reaching the chamber (s)"),
    ("spool_time_constant_s", "first-order spool lag time constant, 0 = none (s)"),
    ("deadband_halfwidth_V", "dead band on the spool position before the area maps (V)"),
    ("supply_gain", "weight of the measured supply deviation: P_c = P_nom + g (P_meas - P_nom)"),
    ("flow_attenuation_Pa", "port flows reach the chamber scaled by exp(-value / p) (Pa)"),
    ("leak_orifice_area_m2", "orifice leak to atmosphere, eqs. 6-9 (m^2)"),
    ("leak_laminar_kg_per_s_Pa2", "laminar leak k (p^2 - P_atm^2) at position 0 (kg/(s Pa^2))"),
    ("leak_laminar_gradient_kg_per_s_Pa2_m",
     "change of the laminar leak's k per metre of piston position (kg/(s Pa^2 m))"),
    ("heat_rate_per_s", "wall heat exchange rate 1/tau (1/s)"),
    ("heat_coefficient_W_per_m2_K",
     "convective wall coefficient h on the chamber's wall area; > 0 scales orifice "
     "outflows by sqrt(T_w / T) (W/(m^2 K))"),
    ("line_length_m", "valve-chamber tube as a lumped acoustic line of this length; > 0 "
     "makes its cell pressures and flows states, its volume leaves the chamber's (m)"),
    ("line_diameter_m", "inner diameter of the acoustic line (m)"),
    ("line_segments", "cells of the acoustic line (count)"),
    ("line_viscosity_Pa_s", "dynamic viscosity of the air in the acoustic line (Pa s)"),
    ("compliance_m3_per_Pa", "chamber compliance C: the volume grows by C (p - P_atm) with "
     "its pressure (a bellows, a test lung; m^3/Pa)"),
    ("inlet_open_area_m2", "switching valve: inlet area A clip(u, 0, 1) added to the map's, "
     "u the spool (0 closed, 1 open; m^2)"),
    ("exhaust_open_area_m2", "switching valve: exhaust area A clip(1 - u, 0, 1) added to the "
     "map's (a 3/2 valve venting when closed; m^2)"),
    ("exhaust_own_command", "1: the exhaust port is a separate valve driven by its own "
     "command (the inputs' exhaust command, held between samples, undelayed): its area is "
     "the exhaust map of that command plus the exhaust open area times clip(command, 0, 1); "
     "0: the exhaust is a port of the one valve (-)"),
    ("tank_volume_m3", "a finite supply tank of this effective volume per chamber fed; > 0 "
     "makes the supply pressure a state that starts at the window's supply and falls as "
     "the inlet draws from it, dP/dt = -n Rs T m_in / V (m^3)"),
    ("lung_volume_m3", "a second, compliant compartment behind a laminar resistance (a "
     "test lung); > 0 makes its pressure a state: its volume at atmospheric pressure (m^3)"),
    ("lung_compliance_m3_per_Pa", "the second compartment's compliance: its volume grows "
     "by C_L (p_L - P_atm) (m^3/Pa)"),
    ("lung_conductance_kg_per_s_Pa2", "the resistance's laminar conductance k: mass flow "
     "k (p^2 - p_L^2) from the measured compartment into the second (kg/(s Pa^2))"),
)

#: Most points of a tabulated valve map (rig card valve kind ``table``).
TABLE_MAX_POINTS = 16

SLOTS += (
    ("table_points", "a tabulated valve map: the number of its points (0: none); its "
     "areas add to the maps above, linear between points, flat beyond the ends (count)"),
) + tuple((f"table_command_{k}", f"tabulated map: command of point {k} (the command's "
           "unit; increasing)") for k in range(TABLE_MAX_POINTS)) + tuple(
    (f"table_inlet_m2_{k}", f"tabulated map: inlet area at point {k} (m^2)")
    for k in range(TABLE_MAX_POINTS)) + tuple(
    (f"table_exhaust_m2_{k}", f"tabulated map: exhaust area at point {k} (m^2)")
    for k in range(TABLE_MAX_POINTS))

SLOTS += (
    ("volume_table_points", "a compliant chamber's tabulated V(p): the number of its points "
     "(0: none); the volume grows by dV(p), linear between points, the end segments "
     "extended (count)"),
) + tuple((f"volume_table_pressure_Pa_{k}", f"tabulated V(p): absolute pressure of point {k} "
           "(Pa; increasing)") for k in range(TABLE_MAX_POINTS)) + tuple(
    (f"volume_table_volume_m3_{k}", f"tabulated V(p): volume change at point {k} (m^3)")
    for k in range(TABLE_MAX_POINTS))

SLOTS += (
    ("sensor_time_constant_s", "a first-order lag of the pressure reading behind the "
     "chamber pressure (an undeclared causal anti-alias filter, a sensor on a stub), "
     "dr/dt = (p - r) / tau; > 0 makes the reading a state (s)"),
    ("sensor_natural_frequency_rad_per_s", "a second-order lag of the pressure reading, "
     "r'' = w^2 (p - r) - 2 z w r' (an analogue anti-alias filter): its natural frequency "
     "w; > 0 makes the reading and its rate states, and overrides the first-order lag "
     "(rad/s)"),
    ("sensor_damping", "the second-order reading lag's damping ratio z (-)"),
    ("inputs_advance_s", "the measured position and supply passed the reading's lag too "
     "(an undeclared filter on every channel of the DAQ): the chamber at time t sees them "
     "as measured at t + this advance, the lag's group delay; beyond the last sample they "
     "hold its value (s)"),
)

SLOTS += (
    ("spool_natural_frequency_rad_per_s", "second-order spool dynamics, s'' = w^2 (u - s) "
     "- 2 z w s' (a proportional valve's spool with its position loop): the natural "
     "frequency w; > 0 makes the spool's position and velocity states and overrides the "
     "first-order spool lag (rad/s)"),
    ("spool_damping", "the second-order spool's damping ratio z (-)"),
    ("deadband_rounding_V", "the dead band's corners rounded over ||s| - w| < r: the slope "
     "of the opening rises as a smoothstep from 0 to 1 across the corner (C2; gradual "
     "opening of real spool edges); 0 is the hard dead band (V)"),
)

SLOTS += (
    ("wave_length_m", "valve-chamber tube as a transmission line of this length (waves "
     "delayed by its transit time, friction lumped at its ends); > 0 makes its waves' "
     "history a state, its volume leaves the chamber's (m)"),
    ("wave_diameter_m", "inner diameter of the transmission-line tube (m)"),
    ("wave_viscosity_Pa_s", "dynamic viscosity of the air in the transmission-line tube "
     "(Pa s)"),
    ("wave_segments", "line elements of the transmission-line tube, its friction lumped "
     "at their junctions (count)"),
    ("wave_grid_s", "the transmission-line tube's grid: its junctions and ends update at "
     "most this far apart (an element's transit time if shorter), and a front is spread "
     "by about one step per element (s)"),
    ("wave_unsteady_friction", "the transmission-line tube's unsteady wall shear: this "
     "share of Zielke's frequency-dependent friction beside the quasi-steady one; 0 = "
     "none (-)"),
)

SLOTS += (
    ("reading_offset_Pa", "a miscalibrated pressure sensor's zero offset o: the reading is "
     "P_atm + g (p - P_atm) + o (its value at atmospheric pressure less P_atm; Pa)"),
    ("reading_gain_error", "the miscalibrated sensor's gain error: g - 1 in the reading "
     "P_atm + g (p - P_atm) + o (-)"),
    ("reading_curvature_Pa", "a curved sensor's reading: k in P_atm + g y + k (y / 1 bar)^2 "
     "+ o, y = p - P_atm (its reading's departure from its straight line at 1 bar "
     "gauge; Pa)"),
    ("reading_drift_Pa_per_s", "a drifting sensor zero: o grows by a t, t on the "
     "recording's clock (Pa/s)"),
    ("reading_warm_up_Pa", "a sensor zero that settles as the sensor warms: o grows by "
     "b (1 - exp(-t / tau)), t >= 0 on the recording's clock (Pa)"),
    ("reading_warm_up_time_constant_s", "the warming zero's time constant tau (read only "
     "where reading_warm_up_Pa is not 0; s)"),
)

#: Most terms of an open-form closure (:mod:`pneubayes.effects.closure`): the compiled
#: simulator's slots, and what :func:`pneubayes.effects.closure_terms.parse_terms` accepts.
CLOSURE_MAX_TERMS = 4

SLOTS += (
    ("closure_terms", "an open-form closure: the number of its terms (0: none); term k "
     "adds the mass flow c_k F_a F_b into the chamber, the features F of "
     ":mod:`pneubayes.effects.closure_features` (count)"),
) + tuple((f"closure_feature_a_{k}", f"closure term {k}: code of its first feature "
           "(a float holding the integer code; -)") for k in range(CLOSURE_MAX_TERMS)) + tuple(
    (f"closure_feature_b_{k}", f"closure term {k}: code of its second feature (0, the "
     "feature 'one', for a single feature; -)") for k in range(CLOSURE_MAX_TERMS)) + tuple(
    (f"closure_threshold_a_{k}", f"closure term {k}: the first feature's hinge threshold "
     "(the feature's unit; read only for a hinge feature)")
    for k in range(CLOSURE_MAX_TERMS)) + tuple(
    (f"closure_threshold_b_{k}", f"closure term {k}: the second feature's hinge threshold "
     "(the feature's unit; read only for a hinge feature)")
    for k in range(CLOSURE_MAX_TERMS)) + tuple(
    (f"closure_coefficient_{k}", f"closure term {k}: its coefficient c_k (kg/s per the "
     "features' units)") for k in range(CLOSURE_MAX_TERMS)) + tuple(
    (f"closure_relaxed_{s}_{k}", f"closure term {k}: the simulator's working value of its "
     f"{'first' if s == 'a' else 'second'} feature's relaxed pressure p_bar (feature "
     "pressure_relaxation; Pa), written by the compiled simulator on its own copy of the "
     "slots as it steps; lowered as 0")
    for s in "ab" for k in range(CLOSURE_MAX_TERMS))

SLOTS += (
    ("spool_rate_limit_V_per_s", "the first-order spool's speed limit r: ds/dt = "
     "clip((u - s) / tau, -r, r) (a proportional valve whose spool drive saturates: a large "
     "step is a ramp at r, then the lag); 0 = none (command unit/s)"),
)

SLOTS += (
    ("stiction_band_V", "a sticking valve: the command the valve sees holds until the "
     "command moves this far from it, then jumps to within (1 - f) times it of the command "
     "(simulation.stiction); 0 = a free valve (command unit)"),
    ("stiction_slip_fraction", "the sticking valve's slip f in [0, 1]: 0 stops a band short "
     "of the command (play, backlash), 1 jumps onto it (-)"),
)

SLOTS += (
    ("spool_fall_time_constant_s", "the first-order spool's time constant while the "
     "command is below it (falling; a spring returning a single-solenoid spool); 0 = the "
     "rise's, spool_time_constant_s (s)"),
)

SLOTS += (
    ("sensor_pressure_exponent", "the first-order reading lag's pressure dependence n: its "
     "time constant is sensor_time_constant_s (2 P_atm / (p + r))^n (a sensor read through "
     "a laminar passage, n = 1); 0 = a constant time constant (-)"),
)

#: Most plays of an open-form volume play (:mod:`pneubayes.effects.volume_play`).
VOLUME_PLAY_MAX_TERMS = 2

SLOTS += tuple(
    (f"volume_play_compliance_m3_per_Pa_{k}", f"volume play {k}: a wall whose give is "
     "held by friction adds C_k (w_k - P_atm) to the chamber's volume, w_k the play of the "
     "chamber pressure (it moves only where |p - w_k| reaches the half-width, with p); 0 = "
     "none (m^3/Pa)") for k in range(VOLUME_PLAY_MAX_TERMS)) + tuple(
    (f"volume_play_half_width_Pa_{k}", f"volume play {k}: its half-width r_k, the pressure "
     "change that moves the held wall (Pa)") for k in range(VOLUME_PLAY_MAX_TERMS)) + tuple(
    (f"volume_play_held_compliance_m3_per_Pa_{k}", f"volume play {k}: the wall's give "
     "while friction holds it (a stop: an elastic give that the held wall takes back once "
     "it slides), adding C_h,k (p - w_k) to the chamber's volume; 0 = none (m^3/Pa)")
    for k in range(VOLUME_PLAY_MAX_TERMS)) + tuple(
    (f"volume_play_anchor_Pa_{k}", f"volume play {k}: the simulator's working anchor, the "
     "play state w_k where it last laid the volume table (Pa), written by the compiled "
     "simulator on its own copy of the slots as it steps "
     "(:mod:`pneubayes.simulation.volume_play`); lowered as 0")
    for k in range(VOLUME_PLAY_MAX_TERMS))
#: The volume plays' compliance slots (sliding and held): any of them not 0 is a play.
VOLUME_PLAY_COMPLIANCE_SLOTS = tuple(f"volume_play_{what}compliance_m3_per_Pa_{k}"
                                     for what in ("", "held_")
                                     for k in range(VOLUME_PLAY_MAX_TERMS))

SLOTS += (
    ("command_clock_period_s", "the valve's driver takes the command on a clock of this "
     "period (its ticks at (phase + k) periods on the recording's clock); 0 = the valve "
     "follows the command at once (s)"),
    ("command_clock_phase", "the driver clock's first tick, as a share of its period after "
     "the recording's time 0 (-)"),
    ("command_clock_latency_s", "the driver's latency: a command taken at a tick reaches "
     "the valve this much later (s)"),
    ("command_clock_pwm", "1: the driver modulates the pulses' width (an on/off valve open "
     "fully for |u| / full of each period, at the command's sign); 0: it holds the taken "
     "command over the period"),
    ("command_clock_full_command_V", "the modulating driver's full scale: a command of this "
     "magnitude keeps the valve open over the whole period (V)"),
    ("command_clock_pulse_trim_s", "the modulating driver's pulses reach the valve this much "
     "shorter (a solenoid that opens later than it closes; negative: longer) (s)"),
    ("command_clock_pulse_alignment", "where in its period the modulating driver's pulse "
     "lies: it starts this share of the period's shut time (1 - duty) after the tick (0: at the "
     "tick, 0.5: centred) (-)"),
)

SLOTS += (
    ("loaded_wall_compliance_m3_per_Pa", "a wall that carries a load (a mass on a spring "
     "driven by the gauge pressure) adds C x to the chamber's volume, x'' + 2 z w x' + w^2 x "
     "= w^2 (p - P_atm): C its static give per pascal; 0 = none (m^3/Pa)"),
    ("loaded_wall_frequency_Hz", "the loaded wall's natural frequency w / (2 pi) (Hz)"),
    ("loaded_wall_damping_ratio", "the loaded wall's damping ratio z (-)"),
)

SLOTS += (
    ("restriction_fill_inverse_area_per_m2", "a restriction in series at the chamber's port "
     "(a fitting, a flow-control needle, a check valve): 1 / its area for flow into the "
     "chamber; the valve's ports see the pressure between the two; 0 = none (1/m^2)"),
    ("restriction_vent_inverse_area_per_m2", "the port's restriction: 1 / its area for flow "
     "out of the chamber; 0 = none (1/m^2)"),
    ("restriction_crack_Pa", "the port restriction's check valve: its wider direction passes "
     "only the narrower one's area below this drop, opening to its own over 1-2 x it; "
     "0 = none (Pa)"),
    ("heat_coupling", "the share of the chamber temperature's departure from the wall's "
     "that the pressure equation feels (the outflow's enthalpy, the wall's heat, the "
     "outflows' sqrt(T_w / T)): 0 = eq. 5, 1 = the energy equation; > 0 makes the "
     "temperature a state (-)"),
)

SLOTS += (
    ("supply_restriction_inverse_area_per_m2", "a restriction in series upstream of the "
     "valve's inlet (a supply hose or fitting, a regulator's or a blower's flow limit): "
     "1 / its area; the inlet sees the pressure between the two; 0 = none (1/m^2)"),
    ("heat_jet_coefficient_W_per_m2_K", "forced convection by the fill's jet: the wall "
     "heat-transfer coefficient grows by this at an inflow of 1 g/s, linearly in the "
     "inflow (heat_transfer form 'forced'; 0 = none) (W/(m^2 K))"),
)

SLOTS += (
    ("inlet_critical_ratio", "the inlet's own critical pressure ratio p_d / p_u (ISO "
     "6358's b): choked below it, eq. 3's subsonic curve laid over the rest; 0 = eq. 3's "
     "1 / theta (-)"),
    ("exhaust_critical_ratio", "the exhaust's critical pressure ratio, as the inlet's; "
     "0 = eq. 3's (-)"),
    ("port_subsonic_index", "beside the ports' critical ratios, ISO 6358's subsonic index "
     "m: the subsonic flow's share of the choked one raised to 2 m; 0 = 1/2, eq. 3's "
     "shape (-)"),
)

SLOTS += (
    ("heat_wall_offset_K", "beside heat exchange, the wall's temperature above the "
     "supply's (a warm body, a cold room); the pressure feels the coupling's share of it, "
     "as of the chamber's departure (K)"),
)

#: The inflow (kg/s) at which heat's forced form adds ``heat_jet_coefficient_W_per_m2_K``
#: to the wall's coefficient (the slot's unit: W/(m^2 K) per this inflow).
JET_FLOW_REF_KG_PER_S = 1e-3
#: Most cells of an acoustic line the compiled simulator holds.
LINE_MAX_SEGMENTS = 8
#: Most line elements of a transmission-line tube.
WAVE_MAX_SEGMENTS = 16
#: Points per wave over one element's transit time that a transmission-line tube's
#: state is resampled on when it is carried from one window to the next.
WAVE_CARRY_POINTS = 32

SLOT_NAMES: tuple[str, ...] = tuple(name for name, _ in SLOTS)
SLOT_INDEX: dict[str, int] = {name: i for i, name in enumerate(SLOT_NAMES)}
N_SLOTS = len(SLOTS)
