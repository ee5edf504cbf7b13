"""Contact laws: one module per law, small numba evaluators called from the engine's loops."""
