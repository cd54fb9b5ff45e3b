"""manip.reference_client (in progress)."""
