"""Identified models and their structures: the model protocol, state-space and modal models, spline-nonlinear and speed-scheduled families."""
