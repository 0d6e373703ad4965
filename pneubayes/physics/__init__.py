"""Pure, vectorised physics of the thin-port model (paper eqs. 1-11, Tables I, II, IV)."""
