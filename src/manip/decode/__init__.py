"""manip-decode: what a packet means, as a tree of labelled nodes (``describe``), rendered as text, an
annotated hex dump or JSON (``render``), and the ``manip-decode`` command (``cli``)."""
