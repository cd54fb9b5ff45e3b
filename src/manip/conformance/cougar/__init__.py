"""The Cougar target of ``manip-conform run --cougar``: the word-level probe over the DRV-11J
(``probe``) and the target's liveness and case selection (``target``)."""
