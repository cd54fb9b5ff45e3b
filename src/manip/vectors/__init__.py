"""The golden test vectors, as JSON files shipped with the package (hex bytes and their decoded form, or
the clause a malformed input breaks): PDP-11 floats, Chaos packets in every framing, manip requests and
replies, error strings, Lisp text, Cougar words.  Read them with ``importlib.resources``."""
