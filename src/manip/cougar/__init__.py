"""manip.cougar (in progress)."""
