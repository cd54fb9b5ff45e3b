"""How a run works: declaring cases (``case``), what a case works with (``context``), running them
(``runner``, ``selection``, ``embedded``, ``bridge``, ``stability``), their outcomes (``results``) and the
suite invariants a case's clauses are kept apart from (``invariants``)."""
