"""The reference Puma server: a simulated arm that implements the whole Chaos manipulator protocol."""
