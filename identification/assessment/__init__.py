"""How good and how sure a model is: fit metrics, hold-out validation, residual tests, parameter uncertainty, model-order assessment."""
