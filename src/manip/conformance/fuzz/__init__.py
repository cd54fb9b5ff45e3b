"""``manip-conform fuzz``: a seeded, bounded fuzz campaign driven by the spec's tables."""
