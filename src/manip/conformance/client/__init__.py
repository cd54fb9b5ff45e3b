"""``manip-conform client``: judging a client implementation live through the harness contract
(``docs/client-harness.md``).

:mod:`.contract` (the messages), :mod:`.process` (the harness as a child process), :mod:`.server` (the
judging server, a scripted Puma per case), :mod:`.wire` (what the client sent, judged),
:mod:`.runner` (cases, outcomes, the report), :mod:`.cli` (the command).  The cases are in
:mod:`manip.conformance.cases.client`.
"""
