"""manip: specification and conformance toolkit for the MIT Puma/Cougar manipulator protocols.

Layers, bottom up (imports point down only):

* ``manip.spec``    the protocol as data: clauses, opcode tables, layouts, errata.
* ``manip.codecs``  exact encoders/decoders driven by the spec (construct).
* ``manip.ncp``     sans-I/O cores (Chaos NCP, ...).
* ``manip.links``   asyncio drivers that move bytes.
* applications      ``manip.decode`` (and later server, client, conformance, capture).
"""

__version__ = "0.1.0"
