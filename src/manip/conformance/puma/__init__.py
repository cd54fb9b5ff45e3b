"""The Puma's side of the wrist link judged: ``manip-conform run --puma`` plays Cougar (``judge``) for a
Puma server under test and runs the ``puma.*`` cases (``target``)."""
