"""One decoding per process of a datagram that several team members hear (seed 003 Sec. III-A).

Every member hears every broadcast ("periodic broadcasting of group-level state information from each
vehicle"), so in a companion host (:mod:`companion.host`: K companions of a simulated fleet in one process)
each datagram arrives K times, once at each member's socket, and each member decoded it: parsing the rows
and the digest and checking the signature of ~N packets a second, K times over. That work was O(N^2) per
host and, at 25 vehicles in two hosts, a third of the hosts' CPU (py-spy on an idle ``taskflight up``).

:func:`decode_shared` decodes a given datagram (the same bytes under the same key) once and hands every
member the same :class:`~companion.team.wire.Packet`: it is immutable (frozen dataclasses and tuples all
the way down), so sharing it shares no writable state. What each member does with a packet (the replay
guard, the merge into its own group state, its statistics) stays its own. A packet that fails to decode
raises each time (nothing is cached), so each member counts its own drops. A companion alone in its
process (a real vehicle) hears each datagram once and gains nothing but loses nothing either.
"""

from __future__ import annotations

import functools

from companion.team.wire import Packet, decode_packet

#: packets kept: the members of one host take a datagram within milliseconds of each other, and 50
#: vehicles broadcast ~100 distinct packets a second (plus the board's parts)
CACHED_PACKETS = 512


@functools.lru_cache(maxsize=CACHED_PACKETS)
def _decode(data: bytes, key: bytes | None) -> Packet:
    return decode_packet(data, key=key)


def decode_shared(data: bytes | bytearray | memoryview, key: bytes | None) -> Packet:
    """:func:`~companion.team.wire.decode_packet` of ``data``, decoded once per process for equal bytes and
    key (the same exceptions, raised every time)."""
    if isinstance(data, bytearray | memoryview):
        data = bytes(data)
    if not isinstance(data, bytes):
        return decode_packet(data, key=key)  # its WireError names the type
    return _decode(data, key)


def cache_info() -> functools._CacheInfo:
    """Hits and misses so far (a bench's and a test's view of the sharing)."""
    return _decode.cache_info()
