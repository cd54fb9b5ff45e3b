"""Which non-fatal errors are "trivial" (the 1985 guide's notify-trivial-errors-mixin and
``:trivial-error?``).

With ``notify_trivial_errors`` on, the handler type ``notify-trivial-errors`` goes first in the
manipulator's handler-type list.  Its non-fatal-error handler asks the policy about each error; when the
policy says trivial *and* the request's result is ``None`` anyway (a "done" reply, see
``Request.value_optional``), the request is answered with ``None`` and the error is only notified
(error listeners and the log).  Otherwise it passes the response on, and the generic handler fails the
request as usual.  A request that should return data always fails: there is no value to return.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from manip.reference_client.errors import NonFatalError


@dataclass(frozen=True)
class TrivialErrors:
    """Trivial when the error code or the severity is listed.

    The default lists ``UIM`` (operation not implemented on this arm): the 1985 guide notes that the Puma
    did not implement Set configuration, and a program written for several arms should be able to ask
    for it and carry on.
    """

    codes: frozenset[str] = field(default_factory=lambda: frozenset({"UIM"}))
    severities: frozenset[str] = frozenset()

    def __call__(self, error: NonFatalError) -> bool:
        return error.code in self.codes or error.severity in self.severities
