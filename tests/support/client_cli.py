"""Shared by the ``manip-client`` command tests (``tests/reference_client/test_cli.py`` and
``test_record.py``): invoking the command in-process, and ``watch`` stopped by Ctrl-C in a subprocess
(servers: ``tests/support/servers.py``)."""

from __future__ import annotations

import signal
import subprocess
import sys

from click.testing import CliRunner, Result

from manip.reference_client.cli import main
from tests.support.scripted import segment_reporter
from tests.support.servers import in_thread, scripted_server


def invoke(*args: str) -> Result:
    return CliRunner().invoke(main, list(args), catch_exceptions=False)


def watch_until_ctrl_c(*options: str) -> None:
    """Run ``manip-client ADDRESS watch OPTIONS`` in a subprocess against a server reporting segments 7
    and 8; after both lines, Ctrl-C must end it cleanly (exit 0, on stderr only what it waited for)."""
    with in_thread(scripted_server(segment_reporter)) as address:
        # A process of its own, on purpose: the Ctrl-C is a real SIGINT to the client command.
        command = [sys.executable, "-m", "manip.reference_client.cli", address, "watch", *options]
        # A shell starts background jobs with SIGINT ignored, and a child inherits an ignored signal
        # (a handled one is reset by exec): handle it while starting the command, so Ctrl-C reaches it
        # however the tests were started.
        previous = signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        finally:
            signal.signal(signal.SIGINT, previous)
        with proc:
            try:
                assert proc.stdout is not None
                assert proc.stdout.readline() == "segment 7 completed\n"
                assert proc.stdout.readline() == "segment 8 completed\n"
                proc.send_signal(signal.SIGINT)
                assert proc.wait(10) == 0
                assert proc.stderr is not None
                said = proc.stderr.read().splitlines()  # only what it waited for
                assert len(said) == 1 and said[0].startswith("manip-client: waiting for "), said
            finally:
                if proc.poll() is None:
                    proc.kill()
