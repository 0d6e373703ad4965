"""Inference layer: the paper's least squares, trajectory refinement, emcee posteriors
and posterior-predictive pressure forecasts. Depends on physics, model, simulation and
io; nothing below it depends on this package."""
