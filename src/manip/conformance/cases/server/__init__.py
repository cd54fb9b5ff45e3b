"""Cases of the ``server.*`` ids: a Chaos manipulator server judged over Chaos, one module per area."""
