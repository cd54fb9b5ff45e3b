"""Puma target cases (``manip-conform run --puma [HOST]``): the Puma's side of the wrist link, judged by
the suite playing Cougar, one module per topic.

Each case opens a fresh Chaos connection to the Puma, sets the judging Cougar's script for it
(``_support.begin``) and reads, from the judge's record, the Table 1 commands the Puma sent on the
DRV-11J.  What a case may rely on, so that it holds for any conforming Puma: the clauses of party
``puma`` and their errata (``wrist-sen``: the sensed angles reach Cougar while the arm moves;
``guard-stop``; ``compliant-schemes``: NTD is a joint-rate correction in deg/s integrated into the
commanded path by compliant scheme 0; ``calibrate-wrist``), the spec's time allowances, and the
PUMA 600's kinematics for the poses the Puma reports.  The judge answers as a conformant Cougar unless
the case scripts otherwise; no case depends on the simulator's numbers.
"""
