"""What a run shows: the console (``console``), packets as text (``packet_text``), the JSON and JUnit
reports (``report``) and clause coverage (``coverage``)."""
