"""The full-vehicle source model: parameters, symbolic CasADi model, compiled simulator, manoeuvres."""
