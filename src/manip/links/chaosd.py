"""usim's chaosd unix-socket link: a stream to the local chaosd daemon, which routes.

The daemon is the only neighbour, so every packet goes to it with its final destination in the trailer;
checksums are written but not verified on receipt, as usim neither checks nor computes them the way
CHUDP does (erratum ``chaosd-checksum``).

:func:`serve_chaosd` is the daemon's end of the same socket, for a program that stands in for the
daemon towards hosts that dial it (the client judge plays a Puma behind it): each accepted stream is a
link whose peer is the host that dialled, learnt from the first frame's trailer.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from manip.codecs.framing import ChaosdFrameDecoder, encode_chaosd
from manip.codecs.packet import Packet
from manip.ncp.defects import ChaosDefects

from .errors import LinkError
from .guard import LinkGuard, LinkLimits
from .listener import StreamListener, bind_unix
from .stream import StreamLink, dial, stream_max_body


class ChaosdLink(StreamLink):
    """One unix-socket connection to a chaosd daemon."""

    kind = "chaosd"
    learns_peer = False  # the daemon's trailers name the daemon, not the far end

    def __init__(self, *, my_addr: int, name: str = "", defects: ChaosDefects | None = None) -> None:
        decoder = ChaosdFrameDecoder(max_body=stream_max_body(defects))
        super().__init__(encode_chaosd, decoder, my_addr=my_addr, name=name, defects=defects)

    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        """The daemon routes, so the trailer names the packet's own destination, not a next hop."""
        return super().send(packet, packet.dest_host)


async def connect_chaosd(
    path: str, *, my_addr: int, timeout: float | None = 10.0, defects: ChaosDefects | None = None
) -> ChaosdLink:
    """Connect to the chaosd daemon's socket at ``path`` (sending with ``defects``, when given); raise
    :class:`LinkError` if that fails."""
    link = ChaosdLink(my_addr=my_addr, name=f"chaosd:{path}", defects=defects)
    loop = asyncio.get_running_loop()
    return await dial(
        link, lambda: loop.create_unix_connection(lambda: link, path), f"chaosd socket {path}", timeout
    )


class ChaosdHostLink(StreamLink):
    """The daemon's end of one host's chaosd socket: packets for that host go down it."""

    kind = "chaosd"

    def __init__(self, *, my_addr: int, name: str = "chaosd") -> None:
        super().__init__(encode_chaosd, ChaosdFrameDecoder(), my_addr=my_addr, name=name)


async def serve_chaosd(
    path: str, *, my_addr: int, on_link: Callable[[ChaosdHostLink], None], guard: LinkGuard | None = None
) -> StreamListener:
    """Listen as a chaosd daemon on a socket file at ``path`` (which must not exist yet); ``on_link``
    gets each host's link before any packet arrives on it."""
    try:
        sock = bind_unix(path)
    except OSError as exc:
        raise LinkError(f"cannot listen as chaosd on {path}: {exc}") from exc

    def factory() -> ChaosdHostLink:
        link = ChaosdHostLink(my_addr=my_addr, name=f"chaosd:{path}")
        on_link(link)
        return link

    return StreamListener([sock], factory, guard or LinkGuard(LinkLimits.unlimited()))
