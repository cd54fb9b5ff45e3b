"""A reference server with one defect the fuzz tests must find, switched on by the first argument:

    python tests/support/fuzz_fake_server.py crash|hang|traceback|drop [manip-server options...]

On a request with opcode 0277 (an unassigned opcode, so the fuzzer's unknown-opcode class sends it
now and then) it exits (crash), blocks its event loop (hang), logs a traceback and then answers as
usual (traceback), or answers nothing at all (drop).  Everything else is the reference server, so
nothing else is a finding.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from typing import Any

from manip.reference_server import cli, session
from manip.reference_server.session import ServerSession, State

TRIGGER = 0o277


def main() -> None:
    mode = sys.argv.pop(1)
    serve = ServerSession._serve

    def defective(self: ServerSession, event: Any) -> State | None:
        if event.opcode == TRIGGER:
            if mode == "crash":
                os._exit(3)
            if mode == "hang":
                time.sleep(3600)
            if mode == "drop":
                return None
            try:
                raise RuntimeError("fake defect: opcode 0277")
            except RuntimeError:
                logging.getLogger("manip.reference_server").exception("handler for opcode 0277 failed")
        return serve(self, event)

    # The session runs its transition table, which holds the method itself.
    table = session.TRANSITIONS
    assert isinstance(table, dict)
    for key, (action, state) in list(table.items()):
        if action is serve:
            table[key] = (defective, state)
    cli.main()


if __name__ == "__main__":
    main()
