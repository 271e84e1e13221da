"""Optimisers: optax loops (one jitted step), constraints, progress bars and result objects."""
