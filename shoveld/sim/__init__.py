"""The simulated shovel: plant, scenarios, sensor noise and hidden effects."""
