"""Exact encoders and decoders for the manip protocols, driven by :mod:`manip.spec`.

The most used names are here; the modules hold the rest:

* :mod:`~manip.codecs.pdp11float`  PDP-11 32-bit floats (scalar, numpy, construct)
* :mod:`~manip.codecs.chaos`       the Chaos packet (construct reference, struct fast path, checksum)
* :mod:`~manip.codecs.framing`     CHUDP, manip's TCP link, usim's chaosd socket, raw
* :mod:`~manip.codecs.messages`    request and response bodies per opcode
* :mod:`~manip.codecs.error_string`  ``where: severity code message`` with ``~``/``$`` arguments
* :mod:`~manip.codecs.lisp`, :mod:`~manip.codecs.lispm_text`  the describe-self alist and Lisp Machine text
* :mod:`~manip.codecs.cougar`      the Puma <-> Cougar word protocol and COMINT's streaming decoder
"""

from manip.codecs.chaos import IllegalPacketError, decode_raw, encode_raw
from manip.codecs.error_string import ErrorMessage, parse_error
from manip.codecs.errors import CodecError, DecodeError, EncodeError
from manip.codecs.framing import FRAMINGS, decode_chudp, decode_tcp, encode_chudp, encode_tcp
from manip.codecs.messages import (
    copy_request_data,
    decode_reply,
    decode_request,
    decode_server_packet,
    encode_reply,
    encode_request,
)
from manip.codecs.packet import MAX_DATA, Packet, Trailer
from manip.codecs.pdp11float import pack_f, pack_f_array, unpack_f, unpack_f_array

__all__ = [
    "FRAMINGS",
    "MAX_DATA",
    "CodecError",
    "DecodeError",
    "EncodeError",
    "ErrorMessage",
    "IllegalPacketError",
    "Packet",
    "Trailer",
    "copy_request_data",
    "decode_chudp",
    "decode_raw",
    "decode_reply",
    "decode_request",
    "decode_server_packet",
    "decode_tcp",
    "encode_chudp",
    "encode_raw",
    "encode_reply",
    "encode_request",
    "encode_tcp",
    "pack_f",
    "pack_f_array",
    "parse_error",
    "unpack_f",
    "unpack_f_array",
]
