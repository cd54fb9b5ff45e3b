"""``manip-conform diff A B``: two servers driven by the same request streams, every difference in
their answers paired, classified (a violation, a difference both allowed, or a gap in the spec) and
reported."""
