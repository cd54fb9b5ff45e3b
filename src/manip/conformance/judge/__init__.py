"""Judging packets against the spec, with no I/O: the one violation record (``violation``), the wire
packet record (``packets``), the pure checkers of what a server sent (``checks``) and of what a client
sent (``client_checks``), and the client-side protocol model of the stateful cases (``model``).
Live cases, replay, ``verify`` and the capture view all judge through here."""
