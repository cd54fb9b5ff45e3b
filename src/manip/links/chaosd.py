"""usim's chaosd unix-socket link (client side): a stream to the local chaosd daemon, which routes.

The daemon is the only neighbour, so every packet goes to it with its final destination in the trailer;
checksums are written but not verified on receipt, as usim neither checks nor computes them the way
CHUDP does (erratum ``chaosd-checksum``).
"""

from __future__ import annotations

import asyncio

from manip.codecs.framing import ChaosdFrameDecoder, encode_chaosd
from manip.codecs.packet import Packet

from .stream import StreamLink, dial


class ChaosdLink(StreamLink):
    """One unix-socket connection to a chaosd daemon."""

    kind = "chaosd"
    learns_peer = False  # the daemon's trailers name the daemon, not the far end

    def __init__(self, *, my_addr: int, name: str = "") -> None:
        super().__init__(encode_chaosd, ChaosdFrameDecoder(), my_addr=my_addr, name=name)

    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        """The daemon routes, so the trailer names the packet's own destination, not a next hop."""
        return super().send(packet, packet.dest_host)


async def connect_chaosd(path: str, *, my_addr: int, timeout: float | None = 10.0) -> ChaosdLink:
    """Connect to the chaosd daemon's socket at ``path``; raise :class:`LinkError` if that fails."""
    link = ChaosdLink(my_addr=my_addr, name=f"chaosd:{path}")
    loop = asyncio.get_running_loop()
    return await dial(
        link, lambda: loop.create_unix_connection(lambda: link, path), f"chaosd socket {path}", timeout
    )
