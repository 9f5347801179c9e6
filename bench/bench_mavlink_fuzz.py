"""Bench (c): fuzz the MAVLink endpoint with random and mutated datagrams over loopback UDP.

Sends ``--count`` datagrams (default 10^6) to a real endpoint of a real vehicle (lockstep): random
bytes, valid frames with bits flipped / bytes inserted or removed / truncated / header fields
corrupted (each checked to be invalid with pymavlink's own parser, so a 1-in-65536 CRC collision
cannot sneak a real command in), plus valid frames that must be refused (another target system,
NaN or infinite fields). Afterwards: no exception escaped, the vehicle's state (armed, mode, home,
every parameter) is unchanged, and the endpoint still answers a command. Prints a table of the
counters. ``run_fuzz`` is also used by ``tests/test_mavlink_fuzz.py`` with a small count.
"""

from __future__ import annotations

import argparse
import logging
import math
import random
import socket
import sys
import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from taskflight_common.ports import free_ports

log = logging.getLogger("bench_mavlink_fuzz")


def _corpus(mav: Any, sysid: int) -> list[bytes]:
    """Valid frames of the kinds a ground station sends (targeted at ``sysid``)."""
    m = mav
    msgs = [
        m.heartbeat_encode(6, 8, 0, 0, 0),
        m.command_long_encode(sysid, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
        m.command_long_encode(sysid, 1, 176, 0, 1, 4, 0, 0, 0, 0, 0),
        m.command_long_encode(sysid, 1, 22, 0, 0, 0, 0, 0, 0, 0, 10),
        m.command_int_encode(sysid, 1, 6, 192, 0, 0, -1, 1, 0, 0, -353632610, 1491652300, 20),
        m.set_mode_encode(sysid, 1, 4),
        m.param_set_encode(sysid, 1, b"WPNAV_SPEED", 900.0, 9),
        m.param_request_read_encode(sysid, 1, b"RTL_ALT", -1),
        m.set_position_target_local_ned_encode(0, sysid, 1, 1, 0b110111111000, 10, 0, -10, 0, 0, 0, 0, 0, 0,
                                               0,
                                               0),
        m.set_position_target_global_int_encode(0, sysid, 1, 6, 0b110111000111, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0,
                                                0),
        m.mission_count_encode(sysid, 1, 3, 0),
        m.request_data_stream_encode(sysid, 1, 0, 10, 1),
    ]
    out = []
    for msg in msgs:
        out.append(msg.pack(mav))
        mav.seq = (mav.seq + 1) & 0xFF
    return out


def _refused(mav: Any, sysid: int) -> list[bytes]:
    """Valid frames that must change nothing: other target, NaN/inf fields."""
    m = mav
    msgs = [
        m.command_long_encode(sysid + 1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),  # another system
        m.command_long_encode(sysid, 1, 400, 0, math.nan, 0, 0, 0, 0, 0, 0),  # NaN arm flag
        m.command_long_encode(sysid, 1, 176, 0, math.inf, 4, 0, 0, 0, 0, 0),
        m.command_long_encode(sysid, 1, 179, 0, 0, 0, 0, 0, math.nan, math.nan, math.nan),  # set home NaN
        m.param_set_encode(sysid, 1, b"WPNAV_SPEED", math.nan, 9),
        m.param_set_encode(sysid, 1, b"WPNAV_SPEED", math.inf, 9),
        m.set_mode_encode(sysid + 3, 1, 4),
        m.param_set_encode(sysid + 1, 1, b"WPNAV_SPEED", 300.0, 9),
    ]
    out = []
    for msg in msgs:
        out.append(msg.pack(mav))
        mav.seq = (mav.seq + 1) & 0xFF
    return out


def _mutate(rng: random.Random, frame: bytes) -> bytes:
    b = bytearray(frame)
    kind = rng.randrange(7)
    if kind == 0:  # bit flips
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
    elif kind == 1:  # truncation
        b = b[:rng.randrange(1, len(b))]
    elif kind == 2:  # insert bytes
        i = rng.randrange(len(b))
        b[i:i] = rng.randbytes(rng.randint(1, 8))
    elif kind == 3:  # delete bytes
        i = rng.randrange(len(b))
        del b[i:i + rng.randint(1, 4)]
    elif kind == 4:  # corrupt header fields (length, flags, msgid)
        i = rng.choice((1, 2, 3, 7, 8, 9))
        if i < len(b):
            b[i] = rng.randrange(256)
    elif kind == 5:  # two frames glued, the first damaged
        b = b[:-1] + bytes([b[-1] ^ 0x55]) + frame
    else:  # garbage prefix and suffix
        b = rng.randbytes(rng.randint(1, 16)) + b + rng.randbytes(rng.randint(0, 16))
    return bytes(b)


def _is_valid(data: bytes, checker: Any) -> bool:
    """Whether a CRC-valid MAVLink frame starts at *any* offset of ``data`` (pymavlink decides).

    Any offset, because the endpoint resynchronises one byte after a false start, so it finds a
    genuine frame hidden behind garbage whose fake header claimed a long length.
    """
    for i, byte in enumerate(data):
        if byte not in (0xFD, 0xFE):
            continue
        checker.buf = bytearray()
        checker.buf_index = 0
        checker.expected_length = 8
        checker.have_prefix_error = False
        try:
            m = checker.parse_char(data[i:])
        except Exception:
            continue
        if m is not None and m.get_type() != "BAD_DATA" and not m.get_type().startswith("UNKNOWN"):
            return True
    return False


def _snapshot(sitl: Any) -> tuple[Any, ...]:
    v = sitl.vehicle
    return (v.nav.armed, sitl.modes.mode, tuple(v.home), tuple((d.name, d.value) for d in v.params),
            v.nav.landed_state)


def run_fuzz(count: int, seed: int = 1, state_dir: str | None = None) -> dict[str, Any]:
    """Fuzz ``count`` datagrams; returns the counters and the verdicts (raises on a broken invariant)."""
    import tempfile

    from autopilot_model.sitl import Sitl

    rng = random.Random(seed)
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    tmp = state_dir or tempfile.mkdtemp(prefix="tf_fuzz_")
    sitl = Sitl(urls=[f"udpin:127.0.0.1:{port}"], state_dir=tmp, persist=False)
    ep = sitl.endpoint
    v = sitl.vehicle
    v.run_until(lambda: v.estimator.healthy, 60)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    sock.setblocking(False)
    addr = ("127.0.0.1", port)
    mav = mavlink2.MAVLink(None, 255, 190)
    checker = mavlink2.MAVLink(None, 0, 0)
    checker.robust_parsing = True
    corpus = _corpus(mav, ep.sysid)
    refused = _refused(mav, ep.sysid)
    before = _snapshot(sitl)
    sent = skipped = 0
    t0 = time.perf_counter()
    batch = 200
    while sent < count:
        for _ in range(min(batch, count - sent)):
            r = rng.random()
            if r < 0.15:
                data = rng.randbytes(rng.randint(1, 300))
                if _is_valid(data, checker):
                    skipped += 1
                    continue
            elif r < 0.17:
                data = rng.choice(refused)
            else:
                data = _mutate(rng, rng.choice(corpus))
                if not data or _is_valid(data, checker):
                    skipped += 1
                    continue
            sock.sendto(data, addr)
            sent += 1
        # let the endpoint drain everything, then let the loop run one iteration
        while ep._epoll(0):
            ep.poll()
        v.step(1)
        try:
            while True:
                sock.recv(4096)
        except BlockingIOError:
            pass
    wall = time.perf_counter() - t0
    after = _snapshot(sitl)
    # still answering?
    probe_cmd = mav.command_long_encode(ep.sysid, 1, mavlink2.MAV_CMD_REQUEST_MESSAGE, 0,
                                        mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
    sock.sendto(probe_cmd.pack(mav), addr)
    rx = mavlink2.MAVLink(None, 0, 0)
    rx.robust_parsing = True
    answered = False
    end = time.monotonic() + 10
    while time.monotonic() < end and not answered:
        v.step(5)
        try:
            while True:
                for m in rx.parse_buffer(sock.recv(4096)) or []:
                    if m.get_type() == "COMMAND_ACK" and m.command == mavlink2.MAV_CMD_REQUEST_MESSAGE \
                            and m.result == mavlink2.MAV_RESULT_ACCEPTED:
                        answered = True
        except BlockingIOError:
            pass
    sitl.close()
    sock.close()
    stats = dict(ep.stats)
    return {"sent": sent, "skipped_valid": skipped, "wall_s": wall, "rate": sent / wall,
            "state_unchanged": before == after, "answered": answered, "stats": stats}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=1_000_000, help="datagrams to send")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args()
    logging.basicConfig(level=logging.WARNING)
    r = run_fuzz(args.count, args.seed)
    print("MAVLink endpoint fuzz")
    print(f"{'datagrams sent':32s} {r['sent']:>12,d}")
    print(f"{'wall time (s)':32s} {r['wall_s']:>12.1f}")
    print(f"{'datagrams / s':32s} {r['rate']:>12,.0f}")
    print(f"{'state unchanged':32s} {r['state_unchanged']!s:>12s}")
    print(f"{'answers afterwards':32s} {r['answered']!s:>12s}")
    for k, val in sorted(r["stats"].items()):
        print(f"  {k:30s} {val:>12,d}")
    return 0 if r["state_unchanged"] and r["answered"] else 1


if __name__ == "__main__":
    sys.exit(main())
