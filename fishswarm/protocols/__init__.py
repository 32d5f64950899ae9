"""The wire: key expressions, message types and the msgpack codec. Pure, no I/O."""

from fishswarm.protocols.codec import MessageError, decode, encode
from fishswarm.protocols.keys import KeySpace

__all__ = ["KeySpace", "MessageError", "decode", "encode"]
