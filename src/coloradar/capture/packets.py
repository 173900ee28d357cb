"""Raw DCA1000 packet dumps (``adc_data_Raw_0.bin``): the UDP data packets as they arrived.

Each packet is a 10-byte little-endian header — a 4-byte sequence number (1 for the first packet
of a recording) and a 6-byte byte count (the stream bytes sent before this packet) — followed by
its payload, a fixed size for every packet but the last (1456 bytes by default; it is read from
the first two headers). A dropped packet shows as a jump of the sequence number, and the next
packet's byte count says exactly where its payload lies in the stream, so what was lost is a
known byte range: the frames it touches are reported, never shifted (docs/capture.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..errors import FormatError

__all__ = ["HEADER_BYTES", "PacketStream", "read_packet_dump"]

HEADER_BYTES = 10
"""Bytes of a packet header: sequence number (4) and byte count (6)."""

_MAX_PAYLOAD = 65_000


@dataclass(frozen=True, eq=False)
class PacketStream:
    """The ADC byte stream rebuilt from a packet dump.

    Attributes
    ----------
    data
        uint8 ``(N,)``: the stream, bytes of dropped packets zero.
    missing
        ``(start, stop)`` byte ranges of the stream that no packet delivered.
    packets, dropped_packets
        Packets read; packets missing (sequence-number gaps).
    payload_bytes
        Payload of a full packet.
    """

    data: np.ndarray
    missing: tuple[tuple[int, int], ...]
    packets: int
    dropped_packets: int
    payload_bytes: int


def _headers(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sequence numbers and byte counts of ``(n, >=10)`` uint8 rows."""
    seq = buf[:, 0:4].copy().view("<u4")[:, 0].astype(np.int64)
    bc8 = np.zeros((buf.shape[0], 8), dtype=np.uint8)
    bc8[:, :6] = buf[:, 4:10]
    return seq, bc8.view("<u8")[:, 0].astype(np.int64)


def _payload_size(raw: np.ndarray, name: str) -> int:
    """The payload of a full packet: the offset at which the second header follows the first."""
    n = raw.size
    if n < HEADER_BYTES:
        raise FormatError(f"{name}: {n} bytes, shorter than one packet header ({HEADER_BYTES})")
    seq0, bc0 = (int(v[0]) for v in _headers(raw[None, :HEADER_BYTES]))
    for p in range(1, min(n - 2 * HEADER_BYTES, _MAX_PAYLOAD) + 1):
        s, b = (int(v[0]) for v in _headers(raw[None, HEADER_BYTES + p:2 * HEADER_BYTES + p]))
        # The next packet: sequence one or a few more (drops), byte count at least one payload on.
        if seq0 < s <= seq0 + 64 and b >= bc0 + p and (b - bc0) % p == 0 and \
                (b - bc0) // p == s - seq0:
            return p
    if n - HEADER_BYTES <= _MAX_PAYLOAD:
        return n - HEADER_BYTES           # a single packet
    raise FormatError(f"{name}: no second packet header found after the first (sequence "
                      f"{seq0}, byte count {bc0}); not a DCA1000 raw packet dump (each packet: "
                      "4-byte sequence number, 6-byte byte count, payload)")


def read_packet_dump(raw: bytes | memoryview | np.ndarray, name: str = "<packets>",
                     payload_bytes: int | None = None) -> PacketStream:
    """Rebuild the ADC stream of a DCA1000 raw packet dump.

    Parameters
    ----------
    raw
        The dump's bytes.
    name
        The file's name, for messages.
    payload_bytes
        Payload of a full packet; None: found from the first two headers.

    Returns
    -------
    PacketStream

    Raises
    ------
    FormatError
        No packet structure, sequence numbers that go back, or a byte count that disagrees with
        the payloads before it (the message names the packet and its file offset).
    """
    buf = np.frombuffer(raw, dtype=np.uint8) if not isinstance(raw, np.ndarray) else raw
    p = payload_bytes or _payload_size(buf, name)
    rec = HEADER_BYTES + p
    n_full, tail = divmod(buf.size, rec)
    rows = buf[:n_full * rec].reshape(n_full, rec)
    lens = np.full(n_full, p, dtype=np.int64)
    if tail:
        if tail <= HEADER_BYTES:
            raise FormatError(f"{name}: the last {tail} bytes (from offset {n_full * rec:,}) are "
                              f"a cut packet header; each packet is {HEADER_BYTES} header bytes "
                              f"plus up to {p} payload bytes")
        last = np.zeros((1, rec), dtype=np.uint8)
        last[0, :tail] = buf[n_full * rec:]
        rows = np.concatenate([rows, last])
        lens = np.append(lens, tail - HEADER_BYTES)
    seq, bc = _headers(rows)
    dseq = np.diff(seq)
    bad = np.flatnonzero(dseq <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise FormatError(f"{name}: packet {i} (file offset {i * rec:,}) has sequence number "
                          f"{seq[i]} after {seq[i - 1]}; sequence numbers must increase")
    ends = bc + lens
    gap = bc[1:] - ends[:-1]
    wrong = np.flatnonzero((gap < 0) | ((dseq == 1) & (gap != 0)))
    if wrong.size:
        i = int(wrong[0]) + 1
        raise FormatError(f"{name}: packet {i} (file offset {i * rec:,}, sequence {seq[i]}) "
                          f"has byte count {bc[i]:,} but the packets before it end at byte "
                          f"{ends[i - 1]:,}")
    missing = []
    if bc[0] > 0:
        missing.append((0, int(bc[0])))
    missing += [(int(ends[i]), int(bc[i + 1])) for i in np.flatnonzero(gap > 0)]
    data = np.zeros(int(ends[-1]), dtype=np.uint8)
    # Runs of packets without a gap are one contiguous copy each.
    starts = np.concatenate([[0], np.flatnonzero(gap > 0) + 1, [len(rows)]])
    for a, b in itertools.pairwise(starts):
        block = rows[a:b, HEADER_BYTES:]
        if lens[b - 1] != p:                       # the short last packet
            flat = np.concatenate([block[:-1].ravel(), block[-1, :lens[b - 1]]])
        else:
            flat = block.ravel()
        data[bc[a]:bc[a] + flat.size] = flat
    first_missing = int(seq[0]) - 1
    return PacketStream(data, tuple(missing), len(rows),
                        int(np.sum(dseq - 1)) + max(first_missing, 0), p)
